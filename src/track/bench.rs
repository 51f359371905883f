//! The accuracy benchmark (`monocap bench`): render clips of the body model driven by
//! real motion capture (`monocap synth --style color`), extract their silhouettes as
//! for any clip, track them, and compare with the capture.
//!
//! Joints compared: the 14 the capture and the model both define the same way — head,
//! shoulders, elbows, wrists, hips, knees, ankles and the neck — taken from the
//! capture's own forward kinematics (not from the model retargeted to it).
//!
//! - PCK@0.1: fraction of joints within 10% of the person's image height (the height
//!   of the true silhouette's bounding box in that frame);
//! - the same allowing a left/right swap of whole limbs (one view cannot tell them);
//! - mean 2D error in % of the person's image height;
//! - PA-MPJPE: mean 3D error after the per-frame similarity alignment, in mm;
//! - the same allowing whole-limb swaps and the body's depth mirror (`PA-amb`,
//!   [`metrics::pa_mpjpe_ambiguous`]): what is left is error no such choice explains;
//! - IoU of the model's silhouette with the true silhouette;
//! - lost frames: frames with a person whose PCK@0.1 (with swaps) is below 0.5.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result};
use image::RgbImage;

use super::metrics::{self, Accumulator};
use super::objective::{Evaluator, Target};
use super::prior::{captures_in, typical_shape, Capture, PosePrior};
use super::simplex::{minimize, SimplexOptions};
use super::tracker::{FrameInput, Track, TrackOptions, Tracker};
use crate::body::params::{
    ix, Pose, ShapeValues, MOTION, MOTION_COUNT, SHAPE_COUNT, STANDARD_SHAPE, TYPICAL_SHAPE,
};
use crate::body::skeleton::Joint;
use crate::body::{Body, Camera, Mask};
use crate::clip::write::Frame;
use crate::motion::bvh::Bvh;
use crate::motion::retarget::JointMap;
use crate::synth::{synthesize_with, Style, SynthOptions, Truth, TruthFrame};
use crate::vision::features::{compute, FeatureOptions};
use crate::vision::silhouette::{Segmenter, SilhouetteOptions};
use crate::vision::skin::SkinModel;

/// The joints compared.
pub const JOINTS: [Joint; 14] = [
    Joint::Neck,
    Joint::Head,
    Joint::LeftArm,
    Joint::LeftForeArm,
    Joint::LeftHand,
    Joint::RightArm,
    Joint::RightForeArm,
    Joint::RightHand,
    Joint::LeftUpLeg,
    Joint::LeftLeg,
    Joint::LeftFoot,
    Joint::RightUpLeg,
    Joint::RightLeg,
    Joint::RightFoot,
];

/// Left/right limb pairs, as indices into [`JOINTS`].
const PAIRS: [(&[usize], &[usize]); 2] = [(&[2, 3, 4], &[5, 6, 7]), (&[8, 9, 10], &[11, 12, 13])];

#[derive(Clone, Debug)]
pub struct BenchOptions {
    pub mocap_dir: PathBuf,
    /// Only files whose name contains this.
    pub filter: Option<String>,
    pub azimuths: Vec<f64>,
    /// Person-free lead-in frames, one clip per value.
    pub lead_in: Vec<usize>,
    pub duration_s: f64,
    pub width: u32,
    pub height: u32,
    pub fps: f64,
    pub fov_deg: f64,
    /// Track the true silhouettes instead of extracted ones.
    pub true_silhouettes: bool,
    /// Skip the initialisation: start from the true shape and pose on the first
    /// frame with the person (separates tracking errors from initialisation errors).
    pub oracle_init: bool,
    /// Give the initialisation the true shape (it fits the pose alone).
    pub oracle_shape: bool,
    /// Seed of the rendered clips' background and sensor noise
    /// ([`SynthOptions::seed`]): another seed renders the same motion with other
    /// noise, which shows how far the figures move by chance.
    pub seed: u64,
    /// Every this many frames with a person (0: never), compare the tracker's
    /// answer with the truth's basin under the fitted shape ([`BasinProbe`]).
    pub basin_probe: usize,
    /// Which pose prior the tracker weighs in ([`PriorChoice`]).
    pub prior: PriorChoice,
    /// Which shape the initialisation starts from ([`StartShape`]).
    pub start_shape: StartShape,
    pub track: TrackOptions,
}

