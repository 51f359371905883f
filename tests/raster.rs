//! The rasterizer against a 4×4-supersampled reference over random poses.
//!
//! Sizes are those tracking uses (a body of 2000+ pixels); on a much smaller body
//! (under ~1000 pixels, e.g. 160×120) pixel-centre sampling noise alone passes 1%.

use monocap::body::params::{self, ix, MOTION};
use monocap::body::raster::{render_coverage, render_mask};
use monocap::body::{Body, Camera, Mask};
use rand::{RngExt, SeedableRng};

/// A random pose within the joint limits (angles drawn from the middle of each
/// range so limbs take every direction), standing `dist` cm in front of the camera.
fn random_pose(rng: &mut impl RngExt, dist: f64) -> params::Pose {
    let mut pose = params::rest_pose();
    for (i, m) in MOTION.iter().enumerate().skip(6) {
        let (lo, hi) = (m.lo.max(-120.0), m.hi.min(120.0));
        pose[i] = rng.random_range(lo..hi);
    }
    pose[ix::ROOT_TX] = rng.random_range(-40.0..40.0);
    pose[ix::ROOT_TY] = rng.random_range(-20.0..20.0);
    pose[ix::ROOT_TZ] = -dist;
    pose[ix::ROOT_RX] = rng.random_range(-30.0..30.0);
    pose[ix::ROOT_RY] = rng.random_range(-180.0..180.0);
    pose[ix::ROOT_RZ] = rng.random_range(-20.0..20.0);
    pose
}

fn shape(rng: &mut impl RngExt) -> params::ShapeValues {
    let mut s = params::STANDARD_SHAPE;
    for v in &mut s {
        *v = rng.random_range(0.85..1.15);
    }
    s
}

#[test]
fn mask_area_within_one_percent_of_supersampled_reference() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    for (w, h, dist) in [(320, 240, 450.0), (640, 480, 500.0), (320, 240, 330.0)] {
        let cam = Camera::new(w, h, 55.0);
        let mut mask = Mask::new(w, h);
        let (mut worst, mut signed): (f64, f64) = (0.0, 0.0);
        for _ in 0..25 {
            let body = Body::new(&shape(&mut rng));
            let posed = body.posed(&random_pose(&mut rng, dist));
            render_mask(&body, &posed, &cam, &mut mask);
            let reference: f64 = render_coverage(&body, &posed, &cam, 4)
                .iter()
                .map(|c| *c as f64)
                .sum();
            let area = mask.count() as f64;
            assert!(reference > 300.0, "body too small to judge: {reference}");
            let err = (area - reference).abs() / reference;
            worst = worst.max(err);
            signed += (area - reference) / reference / 25.0;
            assert!(
                err < 0.01,
                "{w}×{h}: area {area} vs reference {reference} ({:.2}%)",
                err * 100.0
            );
        }
        // Pixel-centre sampling must not be biased (a half-pixel slip would show here).
        assert!(signed.abs() < 0.002, "{w}×{h}: mean signed error {signed}");
        println!(
            "{w}×{h}: worst area error {:.3}%, mean signed error {:+.3}% over 25 random poses",
            worst * 100.0,
            signed * 100.0
        );
    }
}

#[test]
fn empty_when_the_body_is_behind_the_camera_or_off_screen() {
    let body = Body::new(&params::STANDARD_SHAPE);
    let cam = Camera::new(64, 48, 55.0);
    let mut mask = Mask::new(64, 48);
    let mut pose = params::rest_pose();
    pose[ix::ROOT_TZ] = 300.0; // behind
    render_mask(&body, &body.posed(&pose), &cam, &mut mask);
    assert_eq!(mask.count(), 0);
    pose[ix::ROOT_TZ] = -300.0;
    pose[ix::ROOT_TX] = 5000.0; // far to the side
    render_mask(&body, &body.posed(&pose), &cam, &mut mask);
    assert_eq!(mask.count(), 0);
    // Straddling the camera plane: parts crossing it are skipped, nothing panics.
    pose[ix::ROOT_TX] = 0.0;
    pose[ix::ROOT_TZ] = -5.0;
    render_mask(&body, &body.posed(&pose), &cam, &mut mask);
}
