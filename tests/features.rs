//! Per-frame features (method.md §4): coremap exactness, outline features on rendered
//! silhouettes of the body model with known landmarks, real DAVIS masks, and
//! degenerate input.

use std::path::Path;

use monocap::body::params::{self, ix, Pose};
use monocap::body::raster::{project_landmarks, render_mask};
use monocap::body::{Body, Camera, Mask};
use monocap::vision::features::{
    compute, debug_image, distance_transform, ExtremityKind, FeatureOptions, FrameFeatures,
};
use rand::{RngExt, SeedableRng};

// Landmark indices (18 joints, then 5 tips).
const HIPS: usize = 0;
const SPINE: usize = 1;
const NECK: usize = 2;
const HEAD: usize = 3;
const L_ARM: usize = 4;
const L_FOREARM: usize = 5;
const R_ARM: usize = 7;
const R_FOREARM: usize = 8;
const L_UPLEG: usize = 10;
const L_LEG: usize = 11;
const L_FOOT: usize = 12;
const R_UPLEG: usize = 14;
const R_LEG: usize = 15;
const R_FOOT: usize = 16;
const HEAD_TOP: usize = 18;
const L_HAND_TIP: usize = 19;
const R_HAND_TIP: usize = 20;
const L_TOE_TIP: usize = 21;
const R_TOE_TIP: usize = 22;

fn random_mask(rng: &mut impl RngExt, w: u32, h: u32, p: f64) -> Mask {
    let mut m = Mask::new(w, h);
    for y in 0..h {
        for x in 0..w {
            if rng.random_bool(p) {
                m.set(x, y, true);
            }
        }
    }
    m
}

/// Brute force: distance from each non-`target` pixel to the nearest `target` pixel.
fn brute(m: &Mask, target: bool) -> Vec<f32> {
    let (w, h) = (m.width() as i64, m.height() as i64);
    let sites: Vec<(i64, i64)> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter(|&(x, y)| m.get(x as u32, y as u32) == target)
        .collect();
    let mut out = vec![0.0; (w * h) as usize];
    if sites.is_empty() {
        return out;
    }
    for y in 0..h {
        for x in 0..w {
            if m.get(x as u32, y as u32) != target {
                let d2 = sites
                    .iter()
                    .map(|&(sx, sy)| (sx - x).pow(2) + (sy - y).pow(2))
                    .min()
                    .unwrap();
                out[(y * w + x) as usize] = (d2 as f64).sqrt() as f32;
            }
        }
    }
    out
}

#[test]
fn distance_transforms_and_coremap_are_exact() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let opts = FeatureOptions {
        core_weight: 2.5,
        ..Default::default()
    };
    for trial in 0..120 {
        let w = rng.random_range(1..40u32);
        let h = rng.random_range(1..40u32);
        // Sparse, dense and blobby masks.
        let p = [0.02, 0.3, 0.7, 0.97][trial % 4];
        let m = random_mask(&mut rng, w, h, p);
        let din = distance_transform(&m, false);
        let dout = distance_transform(&m, true);
        assert_eq!(din, brute(&m, false), "inside, {w}×{h} p={p}");
        assert_eq!(dout, brute(&m, true), "outside, {w}×{h} p={p}");
        let f = compute(&m, None, None, &opts);
        for i in 0..(w * h) as usize {
            let expected = 1.0 + 2.5 * din[i] + dout[i];
            assert!((f.coremap[i] - expected).abs() < 1e-5);
        }
    }
}

