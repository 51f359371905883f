//! Clip writers: frames out to a file whose format is chosen by its extension.
//!
//! [`create`] opens a writer for one of the [`ClipFormat`]s; frames are then
//! [`pushed`](ClipWriter::push) one at a time and the file is completed by
//! [`finish`](ClipWriter::finish).
//!
//! | extension | format                                                        |
//! |-----------|---------------------------------------------------------------|
//! | `.y4m`    | YUV4MPEG2, `C420jpeg` (full-range BT.601 YCbCr, 4:2:0)        |
//! | `.zip`    | one PNG per frame, `000000.png`, `000001.png`, … (deflate)    |
//! | `.tar`    | the same PNG sequence in a plain POSIX ustar archive          |
//! | `.gif`    | animated GIF looping forever, per-frame palettes              |
//!
//! # Memory
//!
//! Writers stream: no format keeps more than about one frame in memory (plus
//! a 64 KiB write buffer and the encoders' working state), so clip length is
//! bounded by disk space only. What each one keeps, and why, is documented
//! on [`ClipFormat`]'s variants.
//!
//! # Temporary file
//!
//! Output goes to `<path>.tmp` (the full file name with `.tmp` appended, e.g.
//! `clip.gif.tmp`) and is renamed to `path` only by a successful
//! [`finish`](ClipWriter::finish), replacing any existing file there. On an
//! I/O or encoding error, or when a writer is dropped without `finish`, the
//! temporary file is removed, so no partial clip is left behind. The file is
//! not `fsync`ed: the rename protects against failed writes, not against a
//! system crash. Two writers for the same `path` at once would clash.
//!
//! # Frame kinds
//!
//! Frames are [`Frame::Rgb`] or [`Frame::Gray`] (0/255 masks, mostly), and
//! the kinds may be mixed freely within one clip: PNG sequences store each
//! frame in its own kind, Y4M stores gray as Y = value with neutral chroma,
//! GIF gives gray frames an exact gray palette.

use std::fmt;
use std::fs::{self, File};
use std::io::{self, BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use image::codecs::gif::{GifEncoder, Repeat};
use image::codecs::png::PngEncoder;
use image::{Delay, GrayImage, ImageEncoder, ImageError, RgbImage, RgbaImage};

/// One frame handed to a [`ClipWriter`]; it borrows the caller's image.
#[derive(Debug, Clone, Copy)]
pub enum Frame<'a> {
    /// A colour frame.
    Rgb(&'a RgbImage),
    /// A gray frame, typically a 0/255 mask.
    Gray(&'a GrayImage),
}

impl Frame<'_> {
    /// Width and height in pixels.
    pub fn dimensions(&self) -> (u32, u32) {
        match self {
            Frame::Rgb(img) => img.dimensions(),
            Frame::Gray(img) => img.dimensions(),
        }
    }
}

/// A clip being written; obtained from [`create`].
///
/// An I/O or encoding error stops the writer: the temporary file is removed,
/// and the failing call and every later [`push`](Self::push) or
/// [`finish`](Self::finish) return [`ClipWriteError::Stopped`] wrapping that
/// error. A frame of the wrong size is rejected without stopping the writer.
///
/// Writers are `Send` so that a clip can be written on a worker thread.
pub trait ClipWriter: Send {
    /// Appends one frame; it must have the size given to [`create`].
    fn push(&mut self, frame: Frame<'_>) -> Result<(), ClipWriteError>;

    /// Completes the file (trailers, flush), closes it and renames the
    /// temporary file to the final path. A clip without frames is an error
    /// ([`ClipWriteError::NoFrames`]) and leaves no file.
    fn finish(self: Box<Self>) -> Result<(), ClipWriteError>;

    /// Number of frames accepted so far.
    fn frames_written(&self) -> usize;
}

/// The output formats, chosen by file extension (see [`ClipFormat::from_path`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ClipFormat {
    /// `.y4m`: YUV4MPEG2 with `C420jpeg` chroma, i.e. JPEG/JFIF full-range
    /// BT.601 YCbCr with chroma sited at the centre of each 2×2 block.
    ///
    /// Chroma is computed by averaging the RGB values of each 2×2 block (fewer
    /// pixels in the last column/row of odd sizes; chroma planes are rounded
    /// up) and converting the average, rounding once. As the conversion is
    /// affine this equals converting then averaging, without double rounding.
    /// Gray frames give Y = value and Cb = Cr = 128.
    ///
    /// Memory: the three planes of one frame (1.5 bytes per pixel, reused).
    Y4m,
    /// `.zip`: one PNG per frame named `000000.png`, `000001.png`, … (more
    /// digits past 999 999), stored with deflate. Gray frames are 8-bit
    /// grayscale PNGs, RGB frames 8-bit RGB PNGs. No frame rate is stored.
    ///
    /// Memory: each PNG is encoded straight into the archive; the archive
    /// keeps a central-directory record per entry (~100 bytes) until finish,
    /// as the ZIP format puts the directory at the end.
    ZipPng,
    /// `.tar`: the same PNG sequence as [`ClipFormat::ZipPng`] in a POSIX
    /// ustar archive (mode 0644, owner 0, mtime 0 so output is reproducible).
    ///
    /// Memory: one encoded PNG, because a tar header gives the entry size
    /// before its data.
    TarPng,
    /// `.gif`: animated GIF that loops forever, full frames with a local
    /// palette each. Frames with at most 256 distinct colours (all gray
    /// frames, flat-colour renders) are stored exactly; others are quantised
    /// per frame with NeuQuant.
    ///
    /// Delays are in 1/100 s; they are chosen so that the time after `n`
    /// frames is `round(n * 100 / fps)` centiseconds, which keeps the average
    /// rate exact (30 fps gives 3, 4, 3, 3, 4, 3, … cs). Browsers show delays
    /// below 2 cs as 10 cs, so GIFs above 50 fps play slowly there.
    ///
    /// Memory: an RGBA copy of one frame (the encoder's input format) and
    /// the encoder's buffers for one frame.
    Gif,
}

impl ClipFormat {
    /// Every format, in the order they are listed in error messages.
    pub const ALL: [ClipFormat; 4] = [
        ClipFormat::Y4m,
        ClipFormat::ZipPng,
        ClipFormat::TarPng,
        ClipFormat::Gif,
    ];

    /// The file extension for this format, without the dot, lower case.
    pub fn extension(self) -> &'static str {
        match self {
            ClipFormat::Y4m => "y4m",
            ClipFormat::ZipPng => "zip",
            ClipFormat::TarPng => "tar",
            ClipFormat::Gif => "gif",
        }
    }

    /// Picks the format from the extension of `path`, ignoring ASCII case.
    ///
    /// A missing or unknown extension gives
    /// [`ClipWriteError::UnsupportedExtension`], whose message lists the
    /// supported ones.
    pub fn from_path(path: &Path) -> Result<Self, ClipWriteError> {
        let extension = path.extension().map(|e| e.to_string_lossy());
        extension
            .as_deref()
            .and_then(|ext| {
                Self::ALL
                    .into_iter()
                    .find(|f| f.extension().eq_ignore_ascii_case(ext))
            })
            .ok_or_else(|| ClipWriteError::UnsupportedExtension {
                path: path.to_path_buf(),
                extension: extension.map(|e| e.into_owned()),
            })
    }
}

