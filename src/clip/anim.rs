//! Animated images through the `image` crate: GIF, APNG, WebP (animated or
//! still), and still PNG/JPEG as one-frame clips.
//!
//! Before any decoder is built the file's own header is read by a small
//! walker here (GIF logical screen, PNG `IHDR`/`acTL`/`fcTL`, WebP
//! `VP8X`/`ANMF`/`VP8 `/`VP8L`): it gives the canvas size, checked with
//! [`Limits::check_size`] before anything of that size is allocated, the
//! frame count and the frame delays, without decoding pixels. The frame rate
//! is the reciprocal of the median delay (a GIF delay of 0 counts as 10 cs,
//! as browsers show it).
//!
//! Frames are composited by the `image` crate to the full canvas (RGBA) and
//! returned as RGB over black. The `image` animation iterators are not
//! `Send`, so decoding runs on a worker thread that hands over one frame at a
//! time through a rendezvous channel.
//!
//! Memory: the decoder's state, its canvas, the frame waiting to be handed
//! over and the frame returned; never the whole clip.

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, Receiver};
use std::thread::JoinHandle;

use image::{AnimationDecoder, ImageDecoder, ImageError, RgbImage, RgbaImage};

use super::decode::{ClipInfo, DecodeError, FrameSource, Limits};

/// An I/O error, or `Truncated` when the file ended early.
fn io_err(path: &Path, source: std::io::Error) -> DecodeError {
    DecodeError::io_or_truncated(path, source, "the file is cut off")
}

/// Which image format a file holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AnimKind {
    Gif,
    /// PNG, animated (APNG) or still.
    Png,
    /// WebP, animated or still.
    WebP,
    Jpeg,
}

/// What the header walk found.
#[derive(Clone, Debug, PartialEq)]
struct Walk {
    width: u32,
    height: u32,
    frames: u64,
    /// Frame delays in seconds (empty for stills).
    delays: Vec<f64>,
    animated: bool,
}

fn read_arr<const N: usize, R: Read>(r: &mut R) -> std::io::Result<[u8; N]> {
    let mut b = [0u8; N];
    r.read_exact(&mut b)?;
    Ok(b)
}

fn skip(r: &mut BufReader<File>, n: u64) -> std::io::Result<()> {
    r.seek_relative(i64::try_from(n).unwrap_or(i64::MAX))
}

fn too_many(path: &Path, limits: &Limits) -> DecodeError {
    DecodeError::TooLarge {
        path: path.to_path_buf(),
        what: format!("more than {} frames", limits.max_frames),
    }
}

