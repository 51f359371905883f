//! ZIP and TAR archives of numbered PNG/JPEG frames (or 0/255 masks).
//!
//! Entries are ordered by a natural sort of their names (`frame2` before
//! `frame10`). Directories, entries without a `.png`/`.jpg`/`.jpeg` name and
//! system litter (`__MACOSX/`, names starting with `.` such as `.DS_Store` or
//! `._x.png`, `Thumbs.db`) are skipped. An entry whose name contains a `..`
//! component, starts with `/` or a drive letter, or contains a backslash or NUL
//! makes the whole archive refused ([`DecodeError::Corrupt`]): nothing is ever
//! extracted to disk, but such an archive is hostile or broken.
//!
//! Zip bombs: an entry's declared size and the bytes actually inflated (read
//! through [`Read::take`]) are both checked against
//! [`Limits::max_entry_bytes`], and the running total against
//! [`Limits::max_total_bytes`]; image dimensions are checked against the size
//! limits by the image decoder before it allocates pixels.
//!
//! All frames must have the size of the first. An archive whose frames are
//! all binary (every pixel gray and 0 or 255) is a mask clip
//! ([`ClipInfo::is_mask`]); deciding this decodes every frame once at open
//! when the first one is binary (it stops at the first non-binary frame).
//!
//! The TAR reader is a small one of our own (ustar, GNU long names, pax
//! `path`/`size` records).
//!
//! Memory: the index of image entries (name, position, size: ~100 bytes
//! each), the ZIP central directory held by the `zip` crate, and one entry's
//! bytes and one decoded frame at a time.

use std::cmp::Ordering;
use std::fs::File;
use std::io::{BufReader, Cursor, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use image::{ImageFormat, RgbImage};

use super::anim::{image_err, jpeg_complete};
use super::decode::{ClipInfo, DecodeError, FrameSource, Limits};

/// An I/O error, or `Truncated` when the file ended early.
fn io_err(path: &Path, source: std::io::Error) -> DecodeError {
    DecodeError::io_or_truncated(path, source, "the archive ends inside an entry")
}

/// Which archive format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ArchiveKind {
    Zip,
    Tar,
}

impl ArchiveKind {
    fn name(self) -> &'static str {
        match self {
            ArchiveKind::Zip => "zip",
            ArchiveKind::Tar => "tar",
        }
    }
}

/// One image entry of the index.
#[derive(Clone, Debug)]
struct Entry {
    name: String,
    /// ZIP: the entry's index in the archive. TAR: the data's byte offset.
    pos: u64,
    /// Declared (uncompressed) size.
    size: u64,
}

/// Compares names with digit runs taken as numbers (`a2` < `a10`).
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (mut x, mut y) = (a.as_bytes(), b.as_bytes());
    loop {
        match (x.first(), y.first()) {
            (None, None) => return a.cmp(b),
            (None, Some(_)) => return Ordering::Less,
            (Some(_), None) => return Ordering::Greater,
            (Some(c), Some(d)) if c.is_ascii_digit() && d.is_ascii_digit() => {
                let nx = x.iter().take_while(|c| c.is_ascii_digit()).count();
                let ny = y.iter().take_while(|c| c.is_ascii_digit()).count();
                let (dx, dy) = (&x[..nx], &y[..ny]);
                let tx = &dx[dx.iter().take_while(|&&c| c == b'0').count()..];
                let ty = &dy[dy.iter().take_while(|&&c| c == b'0').count()..];
                let ord = tx.len().cmp(&ty.len()).then_with(|| tx.cmp(ty));
                if ord != Ordering::Equal {
                    return ord;
                }
                x = &x[nx..];
                y = &y[ny..];
            }
            (Some(c), Some(d)) => {
                let ord = c.to_ascii_lowercase().cmp(&d.to_ascii_lowercase());
                if ord != Ordering::Equal {
                    return ord;
                }
                x = &x[1..];
                y = &y[1..];
            }
        }
    }
}