/// `.y4m, .zip, .tar, .gif`, for error messages.
struct SupportedExtensions;

impl fmt::Display for SupportedExtensions {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, format) in ClipFormat::ALL.iter().enumerate() {
            let sep = if i == 0 { "" } else { ", " };
            write!(f, "{sep}.{}", format.extension())?;
        }
        Ok(())
    }
}

/// Why a clip could not be written. Messages are one line and name the file.
///
/// Underlying errors are part of the message and kept in public fields; they
/// are not also returned by [`std::error::Error::source`], so that printing
/// the error chain does not repeat them.
#[derive(Debug, thiserror::Error)]
pub enum ClipWriteError {
    /// The path has no extension, or one that names no [`ClipFormat`].
    #[error(
        "cannot write clip {}: {} (supported: {})",
        path.display(),
        match extension {
            Some(ext) => format!("unsupported extension \".{ext}\""),
            None => "no file extension".to_owned(),
        },
        SupportedExtensions
    )]
    UnsupportedExtension {
        /// The requested output path.
        path: PathBuf,
        /// Its extension, if it has one.
        extension: Option<String>,
    },

    /// The clip size is zero or too large for the format.
    #[error("cannot write clip {}: invalid size {width}x{height} ({reason})", path.display())]
    InvalidSize {
        /// The requested output path.
        path: PathBuf,
        /// Requested width.
        width: u32,
        /// Requested height.
        height: u32,
        /// What is wrong with it.
        reason: &'static str,
    },

    /// The frame rate is not a positive finite number, has no close rational
    /// form, or cannot be expressed by the format.
    #[error("cannot write clip {}: invalid frame rate {fps} fps ({reason})", path.display())]
    InvalidFrameRate {
        /// The requested output path.
        path: PathBuf,
        /// Requested frame rate.
        fps: f64,
        /// What is wrong with it.
        reason: &'static str,
    },

    /// A pushed frame does not have the clip's size. The writer stays usable.
    #[error(
        "frame {index} of clip {} is {}x{}, but the clip is {}x{}",
        path.display(), actual.0, actual.1, expected.0, expected.1
    )]
    FrameSize {
        /// The output path.
        path: PathBuf,
        /// Zero-based index the frame would have had.
        index: usize,
        /// The clip size.
        expected: (u32, u32),
        /// The frame's size.
        actual: (u32, u32),
    },

    /// An I/O operation on the output (or its temporary file) failed.
    #[error("cannot {action} {}: {error}", path.display())]
    Io {
        /// What was being done, e.g. `"create"` or `"write"`.
        action: &'static str,
        /// The file concerned.
        path: PathBuf,
        /// The I/O error.
        error: io::Error,
    },

    /// An encoder (PNG, ZIP, GIF, Y4M) rejected its input.
    #[error("cannot encode {what} of clip {}: {error}", path.display())]
    Encode {
        /// The output path.
        path: PathBuf,
        /// What was being encoded, e.g. `"frame 3"`.
        what: String,
        /// The encoder's error.
        error: Box<dyn std::error::Error + Send + Sync>,
    },

    /// [`ClipWriter::finish`] was called before any frame was pushed.
    #[error("cannot finish clip {}: no frames were written", path.display())]
    NoFrames {
        /// The output path.
        path: PathBuf,
    },

    /// The writer failed earlier and accepts nothing more.
    #[error("{earlier} (the clip writer stopped at this error)")]
    Stopped {
        /// The error that stopped the writer.
        earlier: Arc<ClipWriteError>,
    },
}

