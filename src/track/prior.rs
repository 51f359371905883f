//! A prior on the pose: how usual a body's joint angles are, learned from motion
//! capture.
//!
//! One silhouette leaves much of a pose open: a limb bent towards the camera or away
//! from it, an upper arm or thigh twisted about its own axis, the pelvis tipped with
//! the spine bent back to make up for it. Among poses that explain the silhouettes
//! equally well, people mostly hold the usual ones. The prior is a Gaussian over 26
//! of the 30 motion parameters (the trunk's pitch and roll and every joint angle;
//! not the root's position or heading), learned from captured poses and their
//! mirror images (left and right exchanged, so it favours neither side), at most
//! 400 poses of each capture so that no long one outweighs the rest. Its cost is robust, `ν · ln(1 + d²/ν)` for the
//! squared Mahalanobis distance d², so a rare pose the silhouettes demand costs
//! a bounded amount more than a usual one.
//!
//! `monocap prior --mocap DIR -o prior.json` learns one from a folder of BVH files;
//! `monocap track --pose-prior prior.json` uses it instead of the built-in one,
//! which is weighed in by default (`--w-prior 20`; 0 for no prior). The built-in
//! prior (`pose_prior.json` next to this file) was learned from the captures in
//! `../shared/data/mocap` (README, "The pose prior").
//!
//! The prior also keeps 32 exemplars, typical whole poses among the captured ones
//! (the medoids of k-means clusters of the same poses), which the initialisation
//! tries as starting points beside the rest pose.
//!
//! The same captures give the shape the initialisation starts from
//! ([`typical_shape`], [`crate::body::params::TYPICAL_SHAPE`]).

use std::path::Path;
use std::sync::{Arc, OnceLock};

use anyhow::{bail, ensure, Context, Result};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::flips::exchange_sides;
use crate::body::params::{ix, Pose, ShapeValues, MOTION, MOTION_COUNT, SHAPE_COUNT};
use crate::motion::bvh::Bvh;
use crate::synth::{synthesize_with, Style, SynthOptions};

/// Format tag of a prior file.
pub const FORMAT: &str = "monocap.pose-prior/1";

/// The parameters the prior weighs (indices into a [`Pose`]): the trunk's pitch
/// and roll and every joint angle.
pub const PRIOR_PARAMS: [usize; PRIOR_DIMS] = {
    let mut p = [0; PRIOR_DIMS];
    p[0] = ix::ROOT_RX;
    p[1] = ix::ROOT_RZ;
    let mut k = 2;
    while k < PRIOR_DIMS {
        p[k] = k + 4;
        k += 1;
    }
    p
};

/// How many parameters the prior weighs.
pub const PRIOR_DIMS: usize = MOTION_COUNT - 4;

/// Degrees² added to each variance when learning: no angle is held tighter than a
/// few degrees, however still it was in the captures.
const MIN_VARIANCE: f64 = 9.0;

/// Captured poses used per capture at most (evenly spread), so a long capture does
/// not outweigh the others.
const POSES_PER_CAPTURE: usize = 400;

/// Exemplars kept ([`PosePrior::exemplar_poses`]).
const EXEMPLARS: usize = 32;

/// ν of the robust cost: about the number of parameters weighed, so a usual pose
/// (d² ≈ ν) sits where the cost begins to flatten.
const NU: f64 = PRIOR_DIMS as f64;

/// A Gaussian over [`PRIOR_PARAMS`].
#[derive(Clone, Debug)]
pub struct PosePrior {
    mean: [f64; PRIOR_DIMS],
    /// The inverse covariance, row-major.
    precision: [[f64; PRIOR_DIMS]; PRIOR_DIMS],
    /// Where it was learned (file names), for the record.
    sources: Vec<String>,
    /// Typical whole poses among the captured ones, over [`PRIOR_PARAMS`]
    /// ([`medoids`]).
    exemplars: Vec<[f64; PRIOR_DIMS]>,
}