/// Walks a GIF's blocks: screen size, frame count, delays.
fn walk_gif(r: &mut BufReader<File>, path: &Path, limits: &Limits) -> Result<Walk, DecodeError> {
    let io = |e| io_err(path, e);
    let head: [u8; 13] = read_arr(r).map_err(io)?;
    if &head[..3] != b"GIF" {
        return Err(DecodeError::corrupt(path, "no GIF signature"));
    }
    let width = u32::from(u16::from_le_bytes([head[6], head[7]]));
    let height = u32::from(u16::from_le_bytes([head[8], head[9]]));
    limits.check_size(path, width, height)?;
    if head[10] & 0x80 != 0 {
        skip(r, 3 << ((head[10] & 7) + 1)).map_err(io)?;
    }
    let mut delays = Vec::new();
    let mut pending_delay = 0.0;
    let skip_sub_blocks = |r: &mut BufReader<File>| -> std::io::Result<()> {
        loop {
            let [len] = read_arr(r)?;
            if len == 0 {
                return Ok(());
            }
            skip(r, u64::from(len))?;
        }
    };
    loop {
        let block = match read_arr::<1, _>(r) {
            Ok([b]) => b,
            // A missing trailer is common; the frames seen so far count.
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => break,
            Err(e) => return Err(io_err(path, e)),
        };
        match block {
            0x3B => break,
            0x21 => {
                let [label] = read_arr(r).map_err(io)?;
                if label == 0xF9 {
                    let gce: [u8; 6] = read_arr(r).map_err(io)?;
                    if gce[0] != 4 || gce[5] != 0 {
                        return Err(DecodeError::corrupt(path, "bad graphic control extension"));
                    }
                    let cs = u16::from_le_bytes([gce[2], gce[3]]);
                    pending_delay = f64::from(if cs == 0 { 10 } else { cs }) / 100.0;
                } else {
                    skip_sub_blocks(r).map_err(io)?;
                }
            }
            0x2C => {
                let desc: [u8; 9] = read_arr(r).map_err(io)?;
                if desc[8] & 0x80 != 0 {
                    skip(r, 3 << ((desc[8] & 7) + 1)).map_err(io)?;
                }
                let [_lzw_min] = read_arr(r).map_err(io)?;
                match skip_sub_blocks(r) {
                    Ok(()) => {}
                    Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
                        return Err(DecodeError::Truncated {
                            path: path.to_path_buf(),
                            what: format!("frame {} is cut off", delays.len()),
                        })
                    }
                    Err(e) => return Err(io_err(path, e)),
                }
                delays.push(if pending_delay > 0.0 {
                    pending_delay
                } else {
                    0.1
                });
                pending_delay = 0.0;
                if delays.len() as u64 > limits.max_frames {
                    return Err(too_many(path, limits));
                }
            }
            other => {
                return Err(DecodeError::corrupt(
                    path,
                    format!("unknown GIF block 0x{other:02x}"),
                ))
            }
        }
    }
    if delays.is_empty() {
        return Err(DecodeError::corrupt(path, "the GIF has no frames"));
    }
    Ok(Walk {
        width,
        height,
        frames: delays.len() as u64,
        animated: delays.len() > 1,
        delays,
    })
}

/// Walks PNG chunks up to the first `IDAT` (still) or `IEND` (APNG).
fn walk_png(r: &mut BufReader<File>, path: &Path, limits: &Limits) -> Result<Walk, DecodeError> {
    let io = |e| io_err(path, e);
    let sig: [u8; 8] = read_arr(r).map_err(io)?;
    if &sig != b"\x89PNG\r\n\x1a\n" {
        return Err(DecodeError::corrupt(path, "no PNG signature"));
    }
    let (mut width, mut height) = (0, 0);
    let mut animated = false;
    let mut delays = Vec::new();
    let mut first = true;
    loop {
        let head: [u8; 8] = match read_arr(r) {
            Ok(h) => h,
            Err(e)
                if e.kind() == std::io::ErrorKind::UnexpectedEof
                    && animated
                    && !delays.is_empty() =>
            {
                break
            }
            Err(e) => return Err(io_err(path, e)),
        };
        let len = u64::from(u32::from_be_bytes([head[0], head[1], head[2], head[3]]));
        let kind = [head[4], head[5], head[6], head[7]];
        if first {
            if &kind != b"IHDR" || len < 8 {
                return Err(DecodeError::corrupt(path, "PNG does not start with IHDR"));
            }
            let ihdr: [u8; 8] = read_arr(r).map_err(io)?;
            width = u32::from_be_bytes([ihdr[0], ihdr[1], ihdr[2], ihdr[3]]);
            height = u32::from_be_bytes([ihdr[4], ihdr[5], ihdr[6], ihdr[7]]);
            limits.check_size(path, width, height)?;
            skip(r, len - 8 + 4).map_err(io)?;
            first = false;
            continue;
        }
        match &kind {
            b"acTL" => {
                animated = true;
                skip(r, len + 4).map_err(io)?;
            }
            b"fcTL" if len >= 26 => {
                let fc: [u8; 26] = read_arr(r).map_err(io)?;
                let num = u16::from_be_bytes([fc[20], fc[21]]);
                let den = u16::from_be_bytes([fc[22], fc[23]]);
                let den = if den == 0 { 100 } else { den };
                delays.push(f64::from(num) / f64::from(den));
                if delays.len() as u64 > limits.max_frames {
                    return Err(too_many(path, limits));
                }
                skip(r, len - 26 + 4).map_err(io)?;
            }
            b"IDAT" if !animated => break,
            b"IEND" => break,
            _ => skip(r, len + 4).map_err(io)?,
        }
    }
    if !animated {
        return Ok(Walk {
            width,
            height,
            frames: 1,
            delays: Vec::new(),
            animated: false,
        });
    }
    if delays.is_empty() {
        return Err(DecodeError::corrupt(
            path,
            "APNG without frame control chunks",
        ));
    }
    Ok(Walk {
        width,
        height,
        frames: delays.len() as u64,
        delays,
        animated: true,
    })
}

