//! The paper's restart experiment (Chen et al. 2005, §5): "In a 250-frame test
//! (left arm bends in frames 0–100, right arm 100–150, left leg 150–200, right leg
//! 200–250), one or two runs of the simplex left wrong poses with high cost; three
//! runs gave correct poses throughout."
//!
//! A synthetic silhouette clip of the standard body is tracked with 1, 2 and 3 runs
//! of the hierarchical simplex per frame, starting from the true first pose (the
//! experiment is about restarts, not initialisation). Prints a table (plain and
//! markdown) and writes a plot of the cost and the mean 3D joint error per frame.
//!
//! ```text
//! cargo run --release --example restarts [plot.png]
//! ```
//!
//! `RESTARTS_SHEET=path.png` also writes a contact sheet of the clip's silhouettes;
//! `RESTARTS_DIAG=1` prints diagnostics of the tracker first (the objective's terms
//! at the true pose, a clip that does not move, every frame tracked alone from the
//! true previous pose, the wrong parameters at a few frames); `RESTARTS_DIAG=2`
//! also lists the wrong parameters of every one-step frame above 5 cm.

use std::ops::ControlFlow;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use image::{Rgb, RgbImage};
use imageproc::drawing::{draw_filled_rect_mut, draw_line_segment_mut};
use imageproc::rect::Rect;
use monocap::body::params::{ix, rest_pose, Pose, STANDARD_SHAPE};
use monocap::body::raster::render_mask;
use monocap::body::skeleton::Joint;
use monocap::body::{Body, Camera, Mask};
use monocap::track::objective::{sole_height, Evaluator, Target};
use monocap::track::tracker::{FrameInput, Track, TrackOptions, Tracker};
use monocap::vision::features::compute;

const FRAMES: usize = 250;
const FPS: f64 = 30.0;
/// Segment boundaries of the script (frames).
const SEGMENTS: [(usize, usize, &str); 4] = [
    (0, 100, "left arm"),
    (100, 150, "right arm"),
    (150, 200, "left leg"),
    (200, 250, "right leg"),
];
/// A frame counts as wrong above this mean 3D joint error (cm).
const WRONG_CM: f64 = 5.0;

// ---------------------------------------------------------------------------
// The script.

/// 0 → 1 → 0 over [a, b) with a cosine ease (0 outside).
fn bump(frame: usize, a: usize, b: usize) -> f64 {
    if frame < a || frame >= b {
        return 0.0;
    }
    let t = (frame - a) as f64 / (b - a) as f64;
    (1.0 - (2.0 * std::f64::consts::PI * t).cos()) / 2.0
}

/// The start pose: standing 4 m in front of the camera, facing it, arms slightly
/// abducted so that they are apart from the body.
fn start_pose() -> Pose {
    let mut p = rest_pose();
    p[ix::ROOT_TY] -= 90.0;
    p[ix::ROOT_TZ] = -400.0;
    p[ix::L_SHOULDER + 1] = 10.0;
    p[ix::R_SHOULDER + 1] = 10.0;
    p
}

/// The true pose of `frame`. Each limb raises sideways and bends in the image
/// plane (the twist turns the elbow's and knee's hinge towards the camera axis),
/// then returns, over its segment.
fn script(frame: usize) -> Pose {
    let mut p = start_pose();
    // Arms: shoulder raises sideways 10° → 80°, twists outwards 0 → 90°, elbow 0 → 100°.
    for (s, sh, el) in [
        (bump(frame, 0, 100), ix::L_SHOULDER, ix::L_ELBOW),
        (bump(frame, 100, 150), ix::R_SHOULDER, ix::R_ELBOW),
    ] {
        p[sh + 1] += 70.0 * s;
        p[sh + 2] += 90.0 * s;
        p[el] += 100.0 * s;
    }
    // Legs: hip raises sideways 0 → 45°, twists outwards 0 → 60°, knee 0 → 80°.
    for (s, hip, knee) in [
        (bump(frame, 150, 200), ix::L_HIP, ix::L_KNEE),
        (bump(frame, 200, 250), ix::R_HIP, ix::R_KNEE),
    ] {
        p[hip + 1] += 45.0 * s;
        p[hip + 2] += 60.0 * s;
        p[knee] += 80.0 * s;
    }
    p
}