/// Refuses names that would escape a directory if extracted.
fn check_name(path: &Path, name: &str) -> Result<(), DecodeError> {
    let bytes = name.as_bytes();
    let drive = bytes.len() >= 2 && bytes[0].is_ascii_alphabetic() && bytes[1] == b':';
    let bad = name.starts_with('/')
        || name.contains('\\')
        || name.contains('\0')
        || drive
        || name.split('/').any(|c| c == "..");
    if bad {
        return Err(DecodeError::corrupt(
            path,
            format!("unsafe entry name {name:?} (absolute, `..` or backslash): archive refused"),
        ));
    }
    Ok(())
}

/// Whether an entry name is a frame (by name; the content is sniffed later).
fn is_frame_name(name: &str) -> bool {
    if name.ends_with('/') || name.split('/').any(|c| c == "__MACOSX") {
        return false;
    }
    let base = name.rsplit('/').next().unwrap_or(name);
    if base.starts_with('.') || base.eq_ignore_ascii_case("thumbs.db") {
        return false;
    }
    let lower = base.to_ascii_lowercase();
    lower.ends_with(".png") || lower.ends_with(".jpg") || lower.ends_with(".jpeg")
}

fn too_large(path: &Path, what: String) -> DecodeError {
    DecodeError::TooLarge {
        path: path.to_path_buf(),
        what,
    }
}

fn check_entry_size(
    path: &Path,
    name: &str,
    size: u64,
    limits: &Limits,
) -> Result<(), DecodeError> {
    if size > limits.max_entry_bytes {
        return Err(too_large(
            path,
            format!(
                "entry {name:?} declares {size} bytes (the limit is {} per entry)",
                limits.max_entry_bytes
            ),
        ));
    }
    Ok(())
}

/// Parses an octal (or GNU base-256) tar number.
fn tar_number(field: &[u8]) -> Option<u64> {
    if field.first().is_some_and(|b| b & 0x80 != 0) {
        let mut v: u64 = u64::from(field[0] & 0x7f);
        for &b in &field[1..] {
            v = v.checked_mul(256)?.checked_add(u64::from(b))?;
        }
        return Some(v);
    }
    let text: Vec<u8> = field
        .iter()
        .copied()
        .skip_while(|&b| b == b' ')
        .take_while(|&b| (b'0'..=b'7').contains(&b))
        .collect();
    if text.is_empty() {
        return Some(0);
    }
    u64::from_str_radix(std::str::from_utf8(&text).ok()?, 8).ok()
}

fn cstr(field: &[u8]) -> String {
    let end = field.iter().position(|&b| b == 0).unwrap_or(field.len());
    String::from_utf8_lossy(&field[..end]).into_owned()
}

/// Most bytes of a GNU long name or pax header we read.
const MAX_META: u64 = 64 << 10;