/// The prior at a base pose, for poses that move a few of its parameters
/// ([`PosePrior::focus`]).
#[derive(Clone, Debug)]
pub struct PriorFocus {
    base: Pose,
    /// The moving parameters the prior weighs: (index in a pose, in the prior).
    dims: Vec<(usize, usize)>,
    /// P·d₀ for the base's offset d₀ from the mean.
    pull: [f64; PRIOR_DIMS],
    /// d₀².
    d2: f64,
}

/// The dot product of two offsets.
fn dot(a: &[f64; PRIOR_DIMS], b: &[f64; PRIOR_DIMS]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a * b).sum()
}

/// The robust cost of a squared distance: `ν · ln(1 + d²/ν)`.
fn robust(d2: f64) -> f64 {
    NU * (d2 / NU).ln_1p()
}

/// A prior as stored (JSON).
#[derive(Serialize, Deserialize)]
struct PriorFile {
    format: String,
    /// The parameters' names, in the order of `mean` and `precision`.
    params: Vec<String>,
    mean: Vec<f64>,
    precision: Vec<Vec<f64>>,
    sources: Vec<String>,
    /// Typical whole poses, each over `params` (absent from older files).
    #[serde(default)]
    exemplars: Vec<Vec<f64>>,
}

impl PosePrior {
    /// Learns the prior from captures' poses: at most [`POSES_PER_CAPTURE`] poses of
    /// each, evenly spread, and every pose also mirrored.
    pub fn learn(captures: &[Capture]) -> Result<PosePrior> {
        let mut samples: Vec<[f64; PRIOR_DIMS]> = Vec::new();
        for Capture { poses, .. } in captures {
            let step = poses.len().div_ceil(POSES_PER_CAPTURE).max(1);
            for pose in poses.iter().step_by(step) {
                samples.push(pick(pose));
                samples.push(pick(&exchange_sides(pose)));
            }
        }
        ensure!(
            samples.len() >= 2 * PRIOR_DIMS,
            "a pose prior needs at least {PRIOR_DIMS} captured poses, got {}",
            samples.len() / 2
        );
        let n = samples.len() as f64;
        let mut mean = [0.0; PRIOR_DIMS];
        for s in &samples {
            for (m, v) in mean.iter_mut().zip(s) {
                *m += v / n;
            }
        }
        let mut cov = DMatrix::<f64>::zeros(PRIOR_DIMS, PRIOR_DIMS);
        for s in &samples {
            let d = DVector::from_iterator(PRIOR_DIMS, s.iter().zip(&mean).map(|(v, m)| v - m));
            cov += &d * d.transpose() / n;
        }
        for i in 0..PRIOR_DIMS {
            cov[(i, i)] += MIN_VARIANCE;
        }
        let sd: Vec<f64> = (0..PRIOR_DIMS).map(|i| cov[(i, i)].sqrt()).collect();
        let inv = cov
            .cholesky()
            .context("the captured poses' covariance is not positive definite")?
            .inverse();
        let mut precision = [[0.0; PRIOR_DIMS]; PRIOR_DIMS];
        for (i, row) in precision.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = inv[(i, j)];
            }
        }
        let exemplars = medoids(&samples, &sd, EXEMPLARS);
        Ok(PosePrior {
            mean,
            precision,
            sources: captures.iter().map(|c| c.name.clone()).collect(),
            exemplars,
        })
    }

    /// The prior built into monocap (see the module's documentation).
    pub fn builtin() -> Arc<PosePrior> {
        static BUILTIN: OnceLock<Arc<PosePrior>> = OnceLock::new();
        BUILTIN
            .get_or_init(|| {
                let p = PosePrior::from_json(include_str!("pose_prior.json"))
                    .expect("the built-in pose prior parses");
                Arc::new(p)
            })
            .clone()
    }

    /// The exemplars: typical whole poses of the captures, over [`PRIOR_PARAMS`]
    /// (none in a file written before they were added).
    pub fn exemplars(&self) -> &[[f64; PRIOR_DIMS]] {
        &self.exemplars
    }

    /// `base` with the weighed angles of each exemplar in turn (its root position
    /// and heading kept): starting points for a search that the rest pose is too
    /// far from ([`crate::track::tracker::TrackOptions::exemplar_starts`]).
    pub fn exemplar_poses(&self, base: &Pose) -> Vec<Pose> {
        self.exemplars
            .iter()
            .map(|e| {
                let mut p = *base;
                for (&i, v) in PRIOR_PARAMS.iter().zip(e) {
                    p[i] = *v;
                }
                p
            })
            .collect()
    }

    /// The captures it was learned from.
    pub fn sources(&self) -> &[String] {
        &self.sources
    }

    /// `pose`'s weighed angles less the captured poses' mean.
    fn offset(&self, pose: &Pose) -> [f64; PRIOR_DIMS] {
        let mut d = pick(pose);
        for (d, m) in d.iter_mut().zip(&self.mean) {
            *d -= m;
        }
        d
    }

    /// The squared Mahalanobis distance of `pose` from the captured poses' mean.
    pub fn distance2(&self, pose: &Pose) -> f64 {
        let d = self.offset(pose);
        dot(&d, &self.pull(&d)).max(0.0)
    }

    /// P·d: the precision matrix times an offset from the mean.
    fn pull(&self, d: &[f64; PRIOR_DIMS]) -> [f64; PRIOR_DIMS] {
        let mut g = [0.0; PRIOR_DIMS];
        for (g, row) in g.iter_mut().zip(&self.precision) {
            *g = dot(row, d);
        }
        g
    }

    /// The prior's cost of `pose` per unit of weight: `ν · ln(1 + d²/ν)`.
    pub fn cost(&self, pose: &Pose) -> f64 {
        robust(self.distance2(pose))
    }

    /// Prepares [`PosePrior::focused_cost`] for poses that differ from `base` in
    /// `params` alone (the search over one group of parameters).
    pub fn focus(&self, base: &Pose, params: &[usize]) -> PriorFocus {
        let d = self.offset(base);
        let pull = self.pull(&d);
        let d2 = dot(&d, &pull);
        let dims = params
            .iter()
            .filter_map(|&k| PRIOR_PARAMS.iter().position(|&q| q == k).map(|i| (k, i)))
            .collect();
        PriorFocus {
            base: *base,
            dims,
            pull,
            d2,
        }
    }

    /// [`PosePrior::cost`] of `pose`, which differs from the focus's base in its
    /// parameters alone: `d² = d₀² + 2δ·Pd₀ + δᵀPδ` over the few that move, so a
    /// group's search pays for its own parameters, not for all 26.
    pub fn focused_cost(&self, focus: &PriorFocus, pose: &Pose) -> f64 {
        let mut d2 = focus.d2;
        for &(k, i) in &focus.dims {
            let di = pose[k] - focus.base[k];
            if di == 0.0 {
                continue;
            }
            let mut s = 2.0 * focus.pull[i];
            for &(l, j) in &focus.dims {
                s += self.precision[i][j] * (pose[l] - focus.base[l]);
            }
            d2 += di * s;
        }
        robust(d2.max(0.0))
    }

    /// Reads a prior file (as written by [`PosePrior::write`]).
    pub fn read(path: &Path) -> Result<PosePrior> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("reading the pose prior {}", path.display()))?;
        PosePrior::from_json(&text).with_context(|| format!("pose prior {}", path.display()))
    }

    pub(crate) fn from_json(text: &str) -> Result<PosePrior> {
        let f: PriorFile = serde_json::from_str(text).context("not a pose prior (JSON)")?;
        if f.format != FORMAT {
            bail!("format {:?}: expected {FORMAT:?}", f.format);
        }
        let names: Vec<&str> = PRIOR_PARAMS.iter().map(|&i| MOTION[i].name).collect();
        if f.params != names {
            bail!("params: expected {}", names.join(", "));
        }
        ensure!(
            f.mean.len() == PRIOR_DIMS
                && f.precision.len() == PRIOR_DIMS
                && f.precision.iter().all(|r| r.len() == PRIOR_DIMS),
            "mean and precision: expected {PRIOR_DIMS} values and {PRIOR_DIMS}×{PRIOR_DIMS}"
        );
        ensure!(
            f.mean
                .iter()
                .chain(f.precision.iter().flatten())
                .all(|v| v.is_finite()),
            "mean and precision: expected finite numbers"
        );
        ensure!(
            f.exemplars
                .iter()
                .all(|e| e.len() == PRIOR_DIMS && e.iter().all(|v| v.is_finite())),
            "exemplars: expected poses of {PRIOR_DIMS} finite values"
        );
        let exemplars = f
            .exemplars
            .iter()
            .map(|e| {
                let mut x = [0.0; PRIOR_DIMS];
                x.copy_from_slice(e);
                x
            })
            .collect();
        let mut mean = [0.0; PRIOR_DIMS];
        mean.copy_from_slice(&f.mean);
        let mut precision = [[0.0; PRIOR_DIMS]; PRIOR_DIMS];
        for (row, r) in precision.iter_mut().zip(&f.precision) {
            row.copy_from_slice(r);
        }
        let p = PosePrior {
            mean,
            precision,
            sources: f.sources,
            exemplars,
        };
        // A precision that is not positive definite would reward some poses
        // without bound.
        let m = DMatrix::from_fn(PRIOR_DIMS, PRIOR_DIMS, |i, j| p.precision[i][j]);
        ensure!(
            m.cholesky().is_some(),
            "precision: expected a positive definite matrix"
        );
        Ok(p)
    }

    /// Writes the prior as JSON.
    pub fn write(&self, path: &Path) -> Result<()> {
        let f = PriorFile {
            format: FORMAT.to_string(),
            params: PRIOR_PARAMS
                .iter()
                .map(|&i| MOTION[i].name.to_string())
                .collect(),
            mean: self.mean.to_vec(),
            precision: self.precision.iter().map(|r| r.to_vec()).collect(),
            sources: self.sources.clone(),
            exemplars: self.exemplars.iter().map(|e| e.to_vec()).collect(),
        };
        let text = serde_json::to_string_pretty(&f)?;
        std::fs::write(path, text + "\n").with_context(|| format!("writing {}", path.display()))
    }
}

