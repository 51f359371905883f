//! Vision: from frames to silhouettes (method.md §3) and the per-frame features the
//! objective needs (§4): coremap, edge map, outline features.

pub mod background;
pub mod blobs;
pub mod cleanup;
pub mod features;
pub mod silhouette;
pub mod skin;