fn mask_bbox(m: &Mask) -> Option<[u32; 4]> {
    let mut b: Option<[u32; 4]> = None;
    for y in 0..m.height() {
        for x in 0..m.width() {
            if m.get(x, y) {
                b = Some(match b {
                    None => [x, y, x, y],
                    Some([x0, y0, x1, _]) => [x0.min(x), y0, x1.max(x), y],
                });
            }
        }
    }
    b
}

// ---------------------------------------------------------------------------
// Measurements.

struct Run {
    restarts: usize,
    cost: Vec<f64>,
    iou: Vec<f64>,
    err3d: Vec<f64>,
    err2d: Vec<f64>,
    seconds: f64,
    evals: u64,
}

fn joint_errors(body: &Body, cam: &Camera, got: &Pose, truth: &Pose) -> (f64, f64) {
    let (a, b) = (body.posed(got), body.posed(truth));
    let (mut e3, mut e2) = (0.0, 0.0);
    for j in Joint::ALL {
        let (pa, pb) = (a.joint(j), b.joint(j));
        e3 += (pa - pb).norm();
        if let (Some(u), Some(v)) = (cam.project(&pa), cam.project(&pb)) {
            e2 += ((u[0] - v[0]).powi(2) + (u[1] - v[1]).powi(2)).sqrt();
        }
    }
    let n = Joint::ALL.len() as f64;
    (e3 / n, e2 / n)
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn max(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::NEG_INFINITY, f64::max)
}

fn min(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::INFINITY, f64::min)
}

// ---------------------------------------------------------------------------
// A 5×7 bitmap font (imageproc's text drawing needs an `ab_glyph` font, which
// this crate cannot name: ab_glyph is only imageproc's dependency).

/// (character, rows top to bottom, bit 4 = leftmost column).
#[rustfmt::skip]
const FONT: &[(char, [u8; 7])] = &[
    (' ', [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00]),
    ('0', [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E]),
    ('1', [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E]),
    ('2', [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F]),
    ('3', [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E]),
    ('4', [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02]),
    ('5', [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E]),
    ('6', [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E]),
    ('7', [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08]),
    ('8', [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E]),
    ('9', [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C]),
    ('A', [0x0E, 0x11, 0x11, 0x11, 0x1F, 0x11, 0x11]),
    ('B', [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E]),
    ('C', [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E]),
    ('D', [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C]),
    ('E', [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F]),
    ('F', [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10]),
    ('G', [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F]),
    ('H', [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11]),
    ('I', [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E]),
    ('J', [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C]),
    ('K', [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11]),
    ('L', [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F]),
    ('M', [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11]),
    ('N', [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11]),
    ('O', [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E]),
    ('P', [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10]),
    ('Q', [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D]),
    ('R', [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11]),
    ('S', [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E]),
    ('T', [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04]),
    ('U', [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E]),
    ('V', [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04]),
    ('W', [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A]),
    ('X', [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11]),
    ('Y', [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04]),
    ('Z', [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F]),
    ('a', [0x00, 0x00, 0x0E, 0x01, 0x0F, 0x11, 0x0F]),
    ('b', [0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x1E]),
    ('c', [0x00, 0x00, 0x0E, 0x10, 0x10, 0x11, 0x0E]),
    ('d', [0x01, 0x01, 0x0D, 0x13, 0x11, 0x11, 0x0F]),
    ('e', [0x00, 0x00, 0x0E, 0x11, 0x1F, 0x10, 0x0E]),
    ('f', [0x06, 0x09, 0x08, 0x1C, 0x08, 0x08, 0x08]),
    ('g', [0x00, 0x0F, 0x11, 0x11, 0x0F, 0x01, 0x0E]),
    ('h', [0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x11]),
    ('i', [0x04, 0x00, 0x0C, 0x04, 0x04, 0x04, 0x0E]),
    ('j', [0x02, 0x00, 0x06, 0x02, 0x02, 0x12, 0x0C]),
    ('k', [0x10, 0x10, 0x12, 0x14, 0x18, 0x14, 0x12]),
    ('l', [0x0C, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E]),
    ('m', [0x00, 0x00, 0x1A, 0x15, 0x15, 0x11, 0x11]),
    ('n', [0x00, 0x00, 0x16, 0x19, 0x11, 0x11, 0x11]),
    ('o', [0x00, 0x00, 0x0E, 0x11, 0x11, 0x11, 0x0E]),
    ('p', [0x00, 0x00, 0x1E, 0x11, 0x1E, 0x10, 0x10]),
    ('q', [0x00, 0x00, 0x0D, 0x13, 0x0F, 0x01, 0x01]),
    ('r', [0x00, 0x00, 0x16, 0x19, 0x10, 0x10, 0x10]),
    ('s', [0x00, 0x00, 0x0E, 0x10, 0x0E, 0x01, 0x1E]),
    ('t', [0x08, 0x08, 0x1C, 0x08, 0x08, 0x09, 0x06]),
    ('u', [0x00, 0x00, 0x11, 0x11, 0x11, 0x13, 0x0D]),
    ('v', [0x00, 0x00, 0x11, 0x11, 0x11, 0x0A, 0x04]),
    ('w', [0x00, 0x00, 0x11, 0x11, 0x15, 0x15, 0x0A]),
    ('x', [0x00, 0x00, 0x11, 0x0A, 0x04, 0x0A, 0x11]),
    ('y', [0x00, 0x00, 0x11, 0x11, 0x0F, 0x01, 0x0E]),
    ('z', [0x00, 0x00, 0x1F, 0x02, 0x04, 0x08, 0x1F]),
    ('.', [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C]),
    (',', [0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08]),
    (':', [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00]),
    (';', [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x04, 0x08]),
    ('-', [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00]),
    ('+', [0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00]),
    ('=', [0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00]),
    ('(', [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02]),
    (')', [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08]),
    ('[', [0x0E, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0E]),
    (']', [0x0E, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0E]),
    ('/', [0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00]),
    ('%', [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03]),
    ('<', [0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02]),
    ('>', [0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08]),
    ('_', [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F]),
    ('|', [0x04, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04]),
    ('\'', [0x0C, 0x04, 0x08, 0x00, 0x00, 0x00, 0x00]),
    ('?', [0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04]),
    ('#', [0x0A, 0x0A, 0x1F, 0x0A, 0x1F, 0x0A, 0x0A]),
];

