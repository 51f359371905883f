//! Clips: frames in (decoders arrive with the decoding work) and frames out (writers).

pub mod write;
