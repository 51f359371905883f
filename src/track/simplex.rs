//! A bounded downhill simplex (Nelder–Mead) minimiser for small, derivative-free,
//! possibly non-smooth costs.
//!
//! The method keeps n + 1 points (the vertices of a simplex in n dimensions) and
//! their costs. Each step moves the worst vertex through the centroid of the others:
//! a reflection (α = 1); if that beats the best vertex, an expansion twice as far
//! (γ = 2); if the reflection is only a little better than the worst vertex, an
//! outside contraction halfway back towards the centroid (ρ = ½); if it is no better
//! at all, an inside contraction halfway between the centroid and the worst vertex.
//! When a contraction fails too, every vertex but the best moves halfway towards the
//! best (a shrink, σ = ½). The search stops when the vertex costs agree, when the
//! simplex has shrunk to a fraction of its initial size, or when the evaluation budget
//! is spent; it returns the best point ever evaluated.
//!
//! Bounds are handled by giving every point outside the box the cost +∞, without
//! calling the cost function. The simplex then never accepts such a point (a vertex
//! is only replaced by a strictly better one), so the method's own contractions and
//! shrinks pull it back inside, with no change to its geometry: clamping or
//! projecting the trial points instead would flatten the simplex against a bound and
//! make it degenerate (it could no longer move off the bound in that coordinate).
//! The cost function's own +∞ (or NaN) answers, for poses it refuses, go the same
//! way. Coordinates whose bounds coincide are fixed and kept out of the simplex, which
//! would otherwise have a vertex outside the box for ever.

/// Tuning of [`minimize`].
#[derive(Clone, Debug)]
pub struct SimplexOptions {
    /// Stop after this many cost evaluations (points outside the bounds are not
    /// evaluated and not counted).
    pub max_evals: usize,
    /// Stop when the spread of the vertex costs is at most
    /// `ftol · (|f_best| + |f_worst|) / 2 + abs_tol` ...
    pub ftol: f64,
    pub abs_tol: f64,
    /// ... or when every vertex lies within this fraction of its initial step from the
    /// best vertex (per coordinate).
    pub xtol: f64,
}

impl Default for SimplexOptions {
    fn default() -> SimplexOptions {
        SimplexOptions {
            max_evals: 200,
            ftol: 1e-4,
            abs_tol: 1e-9,
            xtol: 0.02,
        }
    }
}

/// The best point [`minimize`] evaluated, its cost, and how many times the cost
/// function was called.
#[derive(Clone, Debug, PartialEq)]
pub struct SimplexResult {
    pub x: Vec<f64>,
    pub f: f64,
    pub evals: usize,
}

const ALPHA: f64 = 1.0;
const GAMMA: f64 = 2.0;
const RHO: f64 = 0.5;
const SIGMA: f64 = 0.5;

/// A step that would not move its coordinate (zero, or lost to rounding) becomes
/// this fraction of `max(|x0[k]|, 1)`.
const TINY_STEP: f64 = 1e-4;