#[test]
fn coremap_pattern_on_a_rectangle() {
    // A 20×10 rectangle at (10, 10) in a 40×30 image, w = 1.
    let mut m = Mask::new(40, 30);
    for y in 10..20 {
        m.fill_span(y, 10, 29);
    }
    let f = compute(&m, None, None, &FeatureOptions::default());
    // Inside pixels next to the outline are at distance 1 from the outside: d = 1 + w.
    assert_eq!(f.core(10, 15), 2.0);
    assert_eq!(f.core(20, 10), 2.0);
    // One pixel further in, d = 1 + 2w; the centre rows are 5 from the outside.
    assert_eq!(f.core(11, 15), 3.0);
    assert_eq!(f.core(20, 14), 6.0);
    // Outside pixels next to the outline: d = 1 + 1; diagonal corner: 1 + √2.
    assert_eq!(f.core(9, 15), 2.0);
    assert!((f.core(9, 9) - (1.0 + 2f32.sqrt())).abs() < 1e-6);
    // Outside grows with the distance to the silhouette.
    for x in 1..10 {
        assert!(f.core(x - 1, 15) > f.core(x, 15));
        assert_eq!(f.core(x, 15), 1.0 + (10 - x) as f32);
    }
    // Edges without a frame are the outline: inside pixels with d = 1 + w.
    for y in 0..30 {
        for x in 0..40 {
            let on_outline = m.get(x, y) && f.core(x, y) == 2.0;
            assert_eq!(f.edges.get(x, y), on_outline, "{x},{y}");
        }
    }
    // The plain XOR count is recovered at w = 0 on the rim: d = 1 inside with w = 0.
    let f0 = compute(
        &m,
        None,
        None,
        &FeatureOptions {
            core_weight: 0.0,
            ..Default::default()
        },
    );
    assert_eq!(f0.core(15, 15), 1.0);
}

/// A posed body in front of a 320×240 camera, and what the camera sees.
struct Shot {
    mask: Mask,
    lm: Vec<[f64; 2]>,
    pose: Pose,
}

fn shoot(body: &Body, pose: &Pose, cam: &Camera) -> Option<Shot> {
    let posed = body.posed(pose);
    let mut mask = Mask::new(cam.width, cam.height);
    render_mask(body, &posed, cam, &mut mask);
    let lm: Option<Vec<[f64; 2]>> = project_landmarks(&posed, cam).into_iter().collect();
    Some(Shot {
        mask,
        lm: lm?,
        pose: *pose,
    })
}

/// Arms spread, legs apart, standing, facing the camera within ±60° (or its back).
fn spread_pose(rng: &mut impl RngExt, dist: f64) -> Pose {
    let mut p = params::rest_pose();
    p[ix::ROOT_TX] = rng.random_range(-20.0..20.0);
    p[ix::ROOT_TY] = rng.random_range(-10.0..10.0);
    p[ix::ROOT_TZ] = -dist;
    p[ix::ROOT_RX] = rng.random_range(-6.0..6.0);
    let back = if rng.random_bool(0.25) { 180.0 } else { 0.0 };
    p[ix::ROOT_RY] = back + rng.random_range(-60.0..60.0);
    p[ix::ROOT_RZ] = rng.random_range(-6.0..6.0);
    p[ix::SPINE] = rng.random_range(-5.0..15.0);
    p[ix::SPINE + 1] = rng.random_range(-8.0..8.0);
    p[ix::NECK] = rng.random_range(-10.0..15.0);
    for s in [ix::L_SHOULDER, ix::R_SHOULDER] {
        p[s] = rng.random_range(-20.0..40.0);
        p[s + 1] = rng.random_range(25.0..150.0);
        p[s + 2] = rng.random_range(-40.0..40.0);
    }
    for e in [ix::L_ELBOW, ix::R_ELBOW] {
        p[e] = rng.random_range(0.0..50.0);
    }
    for hip in [ix::L_HIP, ix::R_HIP] {
        p[hip] = rng.random_range(-20.0..30.0);
        p[hip + 1] = rng.random_range(8.0..35.0);
        p[hip + 2] = rng.random_range(-20.0..20.0);
    }
    for k in [ix::L_KNEE, ix::R_KNEE] {
        p[k] = rng.random_range(0.0..35.0);
    }
    for a in [ix::L_ANKLE, ix::R_ANKLE] {
        p[a] = rng.random_range(-10.0..20.0);
    }
    p
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

fn seg_dist(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let l2 = dx * dx + dy * dy;
    let t = if l2 == 0.0 {
        0.0
    } else {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0)
    };
    dist(p, [a[0] + t * dx, a[1] + t * dy])
}

