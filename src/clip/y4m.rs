//! YUV4MPEG2 (`.y4m`) reader: 8-bit 4:2:0 (`C420jpeg`, `C420paldv`, `C420mpeg2`,
//! `C420`, and no `C` tag), 4:2:2, 4:4:4 and `Cmono`.
//!
//! Colour: BT.601 coefficients; the range comes from the vendor tag
//! `XCOLORRANGE=FULL`/`LIMITED` when present, else limited range (what FFmpeg
//! assumes and writes). Chroma is upsampled by replication.
//!
//! Memory: the planes of one frame (reused) and one RGB output frame. The
//! header is parsed and its frame size checked against [`Limits`] before any
//! frame buffer is allocated. [`probe`] counts frames from the file size
//! without decoding.

use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

use image::RgbImage;

use super::decode::{ClipInfo, DecodeError, FrameSource, Limits};

/// Most bytes a header or `FRAME` line may have.
const MAX_LINE: usize = 4096;

/// Chroma layout of a Y4M stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Chroma {
    /// 4:2:0: chroma halved both ways (rounded up).
    C420,
    /// 4:2:2: chroma halved horizontally.
    C422,
    /// 4:4:4: full chroma.
    C444,
    /// Luma only.
    Mono,
}

/// What a Y4M header says.
#[derive(Clone, Debug, PartialEq)]
pub struct Y4mHeader {
    pub width: u32,
    pub height: u32,
    pub fps: f64,
    pub chroma: Chroma,
    /// Full-range samples (`XCOLORRANGE=FULL`); limited otherwise.
    pub full_range: bool,
    /// Length of the header line including its `\n`.
    pub header_len: u64,
}

impl Y4mHeader {
    /// Chroma plane width and height (0×0 for mono).
    fn chroma_size(&self) -> (usize, usize) {
        let (w, h) = (self.width as usize, self.height as usize);
        match self.chroma {
            Chroma::C420 => (w.div_ceil(2), h.div_ceil(2)),
            Chroma::C422 => (w.div_ceil(2), h),
            Chroma::C444 => (w, h),
            Chroma::Mono => (0, 0),
        }
    }

    /// Bytes of pixel data in one frame.
    pub fn frame_bytes(&self) -> u64 {
        let (cw, ch) = self.chroma_size();
        u64::from(self.width) * u64::from(self.height) + 2 * (cw as u64) * (ch as u64)
    }
}

/// Reads one `\n`-terminated line of at most [`MAX_LINE`] bytes (without the `\n`).
/// `Ok(None)` at a clean end of file.
fn read_line<R: BufRead>(
    r: &mut R,
    path: &Path,
    what: &str,
) -> Result<Option<Vec<u8>>, DecodeError> {
    let mut line = Vec::new();
    let n = r
        .by_ref()
        .take(MAX_LINE as u64 + 1)
        .read_until(b'\n', &mut line)
        .map_err(|e| DecodeError::io(path, e))?;
    if n == 0 {
        return Ok(None);
    }
    if line.last() != Some(&b'\n') {
        if line.len() > MAX_LINE {
            return Err(DecodeError::corrupt(
                path,
                format!("{what} line longer than {MAX_LINE} bytes"),
            ));
        }
        return Err(DecodeError::Truncated {
            path: path.to_path_buf(),
            what: format!("the {what} line has no end"),
        });
    }
    line.pop();
    Ok(Some(line))
}

/// Parses a header line (without its `\n`).
pub fn parse_header(line: &[u8], path: &Path) -> Result<Y4mHeader, DecodeError> {
    if !line.is_ascii() {
        return Err(DecodeError::corrupt(path, "header is not ASCII"));
    }
    let text =
        std::str::from_utf8(line).map_err(|_| DecodeError::corrupt(path, "header is not ASCII"))?;
    let mut tokens = text.split(' ').filter(|t| !t.is_empty());
    if tokens.next() != Some("YUV4MPEG2") {
        return Err(DecodeError::UnknownFormat {
            path: path.to_path_buf(),
            what: "no YUV4MPEG2 signature".into(),
        });
    }
    let (mut width, mut height, mut fps) = (None, None, 0.0);
    let mut chroma = Chroma::C420;
    let mut full_range = false;
    for token in tokens {
        let (tag, value) = token.split_at(1);
        match tag {
            "W" => width = value.parse::<u32>().ok(),
            "H" => height = value.parse::<u32>().ok(),
            "F" => {
                let (n, d) = value.split_once(':').ok_or_else(|| {
                    DecodeError::corrupt(path, format!("bad frame rate {value:?}"))
                })?;
                let n: f64 = n
                    .parse()
                    .map_err(|_| DecodeError::corrupt(path, "bad frame rate"))?;
                let d: f64 = d
                    .parse()
                    .map_err(|_| DecodeError::corrupt(path, "bad frame rate"))?;
                if d > 0.0 && n > 0.0 {
                    fps = n / d;
                }
            }
            "C" => {
                chroma = match value {
                    "420jpeg" | "420paldv" | "420mpeg2" | "420" => Chroma::C420,
                    "422" => Chroma::C422,
                    "444" => Chroma::C444,
                    "mono" => Chroma::Mono,
                    other => {
                        return Err(DecodeError::UnsupportedCodec {
                            path: path.to_path_buf(),
                            container: "y4m".into(),
                            codec: format!("rawvideo C{other}"),
                        })
                    }
                }
            }
            // Interlaced (`It`, `Ib`, `Im`) frames are read as woven frames,
            // as FFmpeg does without a deinterlacer.
            "X" => {
                if let Some(range) = value.strip_prefix("COLORRANGE=") {
                    full_range = range.eq_ignore_ascii_case("FULL");
                }
            }
            _ => {}
        }
    }
    let width = width.ok_or_else(|| DecodeError::corrupt(path, "header has no valid W (width)"))?;
    let height =
        height.ok_or_else(|| DecodeError::corrupt(path, "header has no valid H (height)"))?;
    Ok(Y4mHeader {
        width,
        height,
        fps,
        chroma,
        full_range,
        header_len: line.len() as u64 + 1,
    })
}