/// Minimises `f` from `x0`. The initial simplex is x0 and x0 + steps\[k\]·e_k for each
/// k (or x0 − steps\[k\]·e_k when the + vertex would leave \[lo, hi\]; when both would,
/// the farther bound of that coordinate; a zero step is replaced by a tiny one,
/// 10⁻⁴·max(|x0\[k\]|, 1)). Coordinates with `lo[k] == hi[k]` are fixed at
/// that value and not searched.
///
/// Points outside the box \[lo, hi\] (per coordinate; a NaN or infinite coordinate is
/// outside) cost +∞ without calling `f`; `f` may itself return +∞ or NaN (treated as
/// +∞). x0 is clamped into the box first. Returns the best point seen (never worse
/// than x0's cost); its cost is +∞ when no evaluated point had a finite cost, or when
/// `max_evals` is 0 and nothing was evaluated (the result is then x0 clamped). A cost
/// of −∞ stops the search at once.
///
/// `f` is called at most `opts.max_evals` times, never twice in a row at the same
/// point. Allocates a few vectors of (n + 1)·n numbers per call, nothing per
/// evaluation.
///
/// # Panics
///
/// On a programming error: when `steps`, `lo` or `hi` has not the length of `x0`,
/// when `lo[k] > hi[k]` or a bound is NaN, or when a step is not finite.
pub fn minimize(
    mut f: impl FnMut(&[f64]) -> f64,
    x0: &[f64],
    steps: &[f64],
    lo: &[f64],
    hi: &[f64],
    opts: &SimplexOptions,
) -> SimplexResult {
    let n = x0.len();
    assert!(
        steps.len() == n && lo.len() == n && hi.len() == n,
        "simplex::minimize: x0, steps, lo and hi must have one length (got {}, {}, {}, {})",
        n,
        steps.len(),
        lo.len(),
        hi.len()
    );
    for k in 0..n {
        assert!(
            lo[k] <= hi[k],
            "simplex::minimize: bounds of coordinate {k} are empty or NaN: [{}, {}]",
            lo[k],
            hi[k]
        );
        assert!(
            steps[k].is_finite(),
            "simplex::minimize: step of coordinate {k} is not finite: {}",
            steps[k]
        );
    }
    let start: Vec<f64> = (0..n).map(|k| x0[k].clamp(lo[k], hi[k])).collect();
    let mut eval = Evaluator {
        f: &mut f,
        lo,
        hi,
        max_evals: opts.max_evals,
        evals: 0,
        best_x: start.clone(),
        best_f: f64::INFINITY,
        last_x: vec![0.0; n],
        last_f: None,
    };
    // `None` only says the budget ran out; the best point is in `eval` either way.
    let _ = search(&mut eval, &start, steps, opts);
    SimplexResult {
        x: eval.best_x,
        f: eval.best_f,
        evals: eval.evals,
    }
}

/// Counts and filters the calls of the cost function, remembering the best point.
struct Evaluator<'a, F> {
    f: F,
    lo: &'a [f64],
    hi: &'a [f64],
    max_evals: usize,
    evals: usize,
    best_x: Vec<f64>,
    best_f: f64,
    /// The point of the latest call and its cost (`None` before the first).
    last_x: Vec<f64>,
    last_f: Option<f64>,
}

impl<F: FnMut(&[f64]) -> f64> Evaluator<'_, F> {
    /// The cost of `x` (+∞ outside the box or for NaN), or `None` once the budget is
    /// spent: nothing can improve after that, so the search stops.
    fn cost(&mut self, x: &[f64]) -> Option<f64> {
        if self.evals >= self.max_evals {
            return None;
        }
        let inside = x
            .iter()
            .zip(self.lo.iter().zip(self.hi))
            .all(|(&v, (&l, &h))| v.is_finite() && v >= l && v <= h);
        if !inside {
            return Some(f64::INFINITY);
        }
        if let Some(last) = self.last_f {
            if x == &self.last_x[..] {
                return Some(last);
            }
        }
        let y = (self.f)(x);
        self.evals += 1;
        let y = if y.is_nan() { f64::INFINITY } else { y };
        self.last_x.copy_from_slice(x);
        self.last_f = Some(y);
        if y < self.best_f {
            self.best_f = y;
            self.best_x.copy_from_slice(x);
        }
        Some(y)
    }
}

/// The coordinate of the initial vertex along axis k (see [`minimize`]).
fn initial_coordinate(x: f64, step: f64, lo: f64, hi: f64) -> f64 {
    let s = if x + step == x {
        TINY_STEP * x.abs().max(1.0)
    } else {
        step
    };
    let inside = |v: f64| v >= lo && v <= hi && v != x;
    if inside(x + s) {
        x + s
    } else if inside(x - s) {
        x - s
    } else if hi - x >= x - lo {
        hi
    } else {
        lo
    }
}

/// Indices of the best, worst and second-worst vertices (the second worst is the best
/// when there are only two). Costs are never NaN.
fn extremes(fv: &[f64]) -> (usize, usize, usize) {
    let mut best = 0;
    for (i, &y) in fv.iter().enumerate() {
        if y < fv[best] {
            best = i;
        }
    }
    let mut worst = if best == 0 { 1 } else { 0 };
    for (i, &y) in fv.iter().enumerate() {
        if i != best && y > fv[worst] {
            worst = i;
        }
    }
    let mut second = best;
    for (i, &y) in fv.iter().enumerate() {
        if i != best && i != worst && (second == best || y > fv[second]) {
            second = i;
        }
    }
    (best, worst, second)
}