fn chain_dist(p: [f64; 2], lm: &[[f64; 2]], chain: &[usize]) -> f64 {
    chain
        .windows(2)
        .map(|s| seg_dist(p, lm[s[0]], lm[s[1]]))
        .fold(f64::INFINITY, f64::min)
}

fn in_image(p: [f64; 2], w: u32, h: u32) -> bool {
    p[0] >= 2.0 && p[1] >= 2.0 && p[0] <= w as f64 - 2.0 && p[1] <= h as f64 - 2.0
}

#[derive(Default)]
struct Tally {
    exposed: usize,
    found_kind: usize,
    found_any: usize,
    err_sum: f64,
}

impl Tally {
    /// Counts an exposed limb end; `targets` are the acceptable true points.
    fn add(&mut self, f: &FrameFeatures, targets: &[[f64; 2]], kind: ExtremityKind, tol: f64) {
        self.exposed += 1;
        let near = |k: Option<ExtremityKind>| {
            f.extremities
                .iter()
                .filter(|e| k.is_none_or(|k| e.kind == k))
                .map(|e| {
                    targets
                        .iter()
                        .map(|t| dist(e.pos, *t))
                        .fold(f64::INFINITY, f64::min)
                })
                .fold(f64::INFINITY, f64::min)
        };
        let dk = near(Some(kind));
        if dk <= tol {
            self.found_kind += 1;
            self.err_sum += dk;
        }
        if near(None) <= tol {
            self.found_any += 1;
        }
    }

    fn rate(&self) -> f64 {
        self.found_kind as f64 / self.exposed.max(1) as f64
    }

    fn report(&self, what: &str) {
        println!(
            "{what}: {}/{} exposed found with the right kind ({:.1}%), {} with any kind; \
             mean error {:.2} px",
            self.found_kind,
            self.exposed,
            100.0 * self.rate(),
            self.found_any,
            self.err_sum / self.found_kind.max(1) as f64
        );
    }
}