/// Opens a writer for a `width`×`height` clip at `fps` frames per second,
/// in the format given by the extension of `path` (see [`ClipFormat`]).
///
/// The temporary file `<path>.tmp` is created at once, so an unwritable
/// location fails here. `fps` must be positive and finite; it is stored as a
/// rational (see [`rational_frame_rate`]) in Y4M and sets the GIF delays, and
/// is not recorded in PNG archives.
pub fn create(
    path: &Path,
    width: u32,
    height: u32,
    fps: f64,
) -> Result<Box<dyn ClipWriter>, ClipWriteError> {
    let format = ClipFormat::from_path(path)?;
    let invalid_size = |reason| ClipWriteError::InvalidSize {
        path: path.to_path_buf(),
        width,
        height,
        reason,
    };
    if width == 0 || height == 0 {
        return Err(invalid_size("both sides must be at least 1 pixel"));
    }
    if format == ClipFormat::Gif && (width > 0xFFFF || height > 0xFFFF) {
        return Err(invalid_size("GIF allows at most 65535 pixels per side"));
    }
    let invalid_rate = |reason| ClipWriteError::InvalidFrameRate {
        path: path.to_path_buf(),
        fps,
        reason,
    };
    if !fps.is_finite() || fps <= 0.0 {
        return Err(invalid_rate("must be positive and finite"));
    }
    let rate = rational_frame_rate(fps)
        .ok_or_else(|| invalid_rate("no close fraction with 32-bit terms"))?;
    let delays = GifDelays::new(rate);
    if format == ClipFormat::Gif && !delays.fit_gif() {
        return Err(invalid_rate("GIF frames last at most 655.35 s"));
    }

    let tmp = tmp_path(path);
    let file = File::create(&tmp).map_err(|error| ClipWriteError::Io {
        action: "create",
        path: tmp.clone(),
        error,
    })?;
    let out = BufWriter::with_capacity(1 << 16, file);
    let clip = Clip {
        target: path.to_path_buf(),
        tmp,
        width,
        height,
        frames: 0,
    };
    let writer: Box<dyn ClipWriter> = match format {
        ClipFormat::Y4m => Box::new(clip.wrap(Y4mSink::new(out, width, height, rate))?),
        ClipFormat::ZipPng => Box::new(clip.wrap(Ok(ZipSink::new(out)))?),
        ClipFormat::TarPng => Box::new(clip.wrap(Ok(TarSink::new(out)))?),
        ClipFormat::Gif => Box::new(clip.wrap(GifSink::new(out, delays))?),
    };
    Ok(writer)
}

