//! Per-frame image features for the objective (method.md §4, paper §4.2–4.3).
//!
//! [`compute`] turns one input silhouette (and, when the clip has colour frames, the
//! frame) into a [`FrameFeatures`]: everything the objective F = c + e + l + a reads
//! that depends on the input alone. It runs once per frame; the tracker then evaluates
//! the objective thousands of times against it, so every per-pixel field is stored in
//! a form that is cheap to read — a flat row-major `Vec<f32>` (the coremap) or a
//! bit-packed [`Mask`] (edges, regions) that can be AND-ed with the model silhouette 64
//! pixels at a time.
//!
//! What is computed:
//!
//! - **Coremap** (Eq. 3): d = 1 + w·D(S) + D(S̄) from two exact Euclidean distance
//!   transforms (Meijster/Felzenszwalb–Huttenlocher: a column scan, then the lower
//!   envelope of parabolas along each row).
//! - **Edge map** T (Eq. 4): Sobel gradient magnitude of the grey frame above a
//!   threshold, inside the silhouette dilated by a band; for mask clips (no frame) the
//!   silhouette's own outline.
//! - **Outline features** (Eq. 5–6), on the *person*: the largest 8-connected blob of
//!   the silhouette plus the blobs near it. The outer contour comes from
//!   `imageproc::contours`; extremities are points of high convex curvature on it;
//!   the head is the highest local maximum of the outline near the peak of the column
//!   histogram; the neck is the narrowest row of the body below the head; the crotch
//!   is the apex of the background gap between the legs; the region image R holds the
//!   arms (thin parts below the neck) and the legs (below the crotch).

use image::{Rgb, RgbImage};
use imageproc::contours::{find_contours, BorderType};
use imageproc::drawing::{
    draw_cross_mut, draw_filled_circle_mut, draw_hollow_circle_mut, draw_line_segment_mut,
};

use super::blobs::{Blobs, Connectivity};
use super::skin::colour_bins;
use crate::body::Mask;
use std::sync::Arc;

/// Tuning of [`compute`]. Lengths given as a fraction of the body height are relative
/// to the height of the person's bounding box in the current frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FeatureOptions {
    /// w of Eq. 3: weight of the inside distance in the coremap. Default 1.0 (the
    /// paper's tracking value).
    pub core_weight: f64,
    /// Sobel gradient magnitude (of the 8-bit grey frame; maximum ≈ 1443) above which
    /// a pixel is an edge. Default 80.
    pub edge_threshold: f32,
    /// Edges count within this many pixels (Euclidean) of the silhouette. Default 3.
    pub edge_band: u32,
    /// Half-width of the window (in contour points, as a fraction of the body height)
    /// over which the outline's turning angle is measured. It should be about the
    /// width of a limb, so that a limb's end is one sharp turn. Default 0.05.
    pub curvature_scale: f64,
    /// Turning angle (radians) above which a convex outline point is an extremity
    /// candidate. A limb's end turns by almost π; a bent elbow or knee by about π/2.
    /// Default 1.9.
    pub curvature_threshold: f64,
    /// A blob joins the person when its bounding box lies within this gap of the
    /// largest blob's (fraction of body height) … Default 0.1.
    pub blob_gap: f64,
    /// … and its area is at least this fraction of the largest blob's. Default 0.005.
    pub min_blob_fraction: f64,
    /// Temporal coherence: a candidate farther than this (fraction of body height)
    /// from every previous candidate of the same kind is implausible. Default 0.15.
    pub max_jump: f64,
    /// Below this body height (pixels) no head, neck, crotch or regions are sought and
    /// extremity candidates are left [`ExtremityKind::Unknown`]. Default 16.
    pub min_body_height: u32,
    /// Keep the colour bin of each of the person's pixels
    /// ([`FrameFeatures::colours`], for the skin term); off unless it is weighed.
    pub colours: bool,
    /// Keep the frame's brightness ([`FrameFeatures::luma`], for the shading
    /// judge); off unless it is weighed.
    pub luma: bool,
}

impl Default for FeatureOptions {
    fn default() -> Self {
        FeatureOptions {
            core_weight: 1.0,
            edge_threshold: 80.0,
            edge_band: 3,
            curvature_scale: 0.05,
            curvature_threshold: 1.9,
            blob_gap: 0.1,
            min_blob_fraction: 0.005,
            max_jump: 0.15,
            min_body_height: 16,
            colours: false,
            luma: false,
        }
    }
}

/// What an extremity candidate probably is, from its position on the body.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ExtremityKind {
    /// Near the detected head.
    Head,
    /// Above the bottom quarter of the body (a raised foot is taken for a hand).
    Hand,
    /// In the bottom quarter of the body.
    Foot,
    /// Not classified: the person is lower than `min_body_height` pixels.
    Unknown,
}