#[test]
fn outline_features_on_rendered_silhouettes() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(2005);
    let (w, h) = (320, 240);
    let cam = Camera::new(w, h, 55.0);
    let opts = FeatureOptions::default();
    let (mut hands, mut feet) = (Tally::default(), Tally::default());
    let (mut n, mut head_ok, mut head_err) = (0, 0, 0.0);
    let (mut neck_n, mut neck_ok) = (0, 0);
    let (mut crotch_n, mut crotch_ok) = (0, 0);
    let mut saved = false;
    let mut failures = Vec::new();
    while n < 300 {
        let mut shape = params::STANDARD_SHAPE;
        for v in &mut shape {
            *v = rng.random_range(0.9..1.1);
        }
        let body = Body::new(&shape);
        let d = rng.random_range(300.0..450.0);
        let pose = spread_pose(&mut rng, d);
        let Some(shot) = shoot(&body, &pose, &cam) else {
            continue;
        };
        let lm = &shot.lm;
        // The whole body in the picture.
        if !lm.iter().all(|p| in_image(*p, w, h)) {
            continue;
        }
        n += 1;
        let f = compute(&shot.mask, None, None, &opts);
        let bh = f.body_height;
        if !saved {
            std::fs::create_dir_all("/tmp/features_debug").unwrap();
            debug_image(None, &shot.mask, &f)
                .save("/tmp/features_debug/rendered.png")
                .unwrap();
            saved = true;
        }

        // Head: within 8% of body height of the projected head top.
        match f.head {
            Some(hd) if dist(hd, lm[HEAD_TOP]) <= 0.08 * bh => {
                head_ok += 1;
                head_err += dist(hd, lm[HEAD_TOP]);
            }
            other => failures.push(format!("head {other:?} vs {:?}", lm[HEAD_TOP])),
        }

        // Hands that stick out: far from the torso and from every other limb.
        let torso = [HIPS, SPINE, NECK, HEAD, HEAD_TOP];
        let legs_l = [L_UPLEG, L_LEG, L_FOOT, L_TOE_TIP];
        let legs_r = [R_UPLEG, R_LEG, R_FOOT, R_TOE_TIP];
        let arm_l = [NECK, L_ARM, L_FOREARM, L_HAND_TIP];
        let arm_r = [NECK, R_ARM, R_FOREARM, R_HAND_TIP];
        for (tip, own_upper, other_arm) in [
            (L_HAND_TIP, [L_ARM, L_FOREARM], arm_r),
            (R_HAND_TIP, [R_ARM, R_FOREARM], arm_l),
        ] {
            let p = lm[tip];
            let clear = chain_dist(p, lm, &torso) > 0.15 * bh
                && chain_dist(p, lm, &legs_l) > 0.1 * bh
                && chain_dist(p, lm, &legs_r) > 0.1 * bh
                && chain_dist(p, lm, &other_arm) > 0.1 * bh
                && chain_dist(p, lm, &own_upper) > 0.08 * bh;
            if clear {
                hands.add(&f, &[p], ExtremityKind::Hand, 0.06 * bh);
            }
        }
        // Feet apart from each other (and from the hands).
        let foot_gap = dist(lm[L_TOE_TIP], lm[R_TOE_TIP]).min(dist(lm[L_FOOT], lm[R_FOOT]));
        if foot_gap > 0.1 * bh {
            for (toe, ankle) in [(L_TOE_TIP, L_FOOT), (R_TOE_TIP, R_FOOT)] {
                let hand_near = [L_HAND_TIP, R_HAND_TIP]
                    .iter()
                    .any(|&t| dist(lm[t], lm[toe]) < 0.15 * bh);
                if !hand_near {
                    feet.add(&f, &[lm[toe], lm[ankle]], ExtremityKind::Foot, 0.06 * bh);
                }
            }
        }

        // Neck: between the head top and the shoulders, near the neck's column.
        neck_n += 1;
        let shoulder_y = (lm[L_ARM][1] + lm[R_ARM][1]) / 2.0;
        match f.neck {
            Some(nk)
                if nk[1] > lm[HEAD_TOP][1]
                    && nk[1] <= shoulder_y + 0.04 * bh
                    && (nk[0] - lm[NECK][0]).abs() <= 0.08 * bh =>
            {
                neck_ok += 1
            }
            other => failures.push(format!(
                "neck {other:?}: head top {:?}, neck {:?}, shoulders y {shoulder_y:.1}",
                lm[HEAD_TOP], lm[NECK]
            )),
        }

        // Crotch: between the thighs when the knees are well apart.
        let knee_gap = (lm[L_LEG][0] - lm[R_LEG][0]).abs();
        if knee_gap > 0.12 * bh {
            crotch_n += 1;
            let (xl, xr) = (
                lm[L_UPLEG][0].min(lm[R_UPLEG][0]),
                lm[L_UPLEG][0].max(lm[R_UPLEG][0]),
            );
            let knee_y = (lm[L_LEG][1] + lm[R_LEG][1]) / 2.0;
            match f.crotch {
                Some(c)
                    if c[0] >= xl - 0.05 * bh
                        && c[0] <= xr + 0.05 * bh
                        && c[1] >= lm[HIPS][1] - 0.05 * bh
                        && c[1] <= knee_y =>
                {
                    crotch_ok += 1
                }
                other => failures.push(format!(
                    "crotch {other:?}: hips {:?}, upper legs {:?} {:?}, knees y {knee_y:.1} \
                     (pose ry {:.0})",
                    lm[HIPS],
                    lm[L_UPLEG],
                    lm[R_UPLEG],
                    shot.pose[ix::ROOT_RY]
                )),
            }
        }
    }
    println!(
        "head: {head_ok}/{n} within 8% of body height, mean error {:.2} px",
        head_err / head_ok.max(1) as f64
    );
    hands.report("hands");
    feet.report("feet");
    println!("neck: {neck_ok}/{neck_n}; crotch: {crotch_ok}/{crotch_n} with the knees apart");
    for f in failures.iter().take(12) {
        println!("  miss: {f}");
    }
    assert!(head_ok as f64 >= 0.95 * n as f64, "head {head_ok}/{n}");
    assert!(hands.exposed > 100 && feet.exposed > 100);
    assert!(hands.rate() >= 0.85, "hands {:.3}", hands.rate());
    assert!(feet.rate() >= 0.85, "feet {:.3}", feet.rate());
    assert!(
        neck_ok as f64 >= 0.9 * neck_n as f64,
        "neck {neck_ok}/{neck_n}"
    );
    assert!(
        crotch_ok as f64 >= 0.85 * crotch_n as f64,
        "crotch {crotch_ok}/{crotch_n}"
    );
}