/// `out[k] = c[k] + t · (c[k] − w[k])` on the free coordinates (the others keep
/// their fixed values).
fn along(out: &mut [f64], c: &[f64], w: &[f64], t: f64, free: &[usize]) {
    for &k in free {
        out[k] = c[k] + t * (c[k] - w[k]);
    }
}

/// The search proper; `None` when the evaluation budget ran out.
fn search<F: FnMut(&[f64]) -> f64>(
    eval: &mut Evaluator<'_, F>,
    start: &[f64],
    steps: &[f64],
    opts: &SimplexOptions,
) -> Option<()> {
    let n = start.len();
    let (lo, hi) = (eval.lo, eval.hi);
    let free: Vec<usize> = (0..n).filter(|&k| lo[k] < hi[k]).collect();
    let m = free.len();

    let f0 = eval.cost(start)?;
    if m == 0 || f0 == f64::NEG_INFINITY {
        return Some(());
    }

    // Vertex i occupies simplex[i * n..(i + 1) * n]; fixed coordinates keep their value
    // in every vertex and trial point.
    let mut simplex = Vec::with_capacity((m + 1) * n);
    let mut fv = Vec::with_capacity(m + 1);
    let mut scale = vec![0.0; n];
    simplex.extend_from_slice(start);
    fv.push(f0);
    for &k in &free {
        let row = simplex.len();
        simplex.extend_from_slice(start);
        let v = initial_coordinate(start[k], steps[k], lo[k], hi[k]);
        simplex[row + k] = v;
        scale[k] = (v - start[k]).abs();
        let y = eval.cost(&simplex[row..row + n])?;
        fv.push(y);
        if y == f64::NEG_INFINITY {
            return Some(());
        }
    }

    let mut centroid = start.to_vec();
    let mut reflected = start.to_vec();
    let mut trial = start.to_vec();
    loop {
        let (ib, iw, isw) = extremes(&fv);
        let (fb, fw) = (fv[ib], fv[iw]);
        if fb == f64::NEG_INFINITY {
            return Some(());
        }
        // Equal costs (all +∞ included) have converged; a finite best with an
        // infinite worst has not.
        let costs_agree = fw == fb
            || (fw.is_finite()
                && fw - fb <= opts.ftol * 0.5 * (fb.abs() + fw.abs()) + opts.abs_tol);
        if costs_agree {
            return Some(());
        }
        let best = &simplex[ib * n..(ib + 1) * n];
        let small = (0..=m).all(|i| {
            let v = &simplex[i * n..(i + 1) * n];
            free.iter()
                .all(|&k| (v[k] - best[k]).abs() <= opts.xtol * scale[k])
        });
        if small {
            return Some(());
        }

        for &k in &free {
            let sum: f64 = (0..=m)
                .filter(|&i| i != iw)
                .map(|i| simplex[i * n + k])
                .sum();
            centroid[k] = sum / m as f64;
        }
        let worst = iw * n..(iw + 1) * n;

        along(
            &mut reflected,
            &centroid,
            &simplex[worst.clone()],
            ALPHA,
            &free,
        );
        let fr = eval.cost(&reflected)?;
        let shrink = if fr < fb {
            along(&mut trial, &centroid, &simplex[worst.clone()], GAMMA, &free);
            let fe = eval.cost(&trial)?;
            if fe < fr {
                simplex[worst].copy_from_slice(&trial);
                fv[iw] = fe;
            } else {
                simplex[worst].copy_from_slice(&reflected);
                fv[iw] = fr;
            }
            false
        } else if fr < fv[isw] {
            simplex[worst].copy_from_slice(&reflected);
            fv[iw] = fr;
            false
        } else if fr < fw {
            // Outside contraction: halfway from the centroid to the reflected point.
            along(
                &mut trial,
                &centroid,
                &simplex[worst.clone()],
                RHO * ALPHA,
                &free,
            );
            let fc = eval.cost(&trial)?;
            if fc <= fr {
                simplex[worst].copy_from_slice(&trial);
                fv[iw] = fc;
                false
            } else {
                true
            }
        } else {
            // Inside contraction: halfway from the centroid to the worst vertex.
            along(&mut trial, &centroid, &simplex[worst.clone()], -RHO, &free);
            let fc = eval.cost(&trial)?;
            if fc < fw {
                simplex[worst].copy_from_slice(&trial);
                fv[iw] = fc;
                false
            } else {
                true
            }
        };

        if shrink {
            for i in (0..=m).filter(|&i| i != ib) {
                let mut moved = false;
                for &k in &free {
                    let b = simplex[ib * n + k];
                    let v = simplex[i * n + k];
                    trial[k] = b + SIGMA * (v - b);
                    moved |= trial[k] != v;
                }
                if moved {
                    fv[i] = eval.cost(&trial)?;
                    simplex[i * n..(i + 1) * n].copy_from_slice(&trial);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tight(max_evals: usize) -> SimplexOptions {
        SimplexOptions {
            max_evals,
            ftol: 1e-12,
            abs_tol: 1e-15,
            xtol: 1e-7,
        }
    }

    fn rosenbrock(x: &[f64]) -> f64 {
        100.0 * (x[1] - x[0] * x[0]).powi(2) + (1.0 - x[0]).powi(2)
    }

    /// A weighted quadratic bowl centred on `c`.
    fn bowl(c: &[f64]) -> impl Fn(&[f64]) -> f64 + '_ {
        move |x: &[f64]| {
            x.iter()
                .zip(c)
                .enumerate()
                .map(|(k, (&v, &ck))| (1.0 + k as f64) * (v - ck).powi(2))
                .sum()
        }
    }

    /// xorshift64*, for reproducible pseudo-random numbers in [0, 1).
    fn rng(seed: u64) -> impl FnMut() -> f64 {
        let mut s = seed.max(1);
        move || {
            s ^= s >> 12;
            s ^= s << 25;
            s ^= s >> 27;
            (s.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    fn assert_near(x: &[f64], want: &[f64], tol: f64) {
        for (k, (&a, &b)) in x.iter().zip(want).enumerate() {
            assert!(
                (a - b).abs() <= tol,
                "coordinate {k}: {a} vs {b} (x = {x:?})"
            );
        }
    }

    #[test]
    fn shifted_quadratic_3d() {
        let c = [1.5, -2.0, 0.7];
        let r = minimize(
            bowl(&c),
            &[0.0; 3],
            &[1.0; 3],
            &[-10.0; 3],
            &[10.0; 3],
            &tight(2000),
        );
        assert_near(&r.x, &c, 1e-3);
        assert!(r.evals < 2000, "{r:?}");
    }

    #[test]
    fn shifted_quadratic_8d() {
        let c = [1.5, -2.0, 0.7, 3.1, -0.4, 0.0, 2.2, -1.1];
        let r = minimize(
            bowl(&c),
            &[0.0; 8],
            &[1.0; 8],
            &[-10.0; 8],
            &[10.0; 8],
            &tight(10_000),
        );
        assert_near(&r.x, &c, 1e-3);
    }

    #[test]
    fn default_options_get_close_on_a_quadratic() {
        let c = [0.3, -0.2, 0.1];
        let r = minimize(
            bowl(&c),
            &[0.0; 3],
            &[0.5; 3],
            &[-1.0; 3],
            &[1.0; 3],
            &SimplexOptions::default(),
        );
        assert!(r.evals <= 200);
        assert_near(&r.x, &c, 0.05);
    }

    #[test]
    fn rosenbrock_2d() {
        let r = minimize(
            rosenbrock,
            &[-1.2, 1.0],
            &[0.5, 0.5],
            &[-5.0; 2],
            &[5.0; 2],
            &tight(2000),
        );
        assert_near(&r.x, &[1.0, 1.0], 1e-2);
        assert!(r.evals <= 2000);
    }

    #[test]
    fn minimum_on_the_boundary() {
        // Unconstrained minimum at (3, −1); the box stops the first coordinate at 2.
        let (lo, hi) = ([-5.0, -5.0], [2.0, 5.0]);
        let r = minimize(
            |x: &[f64]| {
                assert!(x[0] >= lo[0] && x[0] <= hi[0] && x[1] >= lo[1] && x[1] <= hi[1]);
                (x[0] - 3.0).powi(2) + 2.0 * (x[1] + 1.0).powi(2)
            },
            &[0.0, 0.0],
            &[1.0, 1.0],
            &lo,
            &hi,
            &tight(2000),
        );
        assert_near(&r.x, &[2.0, -1.0], 1e-3);
    }

    #[test]
    fn start_outside_the_box_is_clamped() {
        let r = minimize(
            |x: &[f64]| (x[0] - 0.5).powi(2) + x[1].powi(2),
            &[7.0, -9.0],
            &[0.3, 0.3],
            &[-1.0, -1.0],
            &[1.0, 1.0],
            &tight(1000),
        );
        assert_near(&r.x, &[0.5, 0.0], 1e-3);
    }

    #[test]
    fn infinite_on_half_the_space() {
        // +∞ left of x0 = 0: the first step goes there on purpose (negative step).
        let cost = |x: &[f64]| {
            if x[0] < 0.0 {
                f64::INFINITY
            } else {
                (x[0] - 1.0).powi(2) + (x[1] - 2.0).powi(2)
            }
        };
        let inf = [f64::NEG_INFINITY; 2];
        let sup = [f64::INFINITY; 2];
        let r = minimize(cost, &[0.2, 0.0], &[-1.0, 1.0], &inf, &sup, &tight(2000));
        assert_near(&r.x, &[1.0, 2.0], 1e-3);

        // The minimum on the edge of the infinite region.
        let edge = |x: &[f64]| {
            if x[0] < 0.0 {
                f64::INFINITY
            } else {
                (x[0] + 1.0).powi(2) + (x[1] - 2.0).powi(2)
            }
        };
        let r = minimize(edge, &[0.5, 0.0], &[-1.0, 1.0], &inf, &sup, &tight(2000));
        assert_near(&r.x, &[0.0, 2.0], 1e-3);
    }

    #[test]
    fn only_the_best_vertex_is_finite() {
        // Finite only at x0 itself: the simplex must shrink onto x0 and stop on xtol,
        // not wander until the (huge) budget is spent.
        let x0 = [0.3, -0.7, 1.1];
        let r = minimize(
            |x: &[f64]| if x == x0 { 5.0 } else { f64::INFINITY },
            &x0,
            &[0.1; 3],
            &[-2.0; 3],
            &[2.0; 3],
            &SimplexOptions {
                max_evals: 1_000_000,
                ..SimplexOptions::default()
            },
        );
        assert_eq!((r.x.as_slice(), r.f), (&x0[..], 5.0));
        assert!(r.evals < 100, "{r:?}");
    }

    #[test]
    fn budget_is_respected_and_reported() {
        for max_evals in [0, 1, 2, 3, 4, 5, 17, 50, 150] {
            let mut calls = 0;
            let r = minimize(
                |x: &[f64]| {
                    calls += 1;
                    rosenbrock(x)
                },
                &[-1.2, 1.0],
                &[0.5, 0.5],
                &[-5.0; 2],
                &[5.0; 2],
                &SimplexOptions {
                    max_evals,
                    ftol: 0.0,
                    abs_tol: 0.0,
                    xtol: 0.0,
                },
            );
            assert_eq!(r.evals, calls);
            assert_eq!(calls, max_evals, "the tolerances cannot stop it first");
            if max_evals == 0 {
                assert_eq!((r.x.as_slice(), r.f), (&[-1.2, 1.0][..], f64::INFINITY));
            } else {
                assert_eq!(r.f, rosenbrock(&r.x));
            }
        }
        // A tight box, so that many trial points fall outside and are free.
        for max_evals in [1, 7, 40, 400] {
            let mut calls = 0;
            let r = minimize(
                |x: &[f64]| {
                    calls += 1;
                    x.iter().map(|v| (v - 3.0).powi(2)).sum()
                },
                &[0.0; 4],
                &[1.0; 4],
                &[-0.1; 4],
                &[0.1; 4],
                &tight(max_evals),
            );
            assert_eq!(r.evals, calls);
            assert!(calls <= max_evals);
        }
    }

    #[test]
    fn always_nan_terminates_at_x0() {
        let mut calls = 0;
        let x0 = [0.5, -0.25, 2.0, 1.0];
        let r = minimize(
            |_: &[f64]| {
                calls += 1;
                f64::NAN
            },
            &x0,
            &[0.1; 4],
            &[-3.0; 4],
            &[3.0; 4],
            &SimplexOptions {
                max_evals: usize::MAX,
                ..SimplexOptions::default()
            },
        );
        assert_eq!(r.x, x0);
        assert_eq!(r.f, f64::INFINITY);
        assert_eq!(r.evals, calls);
        assert_eq!(calls, 5, "the initial simplex only");
    }

    #[test]
    fn never_worse_than_the_start() {
        let mut next = rng(7);
        for trial in 0..200 {
            let n = 1 + trial % 6;
            let seed = (next() * 1e9) as u64;
            // A rough, non-smooth, partly infinite cost.
            let cost = move |x: &[f64]| {
                let mut s = 0.0;
                for (k, &v) in x.iter().enumerate() {
                    let q = (v * 7.0 + k as f64 + seed as f64 * 1e-9).sin();
                    s += v.abs() + (q * 3.0).floor();
                }
                if s > 4.0 {
                    f64::INFINITY
                } else if s < -100.0 {
                    f64::NAN
                } else {
                    s
                }
            };
            let x0: Vec<f64> = (0..n).map(|_| 2.0 * next() - 1.0).collect();
            let steps: Vec<f64> = (0..n).map(|_| next() - 0.5).collect();
            let f0 = cost(&x0);
            let mut previous: Option<Vec<f64>> = None;
            let r = minimize(
                |x: &[f64]| {
                    assert_ne!(previous.as_deref(), Some(x), "same point twice in a row");
                    previous = Some(x.to_vec());
                    cost(x)
                },
                &x0,
                &steps,
                &vec![-1.0; n],
                &vec![1.0; n],
                &SimplexOptions {
                    max_evals: 20 + trial,
                    ..SimplexOptions::default()
                },
            );
            let fx = cost(&r.x);
            assert!(r.f <= f0 || f0.is_nan(), "trial {trial}: {} > {f0}", r.f);
            assert!(fx == r.f || (fx.is_nan() && r.f == f64::INFINITY));
            assert!(r.evals <= 20 + trial);
        }
    }

    #[test]
    fn zero_dimensions() {
        let mut calls = 0;
        let r = minimize(
            |x: &[f64]| {
                calls += 1;
                assert!(x.is_empty());
                42.0
            },
            &[],
            &[],
            &[],
            &[],
            &SimplexOptions::default(),
        );
        assert_eq!(
            r,
            SimplexResult {
                x: vec![],
                f: 42.0,
                evals: 1
            }
        );
        assert_eq!(calls, 1);
    }

    #[test]
    fn fixed_coordinates_and_zero_steps() {
        let c = [0.4, 9.0, -0.3];
        let r = minimize(
            |x: &[f64]| {
                assert_eq!(x[1], 1.5, "the fixed coordinate never moves");
                bowl(&c)(x)
            },
            &[0.0, 1.5, 0.0],
            &[0.0, 1.0, 0.2],
            &[-1.0, 1.5, -1.0],
            &[1.0, 1.5, 1.0],
            &tight(2000),
        );
        assert_near(&r.x, &[0.4, 1.5, -0.3], 1e-3);
    }

    #[test]
    fn steps_wider_than_the_box() {
        let r = minimize(
            |x: &[f64]| (x[0] - 0.01).powi(2) + (x[1] + 0.02).powi(2),
            &[0.0, 0.0],
            &[10.0, -10.0],
            &[-0.05, -0.1],
            &[0.1, 0.05],
            &tight(1000),
        );
        assert_near(&r.x, &[0.01, -0.02], 1e-4);
    }

    #[test]
    fn minus_infinity_stops_at_once() {
        let r = minimize(
            |x: &[f64]| if x[0] > 0.5 { f64::NEG_INFINITY } else { 1.0 },
            &[0.0, 0.0],
            &[1.0, 1.0],
            &[-2.0; 2],
            &[2.0; 2],
            &SimplexOptions::default(),
        );
        assert_eq!((r.x, r.f, r.evals), (vec![1.0, 0.0], f64::NEG_INFINITY, 2));
    }

    #[test]
    #[should_panic(expected = "one length")]
    fn mismatched_lengths_panic() {
        minimize(
            |_: &[f64]| 0.0,
            &[0.0; 3],
            &[1.0; 2],
            &[-1.0; 3],
            &[1.0; 3],
            &SimplexOptions::default(),
        );
    }

    #[test]
    #[should_panic(expected = "bounds of coordinate 1")]
    fn empty_box_panics() {
        minimize(
            |_: &[f64]| 0.0,
            &[0.0; 2],
            &[1.0; 2],
            &[-1.0, 1.0],
            &[1.0, -1.0],
            &SimplexOptions::default(),
        );
    }
}