/// Walks a tar file's headers into an index of image entries.
fn index_tar(
    r: &mut BufReader<File>,
    path: &Path,
    limits: &Limits,
) -> Result<Vec<Entry>, DecodeError> {
    let file_len = r.get_ref().metadata().map_err(|e| io_err(path, e))?.len();
    let mut entries = Vec::new();
    let mut offset: u64 = 0;
    let mut long_name: Option<String> = None;
    let mut pax_size: Option<u64> = None;
    let mut seen = 0u64;
    loop {
        let mut block = [0u8; 512];
        match r.read_exact(&mut block) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
                // Without its end-of-archive block a tar file may have lost
                // entries: refused rather than read short.
                let what = if offset == file_len {
                    format!("the tar archive stops at byte {offset} without its end marker")
                } else {
                    format!("a tar header at byte {offset} is cut off")
                };
                return Err(DecodeError::Truncated {
                    path: path.to_path_buf(),
                    what,
                });
            }
            Err(e) => return Err(io_err(path, e)),
        }
        offset += 512;
        if block.iter().all(|&b| b == 0) {
            break;
        }
        let stored = tar_number(&block[148..156])
            .ok_or_else(|| DecodeError::corrupt(path, "bad tar checksum field"))?;
        let sum: u64 = block
            .iter()
            .enumerate()
            .map(|(i, &b)| {
                if (148..156).contains(&i) {
                    32
                } else {
                    u64::from(b)
                }
            })
            .sum();
        if sum != stored {
            return Err(DecodeError::corrupt(
                path,
                format!("tar header at byte {} has a bad checksum", offset - 512),
            ));
        }
        let mut size = tar_number(&block[124..136])
            .ok_or_else(|| DecodeError::corrupt(path, "bad tar size field"))?;
        if let Some(s) = pax_size.take() {
            size = s;
        }
        let data_at = offset;
        let padded = size
            .div_ceil(512)
            .checked_mul(512)
            .ok_or_else(|| DecodeError::corrupt(path, "bad tar size"))?;
        if data_at.saturating_add(size) > file_len {
            return Err(DecodeError::Truncated {
                path: path.to_path_buf(),
                what: format!(
                    "a tar entry at byte {data_at} needs {size} bytes; the file ends first"
                ),
            });
        }
        let kind = block[156];
        let read_meta = |r: &mut BufReader<File>| -> Result<Vec<u8>, DecodeError> {
            if size > MAX_META {
                return Err(too_large(
                    path,
                    format!("a tar metadata entry of {size} bytes"),
                ));
            }
            let mut buf = vec![0u8; size as usize];
            r.read_exact(&mut buf).map_err(|e| io_err(path, e))?;
            r.seek_relative((padded - size) as i64)
                .map_err(|e| io_err(path, e))?;
            Ok(buf)
        };
        match kind {
            b'L' => {
                long_name = Some(cstr(&read_meta(r)?));
            }
            b'x' => {
                let meta = read_meta(r)?;
                for (key, value) in pax_records(&meta) {
                    match key {
                        "path" => long_name = Some(value.to_string()),
                        "size" => pax_size = value.parse().ok(),
                        _ => {}
                    }
                }
            }
            _ => {
                let name = match long_name.take() {
                    Some(n) => n,
                    None => {
                        let base = cstr(&block[..100]);
                        let prefix = if &block[257..262] == b"ustar" {
                            cstr(&block[345..500])
                        } else {
                            String::new()
                        };
                        if prefix.is_empty() {
                            base
                        } else {
                            format!("{prefix}/{base}")
                        }
                    }
                };
                check_name(path, &name)?;
                seen += 1;
                if seen > limits.max_frames.saturating_mul(4).saturating_add(1024) {
                    return Err(too_large(path, "too many archive entries".into()));
                }
                if matches!(kind, b'0' | 0 | b'7') && is_frame_name(&name) {
                    check_entry_size(path, &name, size, limits)?;
                    entries.push(Entry {
                        name,
                        pos: data_at,
                        size,
                    });
                }
                r.seek_relative(padded as i64)
                    .map_err(|e| io_err(path, e))?;
            }
        }
        offset = data_at + padded;
    }
    Ok(entries)
}

/// `len key=value\n` records of a pax header.
fn pax_records(meta: &[u8]) -> Vec<(&str, &str)> {
    let mut out = Vec::new();
    let mut rest = meta;
    while !rest.is_empty() {
        let Some(space) = rest.iter().position(|&b| b == b' ') else {
            break;
        };
        let Some(len) = std::str::from_utf8(&rest[..space])
            .ok()
            .and_then(|s| s.parse::<usize>().ok())
        else {
            break;
        };
        if len <= space + 1 || len > rest.len() {
            break;
        }
        let record = &rest[space + 1..len];
        let record = record.strip_suffix(b"\n").unwrap_or(record);
        if let Ok(text) = std::str::from_utf8(record) {
            if let Some((k, v)) = text.split_once('=') {
                out.push((k, v));
            }
        }
        rest = &rest[len..];
    }
    out
}

fn index_zip(
    zip: &zip::ZipArchive<BufReader<File>>,
    path: &Path,
    limits: &Limits,
) -> Result<Vec<Entry>, DecodeError> {
    if zip.len() as u64 > limits.max_frames.saturating_mul(4).saturating_add(1024) {
        return Err(too_large(path, format!("{} archive entries", zip.len())));
    }
    let mut entries = Vec::new();
    for i in 0..zip.len() {
        let entry = zip.by_index_data(i).map_err(|e| zip_err(path, e))?;
        let name = String::from_utf8_lossy(entry.name_raw()).into_owned();
        check_name(path, &name)?;
        if entry.is_dir() || !is_frame_name(&name) {
            continue;
        }
        check_entry_size(path, &name, entry.size(), limits)?;
        entries.push(Entry {
            name,
            pos: i as u64,
            size: entry.size(),
        });
    }
    Ok(entries)
}

