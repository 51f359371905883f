//! monocap: markerless monocular motion capture after Chen et al. (CGI 2005).
//!
//! The engine is plain synchronous Rust, laid out as the pipeline:
//! `clip` (frames in and out) → `body` (model, kinematics, camera, rasterizer)
//! → `motion` (BVH in and out, retargeting real motion capture) → `synth`
//! (benchmark clips rendered from real motion capture with their ground truth).
//!
//! The service is a shell around the engine: `jobs` (options, worker pool, progress
//! bus), `store` (database and files) and `api` (the HTTP routes).

pub mod api;
pub mod body;
pub mod clip;
pub mod jobs;
pub mod motion;
pub mod store;
pub mod synth;
pub mod track;
pub mod vision;