#[test]
fn temporal_coherence_drops_a_far_surplus_candidate() {
    // Previous frame: hands at two places; now a third convex candidate far away.
    let body = Body::new(&params::STANDARD_SHAPE);
    let cam = Camera::new(320, 240, 55.0);
    let mut pose = params::rest_pose();
    pose[ix::ROOT_TY] = 0.0;
    pose[ix::ROOT_TZ] = -350.0;
    pose[ix::L_SHOULDER + 1] = 90.0;
    pose[ix::R_SHOULDER + 1] = 90.0;
    pose[ix::L_HIP + 1] = 20.0;
    pose[ix::R_HIP + 1] = 20.0;
    let shot = shoot(&body, &pose, &cam).unwrap();
    let opts = FeatureOptions::default();
    let f0 = compute(&shot.mask, None, None, &opts);
    let hands0: Vec<_> = f0
        .extremities
        .iter()
        .filter(|e| e.kind == ExtremityKind::Hand)
        .collect();
    assert_eq!(hands0.len(), 2, "{:?}", f0.extremities);
    // Add a thin spike sticking out of the torso's side: a third "hand".
    let mut m = shot.mask.clone();
    let hips = shot.lm[HIPS];
    let (x0, y0) = (hips[0] as u32, hips[1] as u32 - 20);
    for y in y0..y0 + 3 {
        m.fill_span(y, x0, x0 + 50);
    }
    let without = compute(&m, None, None, &opts);
    let with = compute(&m, None, Some(&f0), &opts);
    let count = |f: &FrameFeatures| {
        f.extremities
            .iter()
            .filter(|e| e.kind == ExtremityKind::Hand)
            .count()
    };
    assert_eq!(count(&without), 3, "{:?}", without.extremities);
    assert_eq!(count(&with), 2, "{:?}", with.extremities);
    // The consistent ones are the ones kept.
    for e in with
        .extremities
        .iter()
        .filter(|e| e.kind == ExtremityKind::Hand)
    {
        assert!(hands0.iter().any(|p| dist(p.pos, e.pos) < 5.0));
    }
}

fn davis_root() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/davis")
}