/// A point of high convex curvature on the outline (Eq. 5).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Extremity {
    /// Pixel coordinates (pixel (i, j) has its centre at (i + 0.5, j + 0.5)).
    pub pos: [f64; 2],
    /// Signed turning angle of the outline over ±k contour points, radians in
    /// [−π, π]; positive is convex. Only convex points above the threshold are kept.
    pub curvature: f64,
    pub kind: ExtremityKind,
}

/// The features of one frame (see the module docs). Pixel coordinates throughout.
#[derive(Clone, Debug)]
pub struct FrameFeatures {
    pub width: u32,
    pub height: u32,
    /// Eq. 3 coremap d = 1 + w·D(S) + D(S̄), row-major (`y * width + x`), from exact
    /// Euclidean distance transforms: D(S) at a pixel inside S is its distance to the
    /// nearest pixel outside S (0 outside S), D(S̄) at a pixel outside S its distance
    /// to the nearest pixel of S. Only pixels of the image count (the image border is
    /// not "outside"); when S or S̄ has no pixel, the other transform is 0. The
    /// core-weighted XOR is Σ over mismatched pixels of this map.
    pub coremap: Vec<f32>,
    /// D(S): each pixel's distance to the nearest pixel outside the silhouette (0
    /// outside it), row-major; how deep inside the person a pixel lies.
    pub inside: Vec<f32>,
    /// Eq. 4 edge map T: pixels whose Sobel gradient magnitude exceeds the threshold
    /// within `edge_band` pixels of the silhouette; without a colour frame, the
    /// silhouette's own outline (pixels of S with a 4-neighbour outside S).
    pub edges: Mask,
    /// Whether `edges` came from a colour frame (false: the outline itself).
    pub colour_edges: bool,
    /// Outer contour of the person's main (largest) blob, in border-following order
    /// (8-connected pixel chain). Empty for an empty silhouette.
    pub contour: Vec<[i32; 2]>,
    /// Eq. 5 candidates for hands, feet and head on the outer contours of the person's
    /// blobs, after the temporal-coherence rule of [`compute`].
    pub extremities: Vec<Extremity>,
    /// Top of the head: the highest local maximum of the outline near the peak of the
    /// column histogram (compare with the model's HeadTop).
    pub head: Option<[f64; 2]>,
    /// Centre of the narrowest row of the body below the head (its two ends are the
    /// concave points of the outline at the neck).
    pub neck: Option<[f64; 2]>,
    /// Apex of the background V between the legs (None when the legs are together).
    pub crotch: Option<[f64; 2]>,
    /// Eq. 6 region image R: arm regions (the thin parts of the silhouette below the
    /// neck, i.e. what an opening with a disc of about a torso's half-depth removes)
    /// and the legs (the silhouette below the crotch).
    pub regions: Mask,
    /// The person: the blobs of the silhouette the outline features were taken from.
    pub person: Mask,
    /// Bounding box of the person, inclusive: [x0, y0, x1, y1]; None when empty.
    pub bbox: Option<[u32; 4]>,
    /// Height of the person's bounding box in pixels (the length unit of the
    /// fractional options); 0 when empty.
    pub body_height: f64,
    /// The colour bin of each of the person's pixels ([`super::skin::colour_bins`]),
    /// for the skin term; None without a colour frame or
    /// [`FeatureOptions::colours`].
    pub colours: Option<Arc<Vec<u16>>>,
    /// The colour frame's brightness (the mean of its channels), row-major; None
    /// without a colour frame of the silhouette's size or unless
    /// [`FeatureOptions::luma`] asks for it.
    pub luma: Option<Arc<Vec<u8>>>,
}

impl FrameFeatures {
    /// Coremap value at a pixel.
    pub fn core(&self, x: u32, y: u32) -> f32 {
        self.coremap[y as usize * self.width as usize + x as usize]
    }
}

/// Computes the features of one frame.
///
/// `silhouette` is the input mask S; `frame`, the colour frame of the same size if the
/// clip has one (a frame of another size is ignored, as for a mask clip). `previous`
/// is the previous frame's features, for temporal coherence:
///
/// *Rule.* For hands and feet separately: when there are more candidates of a kind
/// than the body has (2), the candidates farther than `max_jump` × body height from
/// every previous candidate of that kind are dropped, farthest first, until two are
/// left or no implausible one remains — so implausible candidates go only when
/// consistent ones exist and there are surplus ones, and a limb that reappears far
/// from where the previous frame saw the other is not lost. For the head, when a
/// head candidate lies within the jump of the previous head, the other head candidates
/// are dropped.
pub fn compute(
    silhouette: &Mask,
    frame: Option<&RgbImage>,
    previous: Option<&FrameFeatures>,
    opts: &FeatureOptions,
) -> FrameFeatures {
    let mut f = compute_unlinked(silhouette, frame, opts);
    link(&mut f, previous, opts);
    f
}

