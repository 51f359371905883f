//! RIFF AVI with H.264 (`H264`, `h264`, `X264`, `x264`, `avc1`, …) or Motion JPEG
//! (`MJPG`) video. The RIFF parsing is our own, bounds-checked at every step.
//!
//! Layout read: `RIFF AVI ` → `LIST hdrl` (`avih`, then one `LIST strl` per stream with
//! `strh` and `strf`) and `LIST movi` (chunks `NNdc`/`NNdb` for video stream `NN`,
//! possibly grouped in `LIST rec `). OpenDML files continue in further `RIFF AVIX` lists,
//! each with its own `LIST movi`; they are read the same way. Chunk data is padded to an
//! even size. The sizes of the outer `RIFF` lists are not trusted (writers get them
//! wrong): chunks are walked to the end of the file. The `idx1` index is not needed —
//! the `movi` chunk headers are walked instead, which also works when `idx1` is missing
//! or wrong.
//!
//! What a source keeps between calls: the open file, one `(offset, size)` pair per video
//! chunk (16 bytes a frame), the last frame (a zero-length chunk means "repeat the previous
//! frame"), and for H.264 the decoder with its reorder buffer (see
//! [`crate::clip::h264`]).

use std::collections::VecDeque;
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use image::RgbImage;

use super::h264::{is_annex_b, H264Decoder};
use super::mp4::h264_error;
use super::{ClipInfo, DecodeError, FrameSource, Limits};

/// An I/O error, or `Truncated` when the file ended early.
fn io_err(path: &Path, source: std::io::Error) -> DecodeError {
    DecodeError::io_or_truncated(path, source, "a chunk is cut off")
}

/// Largest `hdrl` list read into memory.
const MAX_HEADER_BYTES: u32 = 4 << 20;
/// Largest single video chunk (one compressed frame).
const MAX_CHUNK_BYTES: u32 = 64 << 20;

/// The container's description of a clip (from its headers and the `movi` chunk list).
pub fn probe(path: &Path, limits: &Limits) -> Result<ClipInfo, DecodeError> {
    Ok(demux(path, limits)?.info)
}

/// Opens an AVI for streaming decode (H.264 or Motion JPEG).
pub fn open(path: &Path, limits: &Limits) -> Result<Box<dyn FrameSource>, DecodeError> {
    let d = demux(path, limits)?;
    let codec = match d.info.codec.as_str() {
        "h264" => {
            let mut dec = H264Decoder::new(limits.max_width, limits.max_height)
                .map_err(|e| h264_error(path, e))?;
            if is_annex_b(&d.extradata) {
                // Parameter sets stored in the stream format: no picture comes out.
                let _ = dec
                    .decode_annex_b(&d.extradata)
                    .map_err(|e| h264_error(path, e))?;
            }
            Codec::H264(Box::new(dec))
        }
        "mjpeg" => Codec::Mjpeg,
        _ => {
            return Err(DecodeError::UnsupportedCodec {
                path: path.to_path_buf(),
                container: "avi".into(),
                codec: d.info.codec,
            })
        }
    };
    Ok(Box::new(AviSource {
        path: path.to_path_buf(),
        info: d.info,
        file: d.file,
        chunks: d.chunks,
        next: 0,
        codec,
        buf: Vec::new(),
        last: None,
        flushed: VecDeque::new(),
        finished: false,
        max_width: limits.max_width,
        max_height: limits.max_height,
    }))
}

struct Demuxed {
    info: ClipInfo,
    file: File,
    chunks: Vec<(u64, u32)>,
    extradata: Vec<u8>,
}

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    b.get(at..at + 4)
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
}

fn fourcc_at(b: &[u8], at: usize) -> Option<[u8; 4]> {
    b.get(at..at + 4).map(|s| [s[0], s[1], s[2], s[3]])
}

/// A chunk's id and data.
type Chunk<'a> = ([u8; 4], &'a [u8]);

/// Sub-chunks `(id, data)` of an in-memory chunk list; a chunk running past the end is
/// an error, a missing pad byte after the last one is not.
fn sub_chunks<'a>(path: &Path, mut b: &'a [u8]) -> Result<Vec<Chunk<'a>>, DecodeError> {
    let mut out = Vec::new();
    while b.len() >= 8 {
        let id = fourcc_at(b, 0).unwrap_or_default();
        let size = u32_at(b, 4).unwrap_or_default() as usize;
        let Some(data) = b.get(8..8 + size) else {
            return Err(DecodeError::corrupt(
                path,
                format!("{} chunk of {size} bytes overruns its list", show(&id)),
            ));
        };
        out.push((id, data));
        let next = (8 + size + (size & 1)).min(b.len());
        b = &b[next..];
    }
    Ok(out)
}

