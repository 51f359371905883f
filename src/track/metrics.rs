//! Accuracy metrics for comparing tracked joints with ground truth.
//!
//! All functions take joint positions as plain arrays; the `pred` and `truth`
//! slices always describe the same joints in the same order.
//!
//! # Metrics
//!
//! * **PCK** (percentage of correct keypoints, [`pck_frame`]): a predicted 2D
//!   joint is *correct* when its pixel distance to the true joint is at most
//!   `alpha * body_height`. The boundary is inclusive. The same call also
//!   reports the mean 2D error divided by the body height, a scale-free
//!   error for one frame.
//! * **Swapped PCK** ([`pck_frame_swapped`]): a single view often cannot tell
//!   a left limb from the matching right limb. For each mirrored limb pair,
//!   the predicted left and right limbs are swapped as a whole when this
//!   lowers the pair's summed 2D distance to the truth. PCK is then computed on
//!   that copy ([`swap_limbs_2d`]). The gap between plain and swapped PCK shows
//!   how much error comes from left/right confusion.
//! * **MPJPE** (mean per-joint position error, [`mpjpe`]): mean Euclidean
//!   distance between predicted and true 3D joints, with no alignment.
//! * **PA-MPJPE** (Procrustes-aligned MPJPE, [`pa_mpjpe`]): MPJPE after the
//!   prediction is mapped onto the truth by the least-squares similarity
//!   transform (scale, proper rotation, translation; Umeyama 1991,
//!   [`align_similarity`]). It measures pose shape only and ignores global
//!   position, orientation and scale, which a single camera cannot recover
//!   reliably. Reflections are not allowed, so a mirrored pose still counts
//!   as an error.
//! * **PA-MPJPE with ambiguities** ([`pa_mpjpe_ambiguous`]): the least
//!   PA-MPJPE over the truth and its depth mirror ([`depth_mirror`]), each
//!   with every combination of whole-limb left/right swaps. One view cannot
//!   tell these apart from the silhouette alone; what remains is the error
//!   that no such choice explains.
//! * [`Accumulator`] sums these over frames and clips. PCK values are pooled
//!   over joints (total correct / total joints). Error fractions, PA-MPJPE and
//!   silhouette IoU are averaged over frames.
//!
//! # Degenerate input
//!
//! Empty inputs never panic and never produce NaN. They count 0 joints, and
//! every mean over nothing is `0.0`. If all predicted points coincide, no
//! rotation or scale can be estimated, so [`align_similarity`] only translates.
//! Mismatched `pred`/`truth` lengths are caller bugs and fail an `assert!`.

use nalgebra::{Matrix3, Vector3, SVD};

/// Pairs of joint index lists that are mirror images (e.g. left arm
/// `[4, 5, 6]` ↔ right arm `[7, 8, 9]`); the lists in a pair have equal length.
pub type LimbPairs<'a> = &'a [(&'a [usize], &'a [usize])];

/// 2D errors of one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Frame2d {
    /// Joints whose distance to the truth is at most `alpha * body_height`.
    pub correct: usize,
    /// Number of joints compared.
    pub joints: usize,
    /// Mean joint distance divided by `body_height` (`0.0` when `joints == 0`).
    pub mean_error_frac: f64,
}

impl Frame2d {
    /// `correct / joints` for this frame, or `0.0` when there are no joints.
    pub fn pck(&self) -> f64 {
        ratio(self.correct as f64, self.joints)
    }
}

fn ratio(sum: f64, count: usize) -> f64 {
    if count == 0 {
        0.0
    } else {
        sum / count as f64
    }
}

fn assert_same_len(pred: usize, truth: usize) {
    assert!(
        pred == truth,
        "metrics: pred has {pred} joints but truth has {truth}"
    );
}