fn open_header(
    path: &Path,
    limits: &Limits,
) -> Result<(BufReader<File>, Y4mHeader, u64), DecodeError> {
    let file = File::open(path).map_err(|e| DecodeError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| DecodeError::io(path, e))?.len();
    let mut reader = BufReader::new(file);
    let line = read_line(&mut reader, path, "header")?.ok_or_else(|| DecodeError::Truncated {
        path: path.to_path_buf(),
        what: "empty file".into(),
    })?;
    let header = parse_header(&line, path)?;
    limits.check_size(path, header.width, header.height)?;
    Ok((reader, header, file_len))
}

fn info_for(
    header: &Y4mHeader,
    file_len: u64,
    limits: &Limits,
    path: &Path,
) -> Result<ClipInfo, DecodeError> {
    // Each frame is `FRAME\n` (params, if any, make the count an upper bound).
    let per_frame = header.frame_bytes() + 6;
    let frame_count = file_len.saturating_sub(header.header_len) / per_frame;
    if frame_count > limits.max_frames {
        return Err(DecodeError::TooLarge {
            path: path.to_path_buf(),
            what: format!("{frame_count} frames (the limit is {})", limits.max_frames),
        });
    }
    let duration_s = if header.fps > 0.0 {
        frame_count as f64 / header.fps
    } else {
        0.0
    };
    Ok(ClipInfo {
        container: "y4m".into(),
        codec: "rawvideo".into(),
        width: header.width,
        height: header.height,
        fps: header.fps,
        frame_count,
        duration_s,
        is_mask: false,
    })
}

/// Reads the header only; the frame count comes from the file size.
pub fn probe(path: &Path, limits: &Limits) -> Result<ClipInfo, DecodeError> {
    let (_, header, file_len) = open_header(path, limits)?;
    info_for(&header, file_len, limits, path)
}

/// Opens a Y4M file for streaming.
pub fn open(path: &Path, limits: &Limits) -> Result<Box<dyn FrameSource>, DecodeError> {
    let (reader, header, file_len) = open_header(path, limits)?;
    let info = info_for(&header, file_len, limits, path)?;
    Ok(Box::new(Y4mSource {
        path: path.to_path_buf(),
        reader,
        buf: Vec::new(),
        header,
        info,
        index: 0,
        done: false,
        max_frames: limits.max_frames,
    }))
}

/// Streaming Y4M decoder (see the module notes for what it keeps).
pub struct Y4mSource {
    path: PathBuf,
    reader: BufReader<File>,
    buf: Vec<u8>,
    header: Y4mHeader,
    info: ClipInfo,
    index: u64,
    done: bool,
    max_frames: u64,
}

impl FrameSource for Y4mSource {
    fn info(&self) -> &ClipInfo {
        &self.info
    }

    fn next_frame(&mut self) -> Result<Option<RgbImage>, DecodeError> {
        if self.done {
            return Ok(None);
        }
        let path = self.path.clone();
        let result = self.read_frame(&path);
        if !matches!(result, Ok(Some(_))) {
            self.done = true;
        }
        result
    }
}