fn show(id: &[u8; 4]) -> String {
    id.iter()
        .map(|&c| {
            if c.is_ascii_graphic() || c == b' ' {
                c as char
            } else {
                '?'
            }
        })
        .collect()
}

/// What `hdrl` says about the first video stream.
struct VideoStream {
    index: usize,
    handler: [u8; 4],
    compression: [u8; 4],
    width: u32,
    height: u32,
    fps: f64,
    extradata: Vec<u8>,
}

fn parse_hdrl(path: &Path, hdrl: &[u8]) -> Result<VideoStream, DecodeError> {
    let mut us_per_frame = 0u32;
    let mut stream_index = 0usize;
    for (id, data) in sub_chunks(path, hdrl)? {
        if &id == b"avih" {
            us_per_frame = u32_at(data, 0).unwrap_or(0);
            continue;
        }
        if &id != b"LIST" || data.get(0..4) != Some(b"strl") {
            continue;
        }
        let index = stream_index;
        stream_index += 1;
        let mut strh = None;
        let mut strf = None;
        for (sid, sdata) in sub_chunks(path, &data[4..])? {
            match &sid {
                b"strh" => strh = Some(sdata),
                b"strf" => strf = Some(sdata),
                _ => {}
            }
        }
        let Some(strh) = strh else { continue };
        if strh.get(0..4) != Some(b"vids") {
            continue;
        }
        let Some(strf) = strf else {
            return Err(DecodeError::corrupt(
                path,
                "video stream without a format (strf)",
            ));
        };
        let handler = fourcc_at(strh, 4).unwrap_or_default();
        let scale = u32_at(strh, 20).unwrap_or(0);
        let rate = u32_at(strh, 24).unwrap_or(0);
        // BITMAPINFOHEADER: size, width, height (negative: top-down), planes, bit count,
        // compression, …; codec extradata follows its 40 bytes.
        let (Some(w), Some(h), Some(compression)) =
            (u32_at(strf, 4), u32_at(strf, 8), fourcc_at(strf, 16))
        else {
            return Err(DecodeError::corrupt(
                path,
                "video format (strf) is too short",
            ));
        };
        let width = w as i32;
        let height = h as i32;
        let fps = if scale > 0 && rate > 0 {
            f64::from(rate) / f64::from(scale)
        } else if us_per_frame > 0 {
            1e6 / f64::from(us_per_frame)
        } else {
            0.0
        };
        return Ok(VideoStream {
            index,
            handler,
            compression,
            width: width.unsigned_abs(),
            height: height.unsigned_abs(),
            fps,
            extradata: strf.get(40..).unwrap_or_default().to_vec(),
        });
    }
    Err(DecodeError::corrupt(
        path,
        "no video stream in the AVI header",
    ))
}

fn codec_name(s: &VideoStream) -> String {
    let norm = |f: [u8; 4]| show(&f).to_ascii_lowercase();
    for f in [s.compression, s.handler] {
        match norm(f).as_str() {
            "h264" | "x264" | "avc1" | "davc" | "vssh" => return "h264".into(),
            "mjpg" | "avrn" | "ljpg" | "jpgl" | "dmb1" => return "mjpeg".into(),
            _ => {}
        }
    }
    let c = norm(s.compression);
    if c.trim_matches(|ch| ch == '?' || ch == ' ').is_empty() {
        norm(s.handler)
    } else {
        c
    }
}