/// The shape the initialisation starts from in a benchmark run
/// ([`TrackOptions::start_shape`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StartShape {
    /// For each capture, the typical performer of the captures from other sources
    /// in the folder ([`typical_shape`], [`super::prior::Capture::source`]; the
    /// default): no clip starts from its own performer's proportions. A folder of
    /// one source has none: its clips start from [`TYPICAL_SHAPE`].
    HeldOut,
    /// [`TYPICAL_SHAPE`], the tracker's default, which was measured from the
    /// benchmark's own captures (flattering: for comparison only).
    Typical,
    /// The standard body (every value 1).
    Standard,
}

/// The pose prior of a benchmark run ([`super::prior`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PriorChoice {
    /// For each capture, a prior learned from the other BVH files in the folder
    /// (the default): no clip is tracked with a prior that has seen its motion. A
    /// folder of one capture has none to learn from: its clips are tracked without
    /// a prior ([`ClipReport::prior`] says so).
    HeldOut,
    /// The built-in prior, which was learned from the benchmark's own captures
    /// (flattering: for comparison only).
    Builtin,
    /// No prior.
    None,
}

impl Default for BenchOptions {
    fn default() -> Self {
        BenchOptions {
            mocap_dir: PathBuf::from("../shared/data/mocap"),
            filter: None,
            azimuths: vec![0.0, 60.0, -120.0],
            lead_in: vec![10, 0],
            duration_s: 3.5,
            width: 320,
            height: 240,
            fps: 30.0,
            fov_deg: 55.0,
            true_silhouettes: false,
            oracle_init: false,
            oracle_shape: false,
            seed: SynthOptions::default().seed,
            basin_probe: 0,
            prior: PriorChoice::HeldOut,
            start_shape: StartShape::HeldOut,
            track: TrackOptions::default(),
        }
    }
}

/// Results of one clip.
#[derive(Clone, Debug)]
pub struct ClipReport {
    pub name: String,
    pub acc: Accumulator,
    pub lost: usize,
    /// Mean IoU of the extracted silhouettes with the true ones.
    pub silhouette_iou: f64,
    /// Frames per second of tracking alone (features + search).
    pub track_fps: f64,
    /// Share of the tracking time spent in the search (the rest: features).
    pub search_share: f64,
    pub evals_per_frame: f64,
    /// Frames on which the true shape and pose cost clearly less than the tracker's
    /// result (by more than [`MISSED_GAP`] of its size): a better answer existed that
    /// the search did not find. On the others the tracker is about as good as the
    /// truth by the objective's measure, or the objective itself prefers its pose.
    pub missed: usize,
    /// How far the fitted shape's proportions are from the performer's
    /// ([`metrics::shape_error`]).
    pub shape_error: f64,
    /// Each of [`JOINTS`]' distance from the truth after the frame's similarity
    /// alignment (as in PA-MPJPE), summed over the frames (mm).
    pub joint_error_mm: [f64; JOINTS.len()],
    /// Each frame with a person, in order.
    pub frames: Vec<FrameReport>,
    /// The truth's basin against the tracker's answer, when asked for
    /// ([`BenchOptions::basin_probe`]).
    pub basin: Option<BasinProbe>,
    /// Whether the tracker weighed a pose prior in ([`BenchOptions::prior`]).
    pub prior: bool,
}

