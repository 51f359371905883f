//! Clips: frames in (decoders behind one trait) and frames out (writers).

pub mod anim;
pub mod archive;
pub mod avi;
pub mod decode;
pub mod ffmpeg;
pub mod h264;
pub mod mp4;
pub mod open;
pub mod write;
pub mod y4m;

pub use decode::{ClipInfo, DecodeError, FrameSource, Limits};

/// A half-open frame range `A..B` with A < B (how frames are named on the command
/// line and in job options).
pub fn parse_frame_range(text: &str) -> Result<(usize, usize), String> {
    let (a, b) = text
        .split_once("..")
        .ok_or_else(|| format!("{text:?}: expected a range A..B"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<usize>()
            .map_err(|_| format!("{text:?}: {v:?} is not a frame number"))
    };
    let (a, b) = (parse(a)?, parse(b)?);
    if a >= b {
        return Err(format!("{text:?}: the range is empty"));
    }
    Ok((a, b))
}
