//! Silhouette quality on every benchmark clip: each capture of `../shared/data/mocap`
//! rendered by `monocap synth --style color` (320×240, 30 fps, 3.5 s) from azimuths
//! 0, 60 and −120, with a 10-frame person-free lead-in and without; prints the mean
//! and worst IoU of the extracted silhouettes with the true ones, and the share of the
//! person's pixels that lie where the clip never shows the scene (covered in every
//! frame: no background subtraction can see the scene there without person-free
//! frames).
//!
//! `cargo run --release --example silhouette_survey [-- NAME-FILTER]`

use monocap::body::Mask;
use monocap::clip::write::Frame;
use monocap::motion::bvh::Bvh;
use monocap::synth::{synthesize_with, Style, SynthOptions};
use monocap::vision::silhouette::{Segmenter, SilhouetteOptions};

const MOCAP: &str = "../shared/data/mocap";

fn main() -> anyhow::Result<()> {
    let filter = std::env::args().nth(1);
    let mut files: Vec<_> = std::fs::read_dir(MOCAP)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "bvh"))
        .collect();
    files.sort();
    println!(
        "{:36} {:>7} {:>8} {:>9} {:>6} {:>12}",
        "clip", "azimuth", "lead-in", "mean IoU", "worst", "never shown"
    );
    for file in files {
        let name = file
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
            .to_string();
        if filter.as_ref().is_some_and(|f| !name.contains(f.as_str())) {
            continue;
        }
        let bvh = Bvh::read(&file)?;
        for azimuth in [0.0, 60.0, -120.0] {
            for lead in [10, 0] {
                let opts = SynthOptions {
                    style: Style::Color,
                    empty_frames: lead,
                    azimuth_deg: azimuth,
                    duration_s: Some(3.5),
                    ..SynthOptions::default()
                };
                let (w, h) = (opts.width, opts.height);
                let (mut frames, mut truth) = (Vec::new(), Vec::new());
                synthesize_with(&bvh, &name, &opts, |f| {
                    let Frame::Rgb(img) = f.image else {
                        anyhow::bail!("a colour clip");
                    };
                    frames.push(img.clone());
                    truth.push(f.mask.clone());
                    Ok(())
                })?;
                let seg = Segmenter::learn(w, h, &SilhouetteOptions::default(), |visit| {
                    frames.iter().for_each(&mut *visit);
                    Ok::<_, ()>(())
                })
                .map_err(|_| anyhow::anyhow!("segmenting"))?;
                let mut sequence = seg.sequence();
                let mut out = Mask::new(w, h);
                let (mut sum, mut n, mut worst) = (0.0, 0, 1.0f64);
                for (i, (f, t)) in frames.iter().zip(&truth).enumerate() {
                    sequence.next(f, &mut out);
                    if i >= lead {
                        let iou = out.iou(t);
                        sum += iou;
                        n += 1;
                        worst = worst.min(iou);
                    }
                }
                // Without a lead-in: the pixels the person covers in every frame, and
                // the share of their pixels that lie there.
                let never_shown = if lead == 0 {
                    let mut always = truth[0].clone();
                    for t in &truth[1..] {
                        always.and_with(t);
                    }
                    let on: u64 = truth.iter().map(|t| t.count_and(&always)).sum();
                    let all: u64 = truth.iter().map(Mask::count).sum();
                    format!("{:.3}", on as f64 / all.max(1) as f64)
                } else {
                    "-".to_string()
                };
                println!(
                    "{name:36} {azimuth:7} {lead:8} {:9.3} {worst:6.3} {never_shown:>12}",
                    sum / n.max(1) as f64
                );
            }
        }
    }
    Ok(())
}
