//! Renders per second of the silhouette rasterizer at 320×240 and 640×480, of
//! forward kinematics followed by a render, and of the parts' row spans
//! (`span_parts`, what the tracker pays per evaluation when it counts shares of
//! pixels, its default); and forward kinematics alone, with every angle new and
//! with the root's alone new (a search over the global group: the other joints'
//! rotations are reused from the last posing).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use monocap::body::params::{self, ix, MOTION};
use monocap::body::raster::{render_mask, span_parts, PartSpans};
use monocap::body::{Body, Camera, Mask, Posed};
use rand::{RngExt, SeedableRng};

fn poses(n: usize) -> Vec<params::Pose> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    (0..n)
        .map(|_| {
            let mut pose = params::rest_pose();
            for (i, m) in MOTION.iter().enumerate().skip(6) {
                pose[i] = rng.random_range(m.lo.max(-90.0)..m.hi.min(90.0)) * 0.6;
            }
            pose[ix::ROOT_TZ] = -450.0;
            pose[ix::ROOT_TY] = -5.0;
            pose[ix::ROOT_RY] = rng.random_range(-180.0..180.0);
            pose
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let body = Body::new(&params::STANDARD_SHAPE);
    let poses = poses(64);
    let posed: Vec<Posed> = poses.iter().map(|p| body.posed(p)).collect();
    let mut group = c.benchmark_group("render_mask");
    group.throughput(Throughput::Elements(1));
    for (w, h) in [(320u32, 240u32), (640, 480)] {
        let cam = Camera::new(w, h, 55.0);
        let mut mask = Mask::new(w, h);
        let mut i = 0;
        group.bench_function(BenchmarkId::from_parameter(format!("{w}x{h}")), |b| {
            b.iter(|| {
                i = (i + 1) % posed.len();
                render_mask(&body, &posed[i], &cam, &mut mask);
                mask.words()[0]
            })
        });
        let mut out = Posed::default();
        group.bench_function(BenchmarkId::new("fk+render", format!("{w}x{h}")), |b| {
            b.iter(|| {
                i = (i + 1) % poses.len();
                body.skeleton.pose(&poses[i], &mut out);
                render_mask(&body, &out, &cam, &mut mask);
                mask.words()[0]
            })
        });
    }
    group.finish();
    let mut group = c.benchmark_group("pose");
    group.throughput(Throughput::Elements(1));
    let mut out = Posed::default();
    let mut i = 0;
    group.bench_function("every angle new", |b| {
        b.iter(|| {
            i = (i + 1) % poses.len();
            body.skeleton.pose(&poses[i], &mut out);
            out.tips[0]
        })
    });
    let mut turned = poses[0];
    group.bench_function("the root's alone new", |b| {
        b.iter(|| {
            i = (i + 1) % poses.len();
            turned[ix::ROOT_RY] = poses[i][ix::ROOT_RY];
            body.skeleton.pose(&turned, &mut out);
            out.tips[0]
        })
    });
    group.finish();
    let mut group = c.benchmark_group("span_parts");
    group.throughput(Throughput::Elements(1));
    let all: Vec<usize> = (0..body.parts.len()).collect();
    for (w, h) in [(320u32, 240u32), (640, 480)] {
        let cam = Camera::new(w, h, 55.0);
        let mut spans = PartSpans::new(w, h);
        let mut i = 0;
        group.bench_function(BenchmarkId::from_parameter(format!("{w}x{h}")), |b| {
            b.iter(|| {
                i = (i + 1) % posed.len();
                span_parts(&body, &posed[i], &cam, &all, &mut spans);
                spans.rows(0)
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