/// Expresses `fps` as a fraction `(numerator, denominator)` in lowest terms.
///
/// Rates close to the NTSC family `k·1000/1001` are snapped to it (so 29.97
/// gives 30000/1001 and 23.976 gives 24000/1001), unless a fraction with a
/// denominator of at most 16 matches exactly (30 → 30/1, 12.5 → 25/2).
/// Otherwise the first continued-fraction convergent within a relative error
/// of 1e-9 is used, or failing that the closest one within 1e-6 whose terms
/// fit in `u32`. Returns `None` for non-positive or non-finite input and for
/// rates with no such fraction.
pub fn rational_frame_rate(fps: f64) -> Option<(u32, u32)> {
    if !fps.is_finite() || fps <= 0.0 {
        return None;
    }
    let rel_error = |(n, d): (u32, u32)| (f64::from(n) / f64::from(d) - fps).abs() / fps;
    let convergents = convergents(fps);

    if let Some(&simple) = convergents
        .iter()
        .take_while(|&&(_, d)| d <= 16)
        .find(|&&c| rel_error(c) <= 1e-9)
    {
        return Some(simple);
    }

    let k = (fps * 1.001).round();
    if (1.0..=f64::from(u32::MAX / 1000)).contains(&k) {
        // `k` is an integer below 2^32 / 1000, so these conversions are exact.
        let (num, den) = (k as u32 * 1000, 1001);
        if rel_error((num, den)) <= 2e-5 {
            let common = gcd(num, den);
            return Some((num / common, den / common));
        }
    }

    convergents
        .iter()
        .copied()
        .find(|&c| rel_error(c) <= 1e-9)
        .or_else(|| {
            let last = *convergents.last()?;
            (rel_error(last) <= 1e-6).then_some(last)
        })
}

fn gcd(mut a: u32, mut b: u32) -> u32 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// Continued-fraction convergents of `x > 0` whose terms fit in `u32`.
fn convergents(x: f64) -> Vec<(u32, u32)> {
    let (mut h_prev, mut h) = (0_u64, 1_u64); // numerators h[-2], h[-1]
    let (mut k_prev, mut k) = (1_u64, 0_u64); // denominators k[-2], k[-1]
    let mut rest = x;
    let mut out = Vec::new();
    for _ in 0..64 {
        let a = rest.floor();
        if a > f64::from(u32::MAX) {
            break;
        }
        let frac = rest - a;
        let a = a as u64; // in 0..=u32::MAX, checked above
        let h_next = a * h + h_prev;
        let k_next = a * k + k_prev;
        let (Ok(num), Ok(den)) = (u32::try_from(h_next), u32::try_from(k_next)) else {
            break;
        };
        if num > 0 {
            out.push((num, den));
        }
        (h_prev, h, k_prev, k) = (h, h_next, k, k_next);
        if frac < 1e-12 {
            break;
        }
        rest = 1.0 / frac;
    }
    out
}

/// `<path>.tmp`: the file name with `.tmp` appended.
fn tmp_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".tmp");
    PathBuf::from(name)
}

/// What a format-specific sink reports; [`Clip`] adds the path and context.
enum SinkError {
    Io(io::Error),
    Encode(Box<dyn std::error::Error + Send + Sync>),
}

impl From<io::Error> for SinkError {
    fn from(error: io::Error) -> Self {
        SinkError::Io(error)
    }
}

impl From<ImageError> for SinkError {
    fn from(error: ImageError) -> Self {
        match error {
            ImageError::IoError(error) => SinkError::Io(error),
            other => SinkError::Encode(Box::new(other)),
        }
    }
}

impl From<zip::result::ZipError> for SinkError {
    fn from(error: zip::result::ZipError) -> Self {
        match error {
            zip::result::ZipError::Io(error) => SinkError::Io(error),
            other => SinkError::Encode(Box::new(other)),
        }
    }
}

impl From<y4m::Error> for SinkError {
    fn from(error: y4m::Error) -> Self {
        match error {
            y4m::Error::IoError(error) => SinkError::Io(error),
            other => SinkError::Encode(Box::new(other)),
        }
    }
}

/// One output format: receives frames already checked for size, in order.
trait Sink: Send {
    /// Encodes and writes frame number `index`.
    fn write_frame(&mut self, index: usize, frame: Frame<'_>) -> Result<(), SinkError>;
    /// Writes any trailer and flushes everything to the file.
    fn finish(self) -> Result<(), SinkError>;
    /// Called before an unfinished sink is dropped and its file deleted.
    fn abandon(&mut self) {}
}

/// The format-independent part of a writer: paths, size, frame count.
struct Clip {
    target: PathBuf,
    tmp: PathBuf,
    width: u32,
    height: u32,
    frames: usize,
}

impl Clip {
    /// Puts `sink` (or the error of making it) into a [`Writer`], which from
    /// then on owns the temporary file and removes it unless finished.
    fn wrap<S: Sink>(self, sink: Result<S, SinkError>) -> Result<Writer<S>, ClipWriteError> {
        match sink {
            Ok(sink) => Ok(Writer {
                clip: self,
                state: State::Open(sink),
            }),
            Err(error) => {
                // The failed sink has already closed the file.
                let _ = fs::remove_file(&self.tmp);
                Err(self.error("write header to", "header", error))
            }
        }
    }

