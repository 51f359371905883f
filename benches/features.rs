//! Features per second (method.md §4) at 320×240 on a rendered silhouette, with a
//! colour frame (Sobel edges) and without (a mask clip). Prints a plain frames-per-
//! second figure before criterion's own measurements.

use std::time::Instant;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use image::{Rgb, RgbImage};
use monocap::body::params::{self, ix};
use monocap::body::raster::render_mask;
use monocap::body::{Body, Camera, Mask};
use monocap::vision::features::{compute, FeatureOptions};

/// A silhouette with arms and legs spread, and a frame: a textured background with
/// the person painted over it in two colours.
fn scene(w: u32, h: u32) -> (Mask, RgbImage) {
    let body = Body::new(&params::STANDARD_SHAPE);
    let mut pose = params::rest_pose();
    pose[ix::ROOT_TY] = 0.0;
    pose[ix::ROOT_TZ] = -350.0;
    pose[ix::ROOT_RY] = 25.0;
    pose[ix::L_SHOULDER + 1] = 70.0;
    pose[ix::R_SHOULDER + 1] = 110.0;
    pose[ix::R_ELBOW] = 30.0;
    pose[ix::L_HIP + 1] = 20.0;
    pose[ix::R_HIP + 1] = 15.0;
    pose[ix::R_KNEE] = 25.0;
    let cam = Camera::new(w, h, 55.0);
    let mut mask = Mask::new(w, h);
    render_mask(&body, &body.posed(&pose), &cam, &mut mask);
    let frame = RgbImage::from_fn(w, h, |x, y| {
        if mask.get(x, y) {
            if y < h / 2 {
                Rgb([200, 60, 50])
            } else {
                Rgb([40, 50, 120])
            }
        } else {
            let v = ((x / 8 + y / 8) % 2) as u8 * 30 + 100;
            Rgb([v, v + 10, v])
        }
    });
    (mask, frame)
}

fn bench(c: &mut Criterion) {
    let (w, h) = (320, 240);
    let (mask, frame) = scene(w, h);
    let opts = FeatureOptions::default();
    let prev = compute(&mask, Some(&frame), None, &opts);
    // A plain figure first.
    let n = 200;
    let t = Instant::now();
    for _ in 0..n {
        std::hint::black_box(compute(&mask, Some(&frame), Some(&prev), &opts));
    }
    let fps = n as f64 / t.elapsed().as_secs_f64();
    println!(
        "features at {w}×{h} with a colour frame: {fps:.0} frames/s ({:.2} ms a frame; {} \
         extremities, head {:?})",
        1000.0 / fps,
        prev.extremities.len(),
        prev.head
    );
    let mut group = c.benchmark_group("features");
    group.throughput(Throughput::Elements(1));
    group.bench_function(BenchmarkId::new("frame", format!("{w}x{h}")), |b| {
        b.iter(|| compute(&mask, Some(&frame), Some(&prev), &opts))
    });
    group.bench_function(BenchmarkId::new("mask", format!("{w}x{h}")), |b| {
        b.iter(|| compute(&mask, None, Some(&prev), &opts))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