/// Does the objective, with the shape the tracker fitted, prefer a pose near the
/// truth to the tracker's answer? On some frames (every
/// [`BenchOptions::basin_probe`]-th) the true pose is given the fitted body (its
/// root placed on the truth's line of sight, then fitted) and refined by the
/// downhill simplex over all 30 values at once: the bottom of the truth's basin.
/// The tracker's answer is refined the same way, so that the two had the same
/// search. Where the truth's basin is the cheaper, a search that found it would be
/// right by the objective's own measure; where it is not, the objective (with this
/// shape) prefers a wrong pose.
#[derive(Clone, Debug, Default)]
pub struct BasinProbe {
    pub frames: usize,
    /// Frames where the bottom of the truth's basin costs less than the tracker's
    /// answer, refined.
    pub truth_cheaper: usize,
    /// ... and by more than a fifth.
    pub truth_much_cheaper: usize,
    /// Sums over the frames of PA-MPJPE (mm): of the tracker's answer refined, of
    /// the bottom of the truth's basin, and of the cheaper of the two.
    pub pa_tracked: f64,
    pub pa_truth: f64,
    pub pa_cheaper: f64,
}

impl BasinProbe {
    pub fn merge(&mut self, o: &BasinProbe) {
        self.frames += o.frames;
        self.truth_cheaper += o.truth_cheaper;
        self.truth_much_cheaper += o.truth_much_cheaper;
        self.pa_tracked += o.pa_tracked;
        self.pa_truth += o.pa_truth;
        self.pa_cheaper += o.pa_cheaper;
    }
}

/// A frame is missed when the truth costs less than the tracker's result by more than
/// this fraction of the result's size (a near-perfect fit is never quite the truth).
pub const MISSED_GAP: f64 = 0.05;

/// One frame's figures (`monocap bench --per-frame`): where a clip goes wrong, and
/// how (the heading and depth errors show a body turned the wrong way or drifted
/// nearer or farther than the person).
#[derive(Clone, Debug)]
pub struct FrameReport {
    pub index: usize,
    pub pck: f64,
    pub pck_swapped: f64,
    pub pa_mpjpe_mm: f64,
    /// PA-MPJPE allowing limb swaps and the depth mirror
    /// ([`metrics::pa_mpjpe_ambiguous`]).
    pub pa_ambiguous_mm: f64,
    pub iou: f64,
    /// The tracker's cost (None where it found no person).
    pub cost: Option<f64>,
    /// The objective at the true shape and pose, on the same silhouette and features.
    pub truth_cost: f64,
    /// The model's heading (root y rotation) minus the truth's, in (−180°, 180°].
    pub heading_error_deg: f64,
    /// The model's root depth over the truth's.
    pub depth_ratio: f64,
}

impl FrameReport {
    /// The header of [`FrameReport::csv_row`].
    pub const CSV_HEADER: &'static str =
        "clip,frame,pck,pck_swapped,pa_mpjpe_mm,pa_ambiguous_mm,iou,cost,truth_cost,heading_error_deg,depth_ratio";

    /// One CSV line (no newline) for the clip `clip`.
    pub fn csv_row(&self, clip: &str) -> String {
        format!(
            "{clip},{},{:.3},{:.3},{:.1},{:.1},{:.4},{},{:.1},{:.1},{:.4}",
            self.index,
            self.pck,
            self.pck_swapped,
            self.pa_mpjpe_mm,
            self.pa_ambiguous_mm,
            self.iou,
            self.cost.map_or(String::new(), |c| format!("{c:.1}")),
            self.truth_cost,
            self.heading_error_deg,
            self.depth_ratio
        )
    }
}