/// [`compute`] without the temporal coherence: everything that depends on this
/// frame alone, nearly all of the work. Frames can go through it in any order, or
/// side by side; [`link`] then adds the coherence in frame order.
pub fn compute_unlinked(
    silhouette: &Mask,
    frame: Option<&RgbImage>,
    opts: &FeatureOptions,
) -> FrameFeatures {
    let (w, h) = (silhouette.width(), silhouette.height());
    let inside = distance_transform(silhouette, false);
    let outside = distance_transform(silhouette, true);
    let cw = opts.core_weight as f32;
    let coremap: Vec<f32> = inside
        .iter()
        .zip(&outside)
        .map(|(di, do_)| 1.0 + cw * di + do_)
        .collect();

    // A colour frame of another size than the silhouette is not used.
    let frame = frame.filter(|fr| fr.width() == w && fr.height() == h);
    let edges = edge_map(silhouette, frame, &inside, &outside, opts);
    let colour_edges = frame.is_some();

    let mut f = FrameFeatures {
        width: w,
        height: h,
        coremap,
        inside,
        edges,
        colour_edges,
        contour: Vec::new(),
        extremities: Vec::new(),
        head: None,
        neck: None,
        crotch: None,
        regions: Mask::new(w, h),
        person: Mask::new(w, h),
        bbox: None,
        body_height: 0.0,
        colours: None,
        luma: None,
    };
    if opts.luma {
        f.luma = frame
            .filter(|fr| fr.dimensions() == (w, h))
            .map(|fr| Arc::new(luma(fr)));
    }
    if silhouette.count() == 0 {
        return f;
    }

    let (person, contours) = select_person(silhouette, opts);
    let Some(bbox) = bounding_box(&person) else {
        return f;
    };
    let body_h = (bbox[3] - bbox[1] + 1) as f64;
    if opts.colours {
        f.colours = frame.and_then(|fr| colour_bins(fr, &person)).map(Arc::new);
    }
    f.person = person;
    f.bbox = Some(bbox);
    f.body_height = body_h;
    if let Some(main) = contours.first() {
        f.contour = main.clone();
    }
    let k = ((opts.curvature_scale * body_h).round() as usize).max(3);
    if body_h < opts.min_body_height as f64 {
        // Too small for head, neck, crotch and regions; candidates stay unclassified.
        for c in &contours {
            convex_points(c, k, opts.curvature_threshold, &mut f.extremities);
        }
        return f;
    }

    f.head = find_head(&f.person, bbox, body_h);
    f.neck = f.head.and_then(|hd| find_neck(&f.person, hd, body_h));
    let axis_x = f
        .neck
        .or(f.head)
        .map(|p| p[0])
        .unwrap_or((bbox[0] + bbox[2] + 1) as f64 / 2.0);
    f.crotch = find_crotch(&f.person, bbox, body_h, axis_x);
    f.regions = find_regions(&f.person, bbox, body_h, f.neck, f.crotch, &f.inside);

    let mut cands = Vec::new();
    for c in &contours {
        convex_points(c, k, opts.curvature_threshold, &mut cands);
    }
    for e in &mut cands {
        e.kind = classify(e.pos, f.head, bbox, body_h);
    }
    f.extremities = cands;
    f
}

/// A colour frame's brightness: the mean of each pixel's three channels, rounded.
pub fn luma(frame: &RgbImage) -> Vec<u8> {
    frame
        .pixels()
        .map(|p| ((u16::from(p[0]) + u16::from(p[1]) + u16::from(p[2]) + 1) / 3) as u8)
        .collect()
}

/// The temporal coherence of [`compute`] (its rule), applied to the features of
/// [`compute_unlinked`] given the previous frame's (linked) features.
pub fn link(f: &mut FrameFeatures, previous: Option<&FrameFeatures>, opts: &FeatureOptions) {
    // As in [`compute_unlinked`]: no person, or too small for classified candidates.
    if f.bbox.is_none() || f.body_height < opts.min_body_height as f64 {
        return;
    }
    if let Some(prev) = previous {
        coherence(&mut f.extremities, prev, opts.max_jump * f.body_height);
    }
}