impl Y4mSource {
    fn read_frame(&mut self, path: &Path) -> Result<Option<RgbImage>, DecodeError> {
        let Some(line) = read_line(&mut self.reader, path, "FRAME")? else {
            return Ok(None);
        };
        if !line.starts_with(b"FRAME") {
            return Err(DecodeError::corrupt(
                path,
                format!("frame {} does not start with FRAME", self.index),
            ));
        }
        if self.index >= self.max_frames {
            return Err(DecodeError::TooLarge {
                path: path.to_path_buf(),
                what: format!("more than {} frames", self.max_frames),
            });
        }
        let n = self.header.frame_bytes() as usize;
        self.buf.resize(n, 0);
        let mut filled = 0;
        while filled < n {
            match self.reader.read(&mut self.buf[filled..]) {
                Ok(0) => {
                    return Err(DecodeError::Truncated {
                        path: path.to_path_buf(),
                        what: format!("frame {} has {filled} of {n} bytes", self.index),
                    })
                }
                Ok(k) => filled += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(DecodeError::io(path, e)),
            }
        }
        self.index += 1;
        Ok(Some(to_rgb(&self.header, &self.buf)))
    }
}

/// Converts one frame's planes to RGB.
pub fn to_rgb(header: &Y4mHeader, planes: &[u8]) -> RgbImage {
    let (w, h) = (header.width as usize, header.height as usize);
    let (cw, ch) = header.chroma_size();
    let (y_plane, rest) = planes.split_at(w * h);
    let (u_plane, v_plane) = rest.split_at(cw * ch);
    let (sx, sy) = match header.chroma {
        Chroma::C420 => (2, 2),
        Chroma::C422 => (2, 1),
        _ => (1, 1),
    };
    // Fixed point, 2^16: (luma scale, luma offset, cr→r, cb→g, cr→g, cb→b).
    let (ys, yo, crr, cbg, crg, cbb): (i32, i32, i32, i32, i32, i32) = if header.full_range {
        (65536, 0, 91881, 22554, 46802, 116130)
    } else {
        (76309, 16, 104597, 25675, 53279, 132201)
    };
    let mut out = vec![0u8; w * h * 3];
    for (row, out_row) in out.chunks_exact_mut(w * 3).enumerate() {
        for (col, px) in out_row.chunks_exact_mut(3).enumerate() {
            let yv = (i32::from(y_plane[row * w + col]) - yo) * ys;
            let (cb, cr) = if header.chroma == Chroma::Mono {
                (0, 0)
            } else {
                let ci = (row / sy) * cw + col / sx;
                (i32::from(u_plane[ci]) - 128, i32::from(v_plane[ci]) - 128)
            };
            let clamp = |v: i32| ((v + 32768) >> 16).clamp(0, 255) as u8;
            px[0] = clamp(yv + crr * cr);
            px[1] = clamp(yv - cbg * cb - crg * cr);
            px[2] = clamp(yv + cbb * cb);
        }
    }
    RgbImage::from_raw(header.width, header.height, out).expect("buffer sized to the frame")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers() {
        let p = Path::new("a.y4m");
        let h = parse_header(
            b"YUV4MPEG2 W5 H3 F30000:1001 Ip A1:1 C422 XCOLORRANGE=FULL",
            p,
        )
        .unwrap();
        assert_eq!(
            (h.width, h.height, h.chroma, h.full_range),
            (5, 3, Chroma::C422, true)
        );
        assert!((h.fps - 29.97).abs() < 0.01);
        assert_eq!(h.frame_bytes(), 15 + 2 * 3 * 3);
        let h = parse_header(b"YUV4MPEG2 W5 H3 F25:1", p).unwrap();
        assert_eq!(
            (h.chroma, h.full_range, h.frame_bytes()),
            (Chroma::C420, false, 15 + 2 * 6)
        );
        // Found by fuzzing: a multi-byte character where a tag letter goes.
        let bad = "YUV4MPEG2 W5 H3 \u{8A30}x".as_bytes();
        assert!(matches!(
            parse_header(bad, p),
            Err(DecodeError::Corrupt { .. })
        ));
        assert!(matches!(
            parse_header(b"YUV4MPEG2 H3", p),
            Err(DecodeError::Corrupt { .. })
        ));
        assert!(matches!(
            parse_header(b"YUV4MPEG2 W2 H2 C420p10", p),
            Err(DecodeError::UnsupportedCodec { .. })
        ));
    }

    #[test]
    fn limited_and_full_range() {
        let mut h = parse_header(b"YUV4MPEG2 W1 H1 Cmono", Path::new("a.y4m")).unwrap();
        assert_eq!(to_rgb(&h, &[16]).get_pixel(0, 0).0, [0, 0, 0]);
        assert_eq!(to_rgb(&h, &[235]).get_pixel(0, 0).0, [255, 255, 255]);
        h.full_range = true;
        assert_eq!(to_rgb(&h, &[16]).get_pixel(0, 0).0, [16, 16, 16]);
        h.chroma = Chroma::C444;
        // Pure red in full-range BT.601: Y 76, Cb 85, Cr 255.
        let px = to_rgb(&h, &[76, 85, 255]).get_pixel(0, 0).0;
        assert!(px[0] >= 253 && px[1] <= 2 && px[2] <= 2, "{px:?}");
    }
}