fn dist2(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

fn dist3(a: [f64; 3], b: [f64; 3]) -> f64 {
    let (dx, dy, dz) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    (dx * dx + dy * dy + dz * dz).sqrt()
}

/// 2D errors of one frame. `pred` and `truth` are pixel positions of the same
/// joints (same order, same length); `body_height` is the person's height in
/// pixels in this frame (> 0).
///
/// A joint is correct when its distance is `<= alpha * body_height`; the
/// boundary is inclusive.
///
/// # Panics
///
/// Panics if `pred.len() != truth.len()`, or if `body_height` is not
/// positive (including NaN).
pub fn pck_frame(pred: &[[f64; 2]], truth: &[[f64; 2]], body_height: f64, alpha: f64) -> Frame2d {
    assert_same_len(pred.len(), truth.len());
    assert!(
        body_height > 0.0,
        "metrics: body_height must be > 0, got {body_height}"
    );
    let threshold = alpha * body_height;
    let mut correct = 0;
    let mut total = 0.0;
    for (&p, &t) in pred.iter().zip(truth) {
        let d = dist2(p, t);
        if d <= threshold {
            correct += 1;
        }
        total += d;
    }
    Frame2d {
        correct,
        joints: pred.len(),
        mean_error_frac: ratio(total, pred.len()) / body_height,
    }
}

/// The same as [`pck_frame`], computed after swapping, independently for
/// each limb pair, the predicted left and right limbs when that lowers the
/// pair's summed 2D distance to the truth (a whole-limb left/right swap, the
/// ambiguity a single view cannot resolve). See [`swap_limbs_2d`].
///
/// # Panics
///
/// Panics in the same cases as [`pck_frame`] and [`swap_limbs_2d`].
pub fn pck_frame_swapped(
    pred: &[[f64; 2]],
    truth: &[[f64; 2]],
    body_height: f64,
    alpha: f64,
    pairs: LimbPairs,
) -> Frame2d {
    let swapped = swap_limbs_2d(pred, truth, pairs);
    pck_frame(&swapped, truth, body_height, alpha)
}

/// The swapped copy of `pred` used by [`pck_frame_swapped`], exposed for
/// reuse, e.g. to swap 3D predictions in the same way.
///
/// For each pair `(left, right)`, the predicted `left[i]` and `right[i]`
/// positions are exchanged for every `i` if the summed distance after the swap
/// is strictly smaller than before. Ties keep the original order. Each pair is
/// decided on the original `pred`, so decisions do not depend on pair order.
/// Pairs are expected to use disjoint joints. If they overlap, later pairs
/// overwrite the results of earlier ones.
///
/// # Panics
///
/// Panics if `pred.len() != truth.len()`, if the two lists of a pair have
/// different lengths, or if a joint index is out of range.
pub fn swap_limbs_2d(pred: &[[f64; 2]], truth: &[[f64; 2]], pairs: LimbPairs) -> Vec<[f64; 2]> {
    assert_same_len(pred.len(), truth.len());
    check_pairs(pairs, pred.len());
    let mut out = pred.to_vec();
    for &(left, right) in pairs {
        let mut kept = 0.0;
        let mut swapped = 0.0;
        for (&l, &r) in left.iter().zip(right) {
            kept += dist2(pred[l], truth[l]) + dist2(pred[r], truth[r]);
            swapped += dist2(pred[r], truth[l]) + dist2(pred[l], truth[r]);
        }
        if swapped < kept {
            for (&l, &r) in left.iter().zip(right) {
                out[l] = pred[r];
                out[r] = pred[l];
            }
        }
    }
    out
}

fn centroid(points: &[[f64; 3]]) -> Vector3<f64> {
    let sum = points
        .iter()
        .fold(Vector3::zeros(), |acc, p| acc + Vector3::from(*p));
    sum / points.len() as f64
}

/// Similarity (scale, rotation, translation) that best maps `pred` onto
/// `truth` in the least-squares sense (Umeyama 1991: SVD of the
/// cross-covariance, with the reflection correction so the result is a proper
/// rotation). Returns the aligned copy of `pred`.
///
/// Degenerate cases: an empty input returns an empty vector. If all predicted
/// points coincide (to rounding), rotation and scale are undefined, so only
/// the translation is applied: every point lands on the truth centroid. If the
/// SVD fails, for example on non-finite input, the same translation-only
/// result is returned.
///
/// # Panics
///
/// Panics if `pred.len() != truth.len()`.
pub fn align_similarity(pred: &[[f64; 3]], truth: &[[f64; 3]]) -> Vec<[f64; 3]> {
    assert_same_len(pred.len(), truth.len());
    if pred.is_empty() {
        return Vec::new();
    }
    let n = pred.len() as f64;
    let mu_p = centroid(pred);
    let mu_t = centroid(truth);
    let translate_only = || -> Vec<[f64; 3]> {
        pred.iter()
            .map(|p| (Vector3::from(*p) - mu_p + mu_t).into())
            .collect()
    };

    // Variance of pred about its centroid, and the cross-covariance
    // Sigma = (1/n) * sum (t - mu_t)(p - mu_p)^T.
    let mut var_p = 0.0;
    let mut sigma = Matrix3::zeros();
    let mut max_abs: f64 = 0.0;
    for (p, t) in pred.iter().zip(truth) {
        let x = Vector3::from(*p) - mu_p;
        let y = Vector3::from(*t) - mu_t;
        var_p += x.norm_squared();
        sigma += y * x.transpose();
        max_abs = p.iter().fold(max_abs, |m, c| m.max(c.abs()));
    }
    var_p /= n;
    sigma /= n;

    // Points that are identical up to rounding leave residuals of order
    // eps * |coordinate| after centering. Treat those as a single point.
    let tiny = 64.0 * f64::EPSILON * max_abs;
    // Written as a positive test so that a NaN variance also falls back.
    let spread = var_p > tiny * tiny;
    if !spread || !sigma.iter().all(|v| v.is_finite()) {
        return translate_only();
    }

    let Some(svd) = SVD::try_new(sigma, true, true, f64::EPSILON, 10_000) else {
        return translate_only();
    };
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return translate_only();
    };
    // Singular values are sorted in descending order, so a reflection is
    // removed by flipping the weakest direction.
    let d = if u.determinant() * v_t.determinant() < 0.0 {
        -1.0
    } else {
        1.0
    };
    let s = Vector3::new(1.0, 1.0, d);
    let rotation = u * Matrix3::from_diagonal(&s) * v_t;
    let scale = svd.singular_values.dot(&s) / var_p;
    let translation = mu_t - rotation * mu_p * scale;

    pred.iter()
        .map(|p| (rotation * Vector3::from(*p) * scale + translation).into())
        .collect()
}