/// Exact Euclidean distance from each pixel to the nearest pixel whose value is
/// `target`, for pixels whose value is not `target` (0 at the others); 0 everywhere
/// when no pixel has the value `target`. Row-major.
///
/// Separable: per column the distance to the nearest site along the column (two
/// scans), then per row the lower envelope of the parabolas g(x')² + (x − x')²
/// (Felzenszwalb & Huttenlocher 2012).
pub fn distance_transform(mask: &Mask, target: bool) -> Vec<f32> {
    let (w, h) = (mask.width() as usize, mask.height() as usize);
    let mut out = vec![0.0f32; w * h];
    if w == 0 || h == 0 {
        return out;
    }
    let is_site = |x: usize, y: usize| mask.get(x as u32, y as u32) == target;
    // Column pass: squared vertical distance to the nearest site (∞ when none).
    let inf = f64::INFINITY;
    let mut g = vec![inf; w * h];
    for x in 0..w {
        let mut last: Option<usize> = None;
        for y in 0..h {
            if is_site(x, y) {
                last = Some(y);
            }
            if let Some(l) = last {
                g[y * w + x] = (y - l) as f64;
            }
        }
        let mut next: Option<usize> = None;
        for y in (0..h).rev() {
            if is_site(x, y) {
                next = Some(y);
            }
            if let Some(n) = next {
                let d = (n - y) as f64;
                if d < g[y * w + x] {
                    g[y * w + x] = d;
                }
            }
        }
    }
    for v in &mut g {
        *v *= *v;
    }
    // Row pass.
    let mut row_out = vec![0.0f64; w];
    let mut v = vec![0usize; w];
    let mut z = vec![0.0f64; w + 1];
    let mut any = false;
    for y in 0..h {
        let row = &g[y * w..(y + 1) * w];
        lower_envelope(row, &mut row_out, &mut v, &mut z);
        for x in 0..w {
            let d = row_out[x];
            if d.is_finite() {
                any = true;
                out[y * w + x] = d.sqrt() as f32;
            }
        }
    }
    if !any {
        out.fill(0.0);
    }
    out
}

/// out[q] = min over p of (q − p)² + f[p], skipping infinite f[p] (∞ when all are).
fn lower_envelope(f: &[f64], out: &mut [f64], v: &mut [usize], z: &mut [f64]) {
    let n = f.len();
    let mut k: usize = 0;
    let mut started = false;
    for q in 0..n {
        if !f[q].is_finite() {
            continue;
        }
        if !started {
            started = true;
            v[0] = q;
            z[0] = f64::NEG_INFINITY;
            z[1] = f64::INFINITY;
            continue;
        }
        let qf = q as f64;
        loop {
            let p = v[k];
            let pf = p as f64;
            let s = ((f[q] + qf * qf) - (f[p] + pf * pf)) / (2.0 * (qf - pf));
            if s <= z[k] {
                // z[0] = −∞, so this never runs past the first parabola.
                k -= 1;
                continue;
            }
            k += 1;
            v[k] = q;
            z[k] = s;
            z[k + 1] = f64::INFINITY;
            break;
        }
    }
    if !started {
        out.fill(f64::INFINITY);
        return;
    }
    let mut j = 0;
    for (q, o) in out.iter_mut().enumerate() {
        let qf = q as f64;
        while z[j + 1] < qf {
            j += 1;
        }
        let p = v[j];
        let d = qf - p as f64;
        *o = d * d + f[p];
    }
}

/// The edge map T (see [`FrameFeatures::edges`]); `frame`, when given, is the
/// silhouette's size.
fn edge_map(
    s: &Mask,
    frame: Option<&RgbImage>,
    inside: &[f32],
    outside: &[f32],
    opts: &FeatureOptions,
) -> Mask {
    let (w, h) = (s.width(), s.height());
    let mut edges = Mask::new(w, h);
    match frame {
        Some(fr) => {
            let gray = image::imageops::grayscale(fr);
            let grad = imageproc::gradients::sobel_gradients(&gray);
            let band = opts.edge_band as f32;
            for (i, (g, d)) in grad.as_raw().iter().zip(outside).enumerate() {
                // Inside S the outside distance is 0; outside, the distance to S.
                if *d <= band && *g as f32 >= opts.edge_threshold {
                    edges.set(i as u32 % w, i as u32 / w, true);
                }
            }
        }
        None => {
            for (i, d) in inside.iter().enumerate() {
                if *d == 1.0 {
                    edges.set(i as u32 % w, i as u32 / w, true);
                }
            }
        }
    }
    edges
}