/// Runs the benchmark, handing each clip's report to `each` as it finishes.
pub fn run(opts: &BenchOptions, mut each: impl FnMut(&ClipReport)) -> Result<Vec<ClipReport>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(&opts.mocap_dir)
        .with_context(|| format!("reading {}", opts.mocap_dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("bvh")))
        .filter(|p| {
            opts.filter.as_ref().is_none_or(|f| {
                p.file_name()
                    .is_some_and(|n| n.to_string_lossy().contains(f.as_str()))
            })
        })
        .collect();
    files.sort();
    anyhow::ensure!(
        !files.is_empty(),
        "no BVH files in {}",
        opts.mocap_dir.display()
    );
    // The held-out priors and start shapes learn from every capture in the folder,
    // filtered or not (no prior is learned when the prior weighs nothing).
    let held_prior = opts.prior == PriorChoice::HeldOut && opts.track.weights.prior > 0.0;
    let captures = match held_prior || opts.start_shape == StartShape::HeldOut {
        true => captures_in(&opts.mocap_dir)?,
        false => Vec::new(),
    };
    let mut out = Vec::new();
    for file in &files {
        let bvh = Bvh::read(file).with_context(|| format!("reading {}", file.display()))?;
        let name = file.file_name().unwrap_or_default().to_string_lossy();
        let mut opts = opts.clone();
        let own = captures.iter().find(|c| c.name == name).map(|c| c.source());
        opts.track.start_shape = match opts.start_shape {
            StartShape::HeldOut => {
                let others: Vec<&Capture> = captures
                    .iter()
                    .filter(|c| Some(c.source()) != own)
                    .collect();
                typical_shape(&others).unwrap_or(TYPICAL_SHAPE)
            }
            StartShape::Typical => TYPICAL_SHAPE,
            StartShape::Standard => STANDARD_SHAPE,
        };
        opts.track.pose_prior = match opts.prior {
            PriorChoice::HeldOut => {
                let others: Vec<Capture> = captures
                    .iter()
                    .filter(|c| c.name != name)
                    .cloned()
                    .collect();
                match others.is_empty() {
                    true => None,
                    false => Some(Arc::new(PosePrior::learn(&others).with_context(|| {
                        format!("learning the pose prior held out from {name}")
                    })?)),
                }
            }
            PriorChoice::Builtin => Some(PosePrior::builtin()),
            PriorChoice::None => None,
        };
        let opts = &opts;
        for &az in &opts.azimuths {
            for &lead in &opts.lead_in {
                let r = run_clip(&bvh, &name, az, lead, opts)
                    .with_context(|| format!("{name} azimuth {az} lead-in {lead}"))?;
                each(&r);
                out.push(r);
            }
        }
    }
    Ok(out)
}

