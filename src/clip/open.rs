//! One entry point for every input clip: the format is sniffed from the
//! file's first bytes (never its extension) and the matching decoder opened.
//!
//! | first bytes                         | format                      |
//! |-------------------------------------|-----------------------------|
//! | `....ftyp` / `moov` / `mdat` / …    | MP4/MOV ([`super::mp4`])    |
//! | `RIFF....AVI `                      | AVI ([`super::avi`])        |
//! | `RIFF....WEBP`                      | WebP ([`super::anim`])      |
//! | `YUV4MPEG2 `                        | Y4M ([`super::y4m`])        |
//! | `GIF87a` / `GIF89a`                 | GIF ([`super::anim`])       |
//! | `\x89PNG\r\n\x1a\n`                 | PNG or APNG ([`super::anim`]) |
//! | `\xFF\xD8\xFF`                      | JPEG, one frame             |
//! | `PK\x03\x04` / `PK\x05\x06`         | ZIP of frames ([`super::archive`]) |
//! | `ustar` at offset 257               | TAR of frames ([`super::archive`]) |
//!
//! When a built-in decoder answers [`DecodeError::UnsupportedCodec`] (HEVC in
//! MP4, say) or the bytes are of no known format, and an `ffmpeg` binary is
//! on `PATH`, the clip is read through it ([`super::ffmpeg`]).

use std::fs::File;
use std::io::Read;
use std::path::Path;

use image::RgbImage;

use super::anim::AnimKind;
use super::archive::ArchiveKind;
use super::decode::{ClipInfo, DecodeError, FrameSource, Limits};
use super::{anim, archive, avi, ffmpeg, mp4, y4m};

/// A container recognised from its first bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sniffed {
    Mp4,
    Avi,
    WebP,
    Y4m,
    Gif,
    Png,
    Jpeg,
    Zip,
    Tar,
}

/// Bytes read for sniffing (TAR's magic sits at 257).
const SNIFF_LEN: usize = 512;

/// Recognises a container from the first bytes of a file.
pub fn sniff(head: &[u8]) -> Option<Sniffed> {
    let at = |off: usize, magic: &[u8]| head.get(off..off + magic.len()) == Some(magic);
    if at(4, b"ftyp")
        || ["moov", "mdat", "free", "skip", "wide", "pnot"]
            .iter()
            .any(|b| at(4, b.as_bytes()))
    {
        return Some(Sniffed::Mp4);
    }
    if at(0, b"RIFF") && at(8, b"AVI ") {
        return Some(Sniffed::Avi);
    }
    if at(0, b"RIFF") && at(8, b"WEBP") {
        return Some(Sniffed::WebP);
    }
    if at(0, b"YUV4MPEG2 ") {
        return Some(Sniffed::Y4m);
    }
    if at(0, b"GIF87a") || at(0, b"GIF89a") {
        return Some(Sniffed::Gif);
    }
    if at(0, b"\x89PNG\r\n\x1a\n") {
        return Some(Sniffed::Png);
    }
    if at(0, b"\xFF\xD8\xFF") {
        return Some(Sniffed::Jpeg);
    }
    if at(0, b"PK\x03\x04") || at(0, b"PK\x05\x06") {
        return Some(Sniffed::Zip);
    }
    if at(257, b"ustar") {
        return Some(Sniffed::Tar);
    }
    None
}

/// Describes unknown first bytes for an error message.
fn describe(head: &[u8]) -> String {
    if head.is_empty() {
        return "the file is empty".into();
    }
    let shown = &head[..head.len().min(16)];
    let printable = shown
        .iter()
        .filter(|b| {
            b.is_ascii_graphic() || **b == b' ' || **b == b'\n' || **b == b'\r' || **b == b'\t'
        })
        .count();
    let hex: Vec<String> = shown.iter().map(|b| format!("{b:02x}")).collect();
    if printable == shown.len() {
        let text: String = String::from_utf8_lossy(shown)
            .chars()
            .map(|c| if c.is_control() { ' ' } else { c })
            .collect();
        format!("unknown format; the file starts like text ({:?}), not a video, image sequence or archive", text.trim_end())
    } else {
        format!("unknown format; the first bytes are {}", hex.join(" "))
    }
}

