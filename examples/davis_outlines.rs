//! Real clothes and the inner outlines: the DAVIS people (lucia, dance-twirl,
//! tennis) tracked from their hand-drawn masks together with their video frames,
//! so that the frames' edges (folds, prints, shadows: everything a real picture
//! has) are weighed in as on a colour clip ([`monocap::track::outlines`]), once
//! with the default `--w-outline` and once with 0. Prints each sequence's mean
//! model IoU with the mask (at the tracker's working size, half the clip's) and the
//! tracking speed: the outlines must not cost the fit on real pictures, where no
//! ground truth says which leg is in front.
//!
//! ```text
//! cargo run --release --example davis_outlines
//! ```
//!
//! Data: `../shared/data/davis/<seq>/{masks/*.png, frames/*.jpg}`; when absent the
//! example says so and exits successfully.

mod common;
use common::list;

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Result};
use image::imageops::{resize, FilterType};
use monocap::body::{Camera, Mask};
use monocap::track::objective::OUTLINE_WEIGHT;
use monocap::track::tracker::{FrameInput, TrackOptions, Tracker};

const SEQUENCES: [&str; 3] = ["lucia", "dance-twirl", "tennis"];

/// The sequence's masks and frames at half size.
fn load(dir: &Path) -> Result<Vec<FrameInput>> {
    let masks = list(&dir.join("masks"), "png")?;
    let frames = list(&dir.join("frames"), "jpg")?;
    if masks.is_empty() || masks.len() != frames.len() {
        bail!(
            "{}: {} masks and {} frames",
            dir.display(),
            masks.len(),
            frames.len()
        );
    }
    masks
        .iter()
        .zip(&frames)
        .map(|(m, f)| {
            let gray = image::open(m)?.to_luma8();
            let rgb = image::open(f)?.to_rgb8();
            let (w, h) = (gray.width() / 2, gray.height() / 2);
            let small = resize(&gray, w, h, FilterType::Triangle);
            Ok(FrameInput {
                silhouette: Mask::from_gray(&small, 128),
                image: Some(resize(&rgb, w, h, FilterType::Triangle)),
            })
        })
        .collect()
}

fn main() -> Result<()> {
    let root = PathBuf::from("../shared/data/davis");
    if !root.is_dir() {
        println!("skipped: no DAVIS data at {}", root.display());
        return Ok(());
    }
    println!("sequence      w_outline  mean IoU  frames/s");
    for seq in SEQUENCES {
        let inputs = load(&root.join(seq))?;
        let (w, h) = (inputs[0].silhouette.width(), inputs[0].silhouette.height());
        for weight in [0.0, OUTLINE_WEIGHT] {
            let mut opts = TrackOptions::default();
            opts.weights.outline = weight;
            let tracker = Tracker::new(Camera::new(w, h, 55.0), opts);
            let frames = inputs.iter().map(|i| {
                Ok(FrameInput {
                    silhouette: i.silhouette.clone(),
                    image: i.image.clone(),
                })
            });
            let started = Instant::now();
            let track =
                tracker.track(frames, Some(inputs.len()), |_, _| ControlFlow::Continue(()))?;
            let secs = started.elapsed().as_secs_f64();
            let ious: Vec<f64> = track.frames.iter().filter_map(|f| f.iou).collect();
            let mean = ious.iter().sum::<f64>() / ious.len().max(1) as f64;
            println!(
                "{seq:13} {weight:9} {mean:9.3} {:9.2}",
                inputs.len() as f64 / secs
            );
        }
    }
    Ok(())
}