/// A capture retargeted to the model, as `monocap synth` retargets it.
#[derive(Clone, Debug)]
pub struct Capture {
    /// The BVH file's name.
    pub name: String,
    /// The model's pose on every frame (at 30 frames/s).
    pub poses: Vec<Pose>,
    /// The performer's shape.
    pub shape: ShapeValues,
}

impl Capture {
    /// The source the capture comes from: its name up to the first `_`
    /// (`bandai_walk_normal_001.bvh` → `bandai`). Captures of one source are taken
    /// to share performers.
    pub fn source(&self) -> &str {
        self.name.split('_').next().unwrap_or(&self.name)
    }
}

/// [`Capture`] of one BVH file.
pub fn capture(bvh: &Bvh, name: &str) -> Result<Capture> {
    // Rendered small and thrown away: only the poses and the shape are wanted.
    let opts = SynthOptions {
        width: 32,
        height: 24,
        style: Style::Silhouette,
        ..SynthOptions::default()
    };
    let truth = synthesize_with(bvh, name, &opts, |_| Ok(()))?;
    let poses = truth
        .frames
        .iter()
        .map(|f| {
            Pose::try_from(f.params.as_slice())
                .map_err(|_| anyhow::anyhow!("{name}: a pose of {} values", f.params.len()))
        })
        .collect::<Result<_>>()?;
    let shape = ShapeValues::try_from(truth.shape.values.as_slice())
        .map_err(|_| anyhow::anyhow!("{name}: a shape of {} values", truth.shape.values.len()))?;
    Ok(Capture {
        name: name.to_string(),
        poses,
        shape,
    })
}