/// Mean per-joint position error after [`align_similarity`] (PA-MPJPE), in the
/// units of `truth`. Returns `0.0` for empty input.
///
/// # Panics
///
/// Panics if `pred.len() != truth.len()`.
pub fn pa_mpjpe(pred: &[[f64; 3]], truth: &[[f64; 3]]) -> f64 {
    let aligned = align_similarity(pred, truth);
    mpjpe(&aligned, truth)
}

/// `points` reflected in the plane through `pivot` square to the line of sight
/// from the camera (at the origin) to `pivot`: a body's depth mirror, which one
/// view sees almost as it sees the body (exactly so under an orthographic camera).
/// Returns the points unchanged when `pivot` is the origin (no line of sight).
pub fn depth_mirror(points: &[[f64; 3]], pivot: [f64; 3]) -> Vec<[f64; 3]> {
    let c = Vector3::from(pivot);
    let Some(d) = c.try_normalize(f64::EPSILON) else {
        return points.to_vec();
    };
    points
        .iter()
        .map(|p| {
            let x = Vector3::from(*p);
            (x - 2.0 * (x - c).dot(&d) * d).into()
        })
        .collect()
}

/// PA-MPJPE allowing what one view cannot tell apart: the least [`pa_mpjpe`]
/// over the truth and its [`depth_mirror`] about `pivot`, each with every
/// combination of whole-limb left/right swaps of `pairs` (the mirror exchanges
/// left and right, so its swaps matter as much). Returns `0.0` for empty input.
///
/// # Panics
///
/// Panics if `pred.len() != truth.len()`, if a pair's index is out of range or
/// its two lists differ in length, or if `pairs` has more than 8 pairs.
pub fn pa_mpjpe_ambiguous(
    pred: &[[f64; 3]],
    truth: &[[f64; 3]],
    pairs: LimbPairs,
    pivot: [f64; 3],
) -> f64 {
    assert_same_len(pred.len(), truth.len());
    assert!(pairs.len() <= 8, "pa_mpjpe_ambiguous: at most 8 limb pairs");
    if pred.is_empty() {
        return 0.0;
    }
    check_pairs(pairs, truth.len());
    let mut best = f64::INFINITY;
    for candidate in [truth.to_vec(), depth_mirror(truth, pivot)] {
        for swaps in 0..1usize << pairs.len() {
            let mut t = candidate.clone();
            for (i, (left, right)) in pairs.iter().enumerate() {
                if swaps >> i & 1 == 1 {
                    exchange(&mut t, left, right);
                }
            }
            best = best.min(pa_mpjpe(pred, &t));
        }
    }
    best
}

/// Panics unless each pair's two lists have one length and name joints below `n`.
fn check_pairs(pairs: LimbPairs, n: usize) {
    for (pair_index, &(left, right)) in pairs.iter().enumerate() {
        assert!(
            left.len() == right.len(),
            "metrics: limb pair {pair_index} has lists of length {} and {}",
            left.len(),
            right.len()
        );
        for &j in left.iter().chain(right) {
            assert!(
                j < n,
                "metrics: limb pair {pair_index} uses joint {j} but there are only {n} joints"
            );
        }
    }
}