/// One clip: synthesise, segment, track, compare.
pub fn run_clip(
    bvh: &Bvh,
    name: &str,
    azimuth: f64,
    lead: usize,
    opts: &BenchOptions,
) -> Result<ClipReport> {
    let synth = SynthOptions {
        width: opts.width,
        height: opts.height,
        fov_deg: opts.fov_deg,
        fps: opts.fps,
        style: Style::Color,
        empty_frames: lead,
        azimuth_deg: azimuth,
        duration_s: Some(opts.duration_s),
        seed: opts.seed,
        ..SynthOptions::default()
    };
    let mut frames: Vec<RgbImage> = Vec::new();
    let mut masks: Vec<Mask> = Vec::new();
    let truth = synthesize_with(bvh, name, &synth, |f| {
        let Frame::Rgb(img) = f.image else {
            anyhow::bail!("a colour clip");
        };
        frames.push(img.clone());
        masks.push(f.mask.clone());
        Ok(())
    })?;
    let (w, h) = (opts.width, opts.height);
    let silhouettes: Vec<Mask> = if opts.true_silhouettes {
        masks.clone()
    } else {
        let seg = Segmenter::learn(w, h, &SilhouetteOptions::default(), |visit| {
            frames.iter().for_each(&mut *visit);
            Ok::<_, ()>(())
        })
        .map_err(|_| anyhow::anyhow!("segmenting"))?;
        let mut sequence = seg.sequence();
        frames
            .iter()
            .map(|f| {
                let mut m = Mask::new(w, h);
                sequence.next(f, &mut m);
                m
            })
            .collect()
    };
    let mut sil_iou = 0.0;
    let mut sil_n = 0;
    for (s, t) in silhouettes.iter().zip(&masks).skip(lead) {
        sil_iou += s.iou(t);
        sil_n += 1;
    }

    let camera = Camera::new(w, h, opts.fov_deg);
    let mut track_opts = opts.track.clone();
    track_opts.fps = opts.fps;
    if opts.oracle_shape {
        track_opts.known_shape = Some(true_shape(&truth));
    }
    if opts.oracle_init {
        let tf = &truth.frames[0];
        let mut pose = [0.0; MOTION_COUNT];
        pose.copy_from_slice(&tf.params);
        track_opts.init_frame = Some(tf.index);
        track_opts.initial = Some((true_shape(&truth), pose));
    }
    let tracker = Tracker::new(camera.clone(), track_opts);
    let n = frames.len();
    // The tracker takes the frames; the truth is scored on copies afterwards.
    let (kept_silhouettes, kept_frames) = (silhouettes.clone(), frames.clone());
    let inputs = silhouettes
        .into_iter()
        .zip(frames)
        .map(|(silhouette, image)| {
            Ok(FrameInput {
                silhouette,
                image: Some(image),
            })
        });
    let started = Instant::now();
    let track = tracker
        .track(inputs, Some(n), |_, _| std::ops::ControlFlow::Continue(()))
        .map_err(anyhow::Error::from)?;
    let secs = started.elapsed().as_secs_f64();

    let map = JointMap::detect(bvh)?;
    let body = Body::new(&track.shape);
    let mut report = ClipReport {
        prior: opts.track.pose_prior.is_some() && opts.track.weights.prior > 0.0,
        name: format!("{name} az {azimuth:+.0} lead {lead}"),
        acc: Accumulator::default(),
        lost: 0,
        silhouette_iou: if sil_n > 0 {
            sil_iou / sil_n as f64
        } else {
            0.0
        },
        track_fps: n as f64 / secs.max(1e-9),
        search_share: track.timing.search / (track.timing.search + track.timing.features).max(1e-9),
        evals_per_frame: track.timing.evals as f64 / n as f64,
        missed: 0,
        shape_error: metrics::shape_error(&track.shape, &truth.shape.values),
        joint_error_mm: [0.0; JOINTS.len()],
        frames: Vec::new(),
        basin: None,
    };
    let truth_costs = truth_costs(
        &kept_silhouettes,
        &kept_frames,
        &truth,
        &camera,
        track.skin.as_ref(),
        opts,
    );
    if opts.basin_probe > 0 {
        report.basin = Some(probe_basins(
            &kept_silhouettes,
            &kept_frames,
            &truth,
            &camera,
            &track,
            &map,
            &masks,
            opts,
        ));
    }
    drop((kept_silhouettes, kept_frames));
    for tf in &truth.frames {
        let f = &track.frames[tf.index];
        let posed = body.posed(&f.pose);
        let mut pred2 = Vec::new();
        let mut pred3 = Vec::new();
        let mut true2 = Vec::new();
        let mut true3 = Vec::new();
        for j in JOINTS {
            let p = posed.joint(j);
            pred3.push(camera.to_contract(&p));
            // A joint behind the camera counts as far off (a NaN would poison the means).
            pred2.push(camera.project(&p).unwrap_or([-1.0e4; 2]));
            let s = map.source[j.index()];
            true3.push(tf.joints3d[s]);
            true2.push(tf.joints2d[s]);
        }
        let height = mask_height(&masks[tf.index]).max(1.0);
        let plain = metrics::pck_frame(&pred2, &true2, height, 0.1);
        let swapped = metrics::pck_frame_swapped(&pred2, &true2, height, 0.1, &PAIRS);
        // PA-MPJPE, and each joint's share of it.
        let aligned = metrics::align_similarity(&pred3, &true3);
        let pa = metrics::mpjpe(&aligned, &true3) * 10.0;
        let pa_ambiguous =
            metrics::pa_mpjpe_ambiguous(&pred3, &true3, &PAIRS, hips_centre(&true3)) * 10.0;
        for ((e, a), t) in report.joint_error_mm.iter_mut().zip(&aligned).zip(&true3) {
            *e += 10.0 * metrics::mpjpe(&[*a], &[*t]);
        }
        let mut model = Mask::new(w, h);
        crate::body::raster::render_mask(&body, &posed, &camera, &mut model);
        let iou = model.iou(&masks[tf.index]);
        if swapped.pck() < 0.5 {
            report.lost += 1;
        }
        report
            .acc
            .add_frame(&plain, &swapped, pa, pa_ambiguous, iou);
        let heading = f.pose[ix::ROOT_RY] - tf.params[ix::ROOT_RY];
        let truth_cost = truth_costs[tf.index];
        if f.cost
            .is_some_and(|c| truth_cost < c - MISSED_GAP * c.abs())
        {
            report.missed += 1;
        }
        report.frames.push(FrameReport {
            index: tf.index,
            pck: plain.pck(),
            pck_swapped: swapped.pck(),
            pa_mpjpe_mm: pa,
            pa_ambiguous_mm: pa_ambiguous,
            iou,
            cost: f.cost,
            truth_cost,
            heading_error_deg: 180.0 - (180.0 - heading).rem_euclid(360.0),
            depth_ratio: f.pose[ix::ROOT_TZ] / tf.params[ix::ROOT_TZ],
        });
    }
    Ok(report)
}