fn zip_err(path: &Path, e: zip::result::ZipError) -> DecodeError {
    match e {
        zip::result::ZipError::Io(io) => io_err(path, io),
        zip::result::ZipError::UnsupportedArchive(what) => DecodeError::UnsupportedCodec {
            path: path.to_path_buf(),
            container: "zip".into(),
            codec: what.to_string(),
        },
        other => DecodeError::corrupt(path, other.to_string()),
    }
}

enum Reader {
    Zip(Box<zip::ZipArchive<BufReader<File>>>),
    Tar(BufReader<File>),
}

/// Reads one entry's bytes, at most `max_entry_bytes` of them.
fn read_entry(
    reader: &mut Reader,
    entry: &Entry,
    path: &Path,
    limits: &Limits,
) -> Result<Vec<u8>, DecodeError> {
    let cap = limits.max_entry_bytes;
    let mut buf = Vec::with_capacity(entry.size.min(cap).min(16 << 20) as usize);
    match reader {
        Reader::Zip(zip) => {
            let file = zip
                .by_index(entry.pos as usize)
                .map_err(|e| zip_err(path, e))?;
            file.take(cap + 1).read_to_end(&mut buf).map_err(|e| {
                if e.kind() == std::io::ErrorKind::InvalidData
                    || e.kind() == std::io::ErrorKind::Other
                {
                    DecodeError::corrupt(path, format!("entry {:?}: {e}", entry.name))
                } else {
                    io_err(path, e)
                }
            })?;
        }
        Reader::Tar(r) => {
            r.seek(SeekFrom::Start(entry.pos))
                .map_err(|e| io_err(path, e))?;
            r.by_ref()
                .take(entry.size.min(cap + 1))
                .read_to_end(&mut buf)
                .map_err(|e| io_err(path, e))?;
            if (buf.len() as u64) < entry.size.min(cap + 1) {
                return Err(DecodeError::Truncated {
                    path: path.to_path_buf(),
                    what: format!("entry {:?} is cut off", entry.name),
                });
            }
        }
    }
    if buf.len() as u64 > cap {
        return Err(too_large(
            path,
            format!(
                "entry {:?} inflates past {cap} bytes (the per-entry limit)",
                entry.name
            ),
        ));
    }
    Ok(buf)
}

/// Decodes a PNG or JPEG held in memory, honouring the size limits.
fn decode_image(
    bytes: &[u8],
    name: &str,
    path: &Path,
    limits: &Limits,
) -> Result<(RgbImage, &'static str), DecodeError> {
    let mut reader = image::ImageReader::new(Cursor::new(bytes));
    let mut il = image::Limits::default();
    il.max_image_width = Some(limits.max_width);
    il.max_image_height = Some(limits.max_height);
    il.max_alloc =
        Some((u64::from(limits.max_width) * u64::from(limits.max_height) * 8).max(64 << 20));
    reader.limits(il);
    let reader = reader.with_guessed_format().map_err(|e| io_err(path, e))?;
    let codec = match reader.format() {
        Some(ImageFormat::Png) => "png",
        Some(ImageFormat::Jpeg) => "jpeg",
        _ => {
            return Err(DecodeError::corrupt(
                path,
                format!("entry {name:?} is neither PNG nor JPEG"),
            ))
        }
    };
    if codec == "jpeg" && !jpeg_complete(bytes) {
        return Err(DecodeError::Truncated {
            path: path.to_path_buf(),
            what: format!("entry {name:?}: the JPEG has no end-of-image marker"),
        });
    }
    let (w, h) = reader.into_dimensions().map_err(|e| image_err(path, e))?;
    limits.check_size(path, w, h)?;
    let mut reader = image::ImageReader::new(Cursor::new(bytes));
    reader.set_format(if codec == "png" {
        ImageFormat::Png
    } else {
        ImageFormat::Jpeg
    });
    let img = reader.decode().map_err(|e| match image_err(path, e) {
        DecodeError::Corrupt { path, what } => DecodeError::Corrupt {
            path,
            what: format!("entry {name:?}: {what}"),
        },
        other => other,
    })?;
    Ok((img.into_rgb8(), codec))
}