fn read_head(path: &Path) -> Result<Vec<u8>, DecodeError> {
    let file = File::open(path).map_err(|error| DecodeError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    let mut head = Vec::with_capacity(SNIFF_LEN);
    file.take(SNIFF_LEN as u64)
        .read_to_end(&mut head)
        .map_err(|error| DecodeError::Io {
            path: path.to_path_buf(),
            error,
        })?;
    Ok(head)
}

/// Whether an error should be retried through ffmpeg.
fn ffmpeg_can_help(e: &DecodeError) -> bool {
    matches!(
        e,
        DecodeError::UnsupportedCodec { .. } | DecodeError::UnknownFormat { .. }
    ) && ffmpeg::available()
}

fn open_builtin(path: &Path, limits: &Limits) -> Result<Box<dyn FrameSource>, DecodeError> {
    let head = read_head(path)?;
    match sniff(&head) {
        Some(Sniffed::Mp4) => mp4::open(path, limits),
        Some(Sniffed::Avi) => avi::open(path, limits),
        Some(Sniffed::WebP) => anim::open(path, AnimKind::WebP, limits),
        Some(Sniffed::Y4m) => y4m::open(path, limits),
        Some(Sniffed::Gif) => anim::open(path, AnimKind::Gif, limits),
        Some(Sniffed::Png) => anim::open(path, AnimKind::Png, limits),
        Some(Sniffed::Jpeg) => anim::open(path, AnimKind::Jpeg, limits),
        Some(Sniffed::Zip) => archive::open(path, ArchiveKind::Zip, limits),
        Some(Sniffed::Tar) => archive::open(path, ArchiveKind::Tar, limits),
        None => Err(DecodeError::UnknownFormat {
            path: path.to_path_buf(),
            what: describe(&head),
        }),
    }
}

fn probe_builtin(path: &Path, limits: &Limits) -> Result<ClipInfo, DecodeError> {
    let head = read_head(path)?;
    match sniff(&head) {
        Some(Sniffed::Mp4) => mp4::probe(path, limits),
        Some(Sniffed::Avi) => avi::probe(path, limits),
        Some(Sniffed::WebP) => anim::probe(path, AnimKind::WebP, limits),
        Some(Sniffed::Y4m) => y4m::probe(path, limits),
        Some(Sniffed::Gif) => anim::probe(path, AnimKind::Gif, limits),
        Some(Sniffed::Png) => anim::probe(path, AnimKind::Png, limits),
        Some(Sniffed::Jpeg) => anim::probe(path, AnimKind::Jpeg, limits),
        Some(Sniffed::Zip) => archive::probe(path, ArchiveKind::Zip, limits),
        Some(Sniffed::Tar) => archive::probe(path, ArchiveKind::Tar, limits),
        None => Err(DecodeError::UnknownFormat {
            path: path.to_path_buf(),
            what: describe(&head),
        }),
    }
}

/// Opens any supported clip for streaming, falling back on ffmpeg (when on
/// `PATH`) for codecs and containers the built-in decoders do not read.
pub fn open(path: &Path, limits: &Limits) -> Result<Box<dyn FrameSource>, DecodeError> {
    match open_builtin(path, limits) {
        Err(e) if ffmpeg_can_help(&e) => ffmpeg::open(path, limits).map_err(|_| e),
        other => other,
    }
}

/// What a clip is, read from its headers where the format allows (a frame
/// archive decodes its first frame; a mask archive all of them).
pub fn probe(path: &Path, limits: &Limits) -> Result<ClipInfo, DecodeError> {
    match probe_builtin(path, limits) {
        Err(e) if ffmpeg_can_help(&e) => ffmpeg::probe(path, limits).map_err(|_| e),
        other => other,
    }
}

/// Opens a clip as masks: `mask = true` treats any clip as silhouettes (each
/// frame thresholded at luma 128 to 0/255, `is_mask` set); `false` is [`open`].
pub fn open_with(
    path: &Path,
    limits: &Limits,
    mask: bool,
) -> Result<Box<dyn FrameSource>, DecodeError> {
    let source = open(path, limits)?;
    if !mask || source.info().is_mask {
        return Ok(source);
    }
    let mut info = source.info().clone();
    info.is_mask = true;
    Ok(Box::new(MaskSource {
        inner: source,
        info,
    }))
}

/// Opens any clip as a mask clip (see [`open_with`]).
pub fn open_masks(path: &Path, limits: &Limits) -> Result<Box<dyn FrameSource>, DecodeError> {
    open_with(path, limits, true)
}

/// Thresholds another source's frames to 0/255.
struct MaskSource {
    inner: Box<dyn FrameSource>,
    info: ClipInfo,
}

/// Whether a pixel of a mask frame is set: BT.601 luma at least 128.
pub fn mask_on([r, g, b]: [u8; 3]) -> bool {
    299 * u32::from(r) + 587 * u32::from(g) + 114 * u32::from(b) >= 128_000
}

impl FrameSource for MaskSource {
    fn info(&self) -> &ClipInfo {
        &self.info
    }

    fn next_frame(&mut self) -> Result<Option<RgbImage>, DecodeError> {
        let Some(mut frame) = self.inner.next_frame()? else {
            return Ok(None);
        };
        for px in frame.pixels_mut() {
            let v = if mask_on(px.0) { 255 } else { 0 };
            px.0 = [v, v, v];
        }
        Ok(Some(frame))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sniffs() {
        assert_eq!(sniff(b"\0\0\0\x18ftypisom"), Some(Sniffed::Mp4));
        assert_eq!(sniff(b"RIFF\0\0\0\0AVI LIST"), Some(Sniffed::Avi));
        assert_eq!(sniff(b"RIFF\0\0\0\0WEBPVP8 "), Some(Sniffed::WebP));
        assert_eq!(sniff(b"YUV4MPEG2 W2 H2"), Some(Sniffed::Y4m));
        assert_eq!(sniff(b"GIF89a"), Some(Sniffed::Gif));
        assert_eq!(sniff(b"\x89PNG\r\n\x1a\n"), Some(Sniffed::Png));
        assert_eq!(sniff(b"\xFF\xD8\xFF\xE0"), Some(Sniffed::Jpeg));
        assert_eq!(sniff(b"PK\x05\x06"), Some(Sniffed::Zip));
        let mut tar = vec![0u8; 512];
        tar[257..263].copy_from_slice(b"ustar\0");
        assert_eq!(sniff(&tar), Some(Sniffed::Tar));
        assert_eq!(sniff(b"hello"), None);
        assert!(describe(b"hello world").contains("text"));
        assert!(describe(b"\x00\x01").contains("00 01"));
    }
}