#[test]
fn davis_masks() {
    let root = davis_root();
    let Ok(dirs) = std::fs::read_dir(&root) else {
        println!("skipped: no DAVIS data at {}", root.display());
        return;
    };
    let mut seqs: Vec<_> = dirs.filter_map(|d| d.ok()).map(|d| d.path()).collect();
    seqs.sort();
    let opts = FeatureOptions::default();
    let mut total = 0;
    for seq in seqs {
        let Ok(files) = std::fs::read_dir(seq.join("masks")) else {
            continue;
        };
        let mut files: Vec<_> = files.filter_map(|d| d.ok()).map(|d| d.path()).collect();
        files.sort();
        let name = seq.file_name().unwrap().to_string_lossy().to_string();
        let (mut frames, mut nonempty, mut heads, mut top_fifth, mut crotches) = (0, 0, 0, 0, 0);
        let (mut hands, mut feet) = (0, 0);
        let mut prev: Option<FrameFeatures> = None;
        for file in &files {
            let gray = image::open(file).unwrap().to_luma8();
            let mask = Mask::from_gray(&gray, 128);
            let f = compute(&mask, None, prev.as_ref(), &opts);
            frames += 1;
            if let Some(b) = f.bbox {
                nonempty += 1;
                if let Some(hd) = f.head {
                    heads += 1;
                    let fifth = b[1] as f64 + 0.2 * (b[3] - b[1] + 1) as f64;
                    if hd[1] <= fifth {
                        top_fifth += 1;
                    }
                }
            }
            crotches += f.crotch.is_some() as usize;
            hands += f
                .extremities
                .iter()
                .filter(|e| e.kind == ExtremityKind::Hand)
                .count();
            feet += f
                .extremities
                .iter()
                .filter(|e| e.kind == ExtremityKind::Foot)
                .count();
            if frames == 30 {
                let stem = file.file_stem().unwrap().to_string_lossy().to_string();
                let jpg = seq.join("frames").join(format!("{stem}.jpg"));
                let frame = image::open(&jpg).ok().map(|i| i.to_rgb8());
                let fc = compute(&mask, frame.as_ref(), prev.as_ref(), &opts);
                std::fs::create_dir_all("/tmp/features_debug").unwrap();
                debug_image(frame.as_ref(), &mask, &fc)
                    .save(format!("/tmp/features_debug/davis_{name}_{stem}.png"))
                    .unwrap();
            }
            prev = Some(f);
        }
        total += frames;
        println!(
            "{name}: {frames} frames, {nonempty} non-empty, head on {heads} ({top_fifth} in the \
             top fifth of the box), crotch on {crotches}, {:.2} hands and {:.2} feet a frame",
            hands as f64 / frames.max(1) as f64,
            feet as f64 / frames.max(1) as f64
        );
        assert!(
            heads as f64 >= 0.9 * nonempty as f64,
            "{name}: head {heads}/{nonempty}"
        );
        assert!(
            top_fifth as f64 >= 0.9 * heads as f64,
            "{name}: top fifth {top_fifth}/{heads}"
        );
    }
    if total == 0 {
        println!("skipped: no DAVIS masks under {}", root.display());
    }
}

#[test]
fn degenerate_input_never_panics() {
    let opts = FeatureOptions::default();
    let mut cases: Vec<Mask> = Vec::new();
    cases.push(Mask::new(64, 48)); // empty
    let mut full = Mask::new(64, 48);
    for y in 0..48 {
        full.fill_span(y, 0, 63);
    }
    cases.push(full);
    let mut one = Mask::new(64, 48);
    one.set(10, 10, true);
    cases.push(one);
    let mut corner = Mask::new(64, 48);
    corner.set(63, 47, true);
    cases.push(corner);
    let mut px = Mask::new(1, 1);
    cases.push(px.clone());
    px.set(0, 0, true);
    cases.push(px);
    cases.push(Mask::new(0, 0));
    cases.push(Mask::new(5, 0));
    let mut lines = Mask::new(80, 60);
    for y in 0..60 {
        lines.set(40, y, true); // vertical line, full height
        lines.set((y + 5).min(79), y, true); // diagonal
    }
    lines.fill_span(30, 0, 79); // horizontal
    cases.push(lines);
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    cases.push(random_mask(&mut rng, 120, 90, 0.05)); // many small blobs
    cases.push(random_mask(&mut rng, 120, 90, 0.5));
    let mut blobs = Mask::new(200, 150);
    for _ in 0..60 {
        let (x, y) = (rng.random_range(0..195u32), rng.random_range(0..145u32));
        for yy in y..y + rng.random_range(1..5) {
            blobs.fill_span(yy, x, x + rng.random_range(0..4));
        }
    }
    cases.push(blobs);
    let mut tall = Mask::new(3, 200); // a tall thin body
    for y in 0..200 {
        tall.fill_span(y, 1, 1);
    }
    cases.push(tall);
    for m in &cases {
        let frame = image::RgbImage::from_fn(m.width(), m.height(), |x, y| {
            image::Rgb([(x * 7) as u8, (y * 13) as u8, ((x + y) * 3) as u8])
        });
        let mut prev: Option<FrameFeatures> = None;
        for fr in [None, Some(&frame)] {
            let f = compute(m, fr, prev.as_ref(), &opts);
            assert_eq!(f.coremap.len(), (m.width() * m.height()) as usize);
            assert!(f.coremap.iter().all(|v| v.is_finite() && *v >= 1.0));
            let img = debug_image(fr, m, &f);
            assert_eq!(img.width(), 2 * m.width());
            prev = Some(f);
        }
    }
}