fn u24(b: &[u8]) -> u32 {
    u32::from(b[0]) | u32::from(b[1]) << 8 | u32::from(b[2]) << 16
}

/// Walks WebP RIFF chunks.
fn walk_webp(r: &mut BufReader<File>, path: &Path, limits: &Limits) -> Result<Walk, DecodeError> {
    let io = |e| io_err(path, e);
    let riff: [u8; 12] = read_arr(r).map_err(io)?;
    if &riff[..4] != b"RIFF" || &riff[8..] != b"WEBP" {
        return Err(DecodeError::corrupt(path, "no WebP signature"));
    }
    let mut size: Option<(u32, u32)> = None;
    let mut animated = false;
    let mut delays = Vec::new();
    loop {
        let head: [u8; 8] = match read_arr(r) {
            Ok(h) => h,
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof && size.is_some() => break,
            Err(e) => return Err(io_err(path, e)),
        };
        let len = u64::from(u32::from_le_bytes([head[4], head[5], head[6], head[7]]));
        let padded = len + (len & 1);
        let mut consumed = 0;
        match &head[..4] {
            b"VP8X" if len >= 10 => {
                let x: [u8; 10] = read_arr(r).map_err(io)?;
                consumed = 10;
                animated = x[0] & 0x02 != 0;
                let (w, h) = (u24(&x[4..7]) + 1, u24(&x[7..10]) + 1);
                limits.check_size(path, w, h)?;
                size = Some((w, h));
            }
            b"VP8 " if len >= 10 && size.is_none() => {
                let v: [u8; 10] = read_arr(r).map_err(io)?;
                consumed = 10;
                if v[3..6] != [0x9d, 0x01, 0x2a] {
                    return Err(DecodeError::corrupt(path, "bad VP8 start code"));
                }
                let w = u32::from(u16::from_le_bytes([v[6], v[7]]) & 0x3fff);
                let h = u32::from(u16::from_le_bytes([v[8], v[9]]) & 0x3fff);
                limits.check_size(path, w, h)?;
                size = Some((w, h));
            }
            b"VP8L" if len >= 5 && size.is_none() => {
                let v: [u8; 5] = read_arr(r).map_err(io)?;
                consumed = 5;
                if v[0] != 0x2f {
                    return Err(DecodeError::corrupt(path, "bad VP8L signature"));
                }
                let bits = u32::from_le_bytes([v[1], v[2], v[3], v[4]]);
                let (w, h) = ((bits & 0x3fff) + 1, ((bits >> 14) & 0x3fff) + 1);
                limits.check_size(path, w, h)?;
                size = Some((w, h));
            }
            b"ANMF" if len >= 16 => {
                let a: [u8; 16] = read_arr(r).map_err(io)?;
                consumed = 16;
                let ms = u24(&a[12..15]);
                delays.push(f64::from(if ms == 0 { 100 } else { ms }) / 1000.0);
                if delays.len() as u64 > limits.max_frames {
                    return Err(too_many(path, limits));
                }
            }
            _ => {}
        }
        if !animated && size.is_some() {
            break;
        }
        match skip(r, padded - consumed) {
            Ok(()) => {}
            Err(e) => return Err(io_err(path, e)),
        }
    }
    let (width, height) =
        size.ok_or_else(|| DecodeError::corrupt(path, "WebP without an image chunk"))?;
    if animated && delays.is_empty() {
        return Err(DecodeError::corrupt(path, "animated WebP without frames"));
    }
    Ok(Walk {
        width,
        height,
        frames: if animated { delays.len() as u64 } else { 1 },
        delays,
        animated,
    })
}