/// Exchanges `points[left[i]]` and `points[right[i]]` for every `i`.
fn exchange<T>(points: &mut [T], left: &[usize], right: &[usize]) {
    for (&l, &r) in left.iter().zip(right) {
        points.swap(l, r);
    }
}

/// Mean per-joint position error without alignment (MPJPE), in the units of
/// `truth`. Returns `0.0` for empty input.
///
/// # Panics
///
/// Panics if `pred.len() != truth.len()`.
pub fn mpjpe(pred: &[[f64; 3]], truth: &[[f64; 3]]) -> f64 {
    assert_same_len(pred.len(), truth.len());
    let total: f64 = pred.iter().zip(truth).map(|(&p, &t)| dist3(p, t)).sum();
    ratio(total, pred.len())
}

/// How far a fitted shape's proportions are from the true ones: the root mean
/// square of the log ratios of the scale factors after their mean is removed (one
/// camera cannot see the overall size, so a body uniformly 10% larger scores 0).
/// 0.1 is about 10% off per value. Returns `0.0` for empty input.
///
/// # Panics
///
/// Panics if `fitted.len() != truth.len()`.
pub fn shape_error(fitted: &[f64], truth: &[f64]) -> f64 {
    assert_same_len(fitted.len(), truth.len());
    let logs: Vec<f64> = fitted
        .iter()
        .zip(truth)
        .map(|(f, t)| (f / t).ln())
        .collect();
    let mean = ratio(logs.iter().sum(), logs.len());
    ratio(logs.iter().map(|l| (l - mean).powi(2)).sum(), logs.len()).sqrt()
}

/// Running totals over many frames and clips.
///
/// Every accessor returns `0.0` when nothing has been added, so an empty
/// accumulator never yields NaN. Values passed to [`Accumulator::add_frame`]
/// are summed unchanged, so a NaN input carries into the means.
#[derive(Clone, Debug, Default)]
pub struct Accumulator {
    frames: usize,
    correct: usize,
    joints: usize,
    correct_swapped: usize,
    joints_swapped: usize,
    sum_error_frac: f64,
    sum_pa_mpjpe: f64,
    sum_pa_ambiguous: f64,
    sum_iou: f64,
}

impl Accumulator {
    /// Adds one frame: plain and swapped 2D results (the swapped
    /// `mean_error_frac` is not used), its PA-MPJPE, the same with ambiguities
    /// ([`pa_mpjpe_ambiguous`]) and its silhouette IoU.
    pub fn add_frame(
        &mut self,
        plain: &Frame2d,
        swapped: &Frame2d,
        pa_mpjpe: f64,
        pa_ambiguous: f64,
        iou: f64,
    ) {
        self.frames += 1;
        self.correct += plain.correct;
        self.joints += plain.joints;
        self.correct_swapped += swapped.correct;
        self.joints_swapped += swapped.joints;
        self.sum_error_frac += plain.mean_error_frac;
        self.sum_pa_mpjpe += pa_mpjpe;
        self.sum_pa_ambiguous += pa_ambiguous;
        self.sum_iou += iou;
    }

    /// Adds all frames of `other`, e.g. to combine per-clip totals.
    pub fn merge(&mut self, other: &Accumulator) {
        self.frames += other.frames;
        self.correct += other.correct;
        self.joints += other.joints;
        self.correct_swapped += other.correct_swapped;
        self.joints_swapped += other.joints_swapped;
        self.sum_error_frac += other.sum_error_frac;
        self.sum_pa_mpjpe += other.sum_pa_mpjpe;
        self.sum_pa_ambiguous += other.sum_pa_ambiguous;
        self.sum_iou += other.sum_iou;
    }

    /// Number of frames added.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Total correct joints / total joints (`0.0` if no joints).
    pub fn pck(&self) -> f64 {
        ratio(self.correct as f64, self.joints)
    }

    /// As [`Accumulator::pck`], with left/right limb swaps allowed.
    pub fn pck_swapped(&self) -> f64 {
        ratio(self.correct_swapped as f64, self.joints_swapped)
    }

    /// Mean over frames of the plain per-frame `mean_error_frac`.
    pub fn mean_error_frac(&self) -> f64 {
        ratio(self.sum_error_frac, self.frames)
    }

