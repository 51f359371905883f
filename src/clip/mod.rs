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