/// Whether JPEG data ends with its end-of-image marker (allowing up to 1 KiB
/// of padding after it). Decoders fill a cut-off scan with gray silently, so
/// a missing marker is how truncation shows.
pub fn jpeg_complete(tail: &[u8]) -> bool {
    let tail = &tail[tail.len().saturating_sub(1024)..];
    tail.windows(2).any(|w| w == [0xFF, 0xD9])
}

fn check_jpeg_end(r: &mut BufReader<File>, path: &Path) -> Result<(), DecodeError> {
    use std::io::{Seek, SeekFrom};
    let len = r.seek(SeekFrom::End(0)).map_err(|e| io_err(path, e))?;
    r.seek(SeekFrom::Start(len.saturating_sub(1024)))
        .map_err(|e| io_err(path, e))?;
    let mut tail = Vec::with_capacity(1024);
    r.by_ref()
        .take(1024)
        .read_to_end(&mut tail)
        .map_err(|e| io_err(path, e))?;
    r.seek(SeekFrom::Start(0)).map_err(|e| io_err(path, e))?;
    if !jpeg_complete(&tail) {
        return Err(DecodeError::Truncated {
            path: path.to_path_buf(),
            what: "the JPEG has no end-of-image marker".into(),
        });
    }
    Ok(())
}

fn walk_jpeg(r: &mut BufReader<File>, path: &Path, limits: &Limits) -> Result<Walk, DecodeError> {
    check_jpeg_end(r, path)?;
    let decoder = image::codecs::jpeg::JpegDecoder::new(r).map_err(|e| image_err(path, e))?;
    let (width, height) = decoder.dimensions();
    limits.check_size(path, width, height)?;
    Ok(Walk {
        width,
        height,
        frames: 1,
        delays: Vec::new(),
        animated: false,
    })
}

/// Maps an `image` error to a [`DecodeError`].
pub fn image_err(path: &Path, e: ImageError) -> DecodeError {
    match e {
        ImageError::Limits(l) => DecodeError::TooLarge {
            path: path.to_path_buf(),
            what: l.to_string(),
        },
        ImageError::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            DecodeError::Truncated {
                path: path.to_path_buf(),
                what: io.to_string(),
            }
        }
        ImageError::IoError(io) => DecodeError::Io {
            path: path.to_path_buf(),
            error: io,
        },
        ImageError::Unsupported(u) => DecodeError::UnsupportedCodec {
            path: path.to_path_buf(),
            container: "image".into(),
            codec: u.to_string(),
        },
        other => {
            let text = other.to_string();
            let lower = text.to_ascii_lowercase();
            if lower.contains("eof") || lower.contains("end of file") || lower.contains("truncat") {
                DecodeError::Truncated {
                    path: path.to_path_buf(),
                    what: text,
                }
            } else {
                DecodeError::Corrupt {
                    path: path.to_path_buf(),
                    what: text,
                }
            }
        }
    }
}

/// The frame rate from the delays (0 for stills).
///
/// Based on the median delay, so that a long hold on one frame does not
/// skew it; the delays within a factor 1.5 of the median are then averaged,
/// because GIF's centisecond delays alternate to approximate rates such as
/// 15 fps (7, 7, 6 cs): the median alone would say 14.29. A result within
/// 0.5 % of a whole number or of an NTSC rate (k·1000/1001) is snapped to it.
fn fps_of(delays: &[f64]) -> f64 {
    if delays.is_empty() {
        return 0.0;
    }
    let mut d = delays.to_vec();
    d.sort_by(f64::total_cmp);
    let mid = d.len() / 2;
    let median = if d.len() % 2 == 1 {
        d[mid]
    } else {
        (d[mid - 1] + d[mid]) / 2.0
    };
    if median <= 0.0 {
        return 0.0;
    }
    let near: Vec<f64> = d
        .iter()
        .copied()
        .filter(|&x| x >= median / 1.5 && x <= median * 1.5)
        .collect();
    let mean = near.iter().sum::<f64>() / near.len() as f64;
    let fps = 1.0 / mean;
    let whole = fps.round();
    let ntsc = (fps * 1.001).round() / 1.001;
    if whole > 0.0 && (fps - whole).abs() <= 0.005 * whole {
        whole
    } else if ntsc > 0.0 && (fps - ntsc).abs() <= 0.005 * ntsc {
        ntsc
    } else {
        fps
    }
}