/// Pixel scale of the font (each font dot is `SCALE`×`SCALE` pixels).
const SCALE: i32 = 2;
/// Advance per character (5 dots and a gap).
const ADVANCE: i32 = 6 * SCALE;
const TEXT_H: i32 = 7 * SCALE;

fn glyph(c: char) -> [u8; 7] {
    FONT.iter()
        .find(|(k, _)| *k == c)
        .or_else(|| FONT.iter().find(|(k, _)| *k == c.to_ascii_uppercase()))
        .map(|(_, g)| *g)
        .unwrap_or([0x1F, 0x11, 0x11, 0x11, 0x11, 0x11, 0x1F])
}

fn text_width(s: &str) -> i32 {
    s.chars().count() as i32 * ADVANCE - SCALE
}

/// Draws `s` with its top-left corner at (x, y).
fn text(img: &mut RgbImage, x: i32, y: i32, s: &str, color: Rgb<u8>) {
    for (i, c) in s.chars().enumerate() {
        let g = glyph(c);
        let x0 = x + i as i32 * ADVANCE;
        for (r, bits) in g.iter().enumerate() {
            for col in 0..5 {
                if bits & (0x10 >> col) != 0 {
                    fill(
                        img,
                        x0 + col * SCALE,
                        y + r as i32 * SCALE,
                        SCALE,
                        SCALE,
                        color,
                    );
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------
// Plotting.

fn fill(img: &mut RgbImage, x: i32, y: i32, w: i32, h: i32, color: Rgb<u8>) {
    if w > 0 && h > 0 {
        draw_filled_rect_mut(img, Rect::at(x, y).of_size(w as u32, h as u32), color);
    }
}

/// A line `width` pixels wide (offset copies of a 1-pixel line).
fn thick_line(img: &mut RgbImage, a: (f32, f32), b: (f32, f32), width: i32, color: Rgb<u8>) {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let steep = dy.abs() > dx.abs();
    for k in 0..width {
        let o = k as f32 - (width - 1) as f32 / 2.0;
        let (ox, oy) = if steep { (o, 0.0) } else { (0.0, o) };
        draw_line_segment_mut(img, (a.0 + ox, a.1 + oy), (b.0 + ox, b.1 + oy), color);
    }
}

/// Round tick spacing giving about `n` ticks over [lo, hi].
fn tick_step(lo: f64, hi: f64, n: f64) -> f64 {
    let raw = (hi - lo) / n;
    let mag = 10f64.powf(raw.log10().floor());
    for m in [1.0, 2.0, 2.5, 5.0, 10.0] {
        if m * mag >= raw {
            return m * mag;
        }
    }
    10.0 * mag
}

fn label(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10()).ceil() as usize
    };
    format!("{v:.decimals$}")
}

struct Series<'a> {
    name: String,
    values: &'a [f64],
    color: Rgb<u8>,
    width: i32,
}

/// One panel: frame on x, `series` on y, in the rectangle (x0, y0, w, h).
#[allow(clippy::too_many_arguments)]
fn panel(
    img: &mut RgbImage,
    (x0, y0, w, h): (i32, i32, i32, i32),
    title: &str,
    series: &[Series],
    floor_zero: bool,
    hline: Option<(f64, &str)>,
) {
    let black = Rgb([0, 0, 0]);
    let grey = Rgb([150, 150, 150]);
    let light = Rgb([232, 232, 232]);
    let finite = series
        .iter()
        .flat_map(|s| s.values.iter().copied())
        .filter(|v| v.is_finite());
    let (mut lo, mut hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if let Some((v, _)) = hline {
        hi = hi.max(v);
    }
    if floor_zero {
        lo = lo.min(0.0);
    }
    if hi - lo < 1e-9 {
        hi = lo + 1.0;
    }
    let pad = (hi - lo) * 0.05;
    if !floor_zero || lo < 0.0 {
        lo -= pad;
    }
    // Headroom for the segment names.
    hi += pad + (hi - lo) * 0.1;
    let step = tick_step(lo, hi, 6.0);
    let fx = |f: f64| x0 as f32 + (f / (FRAMES - 1) as f64 * w as f64) as f32;
    let fy = |v: f64| y0 as f32 + ((hi - v) / (hi - lo) * h as f64) as f32;

    // Grid and ticks.
    let mut t = (lo / step).ceil() * step;
    while t <= hi + 1e-9 {
        let y = fy(t).round() as i32;
        fill(img, x0 + 1, y, w - 1, 1, light);
        fill(img, x0 - 6, y, 6, 1, black);
        let s = label(t, step);
        text(img, x0 - 10 - text_width(&s), y - TEXT_H / 2, &s, black);
        t += step;
    }
    for f in (0..=FRAMES).step_by(25) {
        let x = fx(f as f64).round() as i32;
        fill(img, x, y0 + h, 1, 6, black);
        let s = f.to_string();
        text(img, x - text_width(&s) / 2, y0 + h + 10, &s, black);
    }
    // Segment boundaries (dashed) and their names.
    for (a, b, name) in SEGMENTS {
        if a > 0 {
            let x = fx(a as f64).round() as i32;
            let mut y = y0;
            while y < y0 + h {
                fill(img, x, y, 1, 6.min(y0 + h - y), grey);
                y += 11;
            }
        }
        let xm = fx((a + b) as f64 / 2.0).round() as i32;
        text(img, xm - text_width(name) / 2, y0 + 6, name, grey);
    }
    if let Some((v, name)) = hline {
        let y = fy(v).round() as i32;
        let mut x = x0;
        while x < x0 + w {
            fill(img, x, y, 4.min(x0 + w - x), 1, black);
            x += 8;
        }
        text(
            img,
            x0 + w - text_width(name) - 4,
            y - TEXT_H - 3,
            name,
            black,
        );
    }
    // Curves, clipped to the panel.
    for s in series {
        for f in 1..s.values.len() {
            let (a, b) = (s.values[f - 1], s.values[f]);
            if !(a.is_finite() && b.is_finite()) {
                continue;
            }
            let clip = |v: f64| v.clamp(lo, hi);
            thick_line(
                img,
                (fx((f - 1) as f64), fy(clip(a))),
                (fx(f as f64), fy(clip(b))),
                s.width,
                s.color,
            );
        }
    }
    // Frame and title.
    fill(img, x0, y0, w + 1, 1, black);
    fill(img, x0, y0 + h, w + 1, 1, black);
    fill(img, x0, y0, 1, h + 1, black);
    fill(img, x0 + w, y0, 1, h + 1, black);
    text(img, x0, y0 - TEXT_H - 8, title, black);
}

/// A one-row legend starting at (x, y).
fn legend(img: &mut RgbImage, mut x: i32, y: i32, series: &[Series]) {
    for s in series {
        let ym = (y + TEXT_H / 2) as f32;
        thick_line(
            img,
            (x as f32, ym),
            (x as f32 + 28.0, ym),
            s.width.max(2),
            s.color,
        );
        text(img, x + 36, y, &s.name, Rgb([0, 0, 0]));
        x += 36 + text_width(&s.name) + 30;
    }
}

fn plot(runs: &[Run], truth_cost: &[f64], path: &str) -> Result<()> {
    let (w, h) = (1000u32, 720u32);
    let mut img = RgbImage::from_pixel(w, h, Rgb([255, 255, 255]));
    let colors = [Rgb([220, 30, 30]), Rgb([30, 90, 220]), Rgb([20, 150, 40])];
    let title = "Restarts: 250-frame silhouette clip, tracked from the true first pose";
    text(
        &mut img,
        (w as i32 - text_width(title)) / 2,
        10,
        title,
        Rgb([0, 0, 0]),
    );

    let mut cost: Vec<Series> = runs
        .iter()
        .zip(colors)
        .map(|(r, c)| Series {
            name: format!(
                "{} run{}",
                r.restarts,
                if r.restarts == 1 { "" } else { "s" }
            ),
            values: &r.cost,
            color: c,
            width: 2,
        })
        .collect();
    cost.push(Series {
        name: "true pose".into(),
        values: truth_cost,
        color: Rgb([0, 0, 0]),
        width: 1,
    });
    let plot_w = w as i32 - 110 - 30;
    panel(
        &mut img,
        (110, 92, plot_w, 245),
        "cost F per frame (lower is better; black: F of the true pose)",
        &cost,
        false,
        None,
    );
    let mut entries: Vec<Series> = cost
        .iter()
        .map(|s| Series {
            name: s.name.clone(),
            values: s.values,
            color: s.color,
            width: s.width,
        })
        .collect();
    entries[3].name = "true pose (cost only)".into();
    let total_w: i32 = entries
        .iter()
        .map(|s| 66 + text_width(&s.name))
        .sum::<i32>()
        - 30;
    legend(&mut img, (w as i32 - total_w) / 2, 38, &entries);
    let err: Vec<Series> = runs
        .iter()
        .zip(colors)
        .map(|(r, c)| Series {
            name: format!(
                "{} run{}",
                r.restarts,
                if r.restarts == 1 { "" } else { "s" }
            ),
            values: &r.err3d,
            color: c,
            width: 2,
        })
        .collect();
    panel(
        &mut img,
        (110, 417, plot_w, 245),
        "mean 3D joint error per frame (cm)",
        &err,
        true,
        Some((WRONG_CM, "5 cm")),
    );
    let s = "frame";
    text(
        &mut img,
        110 + plot_w / 2 - text_width(s) / 2,
        h as i32 - 20,
        s,
        Rgb([0, 0, 0]),
    );
    if let Some(dir) = std::path::Path::new(path).parent() {
        if !dir.as_os_str().is_empty() {
            std::fs::create_dir_all(dir)?;
        }
    }
    img.save(path).with_context(|| format!("writing {path}"))?;
    Ok(())
}

/// A contact sheet of every 10th silhouette (for checking the script).
fn sheet(masks: &[Mask], path: &str) -> Result<()> {
    let (mw, mh) = (masks[0].width() / 2, masks[0].height() / 2);
    let cols = 10u32;
    let picks: Vec<usize> = (0..FRAMES).step_by(10).collect();
    let rows = (picks.len() as u32).div_ceil(cols);
    let mut img = RgbImage::from_pixel(cols * mw, rows * (mh + 18), Rgb([255, 255, 255]));
    for (k, &f) in picks.iter().enumerate() {
        let (cx, cy) = ((k as u32 % cols) * mw, (k as u32 / cols) * (mh + 18));
        for y in 0..mh {
            for x in 0..mw {
                let on = masks[f].get(2 * x, 2 * y);
                let c = if on { 0 } else { 225 };
                img.put_pixel(cx + x, cy + 18 + y, Rgb([c, c, c]));
            }
        }
        text(
            &mut img,
            cx as i32 + 4,
            cy as i32 + 2,
            &f.to_string(),
            Rgb([200, 0, 0]),
        );
    }
    img.save(path).with_context(|| format!("writing {path}"))?;
    Ok(())
}

/// Tracks `masks` from `initial` on the first frame with `restarts` runs per frame.
fn track_clip(cam: &Camera, masks: &[Mask], initial: Pose, restarts: usize) -> Result<Track> {
    let o = TrackOptions {
        restarts,
        fps: FPS,
        init_frame: Some(0),
        initial: Some((STANDARD_SHAPE, initial)),
        // The paper's restarts alone: the joint polish (off by default), the
        // smoothed refit (a second search of every frame) and the second pass (a
        // second track, backwards) would blur the comparison.
        polish_evals: 0,
        refit_sigma: 0.0,
        two_way: false,
        ..TrackOptions::default()
    };
    let inputs = masks.iter().map(|m| {
        Ok(FrameInput {
            silhouette: m.clone(),
            image: None,
        })
    });
    Tracker::new(cam.clone(), o)
        .track(inputs, Some(masks.len()), |_, _| ControlFlow::Continue(()))
        .map_err(|e| anyhow::anyhow!("tracking with {restarts} runs: {e}"))
}

/// Diagnostics of the tracker (not part of the experiment): a clip that does not
/// move, and every frame tracked alone from the true previous pose.
fn diagnostics(cam: &Camera, body: &Body, truth: &[Pose], masks: &[Mask]) -> Result<()> {
    // The objective's terms at the true pose: c + e + a is minimal there (the clip
    // is rendered from the model), so only the extremity term l can move the minimum.
    let w = TrackOptions::default().weights;
    let mut prev = None;
    let mut ext = Vec::new();
    for (f, (m, pose)) in masks.iter().zip(truth).enumerate() {
        let feats = compute(m, None, prev.as_ref(), &TrackOptions::default().features);
        let target = Target::new(&feats, &w);
        let mut ev = Evaluator::new(body, cam, &target, w, None);
        let t = ev.terms(pose, &feats);
        ext.push(t.extremity);
        if f % 25 == 0 {
            println!(
                "true pose, frame {f}: xor {:.0}, edge {:.0}, region {:.0}, extremity {:.0} ({:.1} px summed over the 5 ends), total {:.0}",
                t.xor,
                t.edge,
                t.region,
                t.extremity,
                t.extremity / w.extremity,
                t.total
            );
        }
        prev = Some(feats);
    }
    println!(
        "true pose: extremity term mean {:.0}, max {:.0}",
        mean(&ext),
        max(&ext)
    );
    for restarts in 1..=3 {
        let still: Vec<Mask> = vec![masks[0].clone(); 60];
        let t = track_clip(cam, &still, truth[0], restarts)?;
        let errs: Vec<f64> = t
            .frames
            .iter()
            .map(|f| joint_errors(body, cam, &f.pose, &truth[0]).0)
            .collect();
        println!(
            "still clip, {restarts} run(s): 3D error at frames 10/30/59: {:.1} / {:.1} / {:.1} cm, cost {:.0} -> {:.0}",
            errs[10],
            errs[30],
            errs[59],
            t.frames[0].cost.unwrap_or(f64::NAN),
            t.frames[59].cost.unwrap_or(f64::NAN)
        );
    }
    for restarts in 1..=3 {
        let mut errs = Vec::new();
        let mut excess = Vec::new();
        for f in 1..truth.len() {
            let t = track_clip(cam, &masks[f - 1..=f], truth[f - 1], restarts)?;
            let e = joint_errors(body, cam, &t.frames[1].pose, &truth[f]).0;
            errs.push(e);
            if restarts == 3 && e > WRONG_CM && std::env::var("RESTARTS_DIAG").as_deref() == Ok("2")
            {
                let got = t.frames[1].pose;
                let diffs: Vec<String> = (0..got.len())
                    .filter(|&k| (got[k] - truth[f][k]).abs() > 3.0)
                    .map(|k| {
                        format!(
                            "{} {:.1}/{:.1} (prev {:.1})",
                            monocap::body::params::MOTION[k].name,
                            got[k],
                            truth[f][k],
                            truth[f - 1][k]
                        )
                    })
                    .collect();
                println!("  one step to frame {f}: {e:.1} cm: {}", diffs.join(", "));
            }
            let target = Target::new(
                &compute(&masks[f], None, None, &TrackOptions::default().features),
                &TrackOptions::default().weights,
            );
            let mut ev = Evaluator::new(
                body,
                cam,
                &target,
                TrackOptions::default().weights,
                Some(t.ground),
            );
            excess.push(t.frames[1].cost.unwrap_or(f64::NAN) - ev.cost(&truth[f]));
        }
        let worst = (0..errs.len())
            .max_by(|&a, &b| errs[a].total_cmp(&errs[b]))
            .unwrap_or(0);
        println!(
            "one step from the true previous pose, {restarts} run(s): 3D error mean {:.2} cm, max {:.2} cm (frame {}), {} frames > {WRONG_CM} cm; cost - true cost mean {:.0}, {} frames below the truth",
            mean(&errs),
            errs[worst],
            worst + 1,
            errs.iter().filter(|&&e| e > WRONG_CM).count(),
            mean(&excess),
            excess.iter().filter(|&&e| e < 0.0).count()
        );
    }
    Ok(())
}

// ---------------------------------------------------------------------------

fn main() -> Result<()> {
    let started = Instant::now();
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "docs/restarts.png".into());
    let cam = Camera::new(320, 240, 55.0);
    let body = Body::new(&STANDARD_SHAPE);

    // The clip.
    let truth: Vec<Pose> = (0..FRAMES).map(script).collect();
    let mut masks = Vec::with_capacity(FRAMES);
    for (f, pose) in truth.iter().enumerate() {
        let mut m = Mask::new(cam.width, cam.height);
        render_mask(&body, &body.posed(pose), &cam, &mut m);
        let Some([x0, y0, x1, y1]) = mask_bbox(&m) else {
            bail!("frame {f}: empty silhouette");
        };
        if x0 < 2 || y0 < 2 || x1 + 3 > cam.width || y1 + 3 > cam.height {
            bail!("frame {f}: silhouette touches the border ({x0},{y0})-({x1},{y1})");
        }
        masks.push(m);
    }
    let b0 = mask_bbox(&masks[0]).expect("checked");
    println!(
        "clip: {FRAMES} frames at {FPS} fps, {}×{}, person {}×{} px at frame 0",
        cam.width,
        cam.height,
        b0[2] - b0[0] + 1,
        b0[3] - b0[1] + 1
    );
    if let Ok(p) = std::env::var("RESTARTS_SHEET") {
        sheet(&masks, &p)?;
        println!("contact sheet: {p}");
    }

    if std::env::var("RESTARTS_DIAG").is_ok() {
        diagnostics(&cam, &body, &truth, &masks)?;
    }

    // The ground the tracker finds at initialisation: the soles of the first pose.
    let ground = sole_height(&body, &body.posed(&truth[0]));
    // The cost of the true pose, as the tracker sees each frame.
    let opts = TrackOptions::default();
    let mut prev = None;
    let mut truth_cost = Vec::with_capacity(FRAMES);
    for (m, pose) in masks.iter().zip(&truth) {
        let f = compute(m, None, prev.as_ref(), &opts.features);
        let target = Target::new(&f, &opts.weights);
        let mut ev = Evaluator::new(&body, &cam, &target, opts.weights, Some(ground));
        truth_cost.push(ev.cost(pose));
        prev = Some(f);
    }

    // Track with 1, 2, 3 runs.
    let mut runs: Vec<Run> = Vec::new();
    for restarts in 1..=3 {
        let track = track_clip(&cam, &masks, truth[0], restarts)?;
        if track.frames.len() != FRAMES {
            bail!("{} frames tracked of {FRAMES}", track.frames.len());
        }
        if (track.ground - ground).abs() > 1e-9 {
            eprintln!(
                "note: the tracker's ground {} differs from the first pose's soles {ground}",
                track.ground
            );
        }
        let mut run = Run {
            restarts,
            cost: vec![],
            iou: vec![],
            err3d: vec![],
            err2d: vec![],
            seconds: track.timing.total,
            evals: track.timing.evals,
        };
        for (f, tf) in track.frames.iter().enumerate() {
            let (e3, e2) = joint_errors(&body, &cam, &tf.pose, &truth[f]);
            run.cost.push(tf.cost.unwrap_or(f64::NAN));
            run.iou.push(tf.iou.unwrap_or(f64::NAN));
            run.err3d.push(e3);
            run.err2d.push(e2);
        }
        if std::env::var("RESTARTS_DIAG").is_ok() {
            for f in [1usize, 2, 3, 5, 8, 12, 20, 30, 60, 120, 175, 225] {
                let got = track.frames[f].pose;
                let diffs: Vec<String> = (0..got.len())
                    .filter(|&k| (got[k] - truth[f][k]).abs() > 2.0)
                    .map(|k| {
                        format!(
                            "{} {:.1}/{:.1}",
                            monocap::body::params::MOTION[k].name,
                            got[k],
                            truth[f][k]
                        )
                    })
                    .collect();
                eprintln!(
                    "  r{restarts} frame {f}: 3D {:.1} cm, F {:.0} (true pose {:.0}): {}",
                    run.err3d[f],
                    run.cost[f],
                    truth_cost[f],
                    diffs.join(", ")
                );
            }
        }
        eprintln!(
            "{restarts} run(s): {:.1} s, {} evaluations",
            run.seconds, run.evals
        );
        runs.push(run);
    }

    // Tables.
    println!();
    println!(
        "{:>8} {:>9} {:>9} {:>10} {:>8} {:>8} {:>8} {:>8} {:>8} {:>7} {:>9} {:>8}",
        "restarts",
        "mean F",
        "max F",
        "F-F_true",
        "mean IoU",
        "min IoU",
        "3D mean",
        "3D max",
        "2D mean",
        ">5cm",
        "evals/fr",
        "frames/s"
    );
    let mut md = String::new();
    md.push_str("| restarts | mean cost | max cost | mean cost − true-pose cost | mean IoU | min IoU | mean 3D err (cm) | max 3D err (cm) | mean 2D err (px) | max 2D err (px) | frames > 5 cm | evals/frame | frames/s |\n");
    md.push_str("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for r in &runs {
        let excess: Vec<f64> = r.cost.iter().zip(&truth_cost).map(|(a, b)| a - b).collect();
        let wrong = r.err3d.iter().filter(|&&e| e > WRONG_CM).count();
        let fps = FRAMES as f64 / r.seconds;
        let epf = r.evals as f64 / FRAMES as f64;
        println!(
            "{:>8} {:>9.0} {:>9.0} {:>10.0} {:>8.3} {:>8.3} {:>8.2} {:>8.2} {:>8.2} {:>7} {:>9.0} {:>8.1}",
            r.restarts,
            mean(&r.cost),
            max(&r.cost),
            mean(&excess),
            mean(&r.iou),
            min(&r.iou),
            mean(&r.err3d),
            max(&r.err3d),
            mean(&r.err2d),
            wrong,
            epf,
            fps
        );
        md.push_str(&format!(
            "| {} | {:.0} | {:.0} | {:.0} | {:.3} | {:.3} | {:.2} | {:.2} | {:.2} | {:.2} | {} | {:.0} | {:.1} |\n",
            r.restarts,
            mean(&r.cost),
            max(&r.cost),
            mean(&excess),
            mean(&r.iou),
            min(&r.iou),
            mean(&r.err3d),
            max(&r.err3d),
            mean(&r.err2d),
            max(&r.err2d),
            wrong,
            epf,
            fps
        ));
    }
    println!(
        "{:>8} {:>9.0} {:>9.0}   (cost of the true poses)",
        "truth",
        mean(&truth_cost),
        max(&truth_cost)
    );
    println!();
    println!("{md}");

    // Per segment: mean / max 3D error and frames over the threshold.
    let mut seg = String::from("| restarts |");
    for (a, b, name) in SEGMENTS {
        seg.push_str(&format!(" {name} {a}–{b}: mean / max 3D (cm), > 5 cm |"));
    }
    seg.push_str("\n|---:|");
    seg.push_str(&"---:|".repeat(SEGMENTS.len()));
    seg.push('\n');
    for r in &runs {
        seg.push_str(&format!("| {} |", r.restarts));
        for (a, b, _) in SEGMENTS {
            let e = &r.err3d[a..b];
            let n = e.iter().filter(|&&v| v > WRONG_CM).count();
            seg.push_str(&format!(" {:.2} / {:.2}, {n} |", mean(e), max(e)));
        }
        seg.push('\n');
    }
    println!("{seg}");

    plot(&runs, &truth_cost, &out)?;
    println!("plot: {out}");
    println!("total time {:.1} s", started.elapsed().as_secs_f64());
    Ok(())
}