    /// Mean over frames of PA-MPJPE.
    pub fn pa_mpjpe(&self) -> f64 {
        ratio(self.sum_pa_mpjpe, self.frames)
    }

    /// Mean over frames of PA-MPJPE with ambiguities ([`pa_mpjpe_ambiguous`]).
    pub fn pa_mpjpe_ambiguous(&self) -> f64 {
        ratio(self.sum_pa_ambiguous, self.frames)
    }

    /// Mean over frames of IoU.
    pub fn iou(&self) -> f64 {
        ratio(self.sum_iou, self.frames)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Unit};

    #[test]
    fn shape_error_ignores_the_overall_size() {
        let truth = [1.0, 0.8, 1.2, 0.9];
        let larger: Vec<f64> = truth.iter().map(|t| t * 1.1).collect();
        assert!(shape_error(&larger, &truth) < 1e-12);
        let mut off = truth;
        off[1] *= 1.5;
        let e = shape_error(&off, &truth);
        // One of four values 1.5× too large: log 1.5 with its mean removed.
        let l = 1.5f64.ln();
        let expected = ((0.75 * l).powi(2) + 3.0 * (0.25 * l).powi(2)) / 4.0;
        assert!((e - expected.sqrt()).abs() < 1e-12, "{e}");
    }

    /// A deliberately asymmetric, non-planar 3D point set (14 joints).
    fn skeleton3() -> Vec<[f64; 3]> {
        vec![
            [0.0, 1.7, 0.05],
            [0.0, 1.5, 0.0],
            [0.02, 1.0, 0.01],
            [0.0, 0.9, 0.0],
            [0.2, 1.45, 0.02],
            [0.45, 1.2, 0.1],
            [0.6, 1.0, 0.3],
            [-0.2, 1.45, -0.03],
            [-0.4, 1.3, -0.2],
            [-0.35, 1.55, -0.4],
            [0.1, 0.5, 0.08],
            [0.12, 0.05, 0.0],
            [-0.1, 0.45, -0.15],
            [-0.15, 0.0, -0.3],
        ]
    }

    /// Signed volume of the tetrahedron spanned by points 0, 4, 8, 11.
    fn orientation(pts: &[[f64; 3]]) -> f64 {
        let o = Vector3::from(pts[0]);
        let a = Vector3::from(pts[4]) - o;
        let b = Vector3::from(pts[8]) - o;
        let c = Vector3::from(pts[11]) - o;
        a.dot(&b.cross(&c))
    }

    #[test]
    fn similarity_transform_is_removed() {
        let truth = skeleton3();
        let axis = Unit::new_normalize(Vector3::new(0.3, -1.0, 0.5));
        let rot = Rotation3::from_axis_angle(&axis, 2.1);
        let shift = Vector3::new(3.0, -1.5, 7.25);
        let pred: Vec<[f64; 3]> = truth
            .iter()
            .map(|p| (rot * Vector3::from(*p) * 1.7 + shift).into())
            .collect();
        let pa = pa_mpjpe(&pred, &truth);
        let plain = mpjpe(&pred, &truth);
        assert!(pa < 1e-9, "PA-MPJPE {pa}");
        assert!(plain > 1.0, "MPJPE {plain}");
        // And the reverse direction (scale 1/1.7) as well.
        assert!(pa_mpjpe(&truth, &pred) < 1e-9);
    }

    #[test]
    fn reflection_is_not_aligned_away() {
        let truth = skeleton3();
        let mirrored: Vec<[f64; 3]> = truth.iter().map(|p| [-p[0], p[1], p[2]]).collect();
        let pa = pa_mpjpe(&mirrored, &truth);
        assert!(
            pa > 0.05,
            "mirrored PA-MPJPE {pa} should be clearly non-zero"
        );
        // The alignment keeps handedness: it is a proper rotation and a positive scale.
        let aligned = align_similarity(&mirrored, &truth);
        assert!(orientation(&aligned) * orientation(&mirrored) > 0.0);
        assert!(orientation(&aligned) * orientation(&truth) < 0.0);
    }