fn demux(path: &Path, limits: &Limits) -> Result<Demuxed, DecodeError> {
    let file = File::open(path).map_err(|e| io_err(path, e))?;
    let len = file.metadata().map_err(|e| io_err(path, e))?.len();
    let mut r = BufReader::new(file);
    let mut head = [0u8; 12];
    if len < 12 {
        return Err(DecodeError::UnknownFormat {
            path: path.to_path_buf(),
            what: "too short for AVI".into(),
        });
    }
    r.read_exact(&mut head).map_err(|e| io_err(path, e))?;
    if &head[0..4] != b"RIFF" || &head[8..12] != b"AVI " {
        return Err(DecodeError::UnknownFormat {
            path: path.to_path_buf(),
            what: "no RIFF AVI header".into(),
        });
    }

    let mut stream: Option<VideoStream> = None;
    let mut chunks: Vec<(u64, u32)> = Vec::new();
    let mut saw_movi = false;
    // (position, end) of the lists being walked; the outer RIFF ends at the file's end.
    let mut stack: Vec<u64> = vec![len];
    let mut pos = 12u64;
    let mut in_movi_depth: Option<usize> = None;
    while let Some(&end) = stack.last() {
        if pos + 8 > end {
            if pos < end && end == len {
                return Err(DecodeError::truncated(
                    path,
                    format!("chunk header cut off at byte {pos}"),
                ));
            }
            stack.pop();
            if in_movi_depth.is_some_and(|d| stack.len() < d) {
                in_movi_depth = None;
            }
            // Lists are padded to an even size too.
            pos = end + (end & 1);
            continue;
        }
        r.seek(SeekFrom::Start(pos)).map_err(|e| io_err(path, e))?;
        let mut h = [0u8; 8];
        r.read_exact(&mut h).map_err(|e| io_err(path, e))?;
        let id = [h[0], h[1], h[2], h[3]];
        let size = u32::from_le_bytes([h[4], h[5], h[6], h[7]]);
        let data_start = pos + 8;
        let data_end = data_start + u64::from(size);
        if &id == b"RIFF" || &id == b"LIST" {
            let mut kind = [0u8; 4];
            if size < 4 || data_start + 4 > len {
                return Err(DecodeError::truncated(
                    path,
                    format!("{} list at byte {pos} is cut off", show(&id)),
                ));
            }
            r.read_exact(&mut kind).map_err(|e| io_err(path, e))?;
            // An outer list may say more than the file holds (or than its parent): the
            // data left is what counts, except that a header list must be whole.
            let list_end = data_end.min(end);
            match &kind {
                b"hdrl" => {
                    if data_end > end {
                        return Err(DecodeError::truncated(
                            path,
                            "the AVI header list (hdrl) is cut off",
                        ));
                    }
                    if size > MAX_HEADER_BYTES {
                        return Err(DecodeError::corrupt(
                            path,
                            format!("AVI header list of {size} bytes"),
                        ));
                    }
                    let mut b = vec![0u8; size as usize - 4];
                    r.read_exact(&mut b).map_err(|e| io_err(path, e))?;
                    if stream.is_none() {
                        stream = Some(parse_hdrl(path, &b)?);
                    }
                    pos = data_end + u64::from(size & 1);
                }
                b"movi" | b"rec " | b"AVIX" => {
                    if &kind == b"movi" {
                        saw_movi = true;
                        if data_end > len {
                            return Err(DecodeError::truncated(
                                path,
                                format!(
                                    "movi list declares {size} bytes, {} are in the file",
                                    len - data_start
                                ),
                            ));
                        }
                        in_movi_depth = Some(stack.len() + 1);
                    }
                    stack.push(list_end);
                    pos = data_start + 4;
                }
                _ => pos = data_end + u64::from(size & 1),
            }
            continue;
        }
        if data_end > end {
            if in_movi_depth.is_some() || end == len {
                return Err(DecodeError::truncated(
                    path,
                    format!(
                        "{} chunk at byte {pos} declares {size} bytes, {} are left",
                        show(&id),
                        end - data_start
                    ),
                ));
            }
            return Err(DecodeError::corrupt(
                path,
                format!("{} chunk at byte {pos} overruns its list", show(&id)),
            ));
        }
        if in_movi_depth.is_some() {
            if let Some(s) = &stream {
                let want = format!("{:02}", s.index);
                if id[0..2] == *want.as_bytes() && (&id[2..4] == b"dc" || &id[2..4] == b"db") {
                    if size > MAX_CHUNK_BYTES {
                        return Err(DecodeError::corrupt(
                            path,
                            format!("video chunk of {size} bytes"),
                        ));
                    }
                    chunks.push((data_start, size));
                    if chunks.len() as u64 > limits.max_frames {
                        return Err(DecodeError::TooLarge {
                            path: path.to_path_buf(),
                            what: format!("more than {} frames", limits.max_frames),
                        });
                    }
                }
            }
        }
        pos = data_end + u64::from(size & 1);
    }

    let Some(stream) = stream else {
        let declared = u64::from(u32::from_le_bytes([head[4], head[5], head[6], head[7]])) + 8;
        return Err(if declared > len {
            DecodeError::truncated(
                path,
                format!("no AVI header list (hdrl) in the {len} bytes of a {declared}-byte RIFF"),
            )
        } else {
            DecodeError::corrupt(path, "no AVI header list (hdrl)")
        });
    };
    if !saw_movi {
        return Err(DecodeError::truncated(
            path,
            "no movi list (the frames) in the file",
        ));
    }
    limits.check_size(path, stream.width, stream.height)?;
    if chunks.is_empty() {
        return Err(DecodeError::corrupt(path, "the video stream has no frames"));
    }
    let codec = codec_name(&stream);
    let frame_count = chunks.len() as u64;
    let info = ClipInfo {
        container: "avi".into(),
        codec,
        width: stream.width,
        height: stream.height,
        fps: stream.fps,
        frame_count,
        duration_s: if stream.fps > 0.0 {
            frame_count as f64 / stream.fps
        } else {
            0.0
        },
        is_mask: false,
    };
    Ok(Demuxed {
        info,
        file: r.into_inner(),
        chunks,
        extradata: stream.extradata,
    })
}

