//! Frames per second of the per-frame vision stage at 320×240: silhouette (background
//! test + clean-up) and the objective's features (coremap, edges, outline), on a
//! synthetic colour clip rendered from the body model (no shared data needed).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use image::RgbImage;
use monocap::body::params::{self, ix};
use monocap::body::raster::{render_fragments, Fragments};
use monocap::body::{Body, Camera, Mask};
use monocap::vision::features::{self, FeatureOptions};
use monocap::vision::silhouette::{Segmenter, SilhouetteOptions};

/// 40 frames: 10 of a flat-shaded scene, then a body walking across it.
fn clip() -> Vec<RgbImage> {
    let (w, h) = (320, 240);
    let cam = Camera::new(w, h, 55.0);
    let body = Body::new(&params::STANDARD_SHAPE);
    let scene = RgbImage::from_fn(w, h, |x, y| {
        image::Rgb([(120 + x % 40) as u8, (140 + y % 30) as u8, 150])
    });
    let mut frags = Fragments::new(w, h);
    (0..40)
        .map(|i| {
            let mut f = scene.clone();
            if i >= 10 {
                let mut pose = params::rest_pose();
                pose[ix::ROOT_TX] = -80.0 + 5.0 * i as f64;
                pose[ix::ROOT_TY] -= 100.0;
                pose[ix::ROOT_TZ] = -420.0;
                pose[ix::L_SHOULDER] = 40.0;
                pose[ix::R_HIP] = (i as f64 * 0.4).sin() * 30.0;
                render_fragments(&body, &body.posed(&pose), &cam, &mut frags);
                for (k, px) in f.pixels_mut().enumerate() {
                    if frags.depth[k].is_finite() {
                        *px = image::Rgb([60, 90, 170]);
                    }
                }
            }
            f
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let frames = clip();
    let opts = SilhouetteOptions::default();
    let seg = Segmenter::learn(320, 240, &opts, |visit| {
        frames.iter().for_each(&mut *visit);
        Ok::<_, ()>(())
    })
    .unwrap();
    let fopts = FeatureOptions::default();
    let mut mask = Mask::new(320, 240);
    let mut g = c.benchmark_group("vision_320x240");
    g.throughput(Throughput::Elements(1));
    let mut i = 10;
    g.bench_function("silhouette", |b| {
        b.iter(|| {
            i = 10 + (i + 1) % 30;
            seg.silhouette(&frames[i], &mut mask);
            mask.count()
        })
    });
    g.bench_function("silhouette+features", |b| {
        b.iter(|| {
            i = 10 + (i + 1) % 30;
            seg.silhouette(&frames[i], &mut mask);
            features::compute(&mask, Some(&frames[i]), None, &fopts)
                .coremap
                .len()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