fn walk(path: &Path, kind: AnimKind, limits: &Limits) -> Result<(Walk, ClipInfo), DecodeError> {
    let file = File::open(path).map_err(|e| io_err(path, e))?;
    let mut r = BufReader::new(file);
    let w = match kind {
        AnimKind::Gif => walk_gif(&mut r, path, limits)?,
        AnimKind::Png => walk_png(&mut r, path, limits)?,
        AnimKind::WebP => walk_webp(&mut r, path, limits)?,
        AnimKind::Jpeg => walk_jpeg(&mut r, path, limits)?,
    };
    let (container, codec) = match (kind, w.animated) {
        (AnimKind::Gif, _) => ("gif", "gif"),
        (AnimKind::Png, true) => ("apng", "png"),
        (AnimKind::Png, false) => ("png", "png"),
        (AnimKind::WebP, true) => ("webp", "webp"),
        (AnimKind::WebP, false) => ("webp", "webp"),
        (AnimKind::Jpeg, _) => ("jpeg", "jpeg"),
    };
    let fps = if w.animated { fps_of(&w.delays) } else { 0.0 };
    let info = ClipInfo {
        container: container.into(),
        codec: codec.into(),
        width: w.width,
        height: w.height,
        fps,
        frame_count: w.frames,
        duration_s: if w.animated {
            w.delays.iter().sum()
        } else {
            0.0
        },
        is_mask: false,
    };
    Ok((w, info))
}

/// Reads headers only (no pixels are decoded).
pub fn probe(path: &Path, kind: AnimKind, limits: &Limits) -> Result<ClipInfo, DecodeError> {
    Ok(walk(path, kind, limits)?.1)
}

fn image_limits(limits: &Limits) -> image::Limits {
    let mut l = image::Limits::default();
    l.max_image_width = Some(limits.max_width);
    l.max_image_height = Some(limits.max_height);
    // Canvas, previous canvas and a frame, RGBA, with room to spare.
    let frame = u64::from(limits.max_width) * u64::from(limits.max_height) * 4;
    l.max_alloc = Some(frame.saturating_mul(4).max(64 << 20));
    l
}

/// Runs on the worker thread: decodes and hands over frames until the
/// receiver is dropped or the frames end.
fn decode_thread(
    path: PathBuf,
    kind: AnimKind,
    animated: bool,
    limits: Limits,
    tx: mpsc::SyncSender<Result<RgbImage, DecodeError>>,
) {
    let send_err = |e: DecodeError| {
        let _ = tx.send(Err(e));
    };
    let file = match File::open(&path) {
        Ok(f) => BufReader::new(f),
        Err(e) => return send_err(io_err(&path, e)),
    };
    let il = image_limits(&limits);
    let frames: Result<image::Frames<'static>, ImageError> = (|| {
        Ok(match (kind, animated) {
            (AnimKind::Gif, _) => {
                let mut d = image::codecs::gif::GifDecoder::new(file)?;
                d.set_limits(il)?;
                d.into_frames()
            }
            (AnimKind::Png, true) => {
                let d = image::codecs::png::PngDecoder::with_limits(file, il)?;
                d.apng()?.into_frames()
            }
            (AnimKind::WebP, true) => {
                let mut d = image::codecs::webp::WebPDecoder::new(file)?;
                d.set_limits(il)?;
                d.into_frames()
            }
            _ => {
                let mut reader = image::ImageReader::new(file);
                reader.limits(il);
                let img = reader.with_guessed_format()?.decode()?;
                let frame = image::Frame::new(img.into_rgba8());
                image::Frames::new(Box::new(std::iter::once(Ok(frame))))
            }
        })
    })();
    let frames = match frames {
        Ok(f) => f,
        Err(e) => return send_err(image_err(&path, e)),
    };
    for frame in frames {
        let msg = frame
            .map(|f| over_black(f.into_buffer()))
            .map_err(|e| image_err(&path, e));
        let failed = msg.is_err();
        if tx.send(msg).is_err() || failed {
            return;
        }
    }
}

