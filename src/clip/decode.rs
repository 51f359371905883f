//! Frames in: one trait every decoder implements, limits every decoder honours, and
//! the sniffing that picks a decoder from a file's first bytes (never its extension).
//!
//! Decoders stream: `next_frame` returns one frame at a time in display order, so a
//! long clip is never held in memory whole. What a decoder keeps between calls (a
//! reorder buffer for B-frames, an archive's index) is stated on each decoder.

use std::path::{Path, PathBuf};

use image::RgbImage;

/// What a clip is, as far as its container says (or, failing that, as far as
/// decoding it showed).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ClipInfo {
    /// `mp4`, `avi`, `y4m`, `gif`, `apng`, `webp`, `zip`, `tar`, or what ffmpeg names.
    pub container: String,
    /// `h264`, `mjpeg`, `rawvideo`, `gif`, `png`, `jpeg`, `webp`, … as found.
    pub codec: String,
    pub width: u32,
    pub height: u32,
    /// Frames per second (a frame archive has none of its own: 0 unless given).
    pub fps: f64,
    pub frame_count: u64,
    pub duration_s: f64,
    /// The frames are already silhouettes (a ZIP/TAR of binary masks): background
    /// subtraction is skipped for them.
    #[serde(skip)]
    pub is_mask: bool,
}

/// Caps on what an upload can make a decoder allocate or do.
#[derive(Clone, Debug)]
pub struct Limits {
    pub max_width: u32,
    pub max_height: u32,
    /// Most pixels a frame may have (width × height): per-pixel models downstream
    /// (the background model keeps about 130 bytes a pixel, twice that while it
    /// finishes) must fit in memory.
    pub max_pixels: u64,
    /// Most frames a clip may have.
    pub max_frames: u64,
    /// Most bytes one archive entry may inflate to.
    pub max_entry_bytes: u64,
    /// Most bytes all of an archive's entries may inflate to.
    pub max_total_bytes: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_width: 4096,
            max_height: 4096,
            max_pixels: 3840 * 2160,
            max_frames: 100_000,
            max_entry_bytes: 64 << 20,
            max_total_bytes: 8 << 30,
        }
    }
}

impl Limits {
    /// Refuses a frame size over the limits (before anything of that size is allocated).
    pub fn check_size(&self, path: &Path, width: u32, height: u32) -> Result<(), DecodeError> {
        if width == 0
            || height == 0
            || width > self.max_width
            || height > self.max_height
            || width as u64 * height as u64 > self.max_pixels
        {
            return Err(DecodeError::TooLarge {
                path: path.to_path_buf(),
                what: format!(
                    "frame size {width}×{height} (the limit is {}×{} and {} pixels, and neither side may be 0)",
                    self.max_width, self.max_height, self.max_pixels
                ),
            });
        }
        Ok(())
    }
}

/// Why a clip cannot be read. `Display` is one line naming the file and the problem.
#[derive(Debug, thiserror::Error)]
pub enum DecodeError {
    #[error("cannot read {path}: {error}", path = .path.display())]
    Io {
        path: PathBuf,
        /// Named so that the one-line message is not repeated as its source.
        error: std::io::Error,
    },
    #[error("{path} is not a clip monocap can read: {what}", path = .path.display())]
    UnknownFormat { path: PathBuf, what: String },
    #[error("unsupported codec {codec} in {path} ({container}); install ffmpeg to read it", path = .path.display())]
    UnsupportedCodec {
        path: PathBuf,
        container: String,
        codec: String,
    },
    #[error("{path} is too large: {what}", path = .path.display())]
    TooLarge { path: PathBuf, what: String },
    #[error("{path} is damaged: {what}", path = .path.display())]
    Corrupt { path: PathBuf, what: String },
    #[error("{path} ends early: {what}", path = .path.display())]
    Truncated { path: PathBuf, what: String },
    #[error("{path}: {what}", path = .path.display())]
    Other { path: PathBuf, what: String },
}

impl DecodeError {
    pub fn corrupt(path: &Path, what: impl Into<String>) -> DecodeError {
        DecodeError::Corrupt {
            path: path.to_path_buf(),
            what: what.into(),
        }
    }

    pub fn truncated(path: &Path, what: impl Into<String>) -> DecodeError {
        DecodeError::Truncated {
            path: path.to_path_buf(),
            what: what.into(),
        }
    }

    pub fn io(path: &Path, error: std::io::Error) -> DecodeError {
        DecodeError::Io {
            path: path.to_path_buf(),
            error,
        }
    }

    /// An I/O error, or `Truncated` saying `eof` when the file ended early.
    pub fn io_or_truncated(path: &Path, source: std::io::Error, eof: &str) -> DecodeError {
        if source.kind() == std::io::ErrorKind::UnexpectedEof {
            DecodeError::truncated(path, eof)
        } else {
            DecodeError::io(path, source)
        }
    }
}

/// A stream of frames in display order.
pub trait FrameSource: Send {
    fn info(&self) -> &ClipInfo;
    /// The next frame as 8-bit RGB, or `None` after the last one.
    fn next_frame(&mut self) -> Result<Option<RgbImage>, DecodeError>;
}