/// The typical performer's shape among `captures`: for each source
/// ([`Capture::source`]), the median of each shape value over its captures, then
/// the mean over the sources, so that a source with many captures of the same
/// performers counts once. `None` without captures.
pub fn typical_shape(captures: &[&Capture]) -> Option<ShapeValues> {
    let mut sources: Vec<&str> = captures.iter().map(|c| c.source()).collect();
    sources.sort_unstable();
    sources.dedup();
    if sources.is_empty() {
        return None;
    }
    let mut shape = [0.0; SHAPE_COUNT];
    for source in &sources {
        for (k, v) in shape.iter_mut().enumerate() {
            let mut values: Vec<f64> = captures
                .iter()
                .filter(|c| c.source() == *source)
                .map(|c| c.shape[k])
                .collect();
            values.sort_by(f64::total_cmp);
            let n = values.len();
            let median = if n % 2 == 1 {
                values[n / 2]
            } else {
                (values[n / 2 - 1] + values[n / 2]) / 2.0
            };
            *v += median / sources.len() as f64;
        }
    }
    Some(shape)
}

/// Each BVH file in `dir` (sorted by name), retargeted ([`capture`]).
pub fn captures_in(dir: &Path) -> Result<Vec<Capture>> {
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("bvh")))
        .collect();
    files.sort();
    ensure!(!files.is_empty(), "no BVH files in {}", dir.display());
    files
        .iter()
        .map(|f| {
            let name = f
                .file_name()
                .unwrap_or_default()
                .to_string_lossy()
                .to_string();
            let bvh = Bvh::read(f).with_context(|| format!("reading {}", f.display()))?;
            capture(&bvh, &name).with_context(|| format!("posing {name}"))
        })
        .collect()
}