    fn error(&self, action: &'static str, what: &str, error: SinkError) -> ClipWriteError {
        match error {
            SinkError::Io(error) => ClipWriteError::Io {
                action,
                path: self.tmp.clone(),
                error,
            },
            SinkError::Encode(error) => ClipWriteError::Encode {
                path: self.target.clone(),
                what: what.to_owned(),
                error,
            },
        }
    }
}

enum State<S> {
    Open(S),
    /// Stopped by this error; the temporary file is gone.
    Failed(Arc<ClipWriteError>),
    /// Finished or being finished; nothing left to clean up.
    Closed,
}

/// A [`ClipWriter`] over a format-specific [`Sink`].
struct Writer<S: Sink> {
    clip: Clip,
    state: State<S>,
}

impl<S: Sink> Writer<S> {
    /// Records `error` as the one that stopped this writer and cleans up.
    fn stop(&mut self, error: ClipWriteError) -> ClipWriteError {
        let earlier = Arc::new(error);
        if let State::Open(sink) = &mut self.state {
            sink.abandon();
        }
        // Close the file before removing it (needed on Windows).
        self.state = State::Failed(Arc::clone(&earlier));
        let _ = fs::remove_file(&self.clip.tmp);
        ClipWriteError::Stopped { earlier }
    }
}

impl<S: Sink> ClipWriter for Writer<S> {
    fn push(&mut self, frame: Frame<'_>) -> Result<(), ClipWriteError> {
        let sink = match &mut self.state {
            State::Open(sink) => sink,
            State::Failed(earlier) => {
                return Err(ClipWriteError::Stopped {
                    earlier: Arc::clone(earlier),
                })
            }
            State::Closed => unreachable!("a closed writer has been consumed by finish"),
        };
        let clip = &self.clip;
        let expected = (clip.width, clip.height);
        if frame.dimensions() != expected {
            return Err(ClipWriteError::FrameSize {
                path: clip.target.clone(),
                index: clip.frames,
                expected,
                actual: frame.dimensions(),
            });
        }
        match sink.write_frame(clip.frames, frame) {
            Ok(()) => {
                self.clip.frames += 1;
                Ok(())
            }
            Err(error) => {
                let error = clip.error("write", &format!("frame {}", clip.frames), error);
                Err(self.stop(error))
            }
        }
    }

    fn finish(mut self: Box<Self>) -> Result<(), ClipWriteError> {
        let sink = match std::mem::replace(&mut self.state, State::Closed) {
            State::Open(sink) => sink,
            State::Failed(earlier) => return Err(ClipWriteError::Stopped { earlier }),
            State::Closed => unreachable!("a closed writer has been consumed by finish"),
        };
        let clip = &self.clip;
        let result = if clip.frames == 0 {
            let mut sink = sink;
            sink.abandon();
            drop(sink);
            Err(ClipWriteError::NoFrames {
                path: clip.target.clone(),
            })
        } else {
            sink.finish()
                .map_err(|error| clip.error("finish", "trailer", error))
                .and_then(|()| {
                    fs::rename(&clip.tmp, &clip.target).map_err(|error| ClipWriteError::Io {
                        action: "rename temporary file to",
                        path: clip.target.clone(),
                        error,
                    })
                })
        };
        if result.is_err() {
            let _ = fs::remove_file(&clip.tmp);
        }
        result
    }

    fn frames_written(&self) -> usize {
        self.clip.frames
    }
}

impl<S: Sink> Drop for Writer<S> {
    fn drop(&mut self) {
        if let State::Open(mut sink) = std::mem::replace(&mut self.state, State::Closed) {
            sink.abandon();
            drop(sink);
            let _ = fs::remove_file(&self.clip.tmp);
        }
    }
}

/// A cloneable handle on the buffered output file, for encoders (y4m, GIF)
/// that own their writer and cannot give it back: after dropping the encoder
/// the clip still flushes the buffer and sees every write error, including
/// ones from writes the encoder makes in its `Drop` (the GIF trailer).
#[derive(Clone)]
struct SharedOut(Arc<Mutex<SharedState>>);

struct SharedState {
    out: BufWriter<File>,
    /// The first write error, kept in case the encoder swallowed it.
    error: Option<io::Error>,
}

impl SharedOut {
    fn new(out: BufWriter<File>) -> Self {
        SharedOut(Arc::new(Mutex::new(SharedState { out, error: None })))
    }

    fn with<T>(&self, f: impl FnOnce(&mut BufWriter<File>) -> io::Result<T>) -> io::Result<T> {
        let mut state = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        let result = f(&mut state.out);
        if let Err(error) = &result {
            // Interrupted writes are retried by `write_all`, not failures.
            if state.error.is_none() && error.kind() != io::ErrorKind::Interrupted {
                state.error = Some(io::Error::new(error.kind(), error.to_string()));
            }
        }
        result
    }

    /// Flushes the file, reporting the first error seen by any handle.
    fn finish(&self) -> io::Result<()> {
        self.with(|out| out.flush())?;
        let mut state = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        state.error.take().map_or(Ok(()), Err)
    }
}

impl Write for SharedOut {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.with(|out| out.write(buf))
    }

    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        self.with(|out| out.write_all(buf))
    }

    fn flush(&mut self) -> io::Result<()> {
        self.with(|out| out.flush())
    }
}

