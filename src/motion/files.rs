//! Writing a tracked clip's files: the motion as BVH or JSON, and the model's
//! silhouette per frame. The command line and the service's workers write the same
//! files through these.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use anyhow::{Context, Result};

use crate::body::{raster::render_mask, Body, Mask};
use crate::clip::write;
use crate::motion::json::MotionJson;
use crate::track::run::ClipTrack;

/// A motion file format, picked by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MotionFormat {
    Bvh,
    Json,
}

impl MotionFormat {
    /// The format a path's extension names.
    pub fn from_path(path: &Path) -> Result<MotionFormat> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        match ext.as_deref() {
            Some("bvh") => Ok(MotionFormat::Bvh),
            Some("json") => Ok(MotionFormat::Json),
            _ => anyhow::bail!(
                "{}: unknown motion format (use a .bvh or .json extension)",
                path.display()
            ),
        }
    }
}

/// Writes the motion in `format` to `path`.
pub fn write_motion(done: &ClipTrack, format: MotionFormat, path: &Path) -> Result<()> {
    let file = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut w = BufWriter::new(file);
    match format {
        MotionFormat::Json => {
            let motion = MotionJson::new(&done.track, &done.camera, done.fps);
            serde_json::to_writer(&mut w, &motion)?;
            w.write_all(b"\n")?;
        }
        MotionFormat::Bvh => {
            let body = Body::new(&done.track.shape);
            let poses: Vec<_> = done.track.frames.iter().map(|f| f.pose).collect();
            let bvh = crate::motion::export::monocap_bvh(&body.skeleton, &poses, done.fps)?;
            bvh.write(&mut w)?;
        }
    }
    w.flush()
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Writes the model's silhouette of every frame (empty where there is no person) as
/// a mask clip; the extension picks the container (.zip, .tar, .gif, .y4m).
pub fn write_model_masks(done: &ClipTrack, path: &Path) -> Result<()> {
    let cam = &done.camera;
    let body = Body::new(&done.track.shape);
    let mut out = write::create(path, cam.width, cam.height, done.fps)?;
    let mut m = Mask::new(cam.width, cam.height);
    for f in &done.track.frames {
        m.clear();
        if f.person {
            render_mask(&body, &body.posed(&f.pose), cam, &mut m);
        }
        out.push(write::Frame::Gray(&m.to_gray()))?;
    }
    out.finish()?;
    Ok(())
}