/// Medoids of `k` clusters of `samples`: k-means (30 rounds of Lloyd's, from a
/// k-means++ start drawn with a fixed seed, so the same captures give the same
/// exemplars), each angle measured in units of its standard deviation `sd`; each
/// cluster is represented by its member nearest the centre, a pose that was
/// captured rather than an average of several.
fn medoids(samples: &[[f64; PRIOR_DIMS]], sd: &[f64], k: usize) -> Vec<[f64; PRIOR_DIMS]> {
    use rand::{RngExt, SeedableRng};
    if samples.is_empty() || k == 0 {
        return Vec::new();
    }
    let z: Vec<[f64; PRIOR_DIMS]> = samples
        .iter()
        .map(|s| {
            let mut o = [0.0; PRIOR_DIMS];
            for i in 0..PRIOR_DIMS {
                o[i] = s[i] / sd[i];
            }
            o
        })
        .collect();
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let mut centres: Vec<[f64; PRIOR_DIMS]> = vec![z[rng.random_range(0..z.len())]];
    let mut near: Vec<f64> = z.iter().map(|x| dist2(x, &centres[0])).collect();
    while centres.len() < k.min(z.len()) {
        let total: f64 = near.iter().sum();
        let mut r = rng.random_range(0.0..total.max(1e-12));
        let mut pick = z.len() - 1;
        for (i, d) in near.iter().enumerate() {
            if r < *d {
                pick = i;
                break;
            }
            r -= d;
        }
        centres.push(z[pick]);
        for (n, x) in near.iter_mut().zip(&z) {
            *n = n.min(dist2(x, &z[pick]));
        }
    }
    let mut assign = vec![0usize; z.len()];
    for _ in 0..30 {
        for (a, x) in assign.iter_mut().zip(&z) {
            *a = nearest(&centres, x);
        }
        let mut sums = vec![[0.0; PRIOR_DIMS]; centres.len()];
        let mut counts = vec![0usize; centres.len()];
        for (a, x) in assign.iter().zip(&z) {
            counts[*a] += 1;
            for i in 0..PRIOR_DIMS {
                sums[*a][i] += x[i];
            }
        }
        for (c, (s, n)) in centres.iter_mut().zip(sums.iter().zip(&counts)) {
            if *n > 0 {
                for i in 0..PRIOR_DIMS {
                    c[i] = s[i] / *n as f64;
                }
            }
        }
    }
    centres.iter().map(|c| samples[nearest(&z, c)]).collect()
}