    #[test]
    fn degenerate_alignment_inputs() {
        assert!(align_similarity(&[], &[]).is_empty());
        assert_eq!(pa_mpjpe(&[], &[]), 0.0);
        assert_eq!(mpjpe(&[], &[]), 0.0);

        // All predicted points identical: translation only, onto the truth centroid.
        let truth = skeleton3();
        let same = vec![[0.1, 0.1, 0.1]; truth.len()];
        let aligned = align_similarity(&same, &truth);
        let c = centroid(&truth);
        for p in &aligned {
            assert!((Vector3::from(*p) - c).norm() < 1e-12);
        }
        assert!(pa_mpjpe(&same, &truth).is_finite());

        // Identical points with awkward magnitudes (rounding in the centroid).
        let same_big = vec![[0.1e6 + 0.3, -7.7e5, 1.0 / 3.0]; 7];
        let aligned = align_similarity(&same_big, &truth[..7]);
        assert!(aligned.iter().flatten().all(|v| v.is_finite()));

        // Single point, collinear points and an all-identical truth: no NaN.
        assert_eq!(
            align_similarity(&[[1.0, 2.0, 3.0]], &[[4.0, 5.0, 6.0]]),
            vec![[4.0, 5.0, 6.0]]
        );
        let line: Vec<[f64; 3]> = (0..5).map(|i| [i as f64, 0.0, 0.0]).collect();
        let line_t: Vec<[f64; 3]> = (0..5).map(|i| [0.0, 2.0 * i as f64, 1.0]).collect();
        assert!(pa_mpjpe(&line, &line_t) < 1e-9);
        let flat_truth = vec![[1.0, 1.0, 1.0]; 5];
        let pa = pa_mpjpe(&line, &flat_truth);
        assert!(pa.is_finite() && pa < 1e-9, "{pa}");
    }

    #[test]
    #[should_panic]
    fn mismatched_lengths_panic_3d() {
        mpjpe(&[[0.0; 3]; 2], &[[0.0; 3]; 3]);
    }

    #[test]
    #[should_panic]
    fn mismatched_lengths_panic_2d() {
        pck_frame(&[[0.0; 2]; 2], &[[0.0; 2]; 1], 100.0, 0.1);
    }

    #[test]
    fn pck_threshold_boundary() {
        // body_height 20, alpha 0.5 -> threshold exactly 10 px.
        let truth = [[0.0, 0.0], [100.0, 50.0], [10.0, 10.0], [0.0, 0.0]];
        let pred = [
            [0.0, 0.0],     // 0
            [106.0, 58.0],  // 10 (on the boundary: correct)
            [10.0, 20.5],   // 10.5
            [-18.0, -24.0], // 30
        ];
        let f = pck_frame(&pred, &truth, 20.0, 0.5);
        assert_eq!(f.joints, 4);
        assert_eq!(f.correct, 2);
        assert!((f.mean_error_frac - (0.0 + 10.0 + 10.5 + 30.0) / 4.0 / 20.0).abs() < 1e-12);
        assert!((f.pck() - 0.5).abs() < 1e-15);

        let tight = pck_frame(&pred, &truth, 20.0, 0.49);
        assert_eq!(tight.correct, 1);

        let empty = pck_frame(&[], &[], 20.0, 0.5);
        assert_eq!(
            (empty.correct, empty.joints, empty.mean_error_frac),
            (0, 0, 0.0)
        );
        assert_eq!(empty.pck(), 0.0);
    }

    const L_ARM: &[usize] = &[2, 3, 4];
    const R_ARM: &[usize] = &[5, 6, 7];
    const L_LEG: &[usize] = &[8, 9];
    const R_LEG: &[usize] = &[10, 11];
    const PAIRS: LimbPairs = &[(L_ARM, R_ARM), (L_LEG, R_LEG)];

    /// skeleton3's limbs as mirror pairs: arms 4–6 and 7–9, legs 10–11 and 12–13.
    const PAIRS3: LimbPairs = &[(&[4, 5, 6], &[7, 8, 9]), (&[10, 11], &[12, 13])];

    /// skeleton3 placed 5 m from the camera (at the origin), off its axis.
    fn far_skeleton3() -> (Vec<[f64; 3]>, [f64; 3]) {
        let pivot = [0.3, 1.0, -500.0];
        let pts = skeleton3()
            .iter()
            .map(|p| {
                [
                    p[0] * 100.0 + pivot[0],
                    p[1] * 100.0,
                    p[2] * 100.0 + pivot[2],
                ]
            })
            .collect();
        (pts, pivot)
    }

