//! Background subtraction on a real static camera: OpenCV's vtest.mp4 (a walkway with
//! several pedestrians, never empty). The foreground must cover the walkers and not
//! the static scene. Two checks independent of the model's own estimate:
//! - the per-pixel median of the clip (the scene, as pedestrians keep moving) is
//!   almost all background;
//! - pixels that frame differencing shows moving (|I(t) − I(t−4)| large, in blobs of a
//!   person's size) are foreground.

use std::path::Path;

use image::RgbImage;
use monocap::body::Mask;
use monocap::clip::open::open;
use monocap::clip::Limits;
use monocap::vision::silhouette::{Segmenter, SilhouetteOptions};

const CLIP: &str = "../shared/data/video/vtest.mp4";

fn frames(step: usize) -> Vec<RgbImage> {
    let mut src = open(Path::new(CLIP), &Limits::default()).unwrap();
    let mut out = Vec::new();
    let mut i = 0;
    while let Some(f) = src.next_frame().unwrap() {
        if i % step == 0 {
            out.push(f);
        }
        i += 1;
    }
    out
}

fn median(frames: &[RgbImage]) -> RgbImage {
    let (w, h) = frames[0].dimensions();
    RgbImage::from_fn(w, h, |x, y| {
        let mut px = [0u8; 3];
        for (c, p) in px.iter_mut().enumerate() {
            let mut v: Vec<u8> = frames.iter().map(|f| f.get_pixel(x, y).0[c]).collect();
            v.sort_unstable();
            *p = v[v.len() / 2];
        }
        image::Rgb(px)
    })
}

#[test]
fn foreground_covers_the_walkers_not_the_scene() {
    if !Path::new(CLIP).is_file() {
        println!("skipped: {CLIP} is absent (a fresh clone has no ../shared)");
        return;
    }
    // Every other frame (400 frames) keeps the test quick; the model sees them all.
    let clip = frames(2);
    let (w, h) = clip[0].dimensions();
    let opts = SilhouetteOptions::default();
    let seg = Segmenter::learn(w, h, &opts, |visit| {
        clip.iter().for_each(&mut *visit);
        Ok::<_, ()>(())
    })
    .unwrap();

    // The scene: the clip's median frame is almost all background.
    let mut fg = Mask::new(w, h);
    seg.model
        .foreground(&median(&clip), &opts.background, &mut fg);
    let scene_fraction = fg.count() as f64 / (w * h) as f64;

    // Walkers: strong frame differences must be foreground. Differencing also fires
    // where a walker was 4 frames ago (background now), so a moving pixel counts as
    // covered when it is foreground in either of the two frames.
    // Edges of a walker blur over a pixel or two (motion, compression): a moving
    // pixel within 2 pixels of the foreground counts as covered.
    let masks: Vec<Mask> = clip
        .iter()
        .map(|f| {
            let mut m = Mask::new(w, h);
            seg.model.foreground(f, &opts.background, &mut m);
            let grown = imageproc::morphology::dilate(
                &m.to_gray(),
                imageproc::distance_transform::Norm::LInf,
                2,
            );
            Mask::from_gray(&grown, 128)
        })
        .collect();
    let (mut moving, mut covered) = (0u64, 0u64);
    for t in 4..clip.len() {
        for (x, y, p) in clip[t].enumerate_pixels() {
            let q = clip[t - 4].get_pixel(x, y);
            let diff = (0..3)
                .map(|c| (p.0[c] as i32 - q.0[c] as i32).abs())
                .max()
                .unwrap_or(0);
            if diff > 60 {
                moving += 1;
                covered += (masks[t].get(x, y) || masks[t - 4].get(x, y)) as u64;
            }
        }
    }
    let mut raw = Mask::new(w, h);
    let fg_total: u64 = clip[4..]
        .iter()
        .map(|f| {
            seg.model.foreground(f, &opts.background, &mut raw);
            raw.count()
        })
        .sum();
    let mean_fraction = fg_total as f64 / ((clip.len() - 4) as f64 * (w * h) as f64);
    let coverage = covered as f64 / moving.max(1) as f64;
    println!(
        "vtest: median frame {:.3}% foreground; mean foreground {:.2}% of the image; \
         {:.1}% of {moving} strongly moving pixels covered ({:?})",
        scene_fraction * 100.0,
        mean_fraction * 100.0,
        coverage * 100.0,
        seg.model.source
    );
    assert!(
        scene_fraction < 0.005,
        "the static scene is {:.2}% foreground",
        scene_fraction * 100.0
    );
    assert!(
        mean_fraction < 0.10,
        "mean foreground {:.1}%",
        mean_fraction * 100.0
    );
    assert!(moving > 10_000, "too few moving pixels to judge");
    assert!(
        coverage > 0.9,
        "only {:.1}% of moving pixels are foreground",
        coverage * 100.0
    );
}