/// RGBA composited over black.
fn over_black(rgba: RgbaImage) -> RgbImage {
    let (w, h) = rgba.dimensions();
    let mut out = Vec::with_capacity(w as usize * h as usize * 3);
    for px in rgba.as_raw().chunks_exact(4) {
        let a = u16::from(px[3]);
        for &c in &px[..3] {
            out.push(((u16::from(c) * a + 127) / 255) as u8);
        }
    }
    RgbImage::from_raw(w, h, out).expect("sized to the image")
}

/// Opens an animated (or still) image for streaming.
pub fn open(
    path: &Path,
    kind: AnimKind,
    limits: &Limits,
) -> Result<Box<dyn FrameSource>, DecodeError> {
    let (walk, info) = walk(path, kind, limits)?;
    let (tx, rx) = mpsc::sync_channel(0);
    let thread_path = path.to_path_buf();
    let thread_limits = limits.clone();
    let animated = walk.animated;
    let handle = std::thread::Builder::new()
        .name("monocap-anim".into())
        .spawn(move || decode_thread(thread_path, kind, animated, thread_limits, tx))
        .map_err(|e| io_err(path, e))?;
    Ok(Box::new(AnimSource {
        path: path.to_path_buf(),
        info,
        rx: Some(rx),
        handle: Some(handle),
        index: 0,
        max_frames: limits.max_frames,
    }))
}

/// Streaming animated-image decoder (see the module notes).
pub struct AnimSource {
    path: PathBuf,
    info: ClipInfo,
    rx: Option<Receiver<Result<RgbImage, DecodeError>>>,
    handle: Option<JoinHandle<()>>,
    index: u64,
    max_frames: u64,
}

impl AnimSource {
    fn finish(&mut self) -> Result<Option<RgbImage>, DecodeError> {
        self.rx = None;
        if let Some(h) = self.handle.take() {
            if h.join().is_err() {
                return Err(DecodeError::corrupt(
                    &self.path,
                    "the image decoder failed (panicked)",
                ));
            }
        }
        Ok(None)
    }
}

impl FrameSource for AnimSource {
    fn info(&self) -> &ClipInfo {
        &self.info
    }

    fn next_frame(&mut self) -> Result<Option<RgbImage>, DecodeError> {
        let Some(rx) = &self.rx else {
            return Ok(None);
        };
        // The header walk counted the complete frames: stop there, so that a
        // defect after the last one (a GIF without its trailer byte) is no error.
        if self.index >= self.info.frame_count {
            return self.finish();
        }
        match rx.recv() {
            Ok(Ok(frame)) => {
                if frame.dimensions() != (self.info.width, self.info.height) {
                    self.rx = None;
                    return Err(DecodeError::corrupt(
                        &self.path,
                        format!(
                            "frame {} is {}×{}, the canvas {}×{}",
                            self.index,
                            frame.width(),
                            frame.height(),
                            self.info.width,
                            self.info.height
                        ),
                    ));
                }
                if self.index >= self.max_frames {
                    self.rx = None;
                    return Err(too_many_frames(&self.path, self.max_frames));
                }
                self.index += 1;
                Ok(Some(frame))
            }
            Ok(Err(e)) => {
                self.rx = None;
                Err(e)
            }
            Err(_) => self.finish(),
        }
    }
}

fn too_many_frames(path: &Path, max: u64) -> DecodeError {
    DecodeError::TooLarge {
        path: path.to_path_buf(),
        what: format!("more than {max} frames"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_fps() {
        assert_eq!(fps_of(&[0.1, 0.1, 0.5]), 10.0);
        assert_eq!(fps_of(&[]), 0.0);
        assert_eq!(fps_of(&[0.07, 0.07, 0.06, 0.07, 0.07, 0.06, 2.0]), 15.0);
        assert_eq!(fps_of(&[0.03, 0.04, 0.03, 0.03, 0.04, 0.03]), 30.0);
        assert!((fps_of(&[0.125; 4]) - 8.0).abs() < 1e-12);
        assert!((fps_of(&[0.09; 3]) - 1.0 / 0.09).abs() < 1e-9);
    }
}