struct Y4mSink {
    encoder: y4m::Encoder<SharedOut>,
    out: SharedOut,
    width: usize,
    /// Y, Cb and Cr planes of the current frame, reused.
    planes: [Vec<u8>; 3],
}

impl Y4mSink {
    fn new(
        out: BufWriter<File>,
        width: u32,
        height: u32,
        rate: (u32, u32),
    ) -> Result<Self, SinkError> {
        let (width, height) = (width as usize, height as usize);
        let out = SharedOut::new(out);
        let rate = y4m::Ratio::new(rate.0 as usize, rate.1 as usize);
        // The samples are full range; say so, or readers (FFmpeg too) assume limited.
        let range = y4m::VendorExtensionString::new(b"COLORRANGE=FULL".to_vec())?;
        let encoder = y4m::encode(width, height, rate)
            .with_colorspace(y4m::Colorspace::C420jpeg)
            .append_vendor_extension(range)
            .write_header(out.clone())?;
        let chroma = width.div_ceil(2) * height.div_ceil(2);
        Ok(Y4mSink {
            encoder,
            out,
            width,
            planes: [vec![0; width * height], vec![0; chroma], vec![0; chroma]],
        })
    }
}

impl Sink for Y4mSink {
    fn write_frame(&mut self, _index: usize, frame: Frame<'_>) -> Result<(), SinkError> {
        let [y, cb, cr] = &mut self.planes;
        match frame {
            Frame::Rgb(img) => rgb_to_ycbcr420(img.as_raw(), self.width, y, cb, cr),
            Frame::Gray(img) => {
                y.copy_from_slice(img.as_raw());
                cb.fill(128);
                cr.fill(128);
            }
        }
        let frame = y4m::Frame::new([y, cb, cr], None);
        self.encoder.write_frame(&frame)?;
        Ok(())
    }

    fn finish(self) -> Result<(), SinkError> {
        drop(self.encoder);
        Ok(self.out.finish()?)
    }
}

/// Full-range BT.601 (JFIF) coefficients scaled by 2^16; each row of the
/// chroma matrix sums to zero and the luma row to 2^16, so gray stays exact.
const Y_COEF: [i64; 3] = [19_595, 38_470, 7_471];
const CB_COEF: [i64; 3] = [-11_059, -21_709, 32_768];
const CR_COEF: [i64; 3] = [32_768, -27_439, -5_329];

/// `coef · sum / (count · 2^16) + offset`, rounded and clamped to `u8`.
fn fixed_to_u8(coef: [i64; 3], sum: [i64; 3], count: i64, offset: i64) -> u8 {
    let scale = count << 16;
    let dot: i64 = coef.iter().zip(sum).map(|(c, s)| c * s).sum();
    // The numerator is never negative for sums of 0..=255 samples.
    let value = (dot + offset * scale + scale / 2).div_euclid(scale);
    value.clamp(0, 255) as u8
}

/// Converts packed RGB to JFIF YCbCr 4:2:0, chroma from the average RGB of
/// each (possibly partial) 2×2 block.
fn rgb_to_ycbcr420(rgb: &[u8], width: usize, y: &mut [u8], cb: &mut [u8], cr: &mut [u8]) {
    let row_len = 3 * width;
    for (px, y) in rgb.chunks_exact(3).zip(y) {
        let sum = [px[0], px[1], px[2]].map(i64::from);
        *y = fixed_to_u8(Y_COEF, sum, 1, 0);
    }
    let chroma_width = width.div_ceil(2);
    let chroma_rows = cb
        .chunks_exact_mut(chroma_width)
        .zip(cr.chunks_exact_mut(chroma_width));
    // Pairs of RGB rows; the last holds a single row when the height is odd.
    for ((cb_row, cr_row), row_pair) in chroma_rows.zip(rgb.chunks(2 * row_len)) {
        for (cx, (cb, cr)) in cb_row.iter_mut().zip(cr_row.iter_mut()).enumerate() {
            let mut sum = [0_i64; 3];
            let mut count = 0;
            for row in row_pair.chunks_exact(row_len) {
                // One or, except in an odd last column, two pixels.
                for px in row[6 * cx..].chunks_exact(3).take(2) {
                    for (s, &v) in sum.iter_mut().zip(px) {
                        *s += i64::from(v);
                    }
                    count += 1;
                }
            }
            *cb = fixed_to_u8(CB_COEF, sum, count, 128);
            *cr = fixed_to_u8(CR_COEF, sum, count, 128);
        }
    }
}

/// `000000.png`, `000001.png`, …
fn png_name(index: usize) -> String {
    format!("{index:06}.png")
}

