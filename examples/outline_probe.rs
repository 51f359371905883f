//! Do the colour frame's inner outlines tell a pose from the poses the silhouette
//! confuses it with? For every benchmark capture and azimuth (colour clips as
//! `monocap bench` renders them), each frame's true shape and pose is compared with
//! the same pose after each jump the tracker tries (the depth flips, the nod moved
//! into the trunk, the legs and the arms swapped left for right) by
//! [`monocap::track::outlines::Outlines::disagreement`] on the frame's edges (the
//! true silhouette, so that only the outlines are measured). Prints, per jump, on
//! how many frames the truth disagrees less (by more than 3 pixels), more, or about
//! as much.
//!
//! ```text
//! cargo run --release --example outline_probe [--mocap ../shared/data/mocap]
//! ```
//!
//! Without `../shared/data/mocap` it says so and exits successfully.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::Result;
use monocap::body::{Body, Camera};
use monocap::clip::write::Frame;
use monocap::motion::bvh::Bvh;
use monocap::synth::{synthesize_with, Style, SynthOptions};
use monocap::track::flips::Jump;
use monocap::track::objective::{Target, Weights};
use monocap::track::outlines::Outlines;
use monocap::vision::features::{compute, FeatureOptions};

/// Differences up to this many pixels count as a tie.
const TIE: f64 = 3.0;

fn jump_name(j: Jump) -> String {
    match j {
        Jump::Flip(f) => f.name.replace(' ', "_"),
        Jump::NodIntoTrunk => "nod_into_trunk".into(),
        Jump::SwapLegs => "legs_swapped".into(),
        Jump::SwapArms => "arms_swapped".into(),
    }
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = match args.iter().position(|a| a == "--mocap") {
        Some(i) => PathBuf::from(args.get(i + 1).cloned().unwrap_or_default()),
        None => PathBuf::from("../shared/data/mocap"),
    };
    let Ok(entries) = std::fs::read_dir(&dir) else {
        println!("skipped: no motion capture at {}", dir.display());
        return Ok(());
    };
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("bvh")))
        .collect();
    files.sort();
    // Per jump: frames where the truth disagrees less, more, about as much.
    let mut tally: BTreeMap<String, [u32; 3]> = BTreeMap::new();
    for file in &files {
        let bvh = Bvh::read(file)?;
        let name = file.file_name().unwrap_or_default().to_string_lossy();
        for az in [0.0, 60.0, -120.0] {
            let synth = SynthOptions {
                style: Style::Color,
                empty_frames: 0,
                azimuth_deg: az,
                duration_s: Some(3.5),
                ..SynthOptions::default()
            };
            let mut pictures = Vec::new();
            let mut masks = Vec::new();
            let truth = synthesize_with(&bvh, &name, &synth, |f| {
                if let Frame::Rgb(img) = f.image {
                    pictures.push(img.clone());
                }
                masks.push(f.mask.clone());
                Ok(())
            })?;
            let cam = Camera::new(synth.width, synth.height, synth.fov_deg);
            let mut shape = [0.0; 12];
            shape.copy_from_slice(&truth.shape.values);
            let body = Body::new(&shape);
            let mut outlines = Outlines::new(&cam);
            let mut clip: BTreeMap<String, [u32; 3]> = BTreeMap::new();
            for tf in &truth.frames {
                let (Some(picture), Some(mask)) = (pictures.get(tf.index), masks.get(tf.index))
                else {
                    continue;
                };
                let f = compute(mask, Some(picture), None, &FeatureOptions::default());
                let target = Target::new(&f, &Weights::default());
                let mut pose = [0.0; 30];
                pose.copy_from_slice(&tf.params);
                let Some(d_true) = outlines.disagreement(&body, &cam, &target, &pose) else {
                    continue;
                };
                for jump in Jump::all() {
                    let Some(other) = jump.apply(&body, &pose) else {
                        continue;
                    };
                    let Some(d) = outlines.disagreement(&body, &cam, &target, &other) else {
                        continue;
                    };
                    let slot = if d > d_true + TIE {
                        0
                    } else if d < d_true - TIE {
                        1
                    } else {
                        2
                    };
                    clip.entry(jump_name(jump)).or_default()[slot] += 1;
                }
            }
            let swaps: Vec<String> = ["legs_swapped", "arms_swapped"]
                .iter()
                .filter_map(|k| {
                    clip.get(*k)
                        .map(|t| format!("{k} {}/{}/{}", t[0], t[1], t[2]))
                })
                .collect();
            println!("{name} az {az:+.0}: {}", swaps.join(", "));
            for (k, t) in clip {
                let e = tally.entry(k).or_default();
                for i in 0..3 {
                    e[i] += t[i];
                }
            }
        }
    }
    println!("\njump: frames where the truth disagrees less / more / about as much");
    for (k, t) in &tally {
        println!("{k:24} {:5} {:5} {:5}", t[0], t[1], t[2]);
    }
    Ok(())
}