/// Every pixel gray and 0 or 255.
fn is_binary(img: &RgbImage) -> bool {
    img.as_raw()
        .chunks_exact(3)
        .all(|p| p[0] == p[1] && p[1] == p[2] && (p[0] == 0 || p[0] == 255))
}

/// Streaming reader of an archive's frames (see the module notes).
pub struct ArchiveSource {
    path: PathBuf,
    reader: Reader,
    entries: Vec<Entry>,
    info: ClipInfo,
    limits: Limits,
    next: usize,
    total: u64,
    failed: bool,
}

impl ArchiveSource {
    fn frame(&mut self, i: usize) -> Result<(RgbImage, &'static str), DecodeError> {
        let entry = self.entries[i].clone();
        let bytes = read_entry(&mut self.reader, &entry, &self.path, &self.limits)?;
        self.total += bytes.len() as u64;
        if self.total > self.limits.max_total_bytes {
            return Err(too_large(
                &self.path,
                format!(
                    "entries inflate past {} bytes in all",
                    self.limits.max_total_bytes
                ),
            ));
        }
        let (img, codec) = decode_image(&bytes, &entry.name, &self.path, &self.limits)?;
        drop(bytes);
        if i > 0 && img.dimensions() != (self.info.width, self.info.height) {
            return Err(DecodeError::corrupt(
                &self.path,
                format!(
                    "mixed frame sizes: {:?} is {}×{}, the first frame {}×{}",
                    entry.name,
                    img.width(),
                    img.height(),
                    self.info.width,
                    self.info.height
                ),
            ));
        }
        Ok((img, codec))
    }