/// Encodes `frame` as an 8-bit gray or RGB PNG into `out`.
fn write_png(out: impl Write, frame: Frame<'_>) -> Result<(), ImageError> {
    let encoder = PngEncoder::new(out);
    match frame {
        Frame::Rgb(img) => encoder.write_image(
            img.as_raw(),
            img.width(),
            img.height(),
            image::ExtendedColorType::Rgb8,
        ),
        Frame::Gray(img) => encoder.write_image(
            img.as_raw(),
            img.width(),
            img.height(),
            image::ExtendedColorType::L8,
        ),
    }
}

struct ZipSink {
    zip: zip::ZipWriter<ZipOut>,
    discard: Arc<AtomicBool>,
}

impl ZipSink {
    fn new(file: BufWriter<File>) -> Self {
        let discard = Arc::new(AtomicBool::new(false));
        let out = ZipOut {
            file,
            pos: 0,
            len: 0,
            discard: Arc::clone(&discard),
        };
        ZipSink {
            zip: zip::ZipWriter::new(out),
            discard,
        }
    }
}

impl Sink for ZipSink {
    fn write_frame(&mut self, index: usize, frame: Frame<'_>) -> Result<(), SinkError> {
        let options = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Deflated);
        self.zip.start_file(png_name(index), options)?;
        write_png(&mut self.zip, frame)?;
        Ok(())
    }

    fn finish(self) -> Result<(), SinkError> {
        let out = self.zip.finish()?;
        out.file
            .into_inner()
            .map_err(io::IntoInnerError::into_error)?;
        Ok(())
    }

    fn abandon(&mut self) {
        self.discard.store(true, Ordering::Relaxed);
    }
}

/// The archive file as the `zip` crate sees it.
///
/// A `ZipWriter` dropped unfinished writes the central directory anyway and
/// prints to stderr if that fails. Once `discard` is set (by
/// [`Sink::abandon`] or at the first I/O error) writes and seeks only move a
/// position counter, so that drop-time work neither touches a file about to
/// be deleted nor prints. The `zip` crate never reads back what it wrote.
struct ZipOut {
    file: BufWriter<File>,
    /// Current position and length of the archive; it starts empty.
    pos: u64,
    len: u64,
    discard: Arc<AtomicBool>,
}

impl ZipOut {
    /// Runs `op` on the file unless discarding; an error starts discarding.
    fn file_op<T>(
        &mut self,
        discarded: T,
        op: impl FnOnce(&mut BufWriter<File>) -> io::Result<T>,
    ) -> io::Result<T> {
        if self.discard.load(Ordering::Relaxed) {
            return Ok(discarded);
        }
        op(&mut self.file).inspect_err(|_| self.discard.store(true, Ordering::Relaxed))
    }
}

impl Write for ZipOut {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let written = self.file_op(buf.len(), |file| file.write(buf))?;
        self.pos += written as u64;
        self.len = self.len.max(self.pos);
        Ok(written)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.file_op((), |file| file.flush())
    }
}

impl Seek for ZipOut {
    fn seek(&mut self, to: SeekFrom) -> io::Result<u64> {
        let target = match to {
            SeekFrom::Start(offset) => Some(offset),
            SeekFrom::Current(delta) => self.pos.checked_add_signed(delta),
            SeekFrom::End(delta) => self.len.checked_add_signed(delta),
        }
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "seek before archive start"))?;
        self.file_op(target, |file| file.seek(SeekFrom::Start(target)))?;
        self.pos = target;
        Ok(target)
    }
}

const TAR_BLOCK: usize = 512;

struct TarSink {
    out: BufWriter<File>,
    /// The current frame's PNG: a tar header states the size up front.
    png: Vec<u8>,
}

impl TarSink {
    fn new(out: BufWriter<File>) -> Self {
        TarSink {
            out,
            png: Vec::new(),
        }
    }
}

/// A ustar header for a regular file; `None` if `name` or `size` do not fit.
fn ustar_header(name: &str, size: u64) -> Option<[u8; TAR_BLOCK]> {
    /// Writes `value` as zero-padded octal filling `field` but its last byte (NUL).
    fn octal(field: &mut [u8], value: u64) -> Option<()> {
        let digits = field.len() - 1;
        let text = format!("{value:0digits$o}");
        (text.len() == digits).then(|| field[..digits].copy_from_slice(text.as_bytes()))
    }
    let mut h = [0_u8; TAR_BLOCK];
    if name.len() > 100 {
        return None;
    }
    h[..name.len()].copy_from_slice(name.as_bytes());
    octal(&mut h[100..108], 0o644)?; // mode
    octal(&mut h[108..116], 0)?; // uid
    octal(&mut h[116..124], 0)?; // gid
    octal(&mut h[124..136], size)?;
    octal(&mut h[136..148], 0)?; // mtime
    h[156] = b'0'; // regular file
    h[257..263].copy_from_slice(b"ustar\0");
    h[263..265].copy_from_slice(b"00");
    // The checksum is computed with its own field read as spaces.
    h[148..156].fill(b' ');
    let sum: u64 = h.iter().map(|&b| u64::from(b)).sum();
    octal(&mut h[148..155], sum)?; // six digits, NUL, then the space kept
    Some(h)
}