/// The person's blobs and their outer contours (the largest blob's first).
fn select_person(s: &Mask, opts: &FeatureOptions) -> (Mask, Vec<Vec<[i32; 2]>>) {
    let (w, h) = (s.width(), s.height());
    let blobs = Blobs::label(s, true, Connectivity::Eight);
    let Some((main, keep)) = blobs.person(opts.min_blob_fraction, opts.blob_gap) else {
        return (Mask::new(w, h), Vec::new());
    };
    let person = blobs.mask_of(&keep);
    let pgray = person.to_gray();
    let mut contours: Vec<Vec<[i32; 2]>> = Vec::new();
    for c in find_contours::<i32>(&pgray) {
        if c.border_type != BorderType::Outer || c.parent.is_some() || c.points.is_empty() {
            continue;
        }
        let p0 = c.points[0];
        let is_main = blobs.at(p0.x as u32, p0.y as u32) == Some(main);
        let pts: Vec<[i32; 2]> = c.points.iter().map(|p| [p.x, p.y]).collect();
        if is_main {
            contours.insert(0, pts);
        } else {
            contours.push(pts);
        }
    }
    (person, contours)
}

/// The set pixels' bounding box `[x0, y0, x1, y1]` (inclusive); None when empty.
pub(super) fn bounding_box(m: &Mask) -> Option<[u32; 4]> {
    let mut b: Option<[u32; 4]> = None;
    for y in 0..m.height() {
        for (wi, &word) in m.row(y).iter().enumerate() {
            if word == 0 {
                continue;
            }
            let x0 = wi as u32 * 64 + word.trailing_zeros();
            let x1 = wi as u32 * 64 + 63 - word.leading_zeros();
            b = Some(match b {
                None => [x0, y, x1, y],
                Some(b) => [b[0].min(x0), b[1], b[2].max(x1), y],
            });
        }
    }
    b
}