enum Codec {
    H264(Box<H264Decoder>),
    Mjpeg,
}

struct AviSource {
    path: PathBuf,
    info: ClipInfo,
    file: File,
    chunks: Vec<(u64, u32)>,
    next: usize,
    codec: Codec,
    buf: Vec<u8>,
    /// The last frame handed out, repeated for a zero-length chunk.
    last: Option<RgbImage>,
    /// Frames released by the H.264 decoder's final flush, in display order.
    flushed: VecDeque<RgbImage>,
    finished: bool,
    max_width: u32,
    max_height: u32,
}

impl AviSource {
    fn decode_jpeg(&self) -> Result<RgbImage, DecodeError> {
        use image::ImageDecoder;
        let bad = |e: image::ImageError| {
            DecodeError::corrupt(&self.path, format!("JPEG frame {}: {e}", self.next - 1))
        };
        let dec =
            image::codecs::jpeg::JpegDecoder::new(std::io::Cursor::new(&self.buf)).map_err(bad)?;
        let (w, h) = dec.dimensions();
        if w > self.max_width
            || h > self.max_height
            || (w, h) != (self.info.width, self.info.height)
        {
            return Err(DecodeError::corrupt(
                &self.path,
                format!(
                    "JPEG frame {} is {w}×{h}, the stream says {}×{}",
                    self.next - 1,
                    self.info.width,
                    self.info.height
                ),
            ));
        }
        Ok(image::DynamicImage::from_decoder(dec)
            .map_err(bad)?
            .into_rgb8())
    }

    fn emit(&mut self, frame: RgbImage) -> Result<Option<RgbImage>, DecodeError> {
        if frame.dimensions() != (self.info.width, self.info.height) {
            let (w, h) = frame.dimensions();
            return Err(DecodeError::corrupt(
                &self.path,
                format!(
                    "a frame is {w}×{h}, the stream says {}×{}",
                    self.info.width, self.info.height
                ),
            ));
        }
        self.last = Some(frame.clone());
        Ok(Some(frame))
    }
}

impl FrameSource for AviSource {
    fn info(&self) -> &ClipInfo {
        &self.info
    }

    fn next_frame(&mut self) -> Result<Option<RgbImage>, DecodeError> {
        loop {
            if let Some(f) = self.flushed.pop_front() {
                return self.emit(f);
            }
            if let Some(&(offset, size)) = self.chunks.get(self.next) {
                self.next += 1;
                if size == 0 {
                    // A dropped frame: the previous picture stays on screen.
                    if let Some(prev) = &self.last {
                        return Ok(Some(prev.clone()));
                    }
                    continue;
                }
                self.buf.resize(size as usize, 0);
                self.file
                    .seek(SeekFrom::Start(offset))
                    .map_err(|e| io_err(&self.path, e))?;
                self.file
                    .read_exact(&mut self.buf)
                    .map_err(|e| io_err(&self.path, e))?;
                let frame = match &mut self.codec {
                    Codec::Mjpeg => Some(self.decode_jpeg()?),
                    Codec::H264(dec) => if is_annex_b(&self.buf) {
                        dec.decode_annex_b(&self.buf)
                    } else {
                        dec.decode_length_prefixed(&self.buf, 4)
                    }
                    .map_err(|e| h264_error(&self.path, e))?,
                };
                if let Some(f) = frame {
                    return self.emit(f);
                }
                continue;
            }
            if self.finished {
                return Ok(None);
            }
            self.finished = true;
            if let Codec::H264(dec) = &mut self.codec {
                self.flushed = dec.flush().map_err(|e| h264_error(&self.path, e))?.into();
            }
        }
    }
}