/// The index of the point of `points` nearest `p` (squared Euclidean distance, the
/// first among equals; 0 when there are none).
fn nearest(points: &[[f64; PRIOR_DIMS]], p: &[f64; PRIOR_DIMS]) -> usize {
    points
        .iter()
        .map(|q| dist2(q, p))
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(0, |(i, _)| i)
}

/// Squared Euclidean distance between two points of the prior's space.
fn dist2(a: &[f64; PRIOR_DIMS], b: &[f64; PRIOR_DIMS]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

fn pick(pose: &Pose) -> [f64; PRIOR_DIMS] {
    PRIOR_PARAMS.map(|i| pose[i])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::params::{ix, STANDARD_SHAPE};

    // Within a group the angles go x, z, y ([`MOTION`]).
    const SPINE_Y: usize = ix::SPINE + 2;
    const L_SHOULDER_X: usize = ix::L_SHOULDER;
    const L_SHOULDER_Z: usize = ix::L_SHOULDER + 1;
    const L_SHOULDER_Y: usize = ix::L_SHOULDER + 2;
    const R_SHOULDER_X: usize = ix::R_SHOULDER;
    const R_SHOULDER_Z: usize = ix::R_SHOULDER + 1;
    const L_HIP_X: usize = ix::L_HIP;
    const L_HIP_Y: usize = ix::L_HIP + 2;
    const R_HIP_X: usize = ix::R_HIP;
    const R_HIP_Y: usize = ix::R_HIP + 2;

    /// Poses of a walk-like swing: the thighs and arms swing in opposition, the
    /// knees and elbows bend a little, the twists stay near 0.
    fn swinging() -> Vec<Pose> {
        (0..200)
            .map(|k| {
                let t = k as f64 * 0.1;
                let mut p = [0.0; MOTION_COUNT];
                p[ix::ROOT_TZ] = 300.0;
                p[L_HIP_X] = 25.0 * t.sin();
                p[R_HIP_X] = -25.0 * t.sin();
                p[ix::L_KNEE] = 20.0 + 15.0 * (2.0 * t).sin();
                p[ix::R_KNEE] = 20.0 - 15.0 * (2.0 * t).sin();
                p[L_SHOULDER_X] = -15.0 * t.sin();
                p[R_SHOULDER_X] = 15.0 * t.sin();
                p[ix::L_ELBOW] = 15.0 + 5.0 * t.cos();
                p[ix::R_ELBOW] = 15.0 - 5.0 * t.cos();
                p[L_SHOULDER_Z] = 8.0;
                p[R_SHOULDER_Z] = 8.0;
                p[SPINE_Y] = 3.0 * (1.3 * t).sin();
                p
            })
            .collect()
    }

    fn learned() -> PosePrior {
        PosePrior::learn(&[named("walk", swinging())]).expect("learns")
    }

    #[test]
    fn a_usual_pose_costs_less_than_one_twisted_or_tipped() {
        let prior = learned();
        let usual = swinging()[37];
        let base = prior.cost(&usual);
        for (param, by) in [(L_SHOULDER_Y, 40.0), (R_HIP_Y, -30.0), (ix::ROOT_RX, 20.0)] {
            let mut odd = usual;
            odd[param] += by;
            assert!(
                prior.cost(&odd) > base + 5.0,
                "{} moved by {by}: {} against {base}",
                MOTION[param].name,
                prior.cost(&odd)
            );
        }
        // The root's position and heading are not weighed.
        let mut moved = usual;
        moved[ix::ROOT_TX] += 80.0;
        moved[ix::ROOT_RY] += 120.0;
        assert!((prior.cost(&moved) - base).abs() < 1e-9);
    }

    #[test]
    fn the_focused_cost_is_the_cost_while_only_its_parameters_move() {
        use crate::body::params::Group;
        let prior = PosePrior::builtin();
        let base = swinging()[23];
        for group in Group::ALL {
            let params: Vec<usize> = group.range().collect();
            let focus = prior.focus(&base, &params);
            assert!((prior.focused_cost(&focus, &base) - prior.cost(&base)).abs() < 1e-9);
            let mut moved = base;
            for (n, &k) in params.iter().enumerate() {
                moved[k] += 7.0 - 3.0 * n as f64;
            }
            let (fast, full) = (prior.focused_cost(&focus, &moved), prior.cost(&moved));
            assert!(
                (fast - full).abs() < 1e-9 * full.max(1.0),
                "{fast} against {full}"
            );
        }
    }

    #[test]
    fn the_cost_is_bounded_in_growth_and_favours_neither_side() {
        let prior = learned();
        let usual = swinging()[11];
        // Mirrored poses were learned too: a pose and its mirror image cost the same.
        let mirrored = exchange_sides(&usual);
        assert!(
            (prior.cost(&usual) - prior.cost(&mirrored)).abs() < 1e-6 * prior.cost(&usual).max(1.0)
        );
        // Robust: four times as far costs far less than sixteen times as much.
        let mut a = usual;
        a[ix::L_ELBOW] += 30.0;
        let mut b = usual;
        b[ix::L_ELBOW] += 120.0;
        let (ca, cb) = (
            prior.cost(&a) - prior.cost(&usual),
            prior.cost(&b) - prior.cost(&usual),
        );
        assert!(ca > 0.0 && cb > ca && cb < 8.0 * ca, "{ca} {cb}");
    }

    #[test]
    fn a_prior_survives_a_round_trip_through_its_file() {
        let prior = learned();
        let dir = std::env::temp_dir().join(format!("monocap-prior-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("prior.json");
        prior.write(&path).unwrap();
        let back = PosePrior::read(&path).unwrap();
        assert_eq!(back.sources(), ["walk"]);
        assert_eq!(back.exemplars().len(), prior.exemplars().len());
        for (a, b) in back.exemplars().iter().zip(prior.exemplars()) {
            assert!(
                a.iter().zip(b).all(|(a, b)| (a - b).abs() < 1e-9),
                "{a:?} {b:?}"
            );
        }
        for pose in swinging().iter().step_by(17) {
            assert!((back.cost(pose) - prior.cost(pose)).abs() < 1e-9 * prior.cost(pose).max(1.0));
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn the_exemplars_are_captured_poses_spread_over_them_the_same_each_time() {
        let prior = learned();
        let ex = prior.exemplars();
        assert_eq!(ex.len(), EXEMPLARS);
        assert_eq!(
            ex,
            learned().exemplars(),
            "the same captures, the same exemplars"
        );
        // Each one is a captured pose or its mirror image, not an average.
        let captured: Vec<[f64; PRIOR_DIMS]> = swinging()
            .iter()
            .flat_map(|p| [pick(p), pick(&exchange_sides(p))])
            .collect();
        for e in ex {
            assert!(captured.contains(e), "{e:?} was not captured");
        }
        // Spread over the swing: both thighs forward and back among them.
        let l_hip = PRIOR_PARAMS.iter().position(|&k| k == L_HIP_X).unwrap();
        let (lo, hi) = ex.iter().fold((0.0f64, 0.0f64), |(lo, hi), e| {
            (lo.min(e[l_hip]), hi.max(e[l_hip]))
        });
        assert!(
            lo < -20.0 && hi > 20.0,
            "the left thigh from {lo} to {hi} only"
        );
        // Placed as the base: root and heading kept, the angles the exemplar's.
        let mut base = [0.0; MOTION_COUNT];
        base[ix::ROOT_TZ] = -420.0;
        base[ix::ROOT_RY] = 75.0;
        let poses = prior.exemplar_poses(&base);
        assert_eq!(poses.len(), EXEMPLARS);
        assert_eq!(pick(&poses[3]), ex[3]);
        assert_eq!(
            (poses[3][ix::ROOT_TZ], poses[3][ix::ROOT_RY]),
            (-420.0, 75.0)
        );
        // The built-in prior has its own, and a file written before them reads
        // with none.
        assert_eq!(PosePrior::builtin().exemplars().len(), EXEMPLARS);
        let mut old: serde_json::Value =
            serde_json::from_str(include_str!("pose_prior.json")).expect("JSON");
        old.as_object_mut().unwrap().remove("exemplars");
        let old = PosePrior::from_json(&old.to_string()).expect("an older file reads");
        assert!(old.exemplars().is_empty());
    }

    #[test]
    fn bad_prior_files_are_refused_with_the_reason() {
        let good: serde_json::Value =
            serde_json::from_str(include_str!("pose_prior.json")).expect("JSON");
        let check = |edit: &dyn Fn(&mut serde_json::Value), want: &str| {
            let mut v = good.clone();
            edit(&mut v);
            let err = PosePrior::from_json(&v.to_string()).expect_err(want);
            assert!(format!("{err:#}").contains(want), "{err:#} lacks {want:?}");
        };
        check(
            &|v| v["format"] = "monocap.truth/1".into(),
            "expected \"monocap.pose-prior/1\"",
        );
        check(
            &|v| v["params"][3] = "l_knee".into(),
            "params: expected root_rx",
        );
        check(
            &|v| {
                v["mean"].as_array_mut().unwrap().pop();
            },
            "expected 26 values",
        );
        check(
            &|v| {
                for i in 0..PRIOR_DIMS {
                    v["precision"][i][i] = (-1.0).into();
                }
            },
            "positive definite",
        );
        check(
            &|v| {
                v["exemplars"][5].as_array_mut().unwrap().pop();
            },
            "exemplars: expected poses of 26",
        );
        assert!(PosePrior::from_json("[1, 2]").is_err());
        assert!(PosePrior::learn(&[named("one", swinging()[..3].to_vec())]).is_err());
    }

    /// A capture of the standard body.
    fn named(name: &str, poses: Vec<Pose>) -> Capture {
        Capture {
            name: name.to_string(),
            poses,
            shape: STANDARD_SHAPE,
        }
    }

    #[test]
    fn the_typical_shape_counts_each_source_once() {
        let with = |name: &str, torso: f64| Capture {
            shape: {
                let mut s = STANDARD_SHAPE;
                s[1] = torso;
                s
            },
            ..named(name, Vec::new())
        };
        let a = [
            with("a_1.bvh", 0.7),
            with("a_2.bvh", 0.8),
            with("a_3.bvh", 1.3),
        ];
        let b = with("b.bvh", 1.2);
        assert_eq!(b.source(), "b.bvh");
        assert_eq!(a[0].source(), "a");
        let all: Vec<&Capture> = a.iter().chain([&b]).collect();
        let shape = typical_shape(&all).expect("captures");
        // Source a's median 0.8, source b's 1.2: their mean, not the median of all.
        assert!((shape[1] - 1.0).abs() < 1e-12, "{shape:?}");
        assert!((shape[0] - 1.0).abs() < 1e-12);
        let even = [with("c_1.bvh", 0.7), with("c_2.bvh", 0.9)];
        let even: Vec<&Capture> = even.iter().collect();
        assert!((typical_shape(&even).expect("captures")[1] - 0.8).abs() < 1e-12);
        assert!(typical_shape(&[]).is_none());
    }

    #[test]
    fn the_built_in_prior_was_learned_from_the_nine_captures() {
        let prior = PosePrior::builtin();
        assert_eq!(prior.sources().len(), 9, "{:?}", prior.sources());
        // A body standing with its arms down is a usual pose; one with both
        // thighs twisted far out is not.
        let mut stand = [0.0; MOTION_COUNT];
        stand[ix::ROOT_TZ] = 300.0;
        stand[L_SHOULDER_Z] = 10.0;
        stand[R_SHOULDER_Z] = 10.0;
        let mut odd = stand;
        odd[L_HIP_Y] = 60.0;
        odd[R_HIP_Y] = 60.0;
        assert!(prior.cost(&odd) > prior.cost(&stand) + 10.0);
    }
}