impl Sink for TarSink {
    fn write_frame(&mut self, index: usize, frame: Frame<'_>) -> Result<(), SinkError> {
        self.png.clear();
        write_png(&mut self.png, frame)?;
        let size = self.png.len() as u64;
        let header = ustar_header(&png_name(index), size)
            .ok_or_else(|| SinkError::Encode("tar entry too large for ustar".into()))?;
        self.out.write_all(&header)?;
        self.out.write_all(&self.png)?;
        let padding = self.png.len().next_multiple_of(TAR_BLOCK) - self.png.len();
        self.out.write_all(&[0; TAR_BLOCK][..padding])?;
        Ok(())
    }

    fn finish(mut self) -> Result<(), SinkError> {
        self.out.write_all(&[0; 2 * TAR_BLOCK])?; // end-of-archive marker
        self.out
            .into_inner()
            .map_err(io::IntoInnerError::into_error)?;
        Ok(())
    }
}

/// NeuQuant sampling factor for RGB frames with more than 256 colours
/// (1 = best, 30 = fastest).
const GIF_QUANTISER_SPEED: i32 = 10;

/// Frame delays in centiseconds keeping the cumulative time exact.
#[derive(Debug, Clone, Copy)]
struct GifDelays {
    /// Frame rate as numerator / denominator.
    rate: (u64, u64),
}

impl GifDelays {
    fn new((num, den): (u32, u32)) -> Self {
        GifDelays {
            rate: (num.into(), den.into()),
        }
    }

    /// Whether every delay fits GIF's 16-bit centisecond field: differences
    /// of `round(n * x)` never exceed `ceil(x)`, here `x = 100 / fps`.
    fn fit_gif(self) -> bool {
        let (num, den) = self.rate;
        (100 * den).div_ceil(num) <= u64::from(u16::MAX)
    }

    /// `round(n * 100 / fps)`, halves rounded up.
    fn elapsed_cs(self, n: u64) -> u64 {
        let (num, den) = (u128::from(self.rate.0), u128::from(self.rate.1));
        let cs = (2 * u128::from(n) * 100 * den + num) / (2 * num);
        u64::try_from(cs).unwrap_or(u64::MAX)
    }

    /// Delay of frame `index`, in centiseconds.
    fn delay_cs(self, index: usize) -> u64 {
        let n = index as u64;
        self.elapsed_cs(n + 1) - self.elapsed_cs(n)
    }
}

struct GifSink {
    encoder: GifEncoder<SharedOut>,
    out: SharedOut,
    delays: GifDelays,
}

impl GifSink {
    fn new(out: BufWriter<File>, delays: GifDelays) -> Result<Self, SinkError> {
        let out = SharedOut::new(out);
        let mut encoder = GifEncoder::new_with_speed(out.clone(), GIF_QUANTISER_SPEED);
        encoder.set_repeat(Repeat::Infinite)?;
        Ok(GifSink {
            encoder,
            out,
            delays,
        })
    }
}

impl Sink for GifSink {
    fn write_frame(&mut self, index: usize, frame: Frame<'_>) -> Result<(), SinkError> {
        let (width, height) = frame.dimensions();
        // The encoder takes RGBA only; it builds an exact palette when the
        // frame has at most 256 colours (any gray frame) and runs NeuQuant
        // otherwise.
        let rgba: Vec<u8> = match frame {
            Frame::Rgb(img) => img.pixels().flat_map(|p| [p[0], p[1], p[2], 255]).collect(),
            Frame::Gray(img) => img.pixels().flat_map(|p| [p[0], p[0], p[0], 255]).collect(),
        };
        let rgba = RgbaImage::from_raw(width, height, rgba)
            .expect("buffer holds width * height RGBA pixels");
        // `create` checked that every delay fits in u16 centiseconds.
        let delay_ms = u32::try_from(self.delays.delay_cs(index) * 10).unwrap_or(u32::MAX);
        let delay = Delay::from_numer_denom_ms(delay_ms, 1);
        self.encoder
            .encode_frame(image::Frame::from_parts(rgba, 0, 0, delay))?;
        Ok(())
    }

    fn finish(self) -> Result<(), SinkError> {
        // Dropping the encoder writes the GIF trailer through `out`.
        drop(self.encoder);
        Ok(self.out.finish()?)
    }
}