/// Runs of set pixels in row y, inclusive [x0, x1].
fn runs(m: &Mask, y: u32) -> Vec<(u32, u32)> {
    let mut out = Vec::new();
    let mut start: Option<u32> = None;
    for x in 0..m.width() {
        match (m.get(x, y), start) {
            (true, None) => start = Some(x),
            (false, Some(s)) => {
                out.push((s, x - 1));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push((s, m.width() - 1));
    }
    out
}

/// A local maximum of the outline's top profile, for [`find_head`].
#[derive(Clone, Copy)]
struct TopPeak {
    /// Its row (the top).
    top: i64,
    /// First and last column of its plateau, from the bounding box's left.
    a: usize,
    b: usize,
    /// As wide as a head a little below its top (a raised hand is thinner).
    head_like: bool,
    /// Within the window about the column histogram's peak.
    in_window: bool,
}

fn find_head(mask: &Mask, bbox: [u32; 4], body_h: f64) -> Option<[f64; 2]> {
    let (x0, x1) = (bbox[0] as usize, bbox[2] as usize);
    let n = x1 - x0 + 1;
    let mut hist = vec![0u32; n];
    let mut top: Vec<Option<u32>> = vec![None; n];
    for y in bbox[1]..=bbox[3] {
        for (i, x) in (x0..=x1).enumerate() {
            if mask.get(x as u32, y) {
                hist[i] += 1;
                top[i].get_or_insert(y);
            }
        }
    }
    // Smoothed column histogram and its peak.
    let r = ((0.015 * body_h).round() as usize).max(1);
    let smooth: Vec<u32> = (0..n)
        .map(|i| hist[i.saturating_sub(r)..(i + r + 1).min(n)].iter().sum())
        .collect();
    let peak = (0..n).max_by_key(|&i| (smooth[i], std::cmp::Reverse(i)))?;
    // Local maxima of the outline (the top profile) near the peak: the highest whose
    // width a little below its top is a head's, not a raised hand's.
    let half = ((0.12 * body_h).round() as usize).max(1);
    let (lo, hi) = (peak.saturating_sub(half), (peak + half).min(n - 1));
    let m = ((0.03 * body_h).round() as usize).max(1);
    let height_at = |i: usize| top[i].map(|t| t as i64).unwrap_or(i64::MAX);
    let mut cands: Vec<TopPeak> = Vec::new();
    let mut i = 0;
    while i < n {
        let t = height_at(i);
        if t == i64::MAX {
            i += 1;
            continue;
        }
        // The plateau of the top around column i (within a pixel).
        let (mut a, mut b) = (i, i);
        while a > 0 && height_at(a - 1) == t {
            a -= 1;
        }
        while b + 1 < n && height_at(b + 1) == t {
            b += 1;
        }
        let lower = |j: usize| height_at(j) < t;
        let is_max =
            !(a.saturating_sub(m)..a).any(lower) && !(b + 1..(b + 1 + m).min(n)).any(lower);
        if is_max {
            let probe_y = (t as f64 + 0.06 * body_h) as u32;
            let cx = (x0 + (a + b) / 2) as u32;
            let width = if probe_y <= bbox[3] {
                runs(mask, probe_y)
                    .into_iter()
                    .find(|r| r.0 <= cx && cx <= r.1)
                    .map(|r| (r.1 - r.0 + 1) as f64)
                    .unwrap_or(0.0)
            } else {
                0.0
            };
            cands.push(TopPeak {
                top: t,
                a,
                b,
                head_like: width >= 0.065 * body_h,
                in_window: b >= lo && a <= hi,
            });
        }
        i = b + 1;
    }
    // Head-like in the window, else any in the window, else head-like anywhere (a
    // body bent or leaning far from the column peak).
    let best = |keep: &dyn Fn(&TopPeak) -> bool| {
        cands
            .iter()
            .filter(|c| keep(c))
            .min_by_key(|c| (c.top, ((c.a + c.b) / 2).abs_diff(peak)))
            .copied()
    };
    let pick = best(&|c| c.head_like && c.in_window)
        .or_else(|| best(&|c| c.in_window))
        .or_else(|| best(&|c| c.head_like))?;
    let (ty, a, b) = (pick.top, pick.a, pick.b);
    Some([(x0 + a) as f64 + (b - a + 1) as f64 / 2.0, ty as f64])
}

fn find_neck(m: &Mask, head: [f64; 2], body_h: f64) -> Option<[f64; 2]> {
    let y_start = head[1] as u32;
    let y_lo = head[1] + 0.06 * body_h;
    let y_hi = (head[1] + 0.22 * body_h).min(m.height() as f64 - 1.0);
    let reach = (0.05 * body_h).max(2.0);
    let mut cx = head[0];
    let mut best: Option<(u32, f64, u32)> = None; // (width, centre, row)
    let mut y = y_start;
    while (y as f64) <= y_hi {
        let rs = runs(m, y);
        // The run containing the current centre, else the nearest within reach.
        let dist = |r: &(u32, u32)| {
            let (a, b) = (r.0 as f64, r.1 as f64 + 1.0);
            if cx < a {
                a - cx
            } else if cx > b {
                cx - b
            } else {
                0.0
            }
        };
        let Some(run) = rs.iter().min_by(|a, b| dist(a).total_cmp(&dist(b))) else {
            break;
        };
        if dist(run) > reach {
            break;
        }
        let width = run.1 - run.0 + 1;
        cx = (run.0 + run.1 + 1) as f64 / 2.0;
        if y as f64 >= y_lo && best.is_none_or(|(bw, _, _)| width < bw) {
            best = Some((width, cx, y));
        }
        y += 1;
    }
    best.map(|(_, c, y)| [c, y as f64 + 0.5])
}

fn find_crotch(m: &Mask, bbox: [u32; 4], body_h: f64, axis_x: f64) -> Option<[f64; 2]> {
    // Background gaps between consecutive runs of a row.
    let gaps = |y: u32| -> Vec<(u32, u32)> {
        let rs = runs(m, y);
        rs.windows(2).map(|p| (p[0].1 + 1, p[1].0 - 1)).collect()
    };
    let centre = |g: &(u32, u32)| (g.0 + g.1 + 1) as f64 / 2.0;
    let reach = 0.2 * body_h;
    let start_top = (bbox[3] as f64 - 0.2 * body_h).max(bbox[1] as f64) as u32;
    let mut y = bbox[3];
    let mut gap = None;
    while y >= start_top {
        let near = gaps(y)
            .into_iter()
            .filter(|g| (centre(g) - axis_x).abs() <= reach)
            .min_by(|a, b| {
                (centre(a) - axis_x)
                    .abs()
                    .total_cmp(&(centre(b) - axis_x).abs())
            });
        if let Some(g) = near {
            gap = Some((g, y));
            break;
        }
        if y == 0 {
            break;
        }
        y -= 1;
    }
    let (mut g, y_start) = gap?;
    let mut y = y_start;
    while y > bbox[1] {
        let overlap = |c: &(u32, u32)| c.1.min(g.1) as i64 - c.0.max(g.0) as i64;
        match gaps(y - 1)
            .into_iter()
            .filter(|c| overlap(c) >= 0)
            .max_by_key(overlap)
        {
            Some(c) => {
                g = c;
                y -= 1;
            }
            None => break,
        }
    }
    // A gap that opens only near the feet is no V; nor is one reaching the head.
    let rise = (bbox[3] - y) as f64;
    if rise < 0.1 * body_h || (y - bbox[1]) as f64 <= 0.25 * body_h {
        return None;
    }
    Some([centre(&g), y as f64])
}

fn find_regions(
    m: &Mask,
    bbox: [u32; 4],
    body_h: f64,
    neck: Option<[f64; 2]>,
    crotch: Option<[f64; 2]>,
    inside: &[f32],
) -> Mask {
    let (w, h) = (m.width(), m.height());
    // Opening with a disc of radius r: erosion = D(S) > r, then the pixels within r
    // of the eroded set. Limbs thinner than 2r vanish; the torso stays.
    let r = (0.045 * body_h) as f32;
    let mut eroded = Mask::new(w, h);
    let mut any = false;
    for (i, d) in inside.iter().enumerate() {
        let (x, y) = (i as u32 % w, i as u32 / w);
        if *d > r && m.get(x, y) {
            eroded.set(x, y, true);
            any = true;
        }
    }
    let to_core = if any {
        distance_transform(&eroded, true)
    } else {
        vec![f32::INFINITY; (w * h) as usize]
    };
    let neck_y = neck.map(|n| n[1]).unwrap_or(bbox[1] as f64 + 0.15 * body_h);
    let crotch_y = crotch.map(|c| c[1]).unwrap_or(f64::INFINITY);
    let mut regions = Mask::new(w, h);
    for y in bbox[1]..=bbox[3] {
        let yc = y as f64 + 0.5;
        for x in bbox[0]..=bbox[2] {
            if !m.get(x, y) {
                continue;
            }
            let thin = to_core[(y * w + x) as usize] > r;
            if (yc > neck_y && thin) || yc > crotch_y {
                regions.set(x, y, true);
            }
        }
    }
    regions
}

/// Appends the local maxima of the convex turning angle above `threshold`.
fn convex_points(c: &[[i32; 2]], k: usize, threshold: f64, out: &mut Vec<Extremity>) {
    let n = c.len();
    if n < 2 * k + 3 {
        return;
    }
    // Orientation: sign of the shoelace area.
    let area: i64 = (0..n)
        .map(|i| {
            let (a, b) = (c[i], c[(i + 1) % n]);
            a[0] as i64 * b[1] as i64 - b[0] as i64 * a[1] as i64
        })
        .sum();
    let orient = if area >= 0 { 1.0 } else { -1.0 };
    let turn: Vec<f64> = (0..n)
        .map(|i| {
            let p = c[i];
            let a = c[(i + n - k) % n];
            let b = c[(i + k) % n];
            let (ux, uy) = ((p[0] - a[0]) as f64, (p[1] - a[1]) as f64);
            let (vx, vy) = ((b[0] - p[0]) as f64, (b[1] - p[1]) as f64);
            let cross = ux * vy - uy * vx;
            let dot = ux * vx + uy * vy;
            orient * cross.atan2(dot)
        })
        .collect();
    let mut last: Option<usize> = None;
    for i in 0..n {
        let t = turn[i];
        if t < threshold {
            continue;
        }
        // A maximum over ±k: earlier points strictly lower, later ones not higher (so
        // a plateau counts once, from its first point).
        let is_max = (1..=k).all(|j| turn[(i + n - j) % n] < t && turn[(i + j) % n] <= t);
        if !is_max {
            continue;
        }
        // Centre of the plateau of equal turning at this maximum.
        let mut e = i;
        while e + 1 < i + k && turn[(e + 1) % n] == t {
            e += 1;
        }
        let idx = ((i + e) / 2) % n;
        if let Some(l) = last {
            if idx.abs_diff(l) < k {
                continue;
            }
        }
        last = Some(idx);
        let p = c[idx];
        out.push(Extremity {
            pos: [p[0] as f64 + 0.5, p[1] as f64 + 0.5],
            curvature: t,
            kind: ExtremityKind::Unknown,
        });
    }
}

fn classify(pos: [f64; 2], head: Option<[f64; 2]>, bbox: [u32; 4], body_h: f64) -> ExtremityKind {
    if let Some(hd) = head {
        if (pos[0] - hd[0]).hypot(pos[1] - hd[1]) <= 0.1 * body_h {
            return ExtremityKind::Head;
        }
    }
    if pos[1] >= bbox[3] as f64 + 1.0 - 0.25 * body_h {
        ExtremityKind::Foot
    } else {
        ExtremityKind::Hand
    }
}

fn coherence(cands: &mut Vec<Extremity>, prev: &FrameFeatures, jump: f64) {
    let dist_prev = |e: &Extremity| {
        prev.extremities
            .iter()
            .filter(|p| p.kind == e.kind)
            .map(|p| (p.pos[0] - e.pos[0]).hypot(p.pos[1] - e.pos[1]))
            .fold(f64::INFINITY, f64::min)
    };
    for kind in [ExtremityKind::Hand, ExtremityKind::Foot] {
        loop {
            let of_kind: Vec<usize> = (0..cands.len())
                .filter(|&i| cands[i].kind == kind)
                .collect();
            if of_kind.len() <= 2 {
                break;
            }
            let d: Vec<f64> = of_kind.iter().map(|&i| dist_prev(&cands[i])).collect();
            if !d.iter().any(|&v| v <= jump) {
                break;
            }
            let (worst, dw) = of_kind
                .iter()
                .zip(&d)
                .max_by(|a, b| a.1.total_cmp(b.1))
                .map(|(&i, &v)| (i, v))
                .unwrap();
            if dw <= jump {
                break;
            }
            cands.remove(worst);
        }
    }
    let heads: Vec<usize> = (0..cands.len())
        .filter(|&i| cands[i].kind == ExtremityKind::Head)
        .collect();
    if heads.len() > 1 && heads.iter().any(|&i| dist_prev(&cands[i]) <= jump) {
        cands.retain(|e| e.kind != ExtremityKind::Head || dist_prev(e) <= jump);
    }
}

/// A picture of the features: left, the frame (or black) with the silhouette tinted
/// blue, the regions R tinted green, the edges white, the contour yellow, hands red,
/// feet magenta, head candidates orange, the head a white cross in a circle, the neck
/// cyan and the crotch green; right, the coremap as a heat map (black → red → yellow →
/// white, logarithmic up to its maximum) with the contour on top.
pub fn debug_image(frame: Option<&RgbImage>, silhouette: &Mask, f: &FrameFeatures) -> RgbImage {
    let (w, h) = (f.width, f.height);
    let mut out = RgbImage::new(2 * w, h);
    let frame = frame.filter(|fr| fr.width() == w && fr.height() == h);
    let max_core = f.coremap.iter().copied().fold(1.0f32, f32::max);
    // Logarithmic, so that the inside (a few tens at most) and the far outside (up to
    // the image diagonal) both show.
    let scale = max_core.ln().max(1e-3);
    for y in 0..h {
        for x in 0..w {
            let mut c = frame.map(|fr| fr.get_pixel(x, y).0).unwrap_or([0, 0, 0]);
            c = c.map(|v| v / 2);
            let blend = |c: [u8; 3], t: [u8; 3]| -> [u8; 3] {
                [0, 1, 2].map(|i| ((c[i] as u16 + t[i] as u16) / 2) as u8)
            };
            if silhouette.get(x, y) {
                c = blend(c, [40, 80, 220]);
            }
            if f.regions.get(x, y) {
                c = blend(c, [40, 220, 60]);
            }
            if f.edges.get(x, y) {
                c = [255, 255, 255];
            }
            out.put_pixel(x, y, Rgb(c));
            let t = f.core(x, y).ln() / scale;
            out.put_pixel(w + x, y, Rgb(heat(t)));
        }
    }
    for p in &f.contour {
        for off in [0, w as i32] {
            let (x, y) = (p[0] + off, p[1]);
            out.put_pixel(x as u32, y as u32, Rgb([255, 230, 0]));
        }
    }
    let at = |p: [f64; 2]| (p[0].floor() as i32, p[1].floor() as i32);
    for e in &f.extremities {
        let col = match e.kind {
            ExtremityKind::Hand => [255, 40, 40],
            ExtremityKind::Foot => [255, 0, 255],
            ExtremityKind::Head => [255, 150, 0],
            ExtremityKind::Unknown => [160, 160, 160],
        };
        draw_filled_circle_mut(&mut out, at(e.pos), 3, Rgb(col));
    }
    if let Some(hd) = f.head {
        let (x, y) = at(hd);
        draw_hollow_circle_mut(&mut out, (x, y), 6, Rgb([255, 255, 255]));
        draw_cross_mut(&mut out, Rgb([255, 255, 255]), x, y);
    }
    if let Some(n) = f.neck {
        draw_filled_circle_mut(&mut out, at(n), 3, Rgb([0, 255, 255]));
        let hw = (0.04 * f.body_height) as f32;
        let (x, y) = (n[0] as f32, n[1] as f32);
        draw_line_segment_mut(&mut out, (x - hw, y), (x + hw, y), Rgb([0, 255, 255]));
    }
    if let Some(c) = f.crotch {
        draw_filled_circle_mut(&mut out, at(c), 3, Rgb([0, 255, 0]));
    }
    out
}

/// Black → red → yellow → white for t in [0, 1].
fn heat(t: f32) -> [u8; 3] {
    let t = t.clamp(0.0, 1.0) * 3.0;
    let ch = |v: f32| (v.clamp(0.0, 1.0) * 255.0) as u8;
    [ch(t), ch(t - 1.0), ch(t - 2.0)]
}