    #[test]
    fn depth_mirror_reflects_along_the_line_of_sight() {
        let (pts, pivot) = far_skeleton3();
        let m = depth_mirror(&pts, pivot);
        let d = Vector3::from(pivot).normalize();
        for (p, q) in pts.iter().zip(&m) {
            let (p, q) = (Vector3::from(*p), Vector3::from(*q));
            // Along the line of sight the offset from the pivot changes sign;
            // across it nothing moves.
            let (dp, dq) = (p - Vector3::from(pivot), q - Vector3::from(pivot));
            assert!((dp.dot(&d) + dq.dot(&d)).abs() < 1e-9);
            assert!(((dp - dp.dot(&d) * d) - (dq - dq.dot(&d) * d)).norm() < 1e-9);
        }
        // An involution; the pivot stays; no line of sight, no change.
        let back = depth_mirror(&m, pivot);
        assert!(mpjpe(&back, &pts) < 1e-9);
        assert_eq!(depth_mirror(&[pivot], pivot), vec![pivot]);
        assert_eq!(depth_mirror(&pts, [0.0; 3]), pts);
    }

    #[test]
    fn ambiguous_pa_mpjpe_forgives_swaps_and_the_mirror_only() {
        let (truth, pivot) = far_skeleton3();
        let swap = |pts: &[[f64; 3]], pair: usize| {
            let mut v = pts.to_vec();
            let (l, r) = PAIRS3[pair];
            exchange(&mut v, l, r);
            v
        };
        assert!(pa_mpjpe_ambiguous(&truth, &truth, PAIRS3, pivot) < 1e-9);
        // Arms exchanged, legs exchanged, the depth mirror with its legs exchanged:
        // plain PA-MPJPE counts each, the ambiguous one none.
        let mirror = depth_mirror(&truth, pivot);
        for pred in [swap(&truth, 0), swap(&truth, 1), swap(&mirror, 1)] {
            assert!(pa_mpjpe(&pred, &truth) > 5.0, "{}", pa_mpjpe(&pred, &truth));
            assert!(pa_mpjpe_ambiguous(&pred, &truth, PAIRS3, pivot) < 1e-6);
        }
        // Any other error stays, and never exceeds the plain figure.
        let mut off = truth.clone();
        off[6][0] += 30.0;
        let amb = pa_mpjpe_ambiguous(&off, &truth, PAIRS3, pivot);
        assert!(amb > 1.0 && amb <= pa_mpjpe(&off, &truth) + 1e-12, "{amb}");
        assert_eq!(pa_mpjpe_ambiguous(&[], &[], PAIRS3, pivot), 0.0);
    }

    #[test]
    #[should_panic]
    fn ambiguous_pa_mpjpe_refuses_unequal_limb_lists() {
        let (t, pivot) = far_skeleton3();
        pa_mpjpe_ambiguous(&t, &t, &[(&[4, 5], &[7])], pivot);
    }

    fn skeleton2() -> Vec<[f64; 2]> {
        vec![
            [100.0, 20.0],  // 0 head
            [100.0, 50.0],  // 1 neck
            [80.0, 55.0],   // 2 l shoulder
            [70.0, 90.0],   // 3 l elbow
            [65.0, 120.0],  // 4 l wrist
            [120.0, 55.0],  // 5 r shoulder
            [135.0, 85.0],  // 6 r elbow
            [150.0, 110.0], // 7 r wrist
            [90.0, 130.0],  // 8 l hip
            [85.0, 180.0],  // 9 l ankle
            [110.0, 130.0], // 10 r hip
            [118.0, 182.0], // 11 r ankle
        ]
    }

    #[test]
    fn swapped_limbs_are_recovered() {
        let truth = skeleton2();
        let mut pred = truth.clone();
        exchange(&mut pred, L_ARM, R_ARM);
        exchange(&mut pred, L_LEG, R_LEG);

        let plain = pck_frame(&pred, &truth, 180.0, 0.05);
        assert!(plain.pck() < 1.0);
        assert_eq!(plain.correct, 2); // head and neck only

        let swapped = pck_frame_swapped(&pred, &truth, 180.0, 0.05, PAIRS);
        assert_eq!(swapped.correct, swapped.joints);
        assert_eq!(swapped.pck(), 1.0);
        assert_eq!(swapped.mean_error_frac, 0.0);
        assert_eq!(swap_limbs_2d(&pred, &truth, PAIRS), truth);

        // A correct prediction is left untouched.
        assert_eq!(swap_limbs_2d(&truth, &truth, PAIRS), truth);
        // No pairs: identical to plain.
        assert_eq!(pck_frame_swapped(&pred, &truth, 180.0, 0.05, &[]), plain);
    }