/// The midpoint of the hips in `joints` (ordered as [`JOINTS`]): the pivot of a
/// body's depth mirror.
fn hips_centre(joints: &[[f64; 3]]) -> [f64; 3] {
    let at = |j: Joint| joints[JOINTS.iter().position(|&k| k == j).expect("a hip")];
    let (l, r) = (at(Joint::LeftUpLeg), at(Joint::RightUpLeg));
    std::array::from_fn(|k| (l[k] + r[k]) / 2.0)
}

/// The performer's shape values.
fn true_shape(truth: &Truth) -> ShapeValues {
    let mut shape = [0.0; SHAPE_COUNT];
    shape.copy_from_slice(&truth.shape.values);
    shape
}

fn mask_height(m: &Mask) -> f64 {
    super::tracker::mask_bbox(m).map_or(0.0, |b| (b[3] - b[1] + 1) as f64)
}

/// The objective at the true shape and pose on every frame (+∞ before the person
/// appears), with the features the tracker computes from the same silhouettes and
/// images (and the skin colour it learned).
fn truth_costs(
    silhouettes: &[Mask],
    images: &[RgbImage],
    truth: &Truth,
    camera: &Camera,
    skin: Option<&SkinModel>,
    opts: &BenchOptions,
) -> Vec<f64> {
    let body = Body::new(&true_shape(truth));
    let mut out = vec![f64::INFINITY; silhouettes.len()];
    truth_targets(
        silhouettes,
        images,
        truth,
        skin,
        opts,
        |_| true,
        |tf, target| {
            out[tf.index] = Evaluator::new(&body, camera, target, opts.track.weights, None)
                .with_prior(opts.track.pose_prior.as_deref())
                .cost(&pose_of(&tf.params));
        },
    );
    out
}

/// Hands `each` the tracker's target (features computed as the tracker computes
/// them, the skin colour it learned) on the frames of the truth that `pick` takes,
/// in order.
fn truth_targets(
    silhouettes: &[Mask],
    images: &[RgbImage],
    truth: &Truth,
    skin: Option<&SkinModel>,
    opts: &BenchOptions,
    mut pick: impl FnMut(&TruthFrame) -> bool,
    mut each: impl FnMut(&TruthFrame, &Target),
) {
    let features = FeatureOptions {
        colours: skin.is_some(),
        ..opts.track.features.clone()
    };
    let mut prev = None;
    let mut at = truth.frames.iter().peekable();
    for (i, (s, img)) in silhouettes.iter().zip(images).enumerate() {
        let f = compute(s, Some(img), prev.as_ref(), &features);
        if let Some(tf) = at.next_if(|tf| tf.index == i).filter(|tf| pick(tf)) {
            let mut target = Target::new(&f, &opts.track.weights);
            if let Some(m) = skin {
                target.add_skin(m, opts.track.weights.skin);
            }
            each(tf, &target);
        }
        prev = Some(f);
    }
}