    /// Checks the PNG header of every entry for the frame size (cheap: 24 bytes each).
    fn check_png_sizes(&mut self) -> Result<(), DecodeError> {
        for i in 1..self.entries.len() {
            let entry = &self.entries[i];
            let mut head = [0u8; 24];
            let got = match &mut self.reader {
                Reader::Zip(zip) => {
                    let file = zip
                        .by_index(entry.pos as usize)
                        .map_err(|e| zip_err(&self.path, e))?;
                    read_up_to(file, &mut head)
                }
                Reader::Tar(r) => {
                    r.seek(SeekFrom::Start(entry.pos))
                        .map_err(|e| io_err(&self.path, e))?;
                    read_up_to(r.by_ref().take(entry.size), &mut head)
                }
            };
            let got = got.map_err(|e| {
                DecodeError::corrupt(&self.path, format!("entry {:?}: {e}", entry.name))
            })?;
            if got == 24 && head.starts_with(b"\x89PNG\r\n\x1a\n") && &head[12..16] == b"IHDR" {
                let w = u32::from_be_bytes([head[16], head[17], head[18], head[19]]);
                let h = u32::from_be_bytes([head[20], head[21], head[22], head[23]]);
                if (w, h) != (self.info.width, self.info.height) {
                    return Err(DecodeError::corrupt(
                        &self.path,
                        format!(
                            "mixed frame sizes: {:?} is {w}×{h}, the first frame {}×{}",
                            entry.name, self.info.width, self.info.height
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

fn read_up_to<R: Read>(mut r: R, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

impl FrameSource for ArchiveSource {
    fn info(&self) -> &ClipInfo {
        &self.info
    }

    fn next_frame(&mut self) -> Result<Option<RgbImage>, DecodeError> {
        if self.failed || self.next >= self.entries.len() {
            return Ok(None);
        }
        let i = self.next;
        match self.frame(i) {
            Ok((img, _)) => {
                self.next += 1;
                Ok(Some(img))
            }
            Err(e) => {
                self.failed = true;
                Err(e)
            }
        }
    }
}

/// Opens an archive: indexes it, decodes the first frame for the size and
/// decides whether it is a mask clip. `frames_in_info`: the frame rate to
/// report (archives carry none; 0 if unknown).
pub fn open_archive(
    path: &Path,
    kind: ArchiveKind,
    limits: &Limits,
) -> Result<ArchiveSource, DecodeError> {
    let file = File::open(path).map_err(|e| io_err(path, e))?;
    let mut buffered = BufReader::new(file);
    let (reader, mut entries) = match kind {
        ArchiveKind::Zip => {
            let zip = zip::ZipArchive::new(buffered).map_err(|e| match e {
                zip::result::ZipError::InvalidArchive(_) => {
                    let what = e.to_string();
                    DecodeError::Corrupt {
                        path: path.to_path_buf(),
                        what,
                    }
                }
                other => zip_err(path, other),
            })?;
            let entries = index_zip(&zip, path, limits)?;
            (Reader::Zip(Box::new(zip)), entries)
        }
        ArchiveKind::Tar => {
            let entries = index_tar(&mut buffered, path, limits)?;
            (Reader::Tar(buffered), entries)
        }
    };
    if entries.is_empty() {
        return Err(DecodeError::UnknownFormat {
            path: path.to_path_buf(),
            what: format!("the {} archive holds no PNG or JPEG frames", kind.name()),
        });
    }
    if entries.len() as u64 > limits.max_frames {
        return Err(too_large(
            path,
            format!(
                "{} frames (the limit is {})",
                entries.len(),
                limits.max_frames
            ),
        ));
    }
    let declared: u64 = entries.iter().map(|e| e.size).fold(0, u64::saturating_add);
    if declared > limits.max_total_bytes {
        return Err(too_large(
            path,
            format!(
                "entries declare {declared} bytes in all (the limit is {})",
                limits.max_total_bytes
            ),
        ));
    }
    entries.sort_by(|a, b| natural_cmp(&a.name, &b.name));
    let mut source = ArchiveSource {
        path: path.to_path_buf(),
        reader,
        entries,
        info: ClipInfo {
            container: kind.name().into(),
            codec: String::new(),
            width: 0,
            height: 0,
            fps: 0.0,
            frame_count: 0,
            duration_s: 0.0,
            is_mask: false,
        },
        limits: limits.clone(),
        next: 0,
        total: 0,
        failed: false,
    };
    let (first, codec) = source.frame(0)?;
    source.info.codec = codec.into();
    source.info.width = first.width();
    source.info.height = first.height();
    source.info.frame_count = source.entries.len() as u64;
    source.check_png_sizes()?;
    if is_binary(&first) {
        drop(first);
        let mut all = true;
        for i in 1..source.entries.len() {
            let (img, _) = source.frame(i)?;
            if !is_binary(&img) {
                all = false;
                break;
            }
        }
        source.info.is_mask = all;
    }
    source.total = 0;
    Ok(source)
}

/// Opens an archive of frames for streaming.
pub fn open(
    path: &Path,
    kind: ArchiveKind,
    limits: &Limits,
) -> Result<Box<dyn FrameSource>, DecodeError> {
    Ok(Box::new(open_archive(path, kind, limits)?))
}

/// Indexes the archive and decodes its first frame (all frames for a mask archive).
pub fn probe(path: &Path, kind: ArchiveKind, limits: &Limits) -> Result<ClipInfo, DecodeError> {
    Ok(open_archive(path, kind, limits)?.info.clone())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order() {
        let mut names = vec![
            "frame10.png",
            "frame2.png",
            "frame1.png",
            "Frame3.png",
            "frame002b.png",
        ];
        names.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            names,
            [
                "frame1.png",
                "frame2.png",
                "frame002b.png",
                "Frame3.png",
                "frame10.png"
            ]
        );
    }

    #[test]
    fn names() {
        let p = Path::new("x.zip");
        assert!(check_name(p, "../../etc/passwd").is_err());
        assert!(check_name(p, "/etc/passwd").is_err());
        assert!(check_name(p, "a\\b.png").is_err());
        assert!(check_name(p, "C:x.png").is_err());
        assert!(check_name(p, "a/b..c.png").is_ok());
        assert!(is_frame_name("clip/0001.PNG"));
        assert!(!is_frame_name("__MACOSX/clip/._0001.png"));
        assert!(!is_frame_name(".DS_Store"));
        assert!(!is_frame_name("Thumbs.db"));
        assert!(!is_frame_name("dir/"));
    }

    #[test]
    fn tar_numbers() {
        assert_eq!(tar_number(b"0000644\0"), Some(0o644));
        assert_eq!(tar_number(b"  12 \0"), Some(10));
        assert_eq!(tar_number(&[0x80, 0, 0, 1, 0]), Some(256));
    }
}