    #[test]
    fn swapping_is_decided_per_pair() {
        let truth = skeleton2();
        let mut pred = truth.clone();
        exchange(&mut pred, L_ARM, R_ARM);
        // Legs are the right way round but a little off.
        for j in L_LEG.iter().chain(R_LEG) {
            pred[*j][0] += 3.0;
            pred[*j][1] -= 2.0;
        }
        let out = swap_limbs_2d(&pred, &truth, PAIRS);
        for j in L_ARM.iter().chain(R_ARM) {
            assert_eq!(out[*j], truth[*j], "arm joint {j} should be swapped back");
        }
        for j in L_LEG.iter().chain(R_LEG) {
            assert_eq!(out[*j], pred[*j], "leg joint {j} should be untouched");
        }
        assert_eq!(out[0], pred[0]);
        assert_eq!(out[1], pred[1]);

        // Pair order does not matter.
        let reversed: LimbPairs = &[(L_LEG, R_LEG), (L_ARM, R_ARM)];
        assert_eq!(swap_limbs_2d(&pred, &truth, reversed), out);

        // A swap that would fix one joint but worsen the limb overall is not taken.
        let mut partial = truth.clone();
        partial.swap(8, 10); // only the hips exchanged
        partial[9] = [85.0, 180.0];
        partial[11] = [118.0, 182.0];
        let hips_only = swap_limbs_2d(&partial, &truth, &[(L_LEG, R_LEG)]);
        // kept: 2 * 20 px; swapped: 0 + 2 * |ankle_l - ankle_r| = 2 * ~33 px -> keep.
        assert_eq!(hips_only, partial);
    }

    #[test]
    #[should_panic]
    fn out_of_range_limb_index_panics() {
        let t = skeleton2();
        swap_limbs_2d(&t, &t, &[(&[0], &[99])]);
    }

    #[test]
    #[should_panic]
    fn unequal_limb_lists_panic() {
        let t = skeleton2();
        swap_limbs_2d(&t, &t, &[(&[0, 1], &[2])]);
    }

    #[test]
    fn accumulator_arithmetic_and_merge() {
        let empty = Accumulator::default();
        assert_eq!(empty.frames(), 0);
        for v in [
            empty.pck(),
            empty.pck_swapped(),
            empty.mean_error_frac(),
            empty.pa_mpjpe(),
            empty.iou(),
        ] {
            assert_eq!(v, 0.0);
        }

        let f = |correct, joints, mean_error_frac| Frame2d {
            correct,
            joints,
            mean_error_frac,
        };
        let mut a = Accumulator::default();
        a.add_frame(&f(3, 4, 0.1), &f(4, 4, 0.05), 0.02, 0.01, 0.8);
        a.add_frame(&f(1, 6, 0.3), &f(2, 6, 0.2), 0.06, 0.03, 0.6);
        assert_eq!(a.frames(), 2);
        assert!((a.pck() - 4.0 / 10.0).abs() < 1e-15);
        assert!((a.pck_swapped() - 6.0 / 10.0).abs() < 1e-15);
        assert!((a.mean_error_frac() - 0.2).abs() < 1e-15);
        assert!((a.pa_mpjpe() - 0.04).abs() < 1e-15);
        assert!((a.pa_mpjpe_ambiguous() - 0.02).abs() < 1e-15);
        assert!((a.iou() - 0.7).abs() < 1e-15);

        let mut b = Accumulator::default();
        b.add_frame(&f(10, 10, 0.5), &f(10, 10, 0.5), 0.10, 0.07, 0.1);
        let mut merged = a.clone();
        merged.merge(&b);
        assert_eq!(merged.frames(), 3);
        assert!((merged.pck() - 14.0 / 20.0).abs() < 1e-15);
        assert!((merged.pck_swapped() - 16.0 / 20.0).abs() < 1e-15);
        assert!((merged.mean_error_frac() - 0.9 / 3.0).abs() < 1e-15);
        assert!((merged.pa_mpjpe() - 0.18 / 3.0).abs() < 1e-15);
        assert!((merged.pa_mpjpe_ambiguous() - 0.11 / 3.0).abs() < 1e-15);
        assert!((merged.iou() - 1.5 / 3.0).abs() < 1e-15);

        // Merging an empty accumulator changes nothing; merging into one equals adding.
        let mut same = merged.clone();
        same.merge(&Accumulator::default());
        assert_eq!(format!("{same:?}"), format!("{merged:?}"));
        let mut from_empty = Accumulator::default();
        from_empty.merge(&a);
        assert_eq!(format!("{from_empty:?}"), format!("{a:?}"));
    }
}