/// [`BasinProbe`] for one clip.
#[allow(clippy::too_many_arguments)]
fn probe_basins(
    silhouettes: &[Mask],
    images: &[RgbImage],
    truth: &Truth,
    camera: &Camera,
    track: &Track,
    map: &JointMap,
    masks: &[Mask],
    opts: &BenchOptions,
) -> BasinProbe {
    let body = Body::new(&track.shape);
    // Every value within its limits; the root anywhere.
    let steps: Vec<f64> = MOTION.iter().map(|m| 0.5 * m.scale).collect();
    let mut lo: Vec<f64> = MOTION.iter().map(|m| m.lo).collect();
    let mut hi: Vec<f64> = MOTION.iter().map(|m| m.hi).collect();
    for k in ix::ROOT_TX..=ix::ROOT_TZ {
        lo[k] = f64::NEG_INFINITY;
        hi[k] = f64::INFINITY;
    }
    let refine = |ev: &mut Evaluator, start: Pose| -> (Pose, f64) {
        let (mut best, mut best_f) = (start, ev.cost(&start));
        for _ in 0..BASIN_ROUNDS {
            let r = minimize(
                |x| ev.cost(&pose_of(x)),
                &best,
                &steps,
                &lo,
                &hi,
                &SimplexOptions {
                    max_evals: BASIN_EVALS,
                    ..SimplexOptions::default()
                },
            );
            if r.f < best_f {
                (best, best_f) = (pose_of(&r.x), r.f);
            }
        }
        (best, best_f)
    };
    let pa = |pose: &Pose, tf: &TruthFrame| -> f64 {
        let posed = body.posed(pose);
        let pred: Vec<[f64; 3]> = JOINTS
            .iter()
            .map(|&j| camera.to_contract(&posed.joint(j)))
            .collect();
        let true3: Vec<[f64; 3]> = JOINTS
            .iter()
            .map(|j| tf.joints3d[map.source[j.index()]])
            .collect();
        metrics::mpjpe(&metrics::align_similarity(&pred, &true3), &true3) * 10.0
    };
    let mut out = BasinProbe::default();
    let mut person = 0usize;
    let pick = |tf: &TruthFrame| {
        let tracked = track.frames[tf.index].person;
        person += usize::from(tracked);
        tracked
            && (person - 1).is_multiple_of(opts.basin_probe)
            && mask_height(&masks[tf.index]) > 0.0
    };
    truth_targets(
        silhouettes,
        images,
        truth,
        track.skin.as_ref(),
        opts,
        pick,
        |tf, target| {
            let tracked = &track.frames[tf.index];
            let mut ev = Evaluator::new(&body, camera, target, opts.track.weights, None)
                .with_prior(opts.track.pose_prior.as_deref());
            let mut start = pose_of(&tf.params);
            // The fitted body is not the performer's size: its root goes on the truth's
            // line of sight at the tracker's depth, then is fitted.
            let depth = tracked.pose[ix::ROOT_TZ] / start[ix::ROOT_TZ];
            for v in &mut start[ix::ROOT_TX..=ix::ROOT_TZ] {
                *v *= depth;
            }
            let root = minimize(
                |x| {
                    let mut p = start;
                    p[ix::ROOT_TX..=ix::ROOT_TZ].copy_from_slice(x);
                    ev.cost(&p)
                },
                &start[ix::ROOT_TX..=ix::ROOT_TZ],
                &[2.0, 2.0, 10.0],
                &[f64::NEG_INFINITY; 3],
                &[f64::INFINITY; 3],
                &SimplexOptions {
                    max_evals: 300,
                    ..SimplexOptions::default()
                },
            );
            start[ix::ROOT_TX..=ix::ROOT_TZ].copy_from_slice(&root.x);
            let (basin, basin_f) = refine(&mut ev, start);
            let (answer, answer_f) = refine(&mut ev, tracked.pose);
            let (pa_basin, pa_answer) = (pa(&basin, tf), pa(&answer, tf));
            out.frames += 1;
            out.pa_truth += pa_basin;
            out.pa_tracked += pa_answer;
            if basin_f < answer_f {
                out.truth_cheaper += 1;
                out.pa_cheaper += pa_basin;
            } else {
                out.pa_cheaper += pa_answer;
            }
            if basin_f < answer_f - 0.2 * answer_f.abs() {
                out.truth_much_cheaper += 1;
            }
        },
    );
    out
}

/// Rounds of the simplex, and evaluations in each, of [`probe_basins`]' refinements.
const BASIN_ROUNDS: usize = 3;
const BASIN_EVALS: usize = 3000;

fn pose_of(x: &[f64]) -> Pose {
    let mut p = [0.0; MOTION_COUNT];
    p.copy_from_slice(x);
    p
}
