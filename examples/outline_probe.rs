//! Do the colour frame's inner outlines, and its shading, tell a pose from the
//! poses the silhouette confuses it with? For every benchmark capture and azimuth
//! (colour clips as `monocap bench` renders them), each frame's true shape and pose
//! is compared with the same pose after each jump the tracker tries (the depth
//! flips, the nod moved into the trunk, the legs and the arms swapped left for
//! right, the crouch, the whole body's depth mirror
//! ([`monocap::track::flips::depth_mirror`])), by
//! [`monocap::track::outlines::Outlines::disagreement`] on the frame's edges (the
//! true silhouette, so that only the outlines are measured) and by
//! [`monocap::track::shading::Shading::misfit`] on its brightness. Prints, per
//! jump, on how many frames the truth disagrees less (by more than 3 pixels, or 2
//! levels² of mean shading misfit), more, or about as much, and the mean misfits.
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
use monocap::track::shading::Shading;
use monocap::vision::features::{compute, FeatureOptions};

/// Differences up to this many pixels count as a tie.
const TIE: f64 = 3.0;
/// Differences of mean shading misfit up to this many levels² count as a tie.
const SHADE_TIE: f64 = 2.0;

/// Where `d` lies against the truth's `d_true`: 0 the truth less, 1 more, 2 a tie.
fn slot(d: f64, d_true: f64, tie: f64) -> usize {
    if d > d_true + tie {
        0
    } else if d < d_true - tie {
        1
    } else {
        2
    }
}

fn jump_name(j: Jump) -> String {
    match j {
        Jump::Flip(f) => f.name.replace(' ', "_"),
        Jump::NodIntoTrunk => "nod_into_trunk".into(),
        Jump::SwapLegs => "legs_swapped".into(),
        Jump::SwapArms => "arms_swapped".into(),
        Jump::Crouch => "crouched".into(),
        Jump::Mirror => "depth_mirror".into(),
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
    // Per jump: the same by the shading; and the sums of the truth's and the
    // jump's mean misfits.
    let mut shade_tally: BTreeMap<String, ([u32; 3], f64, f64)> = BTreeMap::new();
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
            let mut shading = Shading::new(&cam);
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
                let luma: Vec<u8> = picture
                    .pixels()
                    .map(|p| ((u16::from(p[0]) + u16::from(p[1]) + u16::from(p[2]) + 1) / 3) as u8)
                    .collect();
                let (s_true, _) = shading.misfit(&body, &cam, &luma, mask, &pose);
                let others = Jump::all()
                    .filter_map(|jump| jump.apply(&body, &pose).map(|p| (jump_name(jump), p)));
                for (name, other) in others {
                    let Some(d) = outlines.disagreement(&body, &cam, &target, &other) else {
                        continue;
                    };
                    clip.entry(name.clone()).or_default()[slot(d, d_true, TIE)] += 1;
                    let (s, _) = shading.misfit(&body, &cam, &luma, mask, &other);
                    let e = shade_tally.entry(name).or_default();
                    e.0[slot(s, s_true, SHADE_TIE)] += 1;
                    e.1 += s_true;
                    e.2 += s;
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
    println!(
        "{:24} {:>17}   {:>17}   mean shading misfit (levels²)",
        "", "outlines", "shading"
    );
    for (k, t) in &tally {
        let (s, s_true, s_jump) = shade_tally.get(k).copied().unwrap_or_default();
        let n = f64::from(s[0] + s[1] + s[2]).max(1.0);
        println!(
            "{k:24} {:5} {:5} {:5}   {:5} {:5} {:5}   truth {:6.1}, jump {:6.1}",
            t[0],
            t[1],
            t[2],
            s[0],
            s[1],
            s[2],
            s_true / n,
            s_jump / n
        );
    }
    Ok(())
}
