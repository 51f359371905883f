//! The tracker (method.md §5): initialise on one frame, then fit every frame from
//! its neighbour's solution with the biased, hierarchical downhill simplex. By
//! default the initial frame is fitted twice, from the start shape and from it
//! with a round trunk, each start of a person in place is also tried as its depth
//! mirror, and the start that tracks the buffered frames after it at the lowest
//! cost goes on ([`TrackOptions::round_start`], [`TrackOptions::mirror_starts`]).
//!
//! Frames arrive as a stream ([`FrameInput`]: the silhouette and, for a colour clip,
//! the frame, at the working resolution). What is kept, and why:
//!
//! - until the initial frame is chosen, each frame's [`Target`] (about 8 bytes a
//!   pixel): the frames before it are tracked backwards from it once it is fitted.
//!   The automatic choice looks at most [`TrackOptions::init_window`] frames with a
//!   person, so this buffer is bounded; a user-chosen initial frame must lie within
//!   the first [`MAX_INIT_FRAME`] frames, and with several starts the
//!   [`START_PROBE_FRAMES`] frames after it are read before it is fitted;
//! - after that, only the previous frame's features (temporal coherence of the
//!   extremity candidates) and one pose per frame;
//! - with the second pass ([`TrackOptions::two_way`]), the targets of the block
//!   being read (the first pass reads a whole block before it searches its frames)
//!   and of the block whose second pass (and middle pass,
//!   [`TrackOptions::middle_pass`]) is running: two blocks at most, each under
//!   [`TWO_WAY_BUDGET`] bytes (shorter blocks for large frames); and the first
//!   pass's answers, and the later passes', until their block is merged
//!   ([`super::merge`]).
//!
//! Per frame: the search starts at the previous solution moved by the parameter
//! velocity (when that is not worse than the previous solution itself; and moved
//! along its viewing ray to the person's size when that is better still), or at a
//! keyframe's interpolation; the search box around it is bounded by per-parameter
//! acceleration limits, and the simplex's vertex offsets are the parameters' length
//! scales, capped by that box. The groups are searched one after another (global,
//! torso, arms, legs — by default in the reverse order, see
//! [`TrackOptions::global_first`]), and the whole pass repeats `restarts` times from
//! the solution just found. Then the jumps of [`super::flips`] (each bone flipped
//! in depth, the head's nod moved into the trunk, the limbs swapped left for right)
//! are tried from that solution, each refined, and one kept when it explains the
//! frame better. Last, where the model still fits poorly and when asked for, the
//! joint polish (CMA-ES over every free parameter at once,
//! [`TrackOptions::polish_evals`]) goes on from there: the groups compensate for
//! each other, and a search one group at a time stops short of poses the
//! objective prefers.

use std::collections::VecDeque;
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{channel, sync_channel, Receiver, SyncSender};
use std::sync::Arc;
use std::thread::{Scope, ScopedJoinHandle};
use std::time::Instant;

use image::RgbImage;

use super::flips::Jump;
use super::keyframes::{KeyframeError, Keyframes};
use super::objective::{learn_skin, sole_height, Evaluator, Target, Weights};
use super::outlines::Outlines;
pub use super::prefetch::MAX_THREADS;
use super::prefetch::{default_threads, par_map, Prefetch};
use super::prior::PosePrior;
use super::refit::{Job, Window};
use super::shading::Shading;
use super::simplex::{minimize, SimplexOptions};
use crate::body::params::{
    clamp_to_limits, ix, rest_pose, Group, Pose, ShapeValues, MOTION, MOTION_COUNT, SHAPE,
    SHAPE_COUNT, TYPICAL_SHAPE,
};
use crate::body::parts::round_trunk;
use crate::body::skeleton::{standard_rest, Tip};
use crate::body::{Body, Camera, Mask};
use crate::vision::features::{link, FeatureOptions, FrameFeatures};
use crate::vision::skin::SkinModel;

/// A silhouette lower than this many pixels is not a person (noise, a speck).
const MIN_PERSON_HEIGHT: f64 = 8.0;

/// Largest change of depth, as a factor, when a frame's start is resized to the
/// person ([`Search::resize_over`]).
const MAX_RESIZE: f64 = 1.25;

/// Frames tracked from each initial candidate to choose between them.
const HYPOTHESIS_FRAMES: usize = 15;

/// Restarts of each frame's search in the probes of the initial candidates, which
/// also leave out the jumps, unless [`TrackOptions::full_probes`].
const PROBE_RESTARTS: usize = 1;

/// Frames tracked from each initialisation's start to choose between the
/// initialisations and their depth mirrors ([`TrackOptions::round_start`],
/// [`TrackOptions::mirror_starts`]).
const START_PROBE_FRAMES: usize = 40;

/// Frames either side of the initial frame that measure the person's travel
/// ([`ground_travel`]).
const TRAVEL_FRAMES: usize = 30;

/// A person whose feet move faster than this on the ground (cm/s) travels, and the
/// front/back choice looks at which way ([`Tracker::choose_initial`]).
const TRAVEL_SPEED: f64 = 40.0;

/// A travelling person's candidate is taken for its direction when the cosine
/// between its front and the travel is over this ...
const TRAVEL_ALONG: f64 = 0.7;

/// ... and over the cosine of the candidate the cost chose by this much.
const TRAVEL_MARGIN: f64 = 0.3;

/// Initial candidates whose summed costs over [`HYPOTHESIS_FRAMES`] lie within this
/// fraction of each other are a tie ([`choose_hypothesis`]).
const FACING_TIE: f64 = 0.02;

/// Frames in a block of the second pass ([`TrackOptions::two_way`]): its targets
/// are held until its second pass is done. Fewer for large frames
/// ([`two_way_block`]).
pub const TWO_WAY_BLOCK: usize = 150;

/// The targets of a block of the second pass are kept under this many bytes (at
/// about 8 bytes a pixel, [`TWO_WAY_BLOCK`] frames of up to 167,772 pixels: 512×288
/// and smaller frames have whole blocks), down to [`MIN_TWO_WAY_BLOCK`] frames.
pub const TWO_WAY_BUDGET: usize = 192 << 20;

/// The shortest block of the second pass.
pub const MIN_TWO_WAY_BLOCK: usize = 30;

/// Frames in a block of the second pass for `width`×`height` targets.
pub fn two_way_block(width: u32, height: u32) -> usize {
    let bytes = 8 * (width as usize * height as usize).max(1);
    (TWO_WAY_BUDGET / bytes).clamp(MIN_TWO_WAY_BLOCK, TWO_WAY_BLOCK)
}

/// The default of [`TrackOptions::switch_penalty`].
pub const SWITCH_PENALTY: f64 = 0.03;

/// The default of [`TrackOptions::recover_iou`].
const RECOVER_IOU: f64 = 0.75;

/// A loss is searched for again at most once in this many frames (a silhouette the
/// model cannot match, a person half out of the picture, would otherwise make every
/// frame several times dearer).
const RECOVER_GAP: usize = 5;

/// The default of [`TrackOptions::recover_spike`].
const RECOVER_SPIKE: f64 = 1.5;

/// The frame costs a cost spike is judged against ([`cost_spike`]): the last this
/// many frames'.
const SPIKE_WINDOW: usize = 10;

/// A cost spike needs at least this many earlier frame costs to be judged.
const SPIKE_MIN: usize = 5;

/// The joint polish's initial spread, in length scales of each parameter.
const POLISH_SPREAD: f64 = 0.3;

/// The default of [`TrackOptions::polish_evals`].
const POLISH_EVALS: usize = 0;
/// The default of [`TrackOptions::polish_iou`].
const POLISH_IOU: f64 = 0.85;
/// The most joint-polish evaluations a frame may ask for (seconds a frame: a job
/// cannot hold a worker for days).
pub const MAX_POLISH_EVALS: usize = 10_000;
/// The default of [`TrackOptions::init_joint_evals`].
const INIT_JOINT_EVALS: usize = 8000;
/// The most evaluations [`TrackOptions::init_joint_evals`] may ask for.
pub const MAX_INIT_JOINT_EVALS: usize = 100_000;
/// The joint shape-and-pose fit's initial spread, in length scales of each value.
const INIT_JOINT_SPREAD: f64 = 0.5;
/// The joint shape-and-pose fit's seed: a clip always initialises the same way.
const INIT_JOINT_SEED: u64 = 7;

/// Latest user-chosen initial frame (frames before it are buffered).
pub const MAX_INIT_FRAME: usize = 1800;

/// The smoothed refit's width in frames ([`TrackOptions::refit_sigma`]).
pub const REFIT_SIGMA: f64 = 1.5;
/// Runs of the search in each frame's refit ([`TrackOptions::refit_runs`]).
pub const REFIT_RUNS: usize = 2;
/// The default of [`TrackOptions::refit_again_iou`].
pub const REFIT_AGAIN_IOU: f64 = 0.85;
/// The widest smoothed refit a job may ask for (frames; it averages over three
/// times as many either side).
pub const MAX_REFIT_SIGMA: f64 = 10.0;
/// The most runs of the search a frame's refit may ask for.
pub const MAX_REFIT_RUNS: usize = 20;

/// Checks [`TrackOptions::refit_sigma`] and [`TrackOptions::refit_runs`]; the
/// message names what is wrong, spelling the two as `names` (flags or job
/// options).
pub fn check_refit(sigma: f64, runs: usize, names: (&str, &str)) -> Result<(), String> {
    if !(0.0..=MAX_REFIT_SIGMA).contains(&sigma) {
        return Err(format!(
            "{} {sigma}: expected 0 (none) to {MAX_REFIT_SIGMA} frames",
            names.0
        ));
    }
    if !(1..=MAX_REFIT_RUNS).contains(&runs) {
        return Err(format!(
            "{} {runs}: expected 1 to {MAX_REFIT_RUNS}",
            names.1
        ));
    }
    Ok(())
}

/// Checks a [`TrackOptions::refit_again_iou`], named `name` in the message.
pub fn check_refit_again_iou(iou: f64, name: &str) -> Result<(), String> {
    if !(0.0..=1.0).contains(&iou) {
        return Err(format!(
            "{name} {iou}: expected 0 (one run on every frame) to 1 (every run on every frame)"
        ));
    }
    Ok(())
}

/// The default of [`TrackOptions::refit_anchor`].
pub const REFIT_ANCHOR: f64 = 16.0;
/// The largest [`TrackOptions::refit_anchor`] taken.
pub const MAX_REFIT_ANCHOR: f64 = 10_000.0;

/// Checks a [`TrackOptions::refit_anchor`], named `name` in the message.
pub fn check_refit_anchor(weight: f64, name: &str) -> Result<(), String> {
    if !(0.0..=MAX_REFIT_ANCHOR).contains(&weight) {
        return Err(format!(
            "{name} {weight}: expected 0 (no pull) to {MAX_REFIT_ANCHOR}"
        ));
    }
    Ok(())
}

/// The default of [`TrackOptions::refit_rounds`].
pub const REFIT_ROUNDS: usize = 2;
/// The most rounds of the smoothed refit taken.
pub const MAX_REFIT_ROUNDS: usize = 4;

/// Checks a [`TrackOptions::refit_rounds`], named `name` in the message.
pub fn check_refit_rounds(rounds: usize, name: &str) -> Result<(), String> {
    if !(1..=MAX_REFIT_ROUNDS).contains(&rounds) {
        return Err(format!("{name} {rounds}: expected 1 to {MAX_REFIT_ROUNDS}"));
    }
    Ok(())
}

/// The largest [`TrackOptions::switch_penalty`] taken.
pub const MAX_SWITCH_PENALTY: f64 = 1000.0;

/// Checks a [`TrackOptions::switch_penalty`], named `name` in the message.
pub fn check_switch_penalty(penalty: f64, name: &str) -> Result<(), String> {
    if !(0.0..=MAX_SWITCH_PENALTY).contains(&penalty) {
        return Err(format!(
            "{name} {penalty}: expected 0 to {MAX_SWITCH_PENALTY}"
        ));
    }
    Ok(())
}

/// The default of [`TrackOptions::jump_give_up`].
pub const JUMP_GIVE_UP: f64 = 1.5;

/// Checks a [`TrackOptions::jump_give_up`], named `name` in the message.
pub fn check_jump_give_up(ratio: f64, name: &str) -> Result<(), String> {
    if !(ratio == 0.0 || (1.0..=100.0).contains(&ratio)) {
        return Err(format!("{name} {ratio}: expected 0 (never) or 1 to 100"));
    }
    Ok(())
}

/// Checks a [`TrackOptions::second_pass_window`], named `name` in the message.
pub fn check_second_pass_window(window: usize, name: &str) -> Result<(), String> {
    if !(1..=TWO_WAY_BLOCK).contains(&window) {
        return Err(format!("{name} {window}: expected 1 to {TWO_WAY_BLOCK}"));
    }
    Ok(())
}

/// The most middle passes taken ([`TrackOptions::middle_starts`]).
pub const MAX_MIDDLE_STARTS: usize = 4;

/// Checks a [`TrackOptions::middle_starts`], named `name` in the message.
pub fn check_middle_starts(n: usize, name: &str) -> Result<(), String> {
    if !(1..=MAX_MIDDLE_STARTS).contains(&n) {
        return Err(format!("{name} {n}: expected 1 to {MAX_MIDDLE_STARTS}"));
    }
    Ok(())
}

/// The default of [`TrackOptions::parted_middle_starts`]: a block whose passes part
/// is given the quarter and three-quarter passes beside the middle one.
pub const PARTED_MIDDLE_STARTS: usize = 3;

/// The default of [`TrackOptions::parted_share`]: a block's later passes part when
/// a middle pass's answers lie more than a tenth of the body's image height from
/// the backwards pass's on over this share of the joints (the mean over the
/// frames).
pub const PARTED_SHARE: f64 = 0.05;

/// The default of [`TrackOptions::parted_share_max`]: passes whose answers lie apart on
/// more than this share of the joints (one of them far off over much of the block) are
/// not given more middle passes. A price paid for speed: over three runs of the
/// accuracy benchmark (81 clips), more middle passes within the bound kept 0.007 of the
/// 0.008 of PCK@0.1 that they gained on every clip, for half their extra CPU time
/// (README, "Middle passes where the passes part a little").
pub const PARTED_SHARE_MAX: f64 = 0.3;

/// Checks a [`TrackOptions::parted_share_max`], named `name` in the message: a
/// share above [`PARTED_SHARE`], 1 at most (no bound).
pub fn check_parted_share_max(share: f64, name: &str) -> Result<(), String> {
    if !(share > PARTED_SHARE && share <= 1.0) {
        return Err(format!(
            "{name} {share}: expected a share above {PARTED_SHARE}, 1 at most (no bound)"
        ));
    }
    Ok(())
}

/// Checks a [`TrackOptions::parted_middle_starts`], named `name` in the message.
pub fn check_parted_middle_starts(n: usize, name: &str) -> Result<(), String> {
    if n > MAX_MIDDLE_STARTS {
        return Err(format!(
            "{name} {n}: expected 0 (never) to {MAX_MIDDLE_STARTS}"
        ));
    }
    Ok(())
}

/// Frames handed to the refit's helper thread before the tracker waits for it:
/// enough for the frames up to the initial one in most clips, which come all at
/// once (with a queue of 4 the search of the walk seen from 60° waited for the
/// helper 0.30 s of its 4.1 s). The targets queued are held in memory.
const REFIT_QUEUE: usize = 64;

/// Tuning of the tracker. Defaults follow the paper where it gives a value.
#[derive(Clone, Debug)]
pub struct TrackOptions {
    /// The objective's weights. The initialisation and the choice among its
    /// candidates use the paper's objective, whose edge and region rewards (Eq. 4
    /// and 6) pull a far-off standard body onto the person. The frame-by-frame
    /// search pays them only with [`Weights::track_rewards`]: they reward pixels
    /// the XOR term already prices, and a model a little larger than the person
    /// collects them all, so frame after frame it creeps nearer the camera and bends
    /// to keep its image. Without them (the default) the accuracy benchmark went
    /// from PCK@0.1 0.835 to 0.837, with swaps 0.905 → 0.910, PA-MPJPE 143.7 →
    /// 138.1 mm, model IoU 0.824 → 0.876, lost frames 32 → 33, median 12.5 → 13.8
    /// frames/s with a person-free lead-in; 0.640 → 0.659, 0.852 → 0.877, 165.2 →
    /// 161.8 mm, 0.767 → 0.809, 71 → 32 lost without; from
    /// the true first shape and pose (`--oracle-init`, lead-in) PCK 0.903, PA-MPJPE
    /// 95.6 mm, IoU 0.919, 10 lost; the DAVIS people tracked from their masks, mean
    /// IoU 0.732 → 0.781. Fitting the shape in the initialisation without them as
    /// well (the headings with them) was no better: 0.827, 0.918, 139.8 mm, 0.887,
    /// 23 lost with a lead-in; 0.707, 0.865, 161.0 mm, 0.817, 57 lost without.
    ///
    /// With the rewards, a reward rim ([`Weights::reward_rim`]) withholds them near
    /// the outline only. On the accuracy benchmark from the true first shape and
    /// pose (`monocap bench --lead-in 10 --oracle-init --track-rewards --reward-rim
    /// 2`) it kept the model at the person's depth (median tracked/true root depth
    /// 0.946 → 0.984) and took PCK@0.1 from 0.895 to 0.907, PA-MPJPE from 114 to
    /// 100 mm, IoU from 0.871 to 0.910 and lost frames from 30 to 8; from the
    /// tracker's own start PCK 0.839 → 0.830, with swaps 0.910 → 0.901, PA-MPJPE
    /// 142.5 → 142.6 mm, IoU 0.826 → 0.863, lost 17 → 43.
    pub weights: Weights,
    /// Runs of the hierarchical search per frame (the paper's restarts; 3).
    pub restarts: usize,
    /// Search the groups in the paper's order (global, torso, arms, legs) instead of
    /// the reverse. The reverse is the default: searched first, the global group
    /// absorbs part of every limb's motion (the whole body drifts and pitches) and
    /// later runs cannot undo it. Measured with the true first pose on true
    /// silhouettes (`monocap bench --oracle-init --true-silhouettes`): walk PA-MPJPE
    /// 160 → 97 mm and IoU 0.84 → 0.92, CMU 131_01 187 → 140 mm; on the restart
    /// experiment (`cargo run --release --example restarts`) mean 3D joint error
    /// with 3 runs 166 → 14 cm.
    pub global_first: bool,
    /// Carry every parameter's velocity into the next frame's start, as the paper
    /// does; false (the default) carries the root's position's alone. Angles are
    /// only partly seen in a silhouette (a limb's depth and twist, the body's
    /// heading), so their frame-to-frame difference is much of it the search's own
    /// jitter, and carried on it pushes the next start further off. From the true
    /// first pose (accuracy benchmark with a lead-in) PCK@0.1 0.913 with every
    /// velocity and 0.948 with the root position's alone; from the tracker's own
    /// initialisation 0.861 → 0.876 (without a lead-in 0.850 → 0.855), PA-MPJPE
    /// 126.3 → 118.6 mm, lost frames 30 → 37 (a fast turn the heading's velocity
    /// no longer follows). The probes that choose between the initial candidates
    /// carry every velocity whatever this says: with the root's alone there, the
    /// front/back choice went the other way on some frontal clips (README, "The
    /// root's velocity, the probes' in full").
    pub joint_velocity: bool,
    /// Start from the initial candidate the front/back choice would not take
    /// ([`choose_hypothesis`]; the only one when initialisation found one). A
    /// benchmark diagnostic: a track from each candidate shows what the choice is
    /// worth, and which rule would choose better (README, "What the front/back
    /// choice is worth").
    pub other_candidate: bool,
    /// Simplex evaluations per group and run, per parameter of the group (plus one).
    pub evals_per_param: usize,
    /// Evaluations of the joint polish (0, the default: none): CMA-ES over every
    /// free parameter at once, within the reach around the frame's result, on
    /// frames whose model covers the silhouette with an IoU under
    /// [`TrackOptions::polish_iou`]. The groups compensate for each other (hips
    /// moved by the legs instead of the root), and a search one group at a time
    /// stops where no single group can improve, short of poses the objective
    /// prefers; a search over all parameters at once, learning which move
    /// together, goes on. It runs after the jumps, on their winner, and its answer
    /// is kept only when F plus the inner outlines' cost is lower, as for a jump:
    /// run before them, the polished result outbid the jumps' unpolished ones and
    /// more clips ended with their limbs swapped left for right. On the accuracy
    /// benchmark (`monocap bench --polish-evals 800`, with a lead-in / without) it
    /// takes the lost frames from 30 to 14 and from 24 to 17, the model IoU from
    /// 0.875 to 0.878 and from 0.871 to 0.877, but PCK@0.1 moves within the
    /// benchmark's noise (0.861 → 0.872, 0.848 → 0.840), PA-MPJPE too, and the
    /// median speed falls by a sixth to a quarter (on the DAVIS masks, whose frames
    /// mostly fit below 0.85, by a quarter, for a mean IoU of 0.790 against
    /// 0.781). Off by default for the speed it costs; the README's "The joint
    /// polish where the fit is poor" has every variant measured. At 2,000
    /// evaluations, firing on cost spikes too ([`TrackOptions::polish_spike`]), the
    /// six benchmark runs' mean went PCK@0.1 0.928 → 0.933, PA-MPJPE 79.6 → 77.9 mm,
    /// but lost frames 1 → 11, for about a tenth more CPU; still off (README, "The
    /// joint polish again, where the fit is poor or the cost spikes").
    pub polish_evals: usize,
    /// The joint polish runs on frames whose IoU is under this (0.85 by default;
    /// above 1 for every frame). Most synthetic frames fit well already: spending
    /// the evaluations where the fit is poor keeps most of the speed (polishing
    /// every frame cost a third of it).
    pub polish_iou: f64,
    /// The joint polish runs on a frame whose cost spikes too (on by default when
    /// the polish is on): the same test as [`TrackOptions::recover_spike`]'s, on
    /// the frame's result before the recovery, whatever its IoU.
    pub polish_spike: bool,
    /// Weight of the proportions prior in the initialisation's joint fit
    /// ([`ratio_penalty`]): the log-ratios of upper arm to forearm, thigh to shin
    /// and trunk to thigh held near the start shape's. 0 (none) by default: at 200
    /// (a 15% trade between two segments then costs about a sixth of a typical
    /// frame's F) the six benchmark runs scored a mean PCK@0.1 of 0.920 against
    /// 0.928 and the same PA-MPJPE, 79.6 mm (README "The proportions prior").
    pub shape_ratio_prior: f64,
    /// Whether each frame also tries the crouch down ([`Jump::Crouch`];
    /// README "The crouch as a jump"). On by default; off reproduces the tracker
    /// before it.
    pub crouch_jumps: bool,
    /// Whether each frame also tries the whole body mirrored in depth
    /// ([`Jump::Mirror`]). Off by default: it brings back tracks left on the
    /// person's mirror image where the truth costs far less, but it also trades
    /// near-equal answers and took a walker seen from 60° off the heading its
    /// travel had set; over seed 1 of the accuracy benchmark PA-MPJPE went 59.3 →
    /// 60.8 mm with a lead-in and 61.1 → 61.7 without (README "The whole body
    /// mirrored in depth, as a jump").
    pub mirror_jumps: bool,
    /// A jump ([`Search::try_jumps`]) whose refinement over several groups still
    /// costs more than this many times the frame's result after one of them is
    /// given up before the next (0: never). The swaps, which the inner outlines
    /// judge rather than F, are always refined in full.
    pub jump_give_up: f64,
    /// The smoothed refit ([`super::refit`]): each frame searched again from the
    /// Gaussian average of its neighbours' poses, this many frames wide (its
    /// standard deviation; 0 for none), the answer replacing the first pass's.
    /// It runs on a helper thread a few frames behind the search when there are
    /// two threads or more. Keyframes' frames, and the initial frame when its pose
    /// is given ([`TrackOptions::initial`]), keep the first pass's answer. On the
    /// accuracy benchmark (σ 1.5, two runs, against none) PA-MPJPE went from 129.7
    /// to 126.3 mm with a person-free lead-in and from 125.7 to 122.3 mm without,
    /// lower on 26 of the 27 clips of each row, with PCK@0.1 (0.861 → 0.861, 0.848
    /// → 0.850), the model IoU (0.875 → 0.876, 0.871 → 0.871) and lost frames (30
    /// → 30, 24 → 20) kept, for 3–4% of the speed; the README's "The smoothed
    /// refit" has the variants measured.
    pub refit_sigma: f64,
    /// Runs of the hierarchical search in each frame's refit, at most: the
    /// runs after the first go on only while the frame's model IoU is under
    /// [`TrackOptions::refit_again_iou`].
    pub refit_runs: usize,
    /// A frame's refit searches again (up to [`TrackOptions::refit_runs`] runs)
    /// only while its model covers the silhouette with an IoU under this (0.85 by
    /// default; 0: one run everywhere, 1: every run on every frame; a run that
    /// leaves the cost infinite, below the ground, is always followed by another).
    /// Where the first run fits well a second moves the joints little (README
    /// "The refit's second run where the fit is poor").
    pub refit_again_iou: f64,
    /// The refit's pull toward its start: a frame's refit pays this × Σ_k ((β_k −
    /// s_k) / λ_k)² on top of F, s the Gaussian average of its neighbours' poses
    /// it starts from and λ_k each parameter's length scale
    /// ([`Evaluator::with_anchor`]); what the silhouette pins down moves as F
    /// wants, what it leaves free (a limb turned about its own axis, a depth the
    /// camera cannot see) stays smooth. 0 for none; [`REFIT_ANCHOR`] by default.
    /// The frame's reported cost is F alone. Over the accuracy benchmark's six
    /// runs at 16 against none: PA-MPJPE 63.2 → 62.5 mm (lower on five), with
    /// the ambiguities allowed 57.2 → 56.2 (lower on all six), PCK@0.1 0.958 →
    /// 0.957, model IoU 0.938 both, no frame lost; the DAVIS people's mean IoU
    /// 0.812 → 0.810 (README, "The refit pulled toward its start").
    pub refit_anchor: f64,
    /// Rounds of the smoothed refit: each round after the first searches every
    /// frame again from the Gaussian average of the round before's answers (and
    /// is pulled toward it, [`TrackOptions::refit_anchor`]); 1 to 4,
    /// [`REFIT_ROUNDS`] by default. Each round has a helper thread of its own
    /// when there are two threads or more. Over the accuracy benchmark's six runs,
    /// two rounds against one: PA-MPJPE 62.5 → 61.6 mm (lower on all six), PCK@0.1
    /// 0.957 → 0.959, model IoU 0.938 both, no frame lost; the DAVIS people's mean
    /// IoU 0.810 both; 7% of the speed (README, "The refit in two rounds").
    pub refit_rounds: usize,
    /// A frame whose model covers its silhouette with an IoU under this is taken for
    /// a loss and searched again widely, at most every fifth frame (0.75 by default,
    /// 0 for never): wide fits from the result and from it turned 60° either way.
    pub recover_iou: f64,
    /// A frame whose cost is over this many times the median of the last
    /// [`SPIKE_WINDOW`] frames' costs is taken for a loss too ([`cost_spike`]),
    /// under the same limit of one recovery every fifth frame (1.5 by default, 0
    /// for never). On the accuracy benchmark (seeds 1–3, with a person-free
    /// lead-in and without) PA-MPJPE fell on all six runs, by 0.5–3.4 mm, for
    /// 1–4% of the speed; the README's "The recovery after a cost spike" has
    /// the figures.
    pub recover_spike: f64,
    /// The second pass (on by default): each block of [`TWO_WAY_BLOCK`] frames
    /// (fewer for frames of more than 167,772 pixels, [`two_way_block`]) is tracked
    /// a second time, initialised afresh (with the clip's shape) on its last frame
    /// with a person and searched backwards, and a frame takes the second pass's
    /// answer where the choice among the passes' answers does
    /// ([`TrackOptions::switch_penalty`]). A track that lost the person, or started
    /// from a wrong pose, is seldom lost in the same way when followed from the
    /// other end. Over the accuracy benchmark's three noise seeds, with a
    /// person-free lead-in and without, every one of the six runs gained in PCK@0.1,
    /// PCK with swaps, PA-MPJPE, model IoU and lost frames (README, "The second
    /// pass"). With more than one thread it runs beside the first pass: a median
    /// 12.1 and 10.9 frames/s with a lead-in and without, against 17.9 and 17.2 for
    /// the first pass alone, on the same machine. Frames are reported as the first
    /// pass leaves them, and a frame whose answer the second pass replaces is
    /// reported again once its block is done ([`Progress::revised`]); a block's
    /// targets are held until then.
    pub two_way: bool,
    /// Where the second pass starts: the frame that scores best as an initial frame
    /// (as the first pass chooses its own) among the block's last this many frames
    /// with a person, the latest among equals; it is then tracked backwards to the
    /// block's first frame and forwards to its last. 1 (the default): the last
    /// frame with a person. With 15 the one frame the six benchmark runs lose, CMU
    /// 131_01 from −120° on its last frame, where the performer is crouched, is
    /// found, but over two of the runs it traded: seed 3 with a lead-in better,
    /// seed 1 worse, with 5 lost frames (README, "The one lost frame, looked at").
    pub second_pass_window: usize,
    /// The middle pass (on by default; only with [`TrackOptions::two_way`]): each
    /// block is tracked a third time, initialised afresh (with the clip's shape) on
    /// the middle one of its frames with a person and searched from there backwards
    /// to the block's first frame and forwards to its last, beside the second pass;
    /// a frame takes one of the answers ([`TrackOptions::switch_penalty`]). More
    /// such passes from other inner frames: [`TrackOptions::middle_starts`].
    /// Each start goes wrong in its own places. Over the accuracy benchmark's six
    /// runs (seeds 1–3, with a person-free lead-in and without) PCK@0.1, PA-MPJPE
    /// and the model IoU were better on all six (means 0.853 → 0.866, 115.0 → 111.8
    /// mm, 0.908 → 0.912), lost frames 45 → 40 in all (README, "The middle pass").
    pub middle_pass: bool,
    /// How many middle passes ([`TrackOptions::middle_pass`]; 1 by default): with
    /// n, the block's frames with a person are cut into n + 1 equal runs and a pass
    /// starts where each run meets the next (1: the middle frame; 3: the quarter,
    /// middle and three-quarter frames). More answers for each frame to choose
    /// among, at one pass's work each. Over the accuracy benchmark's six runs
    /// (seeds 1–3, with a person-free lead-in and without), 3 against 1: PCK@0.1
    /// 0.949 → 0.954 and PA-MPJPE 66.7 → 65.1 mm on the means, both better on five
    /// runs of the six, for 1.45 times the CPU time (README, "More middle
    /// passes"): not the default, which keeps the speed target.
    pub middle_starts: usize,
    /// Middle passes on a block whose passes part: where, after the backwards
    /// pass and the [`TrackOptions::middle_starts`] middle passes, a middle pass's
    /// answers lie apart from the backwards pass's ([`PARTED_SHARE`], no more than
    /// [`PARTED_SHARE_MAX`]), the block is given this many middle passes in all, as
    /// [`TrackOptions::middle_starts`] would start them (the passes already run are
    /// not run again), so it comes out as with that many from the outset. 0, or no
    /// more than `middle_starts`: never. 3 by default since the probes became
    /// cheaper ([`TrackOptions::full_probes`]), which pays for them: over the six
    /// runs of the accuracy benchmark the two together scored PCK@0.1 0.953 and
    /// PA-MPJPE 65.6 mm against 0.949 and 66.7 before, at 1.02 times the CPU time
    /// on the run timed (README, "Cheaper probes, more middle passes").
    pub parted_middle_starts: usize,
    /// When a block's passes part ([`TrackOptions::parted_middle_starts`]): a
    /// middle pass's answers put more than this share of the joints more than a
    /// tenth of the body's image height from the backwards pass's (the mean over
    /// the block's frames, [`super::merge::apart`]), and no more than
    /// [`TrackOptions::parted_share_max`]; [`PARTED_SHARE`] by default, below 0 on
    /// every block the bound lets through.
    pub parted_share: f64,
    /// The most of the joints a middle pass's answers may put apart from the
    /// backwards pass's for the block to be given more middle passes
    /// ([`TrackOptions::parted_share`]); [`PARTED_SHARE_MAX`] by default, 1 or
    /// more for no bound.
    pub parted_share_max: f64,
    /// How each frame chooses among the passes' answers ([`super::merge::choose`]):
    /// over each block, the sequence with the least summed cost plus this many
    /// times the median frame's cost for each length scale a pose moves from one
    /// frame to the next (0: each frame's cheapest answer). A wrong pose cheaper on
    /// a frame or two then no longer breaks into a track that is right on either
    /// side of it. Over the accuracy benchmark's six runs (seeds 1–3, with a
    /// person-free lead-in and without), 0.03 against 0: PCK@0.1 higher on all six
    /// (means 0.866 → 0.876), PA-MPJPE with the ambiguities allowed lower on all
    /// six (95.6 → 94.2 mm), PA-MPJPE 111.8 → 110.1 mm, lost frames 40 → 25 in all,
    /// the model IoU 0.002–0.003 lower (README, "The choice among the passes'
    /// answers"). The choice evaluates nothing.
    pub switch_penalty: f64,
    /// The initial frame (None: chosen automatically).
    pub init_frame: Option<usize>,
    /// Frames with a person looked at when choosing the initial frame.
    pub init_window: usize,
    /// Frames per second of the clip (scales the acceleration limits).
    pub fps: f64,
    /// Multiplier of the per-parameter acceleration limits (reach of the search box
    /// around the predicted pose, in length scales per frame² at 30 fps).
    pub reach: f64,
    pub keyframes: Keyframes,
    pub features: FeatureOptions,
    /// Skip the initialisation: start from this shape and pose on the initial frame
    /// (experiments that separate initialisation from tracking).
    pub initial: Option<(ShapeValues, Pose)>,
    /// The person's shape when it is known: the initialisation fits only the pose.
    pub known_shape: Option<ShapeValues>,
    /// The shape the initialisation places and poses before it fits the shape, and
    /// from which that fit starts ([`TYPICAL_SHAPE`] by default). One silhouette
    /// says little about proportions: the fit mostly keeps the lengths it starts
    /// from (README, "The typical performer").
    pub start_shape: ShapeValues,
    /// Initialise a second time from [`TrackOptions::start_shape`] with a round
    /// trunk ([`round_trunk`]: its torso and pelvis as wide as they are deep), and
    /// keep whichever start, shape and pose, tracks the next
    /// [`START_PROBE_FRAMES`] frames at the lower summed cost (true by default). A
    /// standing person's heading and trunk width trade against each other in one
    /// silhouette: a wide trunk turned to the side explains a narrow one seen from
    /// the front, and the initialisation settles on the heading its start shape's
    /// trunk suggests; a round trunk leaves the heading to the limbs. The frames
    /// that follow tell the two apart better than the initial frame does (README,
    /// "Two starts, a round trunk and the start shape's").
    pub round_start: bool,
    /// Fit each of the initialisation's 12 headings twice (true by default): from
    /// the rest pose, as the paper does, and from the pose prior's exemplar
    /// ([`PosePrior::exemplar_poses`]: 32 typical whole poses of the captures it
    /// was learned from) that costs least at that heading, keeping the cheaper
    /// fit. A pose far from the rest pose (a fighting stance, a bow, a leg raised
    /// for a kick) is out of the simplex's reach from it, which then settles on a
    /// wrong heading that explains the outline as well; one exemplar near the
    /// person's pose starts the search in the right basin (README, "Whole poses
    /// from the captures as starts"). No effect without a pose prior, or with one
    /// whose file holds no exemplars.
    pub exemplar_starts: bool,
    /// Try each start's depth mirror as one more start (true by default): the
    /// start's pose reflected front to back across the line of sight
    /// ([`super::flips::depth_mirror`]: nearly the same silhouette, left and right
    /// exchanged, the heading mirrored), refined on the initial frame, then
    /// tracked over the [`START_PROBE_FRAMES`] frames after it like the other
    /// starts; the start that tracks them at the lowest summed cost goes on. The
    /// initial frame alone hardly tells a body from its depth mirror; the frames
    /// after it tell them apart better (README, "The depth mirror as a start").
    /// Not for a person who travels: the direction of travel chooses between a
    /// start and its mirror there ([`Tracker::choose_initial`]).
    pub mirror_starts: bool,
    /// Probe the initial candidates as the frames are tracked (false by default):
    /// each candidate's [`HYPOTHESIS_FRAMES`] frames searched with every restart
    /// and every jump. By default the probes search each frame once
    /// ([`PROBE_RESTARTS`]) and try no jumps: they only rank the candidates, and
    /// at full cost they took a fifth of the tracker's time. Cheaper probes pay for
    /// the default's more middle passes where the passes part
    /// ([`TrackOptions::parted_middle_starts`]; README, "Cheaper probes, more
    /// middle passes").
    pub full_probes: bool,
    /// Evaluations of the initialisation's joint fit (8,000 by default; 0 for
    /// none): after the simplex has fitted the shape and the pose in turn, CMA-ES
    /// over the 12 shape values and the 30 pose values at once, under the
    /// tracking objective (no rewards, shares of pixels), the root moved with the
    /// body's size so that its image keeps its place, the pose prior weighed in
    /// ([`Tracker::joint_fit`]).
    /// The fits one at a time stop where neither alone improves, a shape and
    /// pose that explain the silhouette worse than the person's own. Over the
    /// accuracy benchmark's six runs (seeds 1–3, with a person-free lead-in and
    /// without) against none: PCK@0.1 0.905 → 0.916, PA-MPJPE 85.8 → 84.3 mm
    /// (worse on two runs), model IoU 0.911 → 0.919 (higher on all six), lost
    /// frames 104 → 93, for 7% of the speed, with 4,000 evaluations; with 8,000
    /// (the default since 2026-12-02) PCK@0.1 0.920, PA-MPJPE 81.6 mm, IoU 0.927,
    /// 55 lost (README, "The joint fit of shape and pose"); weighing the pose prior
    /// too (since that day's second session) 0.928, 78.7 mm, 0.930, 45 lost (README,
    /// "The pose prior in the joint fit").
    pub init_joint_evals: usize,
    /// The prior on the pose weighed into F by [`Weights::prior`] (the built-in one
    /// by default, [`PosePrior::builtin`]; None for none).
    pub pose_prior: Option<Arc<PosePrior>>,
    /// When set (by another thread), tracking stops with [`TrackError::Canceled`]
    /// at the next step, also inside the initialisation, which reports no frame for
    /// a while (how a service cancels a job promptly).
    pub stop: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
    /// Threads the tracker may use; 0 (the default) for one per core, 1 to keep
    /// all the work on the caller's thread. Beyond one, each frame's features are
    /// computed on helper threads ahead of the search, and the initialisation's
    /// independent fits run side by side; the result is the same whatever the
    /// number. At most [`MAX_THREADS`] are used.
    pub threads: usize,
}

impl Default for TrackOptions {
    fn default() -> Self {
        TrackOptions {
            weights: Weights::default(),
            restarts: 3,
            global_first: false,
            joint_velocity: false,
            other_candidate: false,
            evals_per_param: 25,
            polish_evals: POLISH_EVALS,
            polish_iou: POLISH_IOU,
            polish_spike: true,
            shape_ratio_prior: 0.0,
            crouch_jumps: true,
            mirror_jumps: false,
            jump_give_up: JUMP_GIVE_UP,
            recover_iou: RECOVER_IOU,
            recover_spike: RECOVER_SPIKE,
            refit_sigma: REFIT_SIGMA,
            refit_runs: REFIT_RUNS,
            refit_again_iou: REFIT_AGAIN_IOU,
            refit_anchor: REFIT_ANCHOR,
            refit_rounds: REFIT_ROUNDS,
            two_way: true,
            second_pass_window: 1,
            middle_pass: true,
            middle_starts: 1,
            parted_middle_starts: PARTED_MIDDLE_STARTS,
            parted_share: PARTED_SHARE,
            parted_share_max: PARTED_SHARE_MAX,
            switch_penalty: SWITCH_PENALTY,
            init_frame: None,
            init_window: 60,
            fps: 30.0,
            reach: 3.0,
            keyframes: Keyframes::default(),
            features: FeatureOptions::default(),
            initial: None,
            known_shape: None,
            start_shape: TYPICAL_SHAPE,
            round_start: true,
            exemplar_starts: true,
            mirror_starts: true,
            full_probes: false,
            init_joint_evals: INIT_JOINT_EVALS,
            pose_prior: Some(PosePrior::builtin()),
            stop: None,
            threads: 0,
        }
    }
}

/// One frame of input at the working resolution.
pub struct FrameInput {
    pub silhouette: Mask,
    /// The colour frame, when the clip has one (for the edge map).
    pub image: Option<RgbImage>,
}

/// The result for one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackedFrame {
    pub index: usize,
    /// False when the frame shows no person: its pose is then held from the previous
    /// tracked frame (the first one, before the person appears) and it has no cost
    /// or IoU.
    pub person: bool,
    pub pose: Pose,
    pub cost: Option<f64>,
    pub iou: Option<f64>,
    /// A keyframe applied to this frame's start pose.
    pub keyframe: bool,
}

/// Progress after each frame.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    pub frames_done: usize,
    pub frames_total: Option<usize>,
    /// Frames per second since tracking began.
    pub fps: f64,
    /// This report revises a frame reported before: the second pass
    /// ([`TrackOptions::two_way`]) found a cheaper answer for it.
    /// `frames_done` counts each frame once, on its first report.
    pub revised: bool,
}

/// Where the time went (seconds).
#[derive(Clone, Copy, Debug, Default)]
pub struct Timing {
    /// Silhouette features and the objective's per-frame maps: the time the
    /// tracker's own thread spent on them or waiting for its helpers' (features
    /// computed ahead while it searched do not count).
    pub features: f64,
    /// The search (objective evaluations and simplex bookkeeping) on the
    /// tracker's own thread (the smoothed refit's helper thread not counted).
    pub search: f64,
    /// Evaluations of the objective, on every thread.
    pub evals: u64,
    pub total: f64,
}

/// A tracked clip.
#[derive(Clone, Debug)]
pub struct Track {
    pub camera: Camera,
    pub shape: ShapeValues,
    pub init_frame: usize,
    /// World y of the ground found at initialisation.
    pub ground: f64,
    /// The clip's skin colour, learned on the initial frame (None unless the skin
    /// term is weighed, the clip has colour and the fit showed enough of both skin
    /// and clothes).
    pub skin: Option<SkinModel>,
    pub frames: Vec<TrackedFrame>,
    pub timing: Timing,
}

#[derive(Debug, thiserror::Error)]
pub enum TrackError {
    #[error("the clip has no frames")]
    Empty,
    #[error("no person found in any of the clip's {0} frames")]
    NoPerson(usize),
    #[error("initial frame {frame} is outside the clip, which has {count} frames")]
    InitOutside { frame: usize, count: usize },
    #[error("initial frame {0} must be one of the first {MAX_INIT_FRAME} frames")]
    InitTooLate(usize),
    #[error("initial frame {0} shows no person")]
    InitNoPerson(usize),
    #[error(transparent)]
    Keyframes(#[from] KeyframeError),
    #[error("frame {index} is {width}×{height}, the tracker works at {expected_w}×{expected_h}")]
    FrameSize {
        index: usize,
        width: u32,
        height: u32,
        expected_w: u32,
        expected_h: u32,
    },
    #[error("canceled")]
    Canceled,
    #[error(transparent)]
    Input(anyhow::Error),
}

/// Fits the body model to a stream of silhouettes.
pub struct Tracker {
    pub camera: Camera,
    pub opts: TrackOptions,
}

/// A buffered frame before initialisation.
struct Pending {
    /// None on frames without a person (nothing to fit there, nothing kept).
    target: Option<Target>,
    score: f64,
}

impl Tracker {
    pub fn new(camera: Camera, opts: TrackOptions) -> Tracker {
        Tracker { camera, opts }
    }

    /// The checks of the options against a clip of `total` frames (when known) that
    /// need no frame: callers run them before decoding anything.
    pub fn check(&self, total: Option<usize>) -> Result<(), TrackError> {
        if let (Some(f), Some(t)) = (self.opts.init_frame, total) {
            if f >= t {
                return Err(TrackError::InitOutside { frame: f, count: t });
            }
        }
        if let Some(f) = self.opts.init_frame {
            if f >= MAX_INIT_FRAME {
                return Err(TrackError::InitTooLate(f));
            }
        }
        if let Some(t) = total {
            self.opts.keyframes.check_frames(t)?;
        }
        Ok(())
    }

    /// Tracks every frame of `frames`, calling `on_frame` with each frame's final
    /// result, in frame order (the frames up to the initial one once the search has
    /// gone back from it to the first; each frame a few frames behind the search
    /// with the smoothed refit, which waits for its neighbours). Return
    /// `ControlFlow::Break` to cancel. `total`, when known, is reported in
    /// progress. When a frame cannot be read once tracking has started, the frames
    /// before it are reported before the error is returned.
    pub fn track(
        &self,
        frames: impl Iterator<Item = anyhow::Result<FrameInput>>,
        total: Option<usize>,
        on_frame: impl FnMut(&TrackedFrame, &Progress) -> ControlFlow<()>,
    ) -> Result<Track, TrackError> {
        let started = Instant::now();
        self.check(total)?;
        let size = (self.camera.width, self.camera.height);
        let threads = self.threads();
        let helpers = if threads > 1 { threads } else { 0 };
        std::thread::scope(|scope| {
            let features = self.features();
            let frames = Prefetch::new(scope, frames, size, helpers, &features);
            self.track_prefetched(frames, total, started, on_frame)
        })
    }

    /// The feature options frames are computed with: [`TrackOptions::features`],
    /// with the person's colours kept when the skin term is weighed.
    pub fn features(&self) -> FeatureOptions {
        FeatureOptions {
            colours: self.opts.weights.skin > 0.0,
            luma: self.opts.weights.shading > 0.0,
            ..self.opts.features.clone()
        }
    }

    /// Rounds of the smoothed refit run: one when it is off (frames then pass
    /// straight through), at most [`MAX_REFIT_ROUNDS`].
    fn refit_rounds(&self) -> usize {
        if self.opts.refit_sigma > 0.0 {
            self.opts.refit_rounds.clamp(1, MAX_REFIT_ROUNDS)
        } else {
            1
        }
    }

    /// The threads this tracker uses ([`TrackOptions::threads`], 0 for the machine's
    /// cores).
    fn threads(&self) -> usize {
        match self.opts.threads {
            0 => default_threads(),
            n => n,
        }
        .min(MAX_THREADS)
    }

    fn track_prefetched(
        &self,
        mut frames: Prefetch<impl Iterator<Item = anyhow::Result<FrameInput>>>,
        total: Option<usize>,
        started: Instant,
        mut on_frame: impl FnMut(&TrackedFrame, &Progress) -> ControlFlow<()>,
    ) -> Result<Track, TrackError> {
        let mut timing = Timing::default();
        let mut prev_features: Option<FrameFeatures> = None;
        let mut next_target = |prev: &mut Option<FrameFeatures>,
                               timing: &mut Timing,
                               skin: Option<&SkinModel>|
         -> Next {
            let t0 = Instant::now();
            let (index, mut f) = match frames.next()? {
                Ok(next) => next,
                Err(e) => return Some(Err(e)),
            };
            link(&mut f, prev.as_ref(), &self.opts.features);
            let score = init_score(&f);
            let target = (f.body_height >= MIN_PERSON_HEIGHT).then(|| {
                let mut t = Target::new(&f, &self.opts.weights);
                t.init_score = score;
                if let Some(m) = skin {
                    t.add_skin(m, self.opts.weights.skin);
                }
                t
            });
            *prev = Some(f);
            timing.features += t0.elapsed().as_secs_f64();
            Some(Ok((index, target, score)))
        };

        // Phase 1: buffer frames until the initial frame is known.
        let mut pending: Vec<Pending> = Vec::new();
        let mut person_frames = 0;
        let mut exhausted = false;
        // Several starts track the frames after the initial one to choose between
        // them: two initialisations, each start and its depth mirror.
        let two_starts =
            self.opts.round_start && self.opts.known_shape.is_none() && self.opts.initial.is_none();
        let mirror_starts = self.opts.mirror_starts && self.opts.initial.is_none();
        let probe_len = if two_starts || mirror_starts {
            START_PROBE_FRAMES
        } else {
            0
        };
        loop {
            let enough = match self.opts.init_frame {
                Some(f) => pending.len() > f + probe_len,
                // Enough people seen; or a bounded wait for one to stay a while.
                None => {
                    person_frames >= self.opts.init_window.max(1)
                        || (person_frames > 0 && pending.len() >= MAX_INIT_FRAME)
                }
            };
            if enough {
                break;
            }
            let Some(next) = next_target(&mut prev_features, &mut timing, None) else {
                exhausted = true;
                break;
            };
            let (_, target, score) = next?;
            self.check_stop()?;
            if target.is_some() {
                person_frames += 1;
            }
            pending.push(Pending { target, score });
        }
        if pending.is_empty() {
            return Err(TrackError::Empty);
        }
        let init = match self.opts.init_frame {
            Some(f) if f >= pending.len() => {
                return Err(TrackError::InitOutside {
                    frame: f,
                    count: pending.len(),
                })
            }
            Some(f) => {
                if pending[f].target.is_none() {
                    return Err(TrackError::InitNoPerson(f));
                }
                f
            }
            None => {
                // The best-scoring frame; the earliest among equals.
                let best = pending
                    .iter()
                    .enumerate()
                    .filter(|(_, p)| p.target.is_some())
                    .max_by(|a, b| a.1.score.total_cmp(&b.1.score).then(b.0.cmp(&a.0)));
                match best {
                    Some((i, _)) => i,
                    None if exhausted => return Err(TrackError::NoPerson(pending.len())),
                    None => return Err(TrackError::NoPerson(pending.len())),
                }
            }
        };

        // Phase 2: initialise.
        let t0 = Instant::now();
        let init_target = pending[init].target.as_ref().expect("a person frame");
        // The initialisation and the choice among its candidates judge by the
        // paper's objective (with its rewards, [`Weights::track_rewards`]), but for
        // the initialisation's joint fit of shape and pose, which judges by the
        // tracking objective ([`Tracker::initialise`]).
        // One start, or two: from the start shape and from it with a round trunk
        // ([`TrackOptions::round_start`]).
        let starts: Vec<(ShapeValues, Vec<Pose>)> = match self.opts.initial {
            Some((shape, pose)) => vec![(shape, vec![pose])],
            None if two_starts => {
                // Independent of each other: side by side, each with the answer it gives
                // alone (each also fits its headings on the threads it is given).
                let round = round_trunk(&self.opts.start_shape);
                par_map(&[false, true], self.threads(), |&rounded| {
                    if rounded {
                        self.initialise_with(init_target, None, &round)
                    } else {
                        self.initialise(init_target)
                    }
                })
            }
            None => vec![self.initialise(init_target)],
        };
        // Initialisation gives up early when asked to stop; its result is then moot.
        self.check_stop()?;
        // The clip's skin colour, from the (first) initialisation's best fit (before
        // the next frames choose between the candidates, which they do with it);
        // every frame's target rewards the bare parts for covering it from now on.
        let skin = (self.opts.weights.skin > 0.0)
            .then(|| {
                let (shape, candidates) = &starts[0];
                learn_skin(&Body::new(shape), &self.camera, init_target, &candidates[0])
            })
            .flatten();
        if let Some(m) = &skin {
            for t in pending.iter_mut().filter_map(|p| p.target.as_mut()) {
                t.add_skin(m, self.opts.weights.skin);
            }
        }
        let init_target = pending[init].target.as_ref().expect("a person frame");
        let targets: Vec<Option<&Target>> = pending.iter().map(|p| p.target.as_ref()).collect();
        // Several candidates: keep the one that explains the next frames best (a
        // near tie goes to the one facing the camera, [`choose_hypothesis`]).
        let mut picked: Vec<(ShapeValues, Pose)> = Vec::with_capacity(starts.len());
        for (shape, candidates) in &starts {
            let body = Body::new(shape);
            let pose = if candidates.len() == 1 {
                candidates[0]
            } else {
                let (totals, evals) =
                    self.probe_candidates(&body, candidates, &targets, 0, init)?;
                timing.evals += evals;
                let (chosen, evals) =
                    self.choose_initial(&body, init_target, &totals, &targets, init);
                timing.evals += evals;
                match totals.iter().find(|(_, p)| *p != chosen) {
                    Some((_, other)) if self.opts.other_candidate => *other,
                    _ => chosen,
                }
            };
            picked.push((*shape, pose));
        }
        if mirror_starts {
            // Each start's depth mirror, refined on the initial frame, unless the
            // person travels: then the direction of travel has chosen between the
            // start and its mirror ([`Tracker::choose_initial`]). Independent of
            // each other: side by side.
            let in_place: Vec<(ShapeValues, Pose)> = picked
                .iter()
                .filter(|(shape, pose)| {
                    let body = Body::new(shape);
                    self.travel(&body, pose, &targets, init).is_none()
                })
                .copied()
                .collect();
            let mirrors = par_map(&in_place, self.threads(), |(shape, pose)| {
                let (mirror, evals) = self.mirror_start(shape, pose, init_target);
                (*shape, mirror, evals)
            });
            for (shape, mirror, evals) in mirrors {
                timing.evals += evals;
                picked.push((shape, mirror));
            }
            self.check_stop()?;
        }
        let ((shape, init_pose), mut probed) = match picked[..] {
            [one] => (one, Probed::new()),
            _ => {
                let (best, probed, evals) = self.probe_starts(&picked, &targets, init)?;
                timing.evals += evals;
                (best, probed)
            }
        };
        let body = Body::new(&shape);
        let (mut search, init_frame) = self.start_on(&body, init, init_target, init_pose);
        let (ground, init_pose) = (search.ground, init_frame.pose);
        let mut results: Vec<Option<TrackedFrame>> = vec![None; init + 1];
        let mut done = 0usize;
        let mut emit = |frame: TrackedFrame,
                        done: &mut usize,
                        revised: bool|
         -> Result<TrackedFrame, TrackError> {
            if !revised {
                *done += 1;
            }
            let secs = started.elapsed().as_secs_f64();
            let progress = Progress {
                frames_done: *done,
                frames_total: total,
                fps: if secs > 0.0 { *done as f64 / secs } else { 0.0 },
                revised,
            };
            match on_frame(&frame, &progress) {
                ControlFlow::Continue(()) => Ok(frame),
                ControlFlow::Break(()) => Err(TrackError::Canceled),
            }
        };
        results[init] = Some(init_frame);
        timing.search += t0.elapsed().as_secs_f64();

        // Phases 3 and 4 hand each tracked frame to the smoothed refit, which hands
        // the frames back in order once their neighbours are known (at once when it
        // is off); a frame is reported when it comes back. With the second pass,
        // each block's targets are all read before the first pass searches its
        // frames, and the second pass runs on the block meanwhile, on a thread of
        // its own (see [`TwoWay`]).
        let mut out: Vec<TrackedFrame> = Vec::new();
        let mut targets: Vec<Option<Arc<Target>>> = pending
            .into_iter()
            .map(|p| p.target.map(Arc::new))
            .collect();
        std::thread::scope(|scope| -> Result<(), TrackError> {
            let mut refit = Refit::start(scope, self, &body, ground);
            let pass = Pass {
                scope,
                tracker: self,
                body: &body,
                shape,
            };
            let block = two_way_block(self.camera.width, self.camera.height);
            let mut two_way = TwoWay::new(
                if self.opts.two_way { block } else { 0 },
                self.opts.initial.is_some().then_some(init),
                self.opts.switch_penalty,
            );
            let mut take =
                |refit: &mut Refit, two_way: &mut TwoWay, end: bool| -> Result<(), TrackError> {
                    two_way.poll()?;
                    for (f, revised) in two_way.merge(refit.finished(end)) {
                        if revised {
                            // `out` holds every frame from the first on.
                            let i = f.index;
                            out[i] = emit(f, &mut done, true)?;
                        } else {
                            out.push(emit(f, &mut done, false)?);
                        }
                    }
                    Ok(())
                };
            // Frames read but not yet searched (an input's failure in its place).
            let mut queue = Queue::new();
            let mut input_done = exhausted;
            let mut read = || next_target(&mut prev_features, &mut timing, skin.as_ref());
            for target in &targets {
                two_way.gather(&pass, target.as_ref())?;
            }
            if exhausted {
                two_way.end_input(&pass)?;
            }

            // Phase 3: backwards from the initial frame, then forwards over the buffer.
            let mut searched = 0.0;
            // Frames are reported behind the search (those before the initial frame
            // after it has gone back to the first): a stop is looked for here too.
            // The frames the winning start's probe tracked are taken as they are: the
            // first pass would track them the same way.
            let mut step = |i: usize, target: Option<&Target>, history: &mut History| {
                self.check_stop()?;
                if let Some((f, after)) = probed.remove(&i) {
                    *history = after;
                    return Ok(f);
                }
                let t0 = Instant::now();
                let f = search.step(i, target, history);
                searched += t0.elapsed().as_secs_f64();
                Ok::<_, TrackError>(f)
            };
            while !input_done && two_way.waits_for(init) {
                input_done = !two_way.enqueue(&pass, read(), &mut queue)?;
            }
            let mut history = History::new(init_pose);
            for i in (0..init).rev() {
                results[i] = Some(step(i, targets[i].as_deref(), &mut history)?);
            }
            for (i, (result, target)) in results.iter_mut().zip(&mut targets).enumerate() {
                // A given initial pose is kept on its frame, as a keyframe's is.
                let given = i == init && self.opts.initial.is_some();
                let frame = result.take().expect("tracked");
                refit.push(frame, target.take().filter(|_| !given));
            }
            take(&mut refit, &mut two_way, false)?;

            // Phase 4: forwards over the rest of the buffer, then the stream.
            let read_ahead = std::mem::take(&mut queue);
            queue.extend(targets.into_iter().enumerate().skip(init + 1).map(Ok));
            queue.extend(read_ahead);
            let mut history = History::new(init_pose);
            loop {
                // The next frame, with the second pass, once its block is whole.
                while !input_done
                    && queue.front().is_none_or(|next| match next {
                        Ok((i, _)) => two_way.waits_for(*i),
                        Err(_) => false,
                    })
                {
                    input_done = !two_way.enqueue(&pass, read(), &mut queue)?;
                }
                let Some(next) = queue.pop_front() else {
                    break;
                };
                let (i, target) = match next {
                    Ok(next) => next,
                    Err(e) => {
                        // The frames tracked before a bad one are reported first
                        // (as the first pass left them).
                        two_way.abandon()?;
                        take(&mut refit, &mut two_way, true)?;
                        return Err(e);
                    }
                };
                let f = step(i, target.as_deref(), &mut history)?;
                refit.push(f, target);
                take(&mut refit, &mut two_way, false)?;
            }
            // The last block's second pass, while the helper refits the last frames.
            two_way.finish(&pass)?;
            take(&mut refit, &mut two_way, true)?;
            let (refit_evals, refit_secs) = refit.spent();
            timing.search += searched + refit_secs + two_way.secs;
            timing.evals += refit_evals + two_way.evals;
            Ok(())
        })?;
        if let Some(t) = total {
            if out.len() != t {
                // The container's count was off; keyframes are checked against the truth.
                self.opts.keyframes.check_frames(out.len())?;
            }
        } else {
            self.opts.keyframes.check_frames(out.len())?;
        }
        hold_missing(&mut out);
        timing.evals += search.evals;
        timing.total = started.elapsed().as_secs_f64();
        Ok(Track {
            camera: self.camera.clone(),
            shape,
            init_frame: init,
            ground,
            skin,
            frames: out,
            timing,
        })
    }

    /// [`TrackError::Canceled`] once [`TrackOptions::stop`] is set.
    fn check_stop(&self) -> Result<(), TrackError> {
        match &self.opts.stop {
            Some(s) if s.load(std::sync::atomic::Ordering::Relaxed) => Err(TrackError::Canceled),
            _ => Ok(()),
        }
    }

    fn stopping(&self) -> bool {
        self.check_stop().is_err()
    }

    /// The search that tracks on from the initial frame `index`, and that frame's
    /// result: `pose`, or a keyframe's on that frame, which overrides what
    /// initialisation found; the ground under its soles.
    fn start_on<'a>(
        &'a self,
        body: &'a Body,
        index: usize,
        target: &Target,
        pose: Pose,
    ) -> (Search<'a>, TrackedFrame) {
        let mut search = Search::new(self, body, f64::NEG_INFINITY);
        let mut pose = pose;
        let keyframe = self.opts.keyframes.at(index).is_some();
        if keyframe {
            let mut history = History::new(pose);
            pose = search.step(index, Some(target), &mut history).pose;
        }
        search.ground = sole_height(body, &body.posed(&pose));
        let (cost, iou) = search.measure(target, &pose);
        let frame = TrackedFrame {
            index,
            person: true,
            pose,
            cost: Some(cost),
            iou: Some(iou),
            keyframe,
        };
        (search, frame)
    }

    /// Whether a block's later passes part ([`TrackOptions::parted_middle_starts`]):
    /// some middle pass's answers lie apart from the backwards pass's on more than
    /// [`TrackOptions::parted_share`] of the joints and no more than
    /// [`TrackOptions::parted_share_max`] ([`super::merge::apart`]). False when the
    /// backwards pass failed.
    fn passes_part(&self, body: &Body, passes: &[BlockResult]) -> bool {
        let Some(Ok((last, _))) = passes.first() else {
            return false;
        };
        let (lo, hi) = (self.opts.parted_share, self.opts.parted_share_max);
        passes[1..]
            .iter()
            .filter_map(|p| p.as_ref().ok())
            .map(|(f, _)| super::merge::apart(body, &self.camera, last, f))
            .any(|share| share > lo && share <= hi)
    }

    /// The passes after the first over one block of frames
    /// ([`TrackOptions::two_way`]; the targets of frames `from`, `from` + 1, …): the
    /// backwards pass, and the middle passes ([`TrackOptions::middle_pass`]) side by
    /// side with it when there are two threads or more; then, where they part
    /// ([`TrackOptions::parted_middle_starts`]), more middle passes. Their answers
    /// for the block's frames up to its last one with a person (none when the block
    /// has no person), in frame order and, for each frame, in the passes' order;
    /// and the evaluations spent.
    fn block_passes(
        &self,
        body: &Body,
        shape: ShapeValues,
        from: usize,
        targets: Vec<Option<Arc<Target>>>,
        abort: &AtomicBool,
    ) -> BlockResult {
        let n = self.opts.middle_starts;
        let middles = (1..=n).map(|k| BlockStart::Inner(k, n + 1));
        let starts: Vec<BlockStart> = match self.opts.middle_pass {
            true => std::iter::once(BlockStart::Last).chain(middles).collect(),
            false => vec![BlockStart::Last],
        };
        let run = |starts: &[BlockStart]| {
            par_map(starts, self.threads(), |&start| {
                self.block_pass(body, shape, from, targets.clone(), abort, start)
            })
        };
        let mut passes = run(&starts);
        let more = self.opts.parted_middle_starts;
        if self.opts.middle_pass && more > n && self.passes_part(body, &passes) {
            let extra: Vec<BlockStart> = (1..=more)
                .map(|k| BlockStart::Inner(k, more + 1))
                .filter(|s| !starts.iter().any(|t| s.same_as(t)))
                .collect();
            passes.extend(run(&extra));
            let starts = starts.into_iter().chain(extra);
            // The passes in the order of their starts through the block, the
            // backwards pass first: as many middle passes from the outset would be.
            let mut paired: Vec<(BlockStart, BlockResult)> = starts.zip(passes).collect();
            paired.sort_by(|a, b| a.0.order(&b.0));
            passes = paired.into_iter().map(|(_, pass)| pass).collect();
        }
        let mut answers = Vec::new();
        let mut spent = 0;
        for pass in passes {
            let (frames, evals) = pass?;
            spent += evals;
            answers.extend(frames);
        }
        // A stable sort: each frame's answers stay in the passes' order.
        answers.sort_by_key(|f| f.index);
        Ok((answers, spent))
    }

    /// One pass over a block of frames after the first pass (the targets of frames
    /// `from`, `from` + 1, …): initialised afresh on the block's last frame with a
    /// person, or on the middle one of its frames with a person, with the clip's
    /// shape, its candidates chosen as the first pass's are (probed on the frames
    /// before that one), tracked backwards to the block's first frame (and from the
    /// middle forwards to its last frame with a person) and refitted. Its frames up
    /// to that last one with a person (none when the block has no person), and the
    /// evaluations spent. Gives up ([`TrackError::Canceled`]) once `abort` is set,
    /// as on a stop.
    fn block_pass(
        &self,
        body: &Body,
        shape: ShapeValues,
        from: usize,
        mut targets: Vec<Option<Arc<Target>>>,
        abort: &AtomicBool,
        start: BlockStart,
    ) -> BlockResult {
        let check = || match abort.load(Ordering::Relaxed) {
            true => Err(TrackError::Canceled),
            false => self.check_stop(),
        };
        let people: Vec<usize> = (0..targets.len())
            .filter(|&i| targets[i].is_some())
            .collect();
        let Some(&last) = people.last() else {
            return Ok((Vec::new(), 0));
        };
        targets.truncate(last + 1);
        let init = match start {
            BlockStart::Last => {
                // The best-scoring of the last few frames with a person (the
                // latest among equals).
                let window = self.opts.second_pass_window.max(1);
                let tail = &people[people.len().saturating_sub(window)..];
                let score = |i: usize| {
                    targets[i]
                        .as_ref()
                        .map_or(f64::NEG_INFINITY, |t| t.init_score)
                };
                tail.iter()
                    .copied()
                    .max_by(|&a, &b| score(a).total_cmp(&score(b)))
                    .unwrap_or(last)
            }
            BlockStart::Inner(k, parts) => people[(people.len() - 1) * k / parts],
        };
        let init_target = targets[init].as_deref().expect("a person frame");
        let (_, candidates) =
            self.initialise_with(init_target, Some(shape), &self.opts.start_shape);
        check()?;
        let mut evals = 0;
        let init_pose = if candidates.len() == 1 {
            candidates[0]
        } else {
            let refs: Vec<Option<&Target>> =
                targets[..=init].iter().map(Option::as_deref).collect();
            let (totals, e) = self.probe_candidates(body, &candidates, &refs, from, init)?;
            evals += e;
            let (chosen, e) = self.choose_initial(body, init_target, &totals, &refs, init);
            evals += e;
            chosen
        };
        let (mut search, init_frame) = self.start_on(body, from + init, init_target, init_pose);
        let (ground, init_pose) = (search.ground, init_frame.pose);
        let mut frames = vec![None; last + 1];
        frames[init] = Some(init_frame);
        let mut history = History::new(init_pose);
        for i in (0..init).rev() {
            check()?;
            frames[i] = Some(search.step(from + i, targets[i].as_deref(), &mut history));
        }
        let mut history = History::new(init_pose);
        for i in init + 1..=last {
            check()?;
            frames[i] = Some(search.step(from + i, targets[i].as_deref(), &mut history));
        }
        evals += search.evals;
        // The refit: every frame's neighbours are known, so each round's frames are
        // refitted side by side (each exactly as one thread would).
        let mut frames: Vec<Refitted> = frames
            .into_iter()
            .map(|f| f.expect("tracked"))
            .zip(targets)
            .collect();
        for _ in 0..self.refit_rounds() {
            let mut window = Window::new(self.opts.refit_sigma);
            for (f, t) in frames {
                window.push(f, t);
            }
            let jobs: Vec<Job<Arc<Target>>> = std::iter::from_fn(|| window.next(true)).collect();
            // A search of its own for each job (a search's outline buffers are not
            // shared between threads).
            let refitted = par_map(&jobs, self.threads(), |job| match check() {
                Ok(()) => Search::new(self, body, ground).refit(job),
                Err(_) => (job.frame.clone(), 0),
            });
            check()?;
            evals += refitted.iter().map(|(_, e)| e).sum::<u64>();
            frames = refitted
                .into_iter()
                .zip(jobs)
                .map(|((f, _), job)| (f, job.target))
                .collect();
        }
        Ok((frames.into_iter().map(|(f, _)| f).collect(), evals))
    }

    /// Each initial candidate tracked over the frames after `init` (then, when there
    /// are too few, the ones before it), each with its own history, under the
    /// paper's objective: their summed costs, for [`choose_hypothesis`], and the
    /// evaluations spent. `targets` holds the targets of frames `from`, `from` + 1,
    /// … up to the last one probed (None without a person); `init` counts from
    /// `from`.
    fn probe_candidates(
        &self,
        body: &Body,
        candidates: &[Pose],
        targets: &[Option<&Target>],
        from: usize,
        init: usize,
    ) -> Result<(Vec<(f64, Pose)>, u64), TrackError> {
        let (after, before) = probe_frames(targets.len(), init, HYPOTHESIS_FRAMES);
        // These frames' targets under the paper's objective, made once for all the
        // candidates (none without a reward rim).
        let paper: Vec<Option<Target>> = (0..targets.len())
            .map(|i| {
                let probed = after.contains(&i) || before.contains(&i);
                probed.then(|| targets[i].and_then(Target::paper)).flatten()
            })
            .collect();
        // Each candidate's probe is independent of the others': side by side.
        let probed: Vec<Result<(f64, u64), TrackError>> =
            par_map(candidates, self.threads(), |c| {
                let mut probe = Search::new(self, body, sole_height(body, &body.posed(c)));
                probe.weigh_outlines = false;
                probe.joint_velocity = true;
                if !self.opts.full_probes {
                    probe.restarts = PROBE_RESTARTS;
                    probe.jumps = false;
                }
                let mut total = 0.0;
                for run in [&after, &before] {
                    let mut history = History::new(*c);
                    for &i in run.iter() {
                        self.check_stop()?;
                        let t = paper[i].as_ref().or(targets[i]);
                        total += probe.step(from + i, t, &mut history).cost.unwrap_or(0.0);
                    }
                }
                Ok((total, probe.evals))
            });
        let mut totals: Vec<(f64, Pose)> = Vec::with_capacity(candidates.len());
        let mut evals = 0;
        for (c, probed) in candidates.iter().zip(probed) {
            let (total, e) = probed?;
            evals += e;
            totals.push((total, *c));
        }
        Ok((totals, evals))
    }

    /// The start, shape and initial pose, among `starts` (one per initialisation,
    /// [`TrackOptions::round_start`], and each one's depth mirror,
    /// [`TrackOptions::mirror_starts`]) that tracks the [`START_PROBE_FRAMES`] frames
    /// after the initial frame `init` (those before it when the clip ends first)
    /// at the lowest summed cost, the initial frame's included; its tracked frames;
    /// and the evaluations spent. The frames are tracked as the first pass tracks
    /// them (from the initial frame on, forwards, then backwards), under the
    /// tracking objective, so the first pass takes the winner's as they are;
    /// `targets` holds the targets of the frames from the first (None without a
    /// person).
    fn probe_starts(
        &self,
        starts: &[(ShapeValues, Pose)],
        targets: &[Option<&Target>],
        init: usize,
    ) -> Result<((ShapeValues, Pose), Probed, u64), TrackError> {
        let (after, before) = probe_frames(targets.len(), init, START_PROBE_FRAMES);
        let init_target = targets[init].expect("a person frame");
        // Each start's probe is independent of the others': side by side.
        let probed: Vec<Result<(f64, Probed, u64), TrackError>> =
            par_map(starts, self.threads(), |(shape, pose)| {
                let body = Body::new(shape);
                let (mut search, frame) = self.start_on(&body, init, init_target, *pose);
                let mut total = frame.cost.unwrap_or(0.0);
                let mut tracked = Probed::new();
                for run in [&after, &before] {
                    let mut history = History::new(frame.pose);
                    for &i in run.iter() {
                        self.check_stop()?;
                        let f = search.step(i, targets[i], &mut history);
                        total += f.cost.unwrap_or(0.0);
                        tracked.insert(i, (f, history.clone()));
                    }
                }
                Ok((total, tracked, search.evals))
            });
        let mut best: Option<(f64, (ShapeValues, Pose), Probed)> = None;
        let mut evals = 0;
        for (start, probed) in starts.iter().zip(probed) {
            let (total, tracked, e) = probed?;
            evals += e;
            if best.as_ref().is_none_or(|(b, _, _)| total < *b) {
                best = Some((total, *start, tracked));
            }
        }
        let (start, tracked) = best.map_or((starts[0], Probed::new()), |(_, s, t)| (s, t));
        Ok((start, tracked, evals))
    }

    /// The depth mirror of the start `pose` ([`super::flips::depth_mirror`]) for a
    /// body of `shape`, refined on the initial frame's `target` as the
    /// initialisation fits a heading (from the joint limits, three runs), under
    /// the tracking objective by which the starts are compared
    /// ([`TrackOptions::mirror_starts`]); and the evaluations spent.
    fn mirror_start(&self, shape: &ShapeValues, pose: &Pose, target: &Target) -> (Pose, u64) {
        let body = Body::new(shape);
        let mirror = super::flips::depth_mirror(pose);
        let (mirror, _, evals) = Search::initial(self, &body).fit_wide_counted(target, mirror, 3);
        (mirror, evals)
    }

    /// The initial pose among the probed candidates (each with its summed cost over
    /// the probe frames) and the evaluations spent choosing: [`choose_hypothesis`],
    /// unless the person travels. People walk and run forwards, so a travelling
    /// person's candidate is the one whose front points along the travel, when it
    /// does so clearly better than the one [`choose_hypothesis`] chose
    /// ([`TRAVEL_ALONG`], [`TRAVEL_MARGIN`]); that one's depth mirror
    /// ([`super::flips::depth_mirror`], which one view cannot tell from it, and which
    /// on a view from 60° off the front is only 60° away in heading), refined, is
    /// among the candidates.
    fn choose_initial(
        &self,
        body: &Body,
        init_target: &Target,
        probes: &[(f64, Pose)],
        targets: &[Option<&Target>],
        init: usize,
    ) -> (Pose, u64) {
        let chosen = choose_hypothesis(probes, &self.camera);
        let Some(travel) = self.travel(body, &chosen, targets, init) else {
            return (chosen, 0);
        };
        // Refined under the paper's objective, as the other candidates were.
        let paper = init_target.paper();
        let mirror = super::flips::depth_mirror(&chosen);
        let (mirror, _, evals) = Search::initial(self, body).fit_wide_counted(
            paper.as_ref().unwrap_or(init_target),
            mirror,
            3,
        );
        let along = |p: &Pose| travel.along(p[ix::ROOT_RY]);
        let best = probes
            .iter()
            .map(|(_, p)| *p)
            .chain([mirror])
            .max_by(|a, b| along(a).total_cmp(&along(b)))
            .unwrap_or(chosen);
        let clearly = along(&best) > TRAVEL_ALONG && along(&best) - along(&chosen) > TRAVEL_MARGIN;
        (if clearly { best } else { chosen }, evals)
    }

    /// The person's travel around the initial frame `init`, the ground under
    /// `body` posed as `pose` there, when they travel at [`TRAVEL_SPEED`] or more
    /// ([`Tracker::silhouette_travel`]).
    fn travel(
        &self,
        body: &Body,
        pose: &Pose,
        targets: &[Option<&Target>],
        init: usize,
    ) -> Option<Travel> {
        let ground = sole_height(body, &body.posed(pose));
        self.silhouette_travel(targets, init, ground)
            .filter(|t| t.speed() >= TRAVEL_SPEED)
    }

    /// The person's travel over up to [`TRAVEL_FRAMES`] frames either side of
    /// `init`, the ground at height `ground` ([`ground_travel`]).
    fn silhouette_travel(
        &self,
        targets: &[Option<&Target>],
        init: usize,
        ground: f64,
    ) -> Option<Travel> {
        let lo = init.saturating_sub(TRAVEL_FRAMES);
        let hi = (init + TRAVEL_FRAMES + 1).min(targets.len());
        let boxes: Vec<(usize, [u32; 4])> = (lo..hi)
            .filter_map(|i| Some((i, mask_bbox(&targets[i]?.silhouette)?)))
            .collect();
        ground_travel(&self.camera, &boxes, ground, self.opts.fps)
    }

    /// Initialisation (method.md §5, paper §5.1) on one frame: place the body of
    /// [`TrackOptions::start_shape`] from the silhouette's bounding box, fit the pose
    /// from several headings (the silhouette does not say which way the person
    /// faces), each from the rest pose and from an exemplar
    /// ([`TrackOptions::exemplar_starts`]), and keep the best, then fit the 12 shape
    /// values with the root translation, and the pose again; then both at once
    /// ([`Tracker::joint_fit`]).
    /// `target` is the frame as tracked: the fits judge by the paper's objective
    /// ([`Target::paper`]), the joint fit by the tracking one.
    ///
    /// Returns the shape and the candidate poses, best first: the best fit and the
    /// best one facing more than 90° away from it, fitted with the best fit's shape
    /// (a silhouette seen from the front and from the back is nearly the same; the
    /// frames that follow tell them apart). Returns early, with a meaningless
    /// result, when [`TrackOptions::stop`] is set.
    pub fn initialise(&self, target: &Target) -> (ShapeValues, Vec<Pose>) {
        self.initialise_with(target, self.opts.known_shape, &self.opts.start_shape)
    }

    /// [`Tracker::initialise`], with the shape `known` when it is given, placing,
    /// posing and fitting from `start_shape` rather than [`TrackOptions::start_shape`].
    fn initialise_with(
        &self,
        target: &Target,
        known: Option<ShapeValues>,
        start_shape: &ShapeValues,
    ) -> (ShapeValues, Vec<Pose>) {
        let plain = target;
        let paper = plain.paper();
        let target = paper.as_ref().unwrap_or(plain);
        let cam = &self.camera;
        let bbox = mask_bbox(&target.silhouette).expect("a person");
        let (_, rest) = standard_rest();
        let start = Body::new(start_shape);
        let posed = start.posed(&rest);
        let top = posed.tips[Tip::HeadTop as usize].y;
        let sole = sole_height(&start, &posed);
        let tall = top - sole;
        let hip_up = rest[ix::ROOT_TY] - sole;
        let h_px = (bbox[3] - bbox[1] + 1) as f64;
        let depth = cam.fy * tall / h_px;
        let u = (bbox[0] + bbox[2] + 1) as f64 / 2.0;
        let v_hips = (bbox[3] + 1) as f64 - h_px * hip_up / tall;
        let mut base = rest_pose();
        base[ix::ROOT_TX] = (u - cam.cx) * depth / cam.fx;
        base[ix::ROOT_TY] = (cam.cy - v_hips) * depth / cam.fy;
        base[ix::ROOT_TZ] = -depth;
        base[ix::L_SHOULDER + 1] = 15.0;
        base[ix::R_SHOULDER + 1] = 15.0;

        // Each heading's fit is independent of the others': side by side.
        let threads = self.threads();
        let exemplars = self
            .opts
            .pose_prior
            .as_deref()
            .filter(|p| self.opts.exemplar_starts && !p.exemplars().is_empty());
        let wide = || Search::initial(self, &start);
        let headings: Vec<i32> = (0..12).collect();
        let mut fits: Vec<(f64, Pose)> = par_map(&headings, threads, |&k| {
            let mut p = base;
            p[ix::ROOT_RY] = k as f64 * 30.0 - 150.0;
            if self.stopping() {
                return (f64::INFINITY, p);
            }
            let (pose, cost) = wide().fit_wide(target, p, 2);
            let Some(e) = exemplars.and_then(|x| cheapest_start(&wide(), target, &p, x)) else {
                return (cost, pose);
            };
            let (other, other_cost) = wide().fit_wide(target, e, 2);
            if other_cost < cost {
                (other_cost, other)
            } else {
                (cost, pose)
            }
        });
        fits.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut refined: Vec<(f64, Pose)> =
            par_map(&fits[..4.min(fits.len())], threads, |(c, p)| {
                if self.stopping() {
                    return (*c, *p);
                }
                let (pose, cost) = wide().fit_wide(target, *p, 3);
                (cost, pose)
            });
        refined.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut pose = refined[0].1;
        let heading = |p: &Pose| p[ix::ROOT_RY];
        let turned = |a: f64, b: f64| {
            let d = (a - b).rem_euclid(360.0);
            d.min(360.0 - d) > 90.0
        };
        let other = fits
            .iter()
            .chain(refined.iter())
            .filter(|(_, p)| turned(heading(p), heading(&pose)))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, p)| *p);

        // A known shape: the pose alone is fitted again, with its body; otherwise
        // the shape with the root translation, alternating with the pose.
        let mut shape = known.unwrap_or(*start_shape);
        let rounds = if known.is_some() {
            let body = Body::new(&shape);
            pose = Search::initial(self, &body).fit_wide(target, pose, 3).0;
            0
        } else {
            3
        };
        for _ in 0..rounds {
            if self.stopping() {
                break;
            }
            let mut x0: Vec<f64> = shape.to_vec();
            x0.extend_from_slice(&pose[ix::ROOT_TX..=ix::ROOT_TZ]);
            let mut steps: Vec<f64> = SHAPE.iter().map(|s| 3.0 * s.scale).collect();
            steps.extend_from_slice(&[2.0, 2.0, 8.0]);
            let mut lo: Vec<f64> = SHAPE.iter().map(|s| s.lo).collect();
            let mut hi: Vec<f64> = SHAPE.iter().map(|s| s.hi).collect();
            for v in &pose[ix::ROOT_TX..=ix::ROOT_TZ] {
                lo.push(v - 50.0);
                hi.push(v + 50.0);
            }
            let fixed = pose;
            let r = minimize(
                |x| {
                    let mut s = [0.0; SHAPE_COUNT];
                    s.copy_from_slice(&x[..SHAPE_COUNT]);
                    let mut p = fixed;
                    p[ix::ROOT_TX..=ix::ROOT_TZ].copy_from_slice(&x[SHAPE_COUNT..]);
                    let body = Body::new(&s);
                    let w = Weights {
                        smooth: false,
                        ..self.opts.weights.unbounded_ends()
                    };
                    Evaluator::new(&body, cam, target, w, None).cost(&p)
                },
                &x0,
                &steps,
                &lo,
                &hi,
                &simplex_options(1200),
            );
            shape.copy_from_slice(&r.x[..SHAPE_COUNT]);
            pose[ix::ROOT_TX..=ix::ROOT_TZ].copy_from_slice(&r.x[SHAPE_COUNT..]);
            let body = Body::new(&shape);
            pose = Search::initial(self, &body).fit_wide(target, pose, 2).0;
        }
        if known.is_none() && !self.stopping() {
            if let Some((s, p)) = self.joint_fit(plain, &shape, &pose) {
                shape = s;
                let body = Body::new(&shape);
                pose = Search::initial(self, &body).fit_wide(target, p, 2).0;
            }
        }
        let mut poses = vec![pose];
        if let Some(o) = other.filter(|_| !self.stopping()) {
            let body = Body::new(&shape);
            let s = Search::initial(self, &body);
            let mut o = o;
            o[ix::ROOT_TX..=ix::ROOT_TZ].copy_from_slice(&pose[ix::ROOT_TX..=ix::ROOT_TZ]);
            poses.push(s.fit_wide(target, o, 3).0);
        }
        (shape, poses)
    }
}

impl Tracker {
    /// The initialisation's joint fit ([`TrackOptions::init_joint_evals`]): CMA-ES
    /// over the 12 shape values and the 30 pose values at once, from `shape` and
    /// `pose`, under the tracking objective on `target` (the frame as tracked, with
    /// shares of pixels and the pose prior, [`TrackOptions::pose_prior`]; without
    /// the prior the search bends the pose to suit a shape, README "The pose prior
    /// in the joint fit"), plus the proportions prior ([`ratio_penalty`], against a
    /// segment traded for its neighbour). Each value moves in units of its length
    /// scale, with a spread of [`INIT_JOINT_SPREAD`] of them; the shape within its
    /// plausible range. A larger or smaller body is moved away from or towards the
    /// camera in proportion, and up or down, so that its head top and soles keep
    /// their place in the picture: the size the silhouette shows is then kept while
    /// the proportions change. The best shape and pose evaluated, when they cost less
    /// than the ones given.
    fn joint_fit(
        &self,
        target: &Target,
        shape: &ShapeValues,
        pose: &Pose,
    ) -> Option<(ShapeValues, Pose)> {
        let budget = self.opts.init_joint_evals;
        if budget == 0 {
            return None;
        }
        let cam = &self.camera;
        let weights = Weights {
            smooth: true,
            ..self.opts.weights.unbounded_ends()
        };
        // The vertical extent (head top over the soles) and the hips' height over
        // the soles of a body in a pose.
        let extent = |body: &Body, p: &Pose| {
            let posed = body.posed(p);
            let sole = sole_height(body, &posed);
            (
                posed.tips[Tip::HeadTop as usize].y - sole,
                p[ix::ROOT_TY] - sole,
            )
        };
        let prior = self.opts.pose_prior.as_deref();
        let base_body = Body::new(shape);
        let (tall0, hips0) = extent(&base_body, pose);
        let ratio =
            |s: &ShapeValues| ratio_penalty(s, &self.opts.start_shape, self.opts.shape_ratio_prior);
        let base_f = Evaluator::new(&base_body, cam, target, weights, None)
            .with_prior(prior)
            .cost(pose)
            + ratio(shape);
        if tall0.is_nan() || tall0 <= 0.0 {
            return None;
        }
        // Scaling about the camera's centre keeps every point's image.
        let eye = cam.world_to_camera.inverse() * nalgebra::Point3::origin();
        let place = |z: &[f64]| -> (ShapeValues, Pose) {
            let mut s = *shape;
            for (k, v) in s.iter_mut().enumerate() {
                *v = (shape[k] + SHAPE[k].scale * z[k]).clamp(SHAPE[k].lo, SHAPE[k].hi);
            }
            let mut p = *pose;
            for (k, v) in p.iter_mut().enumerate() {
                *v = pose[k] + MOTION[k].scale * z[SHAPE_COUNT + k];
            }
            let body = Body::new(&s);
            let (tall, hips) = extent(&body, &p);
            let scale = tall / tall0;
            if scale.is_finite() && scale > 0.0 {
                let sole = p[ix::ROOT_TY] - hips0;
                p[ix::ROOT_TX] = eye.x + scale * (p[ix::ROOT_TX] - eye.x);
                p[ix::ROOT_TY] = eye.y + scale * (sole - eye.y) + hips;
                p[ix::ROOT_TZ] = eye.z + scale * (p[ix::ROOT_TZ] - eye.z);
            }
            (s, p)
        };
        let mut found: Option<(f64, ShapeValues, Pose)> = None;
        let cost = |z: &cmaes::DVector<f64>| -> f64 {
            if self.stopping() {
                return f64::MAX / 4.0;
            }
            let (s, p) = place(z.as_slice());
            let body = Body::new(&s);
            let c = Evaluator::new(&body, cam, target, weights, None)
                .with_prior(prior)
                .cost(&p)
                + ratio(&s);
            if c < found.as_ref().map_or(base_f, |f| f.0) {
                found = Some((c, s, p));
            }
            // CMA-ES needs a number: outside the limits is merely very bad.
            if c.is_finite() {
                c
            } else {
                f64::MAX / 4.0
            }
        };
        let run =
            cmaes::CMAESOptions::new(vec![0.0; SHAPE_COUNT + MOTION_COUNT], INIT_JOINT_SPREAD)
                .max_function_evals(budget)
                .seed(INIT_JOINT_SEED)
                .build(cost);
        // Valid by construction (42 dimensions, a positive spread); a refusal
        // keeps the shape and pose given.
        if let Ok(mut state) = run {
            state.run();
        }
        found.map(|(_, s, p)| (s, p))
    }
}

/// Spread (natural log) of the proportions prior's ratios ([`ratio_penalty`]).
const RATIO_SIGMA: f64 = 0.15;

/// The proportions prior: `weight` times the sum of squared deviations, in units
/// of [`RATIO_SIGMA`], of the log-ratios of upper arm to forearm, thigh to shin and
/// trunk to thigh in `shape` from those in `start`. It holds the trade of one
/// segment for its neighbour (README "The shape over several frames") without
/// pulling the body's size or any one length.
fn ratio_penalty(shape: &ShapeValues, start: &ShapeValues, weight: f64) -> f64 {
    use crate::body::params::sx;
    if weight <= 0.0 {
        return 0.0;
    }
    const PAIRS: [(usize, usize); 3] = [
        (sx::UPPER_ARM, sx::FOREARM),
        (sx::THIGH, sx::SHIN),
        (sx::TORSO_HEIGHT, sx::THIGH),
    ];
    let log_ratio = |s: &ShapeValues, (a, b): (usize, usize)| (s[a] / s[b]).ln();
    weight
        * PAIRS
            .iter()
            .map(|&pair| ((log_ratio(shape, pair) - log_ratio(start, pair)) / RATIO_SIGMA).powi(2))
            .sum::<f64>()
}

/// The initial pose among `candidates` (each with its summed cost over the next
/// frames): the cheapest, unless it turns its back on the camera and a candidate
/// facing the camera comes within [`FACING_TIE`] (a fraction) of its cost.
///
/// One silhouette cannot tell a body from its mirror image in depth (facing the
/// camera or turned away, left and right swapped): only perspective separates them,
/// and only a little. On the benchmark's frontal clips the right one of the two was
/// the dearer over the probe frames in 24 of 54 clip runs, a coin toss. Real clips
/// for motion capture mostly start with the person facing the camera, so a tie goes
/// that way. Over the accuracy benchmark's 162 clip runs (three noise seeds, with
/// and without a lead-in, each clip tracked from both candidates) the cheapest
/// candidate scores a mean PCK@0.1 of 0.753, a 1% tie 0.826 and a 2% tie 0.843; a
/// 2% tie turned 8 choices, 6 of them gaining 0.15–0.63 of a clip's PCK and one (a
/// person facing away) losing 0.28. A keyframe on the initial frame overrides it,
/// and so does a travelling person's direction ([`Tracker::choose_initial`]).
fn choose_hypothesis(candidates: &[(f64, Pose)], camera: &Camera) -> Pose {
    let cheapest = candidates
        .iter()
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .expect("candidates");
    if faces_camera(&cheapest.1, camera) {
        return cheapest.1;
    }
    let slack = FACING_TIE * cheapest.0.abs();
    candidates
        .iter()
        .filter(|(f, p)| faces_camera(p, camera) && *f <= cheapest.0 + slack)
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .unwrap_or(cheapest)
        .1
}

/// A person's move on the ground: x and z in the world (cm) over `secs` seconds.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Travel {
    dx: f64,
    dz: f64,
    secs: f64,
}

impl Travel {
    /// Speed on the ground, cm/s.
    fn speed(&self) -> f64 {
        self.dx.hypot(self.dz) / self.secs.max(1e-9)
    }

    /// The cosine between the travel and the front of a body at `heading`
    /// (degrees; +Z at rest, as [`faces_camera`] has it).
    fn along(&self, heading: f64) -> f64 {
        let h = heading.to_radians();
        (h.sin() * self.dx + h.cos() * self.dz) / self.dx.hypot(self.dz).max(1e-9)
    }
}

/// Where a person goes on the ground (the world's plane y = `ground`), from the
/// bounding boxes of their silhouettes (frame, box): the box's lowest row is where
/// a foot stands (one is down most of the time while walking or running), so the
/// ray through its middle meets the ground where the person is. A straight line
/// fitted to those points over the frames by least squares gives the move. None
/// from fewer than five such points (boxes that reach no lower than the horizon
/// meet no ground).
fn ground_travel(
    camera: &Camera,
    boxes: &[(usize, [u32; 4])],
    ground: f64,
    fps: f64,
) -> Option<Travel> {
    let eye = camera.eye();
    let mut pts: Vec<[f64; 3]> = Vec::with_capacity(boxes.len());
    for &(i, b) in boxes {
        let ray = camera.ray((b[0] + b[2] + 1) as f64 / 2.0, (b[3] + 1) as f64);
        let t = (ground - eye.y) / ray.y;
        if t.is_finite() && t > 0.0 {
            let p = eye + t * ray;
            pts.push([i as f64, p.x, p.z]);
        }
    }
    if pts.len() < 5 {
        return None;
    }
    let n = pts.len() as f64;
    let mean = |k: usize| pts.iter().map(|p| p[k]).sum::<f64>() / n;
    let mt = mean(0);
    let stt: f64 = pts.iter().map(|p| (p[0] - mt).powi(2)).sum();
    let slope = |k: usize| {
        let m = mean(k);
        pts.iter().map(|p| (p[0] - mt) * (p[k] - m)).sum::<f64>() / stt
    };
    let span = pts[pts.len() - 1][0] - pts[0][0];
    Some(Travel {
        dx: slope(1) * span,
        dz: slope(2) * span,
        secs: span / fps.max(1.0),
    })
}

/// Whether the body's front (+Z at rest, turned by the heading) points towards the
/// camera rather than away from it (on the ground plane).
fn faces_camera(pose: &Pose, camera: &Camera) -> bool {
    let h = pose[ix::ROOT_RY].to_radians();
    let eye = camera.eye();
    let to_camera = (eye.x - pose[ix::ROOT_TX], eye.z - pose[ix::ROOT_TZ]);
    h.sin() * to_camera.0 + h.cos() * to_camera.1 > 0.0
}

/// How suitable a frame is for initialisation: the person whole and apart (both
/// hands, both feet and the head found, legs apart), not touching the border.
fn init_score(f: &FrameFeatures) -> f64 {
    use crate::vision::features::ExtremityKind as K;
    let Some(bbox) = f.bbox else {
        return f64::NEG_INFINITY;
    };
    let count = |k: K| f.extremities.iter().filter(|e| e.kind == k).count().min(2) as f64;
    let mut s = count(K::Hand) + count(K::Foot);
    if f.head.is_some() {
        s += 1.0;
    }
    if f.crotch.is_some() {
        s += 1.0;
    }
    if bbox[0] == 0 || bbox[1] == 0 || bbox[2] + 1 >= f.width || bbox[3] + 1 >= f.height {
        s -= 3.0;
    }
    // Among equals, a larger person (nearer, better resolved) wins slightly.
    s + 1e-4 * f.body_height
}

/// The frames a probe tracked, each with the history its tracking left.
type Probed = std::collections::HashMap<usize, (TrackedFrame, History)>;

/// The `n` frames a probe from frame `init` tracks, of `len`: those after it in
/// order, then, where the clip ends first, those before it, backwards.
fn probe_frames(len: usize, init: usize, n: usize) -> (Vec<usize>, Vec<usize>) {
    let after: Vec<usize> = (init + 1..len).take(n).collect();
    let before: Vec<usize> = (0..init).rev().take(n - after.len()).collect();
    (after, before)
}

/// The smoothed refit's runner: its rounds ([`TrackOptions::refit_rounds`]), each
/// a [`RefitRound`] taking the frames the round before it hands back. Frames come
/// back in order.
struct Refit<'a> {
    rounds: Vec<RefitRound<'a>>,
}

impl<'a> Refit<'a> {
    fn start<'scope>(
        scope: &'scope std::thread::Scope<'scope, 'a>,
        tracker: &'a Tracker,
        body: &'a Body,
        ground: f64,
    ) -> Refit<'a> {
        let rounds = (0..tracker.refit_rounds())
            .map(|_| RefitRound::start(scope, tracker, body, ground))
            .collect();
        Refit { rounds }
    }

    /// Adds the next frame in index order (its target, None without a person).
    fn push(&mut self, frame: TrackedFrame, target: Option<Arc<Target>>) {
        self.rounds[0].push(frame, target);
    }

    /// The frames through every round since the last call, in order: without
    /// waiting for the helpers unless `end` (no more frames will come: all of
    /// them).
    fn finished(&mut self, end: bool) -> Vec<TrackedFrame> {
        let (first, later) = self.rounds.split_first_mut().expect("one round at least");
        let mut frames = first.finished(end);
        for round in later {
            for (f, target) in frames {
                round.push(f, target);
            }
            frames = round.finished(end);
        }
        frames.into_iter().map(|(f, _)| f).collect()
    }

    /// Evaluations spent, and seconds spent on the search's own thread.
    fn spent(&self) -> (u64, f64) {
        self.rounds
            .iter()
            .fold((0, 0.0), |(e, s), r| (e + r.evals, s + r.here_secs))
    }
}

/// A frame refitted, with its target (kept for the next round).
type Refitted = (TrackedFrame, Option<Arc<Target>>);

/// One round of the smoothed refit: the frames' [`Window`], and a helper thread
/// that refits them when the tracker has two threads or more (the search's own
/// thread otherwise, and for the last frames of the clip, while the helper
/// finishes the ones before them). Frames come back in order.
struct RefitRound<'a> {
    window: Window<Arc<Target>>,
    here: Search<'a>,
    helper: Option<RefitHelper>,
    /// Frames refitted on the helper thread, in order, not yet collected.
    back: Vec<Refitted>,
    /// Evaluations spent, and seconds spent on the search's own thread.
    evals: u64,
    here_secs: f64,
}

struct RefitHelper {
    /// None once the last frame was sent (the helper then ends).
    jobs: Option<SyncSender<Job<Arc<Target>>>>,
    results: Receiver<(Refitted, u64)>,
    /// Jobs sent and not yet received.
    out: usize,
}

impl<'a> RefitRound<'a> {
    fn start<'scope>(
        scope: &'scope std::thread::Scope<'scope, 'a>,
        tracker: &'a Tracker,
        body: &'a Body,
        ground: f64,
    ) -> RefitRound<'a> {
        let mut helper = None;
        if tracker.threads() > 1 && tracker.opts.refit_sigma > 0.0 {
            let (job_tx, job_rx) = sync_channel::<Job<Arc<Target>>>(REFIT_QUEUE);
            let (out_tx, out_rx) = channel();
            let spawned = std::thread::Builder::new()
                .name("monocap-refit".into())
                .spawn_scoped(scope, move || {
                    let search = Search::new(tracker, body, ground);
                    for job in job_rx {
                        let (f, evals) = search.refit(&job);
                        if out_tx.send(((f, job.target), evals)).is_err() {
                            break;
                        }
                    }
                });
            // A thread the system cannot start: all is refitted here.
            if spawned.is_ok() {
                helper = Some(RefitHelper {
                    jobs: Some(job_tx),
                    results: out_rx,
                    out: 0,
                });
            }
        }
        RefitRound {
            window: Window::new(tracker.opts.refit_sigma),
            here: Search::new(tracker, body, ground),
            helper,
            back: Vec::new(),
            evals: 0,
            here_secs: 0.0,
        }
    }

    /// Adds the next frame in index order (its target, None without a person).
    fn push(&mut self, frame: TrackedFrame, target: Option<Arc<Target>>) {
        self.window.push(frame, target);
    }

    /// The frames refitted since the last call, in order, with their targets:
    /// without waiting for the helper unless `end` (no more frames will come: all
    /// of them).
    fn finished(&mut self, end: bool) -> Vec<Refitted> {
        // Refitted here: at the end, the frames after all those sent to the helper.
        let mut mine = Vec::new();
        while let Some(job) = self.window.next(end) {
            match &mut self.helper {
                Some(RefitHelper {
                    jobs: Some(tx),
                    out,
                    ..
                }) if !end => {
                    // The helper ends only when its jobs are dropped, which is
                    // after this: the send finds it.
                    tx.send(job).expect("the refit helper ended early");
                    *out += 1;
                    self.collect(false);
                }
                _ => {
                    let t0 = Instant::now();
                    let (f, evals) = self.here.refit(&job);
                    self.here_secs += t0.elapsed().as_secs_f64();
                    self.evals += evals;
                    mine.push((f, job.target));
                }
            }
        }
        if end {
            if let Some(h) = &mut self.helper {
                h.jobs = None;
            }
        }
        self.collect(end);
        let mut done = std::mem::take(&mut self.back);
        done.append(&mut mine);
        done
    }

    /// Takes the helper's answers into `back`, waiting for all of them when `all`.
    fn collect(&mut self, all: bool) {
        let Some(h) = &mut self.helper else {
            return;
        };
        while h.out > 0 {
            let got = if all {
                h.results.recv().ok()
            } else {
                h.results.try_recv().ok()
            };
            let Some((f, evals)) = got else {
                break;
            };
            h.out -= 1;
            self.evals += evals;
            self.back.push(f);
        }
    }
}

/// What the second pass runs with: the tracker, the clip's body and shape, and the
/// scope its threads run in.
struct Pass<'scope, 'env> {
    scope: &'scope Scope<'scope, 'env>,
    tracker: &'env Tracker,
    body: &'env Body,
    shape: ShapeValues,
}

/// The next input frame's index, target (None without a person) and score as an
/// initial frame; None after the last frame.
type Next = Option<Result<(usize, Option<Target>, f64), TrackError>>;

/// Frames read and not yet searched by the first pass, with their targets (an
/// input's failure in its place).
type Queue = VecDeque<Result<(usize, Option<Arc<Target>>), TrackError>>;

/// A block's later passes ([`Tracker::block_passes`]): the second and middle
/// passes' answers for its frames, in frame order, and the evaluations spent.
type BlockResult = Result<(Vec<TrackedFrame>, u64), TrackError>;

/// The second pass's bookkeeping ([`TrackOptions::two_way`]): each target of the
/// block being gathered (shared with the first pass, which reads a whole block
/// before it searches its frames), the block whose second pass is running, and
/// the first pass's frames (reported as they come), held until their block's
/// second pass is done and the first pass has handed over the whole block; then
/// each frame takes the answer [`super::merge::choose`] picks among the passes'
/// ([`TrackOptions::switch_penalty`]), and is reported again when that is not the
/// first pass's. The second pass here stands for the block's later passes: the
/// backwards one and, beside it, the middle one ([`TrackOptions::middle_pass`],
/// [`Tracker::block_passes`]).
///
/// With more than one thread, a block's second pass runs on a helper thread while
/// the first pass searches the same frames; at most one block at a time, so the
/// targets of two blocks at most are held. Each pass depends only on the targets,
/// the clip's shape and the options, so the result is the same on any number of
/// threads.
struct TwoWay<'scope> {
    /// Frames per block; 0 when there is no second pass.
    block: usize,
    /// The first frame of the block being gathered, and its targets so far.
    from: usize,
    kept: Vec<Option<Arc<Target>>>,
    /// The block whose second pass runs on a helper thread: its end and thread.
    running: Option<(usize, ScopedJoinHandle<'scope, BlockResult>)>,
    /// Set when the track ends early: the helper then gives up.
    abort: Arc<AtomicBool>,
    /// The later passes' answers not yet merged, in frame order.
    back: VecDeque<TrackedFrame>,
    /// The first pass's frames (refitted) waiting for their block's second pass,
    /// each with whether it has been reported.
    held: VecDeque<(TrackedFrame, bool)>,
    /// The ends of the blocks whose second pass is done and whose frames are not
    /// yet merged, in order.
    ends: VecDeque<usize>,
    /// A frame whose first answer stands (the given initial pose).
    keep_first: Option<usize>,
    /// [`TrackOptions::switch_penalty`].
    penalty: f64,
    evals: u64,
    /// Seconds the first pass's thread spent on the second pass (running it, or
    /// waiting for its helper).
    secs: f64,
}

impl<'scope> TwoWay<'scope> {
    /// Blocks of `block` frames; 0 for no second pass.
    fn new(block: usize, keep_first: Option<usize>, penalty: f64) -> TwoWay<'scope> {
        TwoWay {
            block,
            from: 0,
            kept: Vec::new(),
            running: None,
            abort: Arc::new(AtomicBool::new(false)),
            back: VecDeque::new(),
            held: VecDeque::new(),
            ends: VecDeque::new(),
            keep_first,
            penalty,
            evals: 0,
            secs: 0.0,
        }
    }

    /// Keeps the next frame's target: the block (its first frame and targets) when
    /// this frame completes it.
    fn keep(&mut self, target: Option<&Arc<Target>>) -> Option<(usize, Vec<Option<Arc<Target>>>)> {
        if self.block == 0 {
            return None;
        }
        self.kept.push(target.cloned());
        if self.kept.len() < self.block {
            return None;
        }
        let from = self.from;
        self.from += self.block;
        Some((from, std::mem::take(&mut self.kept)))
    }

    /// Whether frame `index` (read or not) lies in a block not yet handed to the
    /// second pass.
    fn waits_for(&self, index: usize) -> bool {
        self.block > 0 && index >= self.from
    }

    /// Keeps the next frame's target, and starts the second pass on its block when
    /// this frame completes it.
    fn gather(
        &mut self,
        pass: &Pass<'scope, '_>,
        target: Option<&Arc<Target>>,
    ) -> Result<(), TrackError> {
        match self.keep(target) {
            Some((from, targets)) => self.start(pass, from, targets),
            None => Ok(()),
        }
    }

    /// The input has ended: the second pass starts on the last block, however short.
    fn end_input(&mut self, pass: &Pass<'scope, '_>) -> Result<(), TrackError> {
        if self.kept.is_empty() {
            return Ok(());
        }
        let from = self.from;
        let targets = std::mem::take(&mut self.kept);
        self.from += targets.len();
        self.start(pass, from, targets)
    }

    /// Puts the next input frame (None: the input has ended) at the end of the first
    /// pass's `queue`, and its target in the block; false once the input has ended.
    fn enqueue(
        &mut self,
        pass: &Pass<'scope, '_>,
        next: Next,
        queue: &mut Queue,
    ) -> Result<bool, TrackError> {
        match next {
            None => {
                self.end_input(pass)?;
                Ok(false)
            }
            Some(Err(e)) => {
                queue.push_back(Err(e));
                Ok(false)
            }
            Some(Ok((i, target, _))) => {
                let target = target.map(Arc::new);
                self.gather(pass, target.as_ref())?;
                queue.push_back(Ok((i, target)));
                Ok(true)
            }
        }
    }

    /// Starts the second pass over a whole block, once the one before it is done:
    /// on a helper thread, or here with one thread (or when none can be started).
    fn start(
        &mut self,
        pass: &Pass<'scope, '_>,
        from: usize,
        targets: Vec<Option<Arc<Target>>>,
    ) -> Result<(), TrackError> {
        self.wait()?;
        let end = from + targets.len();
        let &Pass {
            tracker,
            body,
            shape,
            ..
        } = pass;
        if tracker.threads() > 1 {
            let abort = Arc::clone(&self.abort);
            let targets = targets.clone();
            let spawned = std::thread::Builder::new()
                .name("monocap-second-pass".into())
                .spawn_scoped(pass.scope, move || {
                    tracker.block_passes(body, shape, from, targets, &abort)
                });
            if let Ok(handle) = spawned {
                self.running = Some((end, handle));
                return Ok(());
            }
        }
        let t0 = Instant::now();
        let result = tracker.block_passes(body, shape, from, targets, &self.abort);
        self.secs += t0.elapsed().as_secs_f64();
        self.done(end, result)
    }

    /// Takes the running block's second pass when it has finished, without waiting.
    fn poll(&mut self) -> Result<(), TrackError> {
        match &self.running {
            Some((_, h)) if h.is_finished() => self.wait(),
            _ => Ok(()),
        }
    }

    /// Waits for the running block's second pass, if any, and takes it.
    fn wait(&mut self) -> Result<(), TrackError> {
        let Some((end, handle)) = self.running.take() else {
            return Ok(());
        };
        let t0 = Instant::now();
        let result = handle
            .join()
            .unwrap_or_else(|e| std::panic::resume_unwind(e));
        self.secs += t0.elapsed().as_secs_f64();
        self.done(end, result)
    }

    fn done(&mut self, end: usize, result: BlockResult) -> Result<(), TrackError> {
        let (frames, evals) = result?;
        self.evals += evals;
        self.accept(end, frames);
        Ok(())
    }

    /// A block's second pass is done: the later passes' answers for its frames,
    /// which end before `end`.
    fn accept(&mut self, end: usize, frames: Vec<TrackedFrame>) {
        self.back.extend(frames);
        self.ends.push_back(end);
    }

    /// The last block's second pass (started when the input ended) is done.
    fn finish(&mut self, pass: &Pass<'scope, '_>) -> Result<(), TrackError> {
        self.end_input(pass)?;
        self.wait()
    }

    /// No more second passes after the one running: the frames held after its block
    /// have gone out as the first pass left them, and are not merged.
    fn abandon(&mut self) -> Result<(), TrackError> {
        self.kept.clear();
        self.wait()
    }

    /// Takes the first pass's next frames (in order) and says what to report: each
    /// frame once, at once (false), with the answer it keeps when its block is
    /// merged by then, and otherwise as the first pass left it; and, once its
    /// block is merged (its second pass done and all its frames handed over),
    /// again (true) each such frame whose answer the merge replaces.
    fn merge(&mut self, frames: Vec<TrackedFrame>) -> Vec<(TrackedFrame, bool)> {
        if self.block == 0 {
            return frames.into_iter().map(|f| (f, false)).collect();
        }
        self.held.extend(frames.into_iter().map(|f| (f, false)));
        let mut out = Vec::new();
        while let Some(&end) = self.ends.front() {
            // The block's frames are all here once the first pass has handed over
            // its last one.
            if self.held.back().is_none_or(|(f, _)| f.index + 1 < end) {
                break;
            }
            self.ends.pop_front();
            let n = self.held.iter().take_while(|(f, _)| f.index < end).count();
            // Each frame's answers, the first pass's first, and whether it has been
            // reported.
            let mut answers: Vec<Vec<TrackedFrame>> = Vec::with_capacity(n);
            let mut reported: Vec<bool> = Vec::with_capacity(n);
            for (first, r) in self.held.drain(..n) {
                while self.back.front().is_some_and(|b| b.index < first.index) {
                    self.back.pop_front();
                }
                let index = first.index;
                let mut these = vec![first];
                while let Some(b) = self.back.pop_front_if(|b| b.index == index) {
                    these.push(b);
                }
                answers.push(these);
                reported.push(r);
            }
            // A given initial pose is held on its frame whatever it costs: its frame
            // is in neither part, so it keeps its first answer, and the choice on
            // either side of it is made without it (a wrong one would otherwise hold
            // its neighbours to its branch).
            let mut chosen = vec![0; n];
            let pinned = answers
                .iter()
                .position(|a| Some(a[0].index) == self.keep_first);
            let parts = match pinned {
                Some(k) => [0..k, k + 1..n],
                None => [0..n, n..n],
            };
            for part in parts {
                let c = super::merge::choose(&answers[part.clone()], self.penalty);
                chosen[part].copy_from_slice(&c);
            }
            // Reported again where the answer changes; once where not yet reported.
            for ((mut these, reported), c) in answers.into_iter().zip(reported).zip(chosen) {
                if c > 0 || !reported {
                    out.push((these.swap_remove(c), reported));
                }
            }
        }
        for (f, reported) in self.held.iter_mut().filter(|(_, r)| !*r) {
            out.push((f.clone(), false));
            *reported = true;
        }
        out
    }
}

impl Drop for TwoWay<'_> {
    /// A track that ends early (an error, a stop) ends the helper's pass too; the
    /// scope it runs in waits for it.
    fn drop(&mut self) {
        self.abort.store(true, Ordering::Relaxed);
    }
}

/// Where a pass after the first starts on its block ([`Tracker::block_pass`]).
#[derive(Clone, Copy)]
enum BlockStart {
    /// The block's last frame with a person (the second pass).
    Last,
    /// With `Inner(k, n)`, the frame k/n of the way through its frames with a
    /// person ([`TrackOptions::middle_pass`], [`TrackOptions::middle_starts`]);
    /// `Inner(1, 2)` is the middle one.
    Inner(usize, usize),
}

impl BlockStart {
    /// Whether the two start at the same point of every block.
    fn same_as(&self, other: &BlockStart) -> bool {
        self.order(other) == std::cmp::Ordering::Equal
    }

    /// The order of two starts: [`BlockStart::Last`] first, then the inner ones by
    /// how far through the block they lie.
    fn order(&self, other: &BlockStart) -> std::cmp::Ordering {
        match (self, other) {
            (BlockStart::Last, BlockStart::Last) => std::cmp::Ordering::Equal,
            (BlockStart::Last, _) => std::cmp::Ordering::Less,
            (_, BlockStart::Last) => std::cmp::Ordering::Greater,
            (&BlockStart::Inner(k, n), &BlockStart::Inner(l, m)) => (k * m).cmp(&(l * n)),
        }
    }
}

/// Whether a frame's cost is a spike: over `k` times the median of the earlier
/// frames' costs `recent`. Never for `k` 0, with fewer than [`SPIKE_MIN`] of them, or
/// when their median is not positive (the objective with the rewards paid while
/// tracking, [`Weights::track_rewards`], can be negative, and then only the IoU
/// starts a recovery). A body that turned while the model did not can leave the
/// silhouette covered well enough for the IoU yet cost several times what the
/// frames before it did.
fn cost_spike(recent: &VecDeque<f64>, cost: f64, k: f64) -> bool {
    if k <= 0.0 || recent.len() < SPIKE_MIN {
        return false;
    }
    let mut sorted: Vec<f64> = recent.iter().copied().collect();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    median > 0.0 && cost > k * median
}

/// The previous solutions a frame's prediction is made from.
#[derive(Clone)]
struct History {
    last: Pose,
    before: Option<Pose>,
    /// The person was absent since `last` (they may come back elsewhere).
    away: bool,
    /// Frames since the last recovery ([`Search::recover`]).
    quiet: usize,
    /// The last [`SPIKE_WINDOW`] frames' costs, oldest first.
    costs: VecDeque<f64>,
}

impl History {
    fn new(pose: Pose) -> History {
        History {
            last: pose,
            before: None,
            away: false,
            quiet: RECOVER_GAP,
            costs: VecDeque::with_capacity(SPIKE_WINDOW),
        }
    }

    /// Whether a frame's cost is a spike against the recent frames' ([`cost_spike`]),
    /// then remembered among them.
    fn spike(&mut self, cost: f64, k: f64) -> bool {
        let spike = cost_spike(&self.costs, cost, k);
        if self.costs.len() == SPIKE_WINDOW {
            self.costs.pop_front();
        }
        self.costs.push_back(cost);
        spike
    }

    fn push(&mut self, pose: Pose) {
        // No velocity across a gap: the person may have come back elsewhere.
        self.before = (!self.away).then_some(self.last);
        self.last = pose;
        self.away = false;
    }

    /// Forget the velocity (after frames without a person).
    fn gap(&mut self) {
        self.before = None;
        self.away = true;
    }
}

struct Search<'a> {
    tracker: &'a Tracker,
    body: &'a Body,
    ground: f64,
    evals: u64,
    /// Buffers of [`Search::outline_cost`], made when first needed.
    outlines: std::cell::RefCell<Option<Outlines>>,
    /// Buffers of [`Search::shading_cost`], made when first needed.
    shading: std::cell::RefCell<Option<Shading>>,
    /// Weigh the inner outlines in ([`Search::outline_cost`]); off for the probes
    /// that compare the initial candidates, which F and the facing rule decide.
    weigh_outlines: bool,
    /// Carry every parameter's velocity into each frame's start
    /// ([`TrackOptions::joint_velocity`]; always for the probes).
    joint_velocity: bool,
    /// The objective's weights: the tracker's, whole pixels in the initialisation.
    weights: Weights,
    /// Restarts of each frame's search ([`TrackOptions::restarts`]; one for the
    /// probes unless [`TrackOptions::full_probes`]).
    restarts: usize,
    /// Whether each frame tries the jumps ([`Search::try_jumps`]; not the probes
    /// unless [`TrackOptions::full_probes`]).
    jumps: bool,
}

impl<'a> Search<'a> {
    /// A search with no ground constraint when `ground` is −∞.
    fn new(tracker: &'a Tracker, body: &'a Body, ground: f64) -> Search<'a> {
        Search {
            tracker,
            body,
            ground,
            evals: 0,
            outlines: std::cell::RefCell::new(None),
            shading: std::cell::RefCell::new(None),
            weigh_outlines: true,
            joint_velocity: tracker.opts.joint_velocity,
            weights: tracker.opts.weights,
            restarts: tracker.opts.restarts,
            jumps: true,
        }
    }

    /// A search for the initialisation, which counts whole pixels
    /// ([`Weights::smooth`]) and weighs the extremity term unbounded and without
    /// claims ([`Weights::unbounded_ends`]).
    fn initial(tracker: &'a Tracker, body: &'a Body) -> Search<'a> {
        let mut s = Search::new(tracker, body, f64::NEG_INFINITY);
        s.weights = s.weights.unbounded_ends();
        s.weights.smooth = false;
        s
    }

    /// Whether this search weighs the inner outlines in on `target`: a colour
    /// frame, a weight above 0, and not a probe of the initial candidates.
    fn weighs_outlines(&self, target: &Target) -> bool {
        self.weigh_outlines && self.tracker.opts.weights.outline > 0.0 && target.edges.is_some()
    }

    /// What `pose`'s inner outlines cost on `target` ([`Weights::outline`] per pixel
    /// of disagreement with the colour frame's edges); 0 where
    /// [`Search::weighs_outlines`] says no.
    fn outline_cost(&self, target: &Target, pose: &Pose) -> f64 {
        if !self.weighs_outlines(target) {
            return 0.0;
        }
        let cam = &self.tracker.camera;
        let d = self
            .outlines
            .borrow_mut()
            .get_or_insert_with(|| Outlines::new(cam))
            .disagreement(self.body, cam, target, pose)
            .unwrap_or(0.0);
        self.tracker.opts.weights.outline * d
    }

    /// What `pose`'s shading costs on `target` ([`Weights::shading`] per level² of
    /// brightness misfit, summed over the person's pixels); 0 where
    /// [`Search::weighs_outlines`] says no or the frame's brightness was not kept.
    fn shading_cost(&self, target: &Target, pose: &Pose) -> f64 {
        let w = self.tracker.opts.weights.shading;
        let Some(luma) = target.luma.as_deref() else {
            return 0.0;
        };
        if !(self.weighs_outlines(target) && w > 0.0) {
            return 0.0;
        }
        let cam = &self.tracker.camera;
        let (misfit, n) = self
            .shading
            .borrow_mut()
            .get_or_insert_with(|| Shading::new(cam))
            .misfit(self.body, cam, luma, &target.silhouette, pose);
        w * misfit * n as f64
    }

    /// What tells apart poses with nearly the same silhouette:
    /// [`Search::outline_cost`] plus [`Search::shading_cost`].
    fn judge_cost(&self, target: &Target, pose: &Pose) -> f64 {
        self.outline_cost(target, pose) + self.shading_cost(target, pose)
    }

    fn evaluator<'b>(&'b self, target: &'b Target) -> Evaluator<'b> {
        let ground = self.ground.is_finite().then_some(self.ground);
        Evaluator::new(
            self.body,
            &self.tracker.camera,
            target,
            self.weights,
            ground,
        )
        .with_prior(self.tracker.opts.pose_prior.as_deref())
    }

    /// Cost and IoU of `pose` on `target`.
    fn measure(&self, target: &Target, pose: &Pose) -> (f64, f64) {
        let mut ev = self.evaluator(target);
        (ev.cost(pose), ev.iou(pose))
    }

    /// Tracks one frame from the history (its neighbour in time).
    fn step(
        &mut self,
        index: usize,
        target: Option<&Target>,
        history: &mut History,
    ) -> TrackedFrame {
        let Some(target) = target else {
            history.gap();
            return TrackedFrame {
                index,
                person: false,
                pose: history.last,
                cost: None,
                iou: None,
                keyframe: false,
            };
        };
        let opts = &self.tracker.opts;
        let mut ev = self.evaluator(target);
        let mut prev = history.last;
        if history.away {
            // Back after frames without a person, maybe elsewhere: move the body over
            // the silhouette (same depth) before searching around it.
            self.replace_over(&mut ev, target, &mut prev);
        }
        // The root position's velocity carries on, or every parameter's
        // ([`Search::joint_velocity`]).
        let mut predicted = prev;
        if let Some(before) = history.before {
            let moving = if self.joint_velocity {
                0..MOTION_COUNT
            } else {
                ix::ROOT_TX..ix::ROOT_TZ + 1
            };
            for k in moving {
                predicted[k] += prev[k] - before[k];
            }
        }
        clamp_to_limits(&mut predicted);
        let (mut keyed, keyframe) = opts.keyframes.start_pose(index, &predicted);
        clamp_to_limits(&mut keyed);
        let mut fixed = [false; MOTION_COUNT];
        if let Some(kf) = opts.keyframes.at(index) {
            for &(k, _) in &kf.params {
                fixed[k] = true;
            }
        }
        // Start from the prediction unless the plain previous pose explains the
        // frame better (a velocity estimate can be wrong).
        let mut start = keyed;
        let mut best_f = ev.cost(&keyed);
        if !keyframe {
            let f_prev = ev.cost(&prev);
            if f_prev < best_f {
                start = prev;
                best_f = f_prev;
            }
        }
        // Or from the start moved along its viewing ray to the person's size, when
        // that explains the frame better: a model that has crept nearer or farther
        // than the person (an approach over many frames costs little per frame, as
        // the edge and region rewards pay for covering the person with a larger
        // body) is put back at their depth before the search.
        if !keyframe {
            let mut sized = start;
            self.resize_over(&mut ev, target, &mut sized);
            let f_sized = ev.cost(&sized);
            if f_sized < best_f {
                start = sized;
                best_f = f_sized;
            }
        }
        // A start below the ground costs +∞, and so may every pose the search can
        // reach from it (the body moved over a person who comes back after a gap
        // can sink past the ground's slack): lift it onto the ground.
        if !best_f.is_finite() {
            let mut lifted = start;
            self.lift_to_ground(&mut lifted);
            let f = ev.cost(&lifted);
            if f < best_f {
                start = lifted;
                best_f = f;
            }
        }
        // The reach of the search: acceleration limits around the prediction.
        let (lo, hi) = self.reach_box(&start, &fixed);
        let mut best = start;
        self.hierarchical(
            &mut ev,
            &mut best,
            &mut best_f,
            &lo,
            &hi,
            self.restarts,
            opts.evals_per_param,
        );
        // A keyframe's frames keep their start (and the keyframe its parameters).
        if !keyframe && self.jumps {
            self.try_jumps(&mut ev, target, &mut best, &mut best_f);
        }
        let mut iou = ev.iou(&best);
        // The joint polish where the fit is poor, within the reach around the result
        // (a jump may have left the box around the start).
        if opts.polish_evals > 0
            && (iou < opts.polish_iou
                || opts.polish_spike && cost_spike(&history.costs, best_f, opts.recover_spike))
        {
            let (lo, hi) = self.reach_box(&best, &fixed);
            let (mut polished, mut polished_f) = (best, best_f);
            if self.polish(
                &mut ev,
                &mut polished,
                &mut polished_f,
                &lo,
                &hi,
                index as u64,
            ) && polished_f + self.judge_cost(target, &polished)
                < best_f + self.judge_cost(target, &best)
            {
                (best, best_f) = (polished, polished_f);
                iou = ev.iou(&best);
            }
        }
        let spike = history.spike(best_f, opts.recover_spike);
        if !keyframe && (iou < opts.recover_iou || spike) && history.quiet >= RECOVER_GAP {
            history.quiet = 0;
            let (better, evals) = self.recover(target, &mut best, &mut best_f);
            ev.evals += evals;
            if better {
                iou = ev.iou(&best);
            }
        } else {
            history.quiet += 1;
        }
        let spent = ev.evals;
        self.evals += spent;
        history.push(best);
        TrackedFrame {
            index,
            person: true,
            pose: best,
            cost: Some(best_f),
            iou: Some(iou),
            keyframe,
        }
    }

    /// One frame of the smoothed refit ([`super::refit`]): the search (its runs,
    /// each parameter within its reach) from the job's start; its answer replaces
    /// the frame's unless its cost is not finite (below the ground). The frame, and
    /// the evaluations spent.
    fn refit(&self, job: &Job<Arc<Target>>) -> (TrackedFrame, u64) {
        let Job {
            frame,
            target,
            start,
        } = job;
        let frame = frame.clone();
        let (Some(target), &Some(start)) = (target.as_deref(), start) else {
            return (frame, 0);
        };
        let opts = &self.tracker.opts;
        let mut ev = self.evaluator(target).with_anchor(start, opts.refit_anchor);
        let mut best = start;
        let mut best_f = ev.cost(&start);
        let (lo, hi) = self.reach_box(&start, &[false; MOTION_COUNT]);
        let mut iou = f64::NAN;
        for _ in 0..opts.refit_runs.max(1) {
            self.hierarchical(
                &mut ev,
                &mut best,
                &mut best_f,
                &lo,
                &hi,
                1,
                opts.evals_per_param,
            );
            iou = if best_f.is_finite() {
                ev.iou(&best)
            } else {
                f64::NAN
            };
            // NaN (an infinite cost) never stops it; 1 runs them all, even on a
            // perfect fit.
            if opts.refit_again_iou < 1.0 && iou >= opts.refit_again_iou {
                break;
            }
        }
        if !best_f.is_finite() {
            return (frame, ev.evals);
        }
        best_f -= ev.anchor_cost(&best);
        let refitted = TrackedFrame {
            pose: best,
            cost: Some(best_f),
            iou: Some(iou),
            ..frame
        };
        (refitted, ev.evals)
    }

    /// The joint polish ([`TrackOptions::polish_evals`]): CMA-ES over the parameters
    /// free in [lo, hi], in units of each parameter's length scale, from `best` with
    /// a spread of 0.3 of them; keeps the best pose it evaluates when it is better.
    /// Seeded by `seed` (the frame), so a clip always tracks the same way.
    fn polish(
        &self,
        ev: &mut Evaluator,
        best: &mut Pose,
        best_f: &mut f64,
        lo: &Pose,
        hi: &Pose,
        seed: u64,
    ) -> bool {
        let budget = self.tracker.opts.polish_evals;
        let free: Vec<usize> = (0..MOTION_COUNT).filter(|&k| lo[k] < hi[k]).collect();
        if budget == 0 || free.len() < 2 {
            return false;
        }
        ev.unfocus();
        let base = *best;
        let mut found = (*best_f, *best);
        let cost = |z: &cmaes::DVector<f64>| -> f64 {
            let mut p = base;
            for (&k, v) in free.iter().zip(z.iter()) {
                p[k] = (base[k] + MOTION[k].scale * v).clamp(lo[k], hi[k]);
            }
            let c = ev.cost(&p);
            if c < found.0 {
                found = (c, p);
            }
            // CMA-ES needs a number: outside the limits is merely very bad.
            if c.is_finite() {
                c
            } else {
                f64::MAX / 4.0
            }
        };
        let run = cmaes::CMAESOptions::new(vec![0.0; free.len()], POLISH_SPREAD)
            .max_function_evals(budget)
            .seed(seed)
            .build(cost);
        // The options are valid by construction (a dimension of 2 or more, a
        // positive spread); a refusal leaves the pose as it is.
        if let Ok(mut state) = run {
            state.run();
        }
        let better = found.0 < *best_f;
        if better {
            (*best_f, *best) = found;
        }
        better
    }

    /// Recovery after a loss: wide fits (every angle within its limits, the heading
    /// within 60° either way) from the result and from it turned 60° either way;
    /// the cheapest replaces the result when it is cheaper. Whether it did, and the
    /// evaluations spent.
    ///
    /// The frame-to-frame search only reaches poses near the prediction: a person
    /// who turns faster than it follows (CMU 131_01 from the front turns about 70°
    /// near frame 90) leaves the model behind for the rest of the clip, the true pose
    /// scoring clearly better on every frame from then on. On the accuracy benchmark
    /// with a lead-in this took PCK from 0.811 to 0.839, lost frames from 47 to 17 and
    /// PA-MPJPE from 146 to 143 mm (without a lead-in PCK 0.560 → 0.580, PA-MPJPE
    /// 190 → 182 mm), for 9% of the speed (median 13.5 → 12.3 frames/s). An IoU
    /// threshold of 0.7, or of 0.8 with every third frame allowed, gave PCK 0.824
    /// and 0.830, also better than none (the benchmark's noise: the search's reach
    /// at 4, 4.5 and 5 gave 0.798, 0.824 and 0.801). On real masks (DAVIS), where
    /// the model's IoU stays near 0.7–0.8 all along, it may run every fifth frame;
    /// the mean IoU moved from 0.728 to 0.732.
    ///
    /// Coarse still: in a synthetic 70° turn (tests/track.rs) it covers the person
    /// again (IoU 0.631 → 0.775) but at heading −57°, costing −37,371 where the true
    /// pose costs −49,471; and a loss the frame's search leaves above IoU 0.75 (a
    /// 45° turn ends at 0.784) does not trigger it through the IoU; a frame whose
    /// cost jumps over the recent frames' starts it too
    /// ([`TrackOptions::recover_spike`], [`cost_spike`]).
    fn recover(&self, target: &Target, best: &mut Pose, best_f: &mut f64) -> (bool, u64) {
        let mut found = false;
        let mut spent = 0;
        for turn in [0.0, -60.0, 60.0] {
            let mut start = *best;
            start[ix::ROOT_RY] += turn;
            let (pose, f, evals) = self.fit_wide_counted(target, start, 2);
            spent += evals;
            if f < *best_f {
                *best_f = f;
                *best = pose;
                found = true;
            }
        }
        (found, spent)
    }

    /// The search box around `around`: each parameter within its reach and its
    /// limits; a `fixed` one (a keyframe's) held where it is.
    fn reach_box(&self, around: &Pose, fixed: &[bool; MOTION_COUNT]) -> (Pose, Pose) {
        let mut lo = *around;
        let mut hi = *around;
        for k in (0..MOTION_COUNT).filter(|&k| !fixed[k]) {
            let reach = self.reach(k);
            lo[k] = (around[k] - reach).max(MOTION[k].lo);
            hi[k] = (around[k] + reach).min(MOTION[k].hi);
        }
        (lo, hi)
    }

    /// How far parameter `k` may move in one frame: the acceleration limit
    /// (`reach` length scales at 30 frames/s, scaled by the squared frame time).
    fn reach(&self, k: usize) -> f64 {
        let opts = &self.tracker.opts;
        let scale = (30.0 / opts.fps.max(1.0)).powi(2);
        opts.reach * MOTION[k].scale * scale
    }

    /// Tries every jump from `best` ([`Jump`]: the depth flips, the nod moved into
    /// the trunk, the left/right swaps, the crouch down, the whole body's depth
    /// mirror): each is refined by
    /// one pass of the search over its parameters within the acceleration reach
    /// around it (half the budget of the frame's own search: it starts near its
    /// answer), and kept when it explains the frame better: F plus, on a colour
    /// frame, the inner outlines' cost ([`Search::outline_cost`]), which tells
    /// apart what the silhouette cannot.
    fn try_jumps(&self, ev: &mut Evaluator, target: &Target, best: &mut Pose, best_f: &mut f64) {
        let opts = &self.tracker.opts;
        let weigh = self.weighs_outlines(target);
        // The result's outline cost, computed when first needed.
        let mut best_o: Option<f64> = None;
        for jump in Jump::all() {
            // A swap looks alike in the silhouette: only the outlines can tell it
            // apart. The crouch may be turned off.
            let skip = match jump {
                Jump::SwapLegs | Jump::SwapArms => !weigh,
                Jump::Crouch => !opts.crouch_jumps,
                Jump::Mirror => !opts.mirror_jumps,
                _ => false,
            };
            if skip {
                continue;
            }
            let params = jump.params();
            let Some(mut pose) = jump.apply(self.body, best) else {
                continue;
            };
            let mut f = ev.cost(&pose);
            let mut lo = *best;
            let mut hi = *best;
            for &k in &params {
                let reach = self.reach(k);
                lo[k] = (pose[k] - reach).max(MOTION[k].lo);
                hi[k] = (pose[k] + reach).min(MOTION[k].hi);
            }
            let give_up = match jump {
                Jump::SwapLegs | Jump::SwapArms => f64::INFINITY,
                _ if opts.jump_give_up > 0.0 && *best_f > 0.0 => opts.jump_give_up * *best_f,
                _ => f64::INFINITY,
            };
            let per_param = opts.evals_per_param / 2;
            let (_, done) =
                self.hierarchical_until(ev, &mut pose, &mut f, (&lo, &hi), 1, per_param, give_up);
            if !done || !f.is_finite() {
                continue;
            }
            let better = if weigh {
                let o = *best_o.get_or_insert_with(|| self.judge_cost(target, best));
                // Outline costs are ≥ 0: a jump dearer by more than the result's
                // own cannot win.
                f - *best_f < o && {
                    let o_jump = self.judge_cost(target, &pose);
                    let wins = f + o_jump < *best_f + o;
                    if wins {
                        best_o = Some(o_jump);
                    }
                    wins
                }
            } else {
                f < *best_f
            };
            if better {
                *best_f = f;
                *best = pose;
            }
        }
    }

    /// Moves the root along its viewing ray (by at most [`MAX_RESIZE`] either way)
    /// so that the model's silhouette is as tall as the person's, then centres it
    /// over them.
    fn resize_over(&self, ev: &mut Evaluator, target: &Target, pose: &mut Pose) {
        let Some((a, b)) = self.boxes(ev, target, pose) else {
            return;
        };
        let model_h = (a[3] - a[1] + 1) as f64;
        let person_h = (b[3] - b[1] + 1) as f64;
        // Scaling the root's camera coordinates keeps its pixel and scales the
        // model's image by the inverse.
        let k = (model_h / person_h).clamp(1.0 / MAX_RESIZE, MAX_RESIZE);
        for v in &mut pose[ix::ROOT_TX..=ix::ROOT_TZ] {
            *v *= k;
        }
        self.replace_over(ev, target, pose);
    }

    /// Raises the root so that the soles are no lower than the ground.
    fn lift_to_ground(&self, pose: &mut Pose) {
        let sole = sole_height(self.body, &self.body.posed(pose));
        if self.ground.is_finite() && sole < self.ground {
            pose[ix::ROOT_TY] += self.ground - sole;
        }
    }

    /// The bounding boxes of the model's silhouette at `pose` and of the person.
    fn boxes(
        &self,
        ev: &mut Evaluator,
        target: &Target,
        pose: &Pose,
    ) -> Option<([u32; 4], [u32; 4])> {
        let cam = &self.tracker.camera;
        let mut m = Mask::new(cam.width, cam.height);
        ev.render(pose, &mut m);
        Some((mask_bbox(&m)?, mask_bbox(&target.silhouette)?))
    }

    /// Shifts the root in the image plane so that the model's silhouette box is
    /// centred on the person's.
    fn replace_over(&self, ev: &mut Evaluator, target: &Target, pose: &mut Pose) {
        let cam = &self.tracker.camera;
        let Some((a, b)) = self.boxes(ev, target, pose) else {
            return;
        };
        let centre = |b: [u32; 4]| [(b[0] + b[2]) as f64 / 2.0, (b[1] + b[3]) as f64 / 2.0];
        let (from, to) = (centre(a), centre(b));
        let depth = -pose[ix::ROOT_TZ];
        if depth > 0.0 {
            pose[ix::ROOT_TX] += (to[0] - from[0]) * depth / cam.fx;
            pose[ix::ROOT_TY] -= (to[1] - from[1]) * depth / cam.fy;
        }
    }

    /// `runs` passes of the group-by-group search within [lo, hi], each simplex
    /// allowed `evals_per_param` evaluations per parameter (plus one); returns the
    /// evaluations spent.
    #[allow(clippy::too_many_arguments)]
    fn hierarchical(
        &self,
        ev: &mut Evaluator,
        best: &mut Pose,
        best_f: &mut f64,
        lo: &Pose,
        hi: &Pose,
        runs: usize,
        evals_per_param: usize,
    ) -> u64 {
        let bounds = (lo, hi);
        let (spent, _) = self.hierarchical_until(
            ev,
            best,
            best_f,
            bounds,
            runs,
            evals_per_param,
            f64::INFINITY,
        );
        spent
    }

    /// [`Search::hierarchical`], given up before a group's simplex (the first
    /// one searched aside) while the cost is still above `give_up`: the
    /// evaluations spent, and whether it went through.
    #[allow(clippy::too_many_arguments)]
    fn hierarchical_until(
        &self,
        ev: &mut Evaluator,
        best: &mut Pose,
        best_f: &mut f64,
        (lo, hi): (&Pose, &Pose),
        runs: usize,
        evals_per_param: usize,
        give_up: f64,
    ) -> (u64, bool) {
        let opts = &self.tracker.opts;
        let before = ev.evals;
        let mut order = Group::ALL;
        if !opts.global_first {
            order.reverse();
        }
        let mut searched = false;
        let mut done = true;
        'runs: for _ in 0..runs.max(1) {
            for g in order {
                let params: Vec<usize> = g.range().filter(|&k| lo[k] < hi[k]).collect();
                if params.is_empty() {
                    continue;
                }
                if searched && *best_f > give_up {
                    done = false;
                    break 'runs;
                }
                let budget = evals_per_param * (params.len() + 1);
                self.simplex_over(ev, best, best_f, &params, lo, hi, budget);
                searched = true;
            }
        }
        ev.unfocus();
        (ev.evals - before, done)
    }

    /// One simplex over `params` from `best` within [lo, hi]; keeps the result when
    /// it is better.
    #[allow(clippy::too_many_arguments)]
    fn simplex_over(
        &self,
        ev: &mut Evaluator,
        best: &mut Pose,
        best_f: &mut f64,
        params: &[usize],
        lo: &Pose,
        hi: &Pose,
        max_evals: usize,
    ) {
        if params.is_empty() {
            return;
        }
        ev.focus(best, params);
        let x0: Vec<f64> = params.iter().map(|&k| best[k]).collect();
        let steps: Vec<f64> = params
            .iter()
            .map(|&k| MOTION[k].scale.min((hi[k] - lo[k]) / 2.0))
            .collect();
        let l: Vec<f64> = params.iter().map(|&k| lo[k]).collect();
        let u: Vec<f64> = params.iter().map(|&k| hi[k]).collect();
        let base = *best;
        let res = minimize(
            |x| {
                let mut p = base;
                for (&k, v) in params.iter().zip(x) {
                    p[k] = *v;
                }
                ev.cost(&p)
            },
            &x0,
            &steps,
            &l,
            &u,
            &simplex_options(max_evals),
        );
        if res.f < *best_f {
            *best_f = res.f;
            for (&k, v) in params.iter().zip(&res.x) {
                best[k] = *v;
            }
        }
    }

    /// Fits a pose with the search box spanning the joint limits (initialisation).
    fn fit_wide(&self, target: &Target, start: Pose, runs: usize) -> (Pose, f64) {
        let (pose, f, _) = self.fit_wide_counted(target, start, runs);
        (pose, f)
    }

    /// [`Search::fit_wide`], also returning the evaluations spent.
    fn fit_wide_counted(&self, target: &Target, start: Pose, runs: usize) -> (Pose, f64, u64) {
        let mut ev = self.evaluator(target);
        let mut lo = [0.0; MOTION_COUNT];
        let mut hi = [0.0; MOTION_COUNT];
        for k in 0..MOTION_COUNT {
            lo[k] = MOTION[k].lo;
            hi[k] = MOTION[k].hi;
        }
        for k in ix::ROOT_TX..=ix::ROOT_TZ {
            lo[k] = start[k] - 100.0;
            hi[k] = start[k] + 100.0;
        }
        lo[ix::ROOT_RY] = start[ix::ROOT_RY] - 60.0;
        hi[ix::ROOT_RY] = start[ix::ROOT_RY] + 60.0;
        let mut best = start;
        let mut best_f = ev.cost(&start);
        limb_grid(&mut ev, &mut best, &mut best_f);
        let per_param = self.tracker.opts.evals_per_param;
        self.hierarchical(&mut ev, &mut best, &mut best_f, &lo, &hi, runs, per_param);
        (best, best_f, ev.evals)
    }
}

/// Of `prior`'s exemplars ([`PosePrior::exemplar_poses`]) placed and turned as
/// `base`, the one `search` prices lowest on `target`: one evaluation each. None
/// when every one costs +∞ (outside the joint limits: a prior file's exemplars
/// are only checked to be finite).
fn cheapest_start(
    search: &Search,
    target: &Target,
    base: &Pose,
    prior: &PosePrior,
) -> Option<Pose> {
    let mut ev = search.evaluator(target);
    prior
        .exemplar_poses(base)
        .into_iter()
        .map(|p| (ev.cost(&p), p))
        .filter(|(f, _)| f.is_finite())
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, p)| p)
}

/// Coarse start for each limb in turn: the best of a grid of raised, spread and
/// bent configurations (a limb far from the rest pose is out of the simplex's reach
/// from it, and limbs barely interact in the silhouette).
fn limb_grid(ev: &mut Evaluator, best: &mut Pose, best_f: &mut f64) {
    const ARM_X: [f64; 5] = [-45.0, 0.0, 45.0, 90.0, 135.0];
    const ARM_Z: [f64; 3] = [5.0, 45.0, 90.0];
    const ELBOW: [f64; 3] = [0.0, 50.0, 100.0];
    const HIP_X: [f64; 4] = [-30.0, 0.0, 30.0, 70.0];
    const HIP_Z: [f64; 2] = [0.0, 25.0];
    const KNEE: [f64; 4] = [0.0, 30.0, 60.0, 100.0];
    // (first angle of the limb's root joint, its bend, grids of root x, root z, bend)
    type Limb<'g> = (usize, usize, &'g [f64], &'g [f64], &'g [f64]);
    let limbs: [Limb; 4] = [
        (ix::L_SHOULDER, ix::L_ELBOW, &ARM_X, &ARM_Z, &ELBOW),
        (ix::R_SHOULDER, ix::R_ELBOW, &ARM_X, &ARM_Z, &ELBOW),
        (ix::L_HIP, ix::L_KNEE, &HIP_X, &HIP_Z, &KNEE),
        (ix::R_HIP, ix::R_KNEE, &HIP_X, &HIP_Z, &KNEE),
    ];
    for (root, bend, xs, zs, bends) in limbs {
        ev.focus(best, &[root, root + 1, bend]);
        for &x in xs {
            for &z in zs {
                for &e in bends {
                    let mut p = *best;
                    p[root] = x;
                    p[root + 1] = z;
                    p[bend] = e;
                    let f = ev.cost(&p);
                    if f < *best_f {
                        *best_f = f;
                        *best = p;
                    }
                }
            }
        }
    }
    ev.unfocus();
}

/// The simplex's stopping rules for this objective: a sum of large terms of both
/// signs, so only an absolute tolerance on the cost means anything.
fn simplex_options(max_evals: usize) -> SimplexOptions {
    SimplexOptions {
        max_evals,
        ftol: 0.0,
        abs_tol: 0.5,
        xtol: 0.01,
    }
}

/// Frames without a person take the pose of the previous tracked frame (those
/// before the person appears, the first tracked one).
fn hold_missing(frames: &mut [TrackedFrame]) {
    let Some(first) = frames.iter().position(|f| f.person) else {
        return;
    };
    let pose = frames[first].pose;
    for f in &mut frames[..first] {
        f.pose = pose;
    }
    let mut last = pose;
    for f in &mut frames[first..] {
        if f.person {
            last = f.pose;
        } else {
            f.pose = last;
        }
    }
}

/// Inclusive bounding box [x0, y0, x1, y1] of a mask's set pixels.
pub fn mask_bbox(m: &Mask) -> Option<[u32; 4]> {
    let mut b: Option<[u32; 4]> = None;
    for y in 0..m.height() {
        for (k, &word) in m.row(y).iter().enumerate() {
            if word == 0 {
                continue;
            }
            let x0 = k as u32 * 64 + word.trailing_zeros();
            let x1 = k as u32 * 64 + 63 - word.leading_zeros();
            b = Some(match b {
                None => [x0, y, x1, y],
                Some([a, c, d, _]) => [a.min(x0), c, d.max(x1), y],
            });
        }
    }
    b
}

/// The shape values' names, in order (for reports).
pub fn shape_names() -> [&'static str; SHAPE_COUNT] {
    std::array::from_fn(|i| SHAPE[i].name)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::params::rest_pose;

    fn facing(heading: f64) -> Pose {
        let mut p = rest_pose();
        p[ix::ROOT_TX] = 30.0;
        p[ix::ROOT_TZ] = -400.0;
        p[ix::ROOT_RY] = heading;
        p
    }

    #[test]
    fn facing_the_camera_follows_the_heading() {
        let cam = Camera::new(320, 240, 55.0);
        for h in [0.0, 60.0, -80.0, 350.0] {
            assert!(faces_camera(&facing(h), &cam), "{h}");
        }
        for h in [180.0, 120.0, -100.0, 540.0] {
            assert!(!faces_camera(&facing(h), &cam), "{h}");
        }
        // A camera turned round to look at the body's back.
        let behind = cam.with_pose(nalgebra::IsometryMatrix3::from_parts(
            nalgebra::Translation3::new(0.0, 0.0, -800.0),
            nalgebra::Rotation3::from_axis_angle(
                &nalgebra::Vector3::y_axis(),
                std::f64::consts::PI,
            ),
        ));
        assert!(faces_camera(&facing(180.0), &behind));
        assert!(!faces_camera(&facing(0.0), &behind));
    }

    /// The boxes of a person whose feet go from `a` to `b` (world, on the ground)
    /// over `frames` frames, seen by `cam`.
    fn walking_boxes(
        cam: &Camera,
        a: [f64; 3],
        b: [f64; 3],
        frames: usize,
    ) -> Vec<(usize, [u32; 4])> {
        (0..frames)
            .map(|i| {
                let t = i as f64 / (frames - 1) as f64;
                let p = nalgebra::Point3::from(
                    nalgebra::Vector3::from(a) * (1.0 - t) + nalgebra::Vector3::from(b) * t,
                );
                let [u, v] = cam.project(&p).expect("in front");
                let (u, v) = (u.round() as u32, v.round() as u32);
                (i + 7, [u - 9, v.saturating_sub(120), u + 8, v - 1])
            })
            .collect()
    }

    #[test]
    fn the_feet_on_the_ground_tell_where_a_person_goes() {
        let cam = Camera::new(320, 240, 55.0);
        // Towards the camera and to its left, 2 m in 2 s (fps 30, 60 frames).
        let (a, b) = ([60.0, -150.0, -700.0], [-60.0, -150.0, -541.0]);
        let boxes = walking_boxes(&cam, a, b, 61);
        let got = ground_travel(&cam, &boxes, -150.0, 30.0).expect("a travel");
        let want = (b[0] - a[0]).atan2(b[2] - a[2]);
        let err = (got.dx.atan2(got.dz) - want).to_degrees();
        assert!(err.abs() < 5.0, "{got:?}: {err}° off");
        assert!((got.speed() - 100.0).abs() < 10.0, "{got:?}");
        assert_eq!(got.secs, 2.0);
        // The front that points that way, and its depth mirror's, which does not.
        let heading = want.to_degrees();
        assert!(got.along(heading) > 0.99);
        assert!(got.along(heading + 180.0) < -0.99);
        assert!(got.along(heading + 90.0).abs() < 0.1);
        // The same from a camera turned round behind the person's far side.
        let behind = cam.with_pose(nalgebra::IsometryMatrix3::from_parts(
            nalgebra::Translation3::new(0.0, 0.0, -1200.0),
            nalgebra::Rotation3::from_axis_angle(
                &nalgebra::Vector3::y_axis(),
                std::f64::consts::PI,
            ),
        ));
        let boxes = walking_boxes(&behind, a, b, 61);
        let got = ground_travel(&behind, &boxes, -150.0, 30.0).expect("a travel");
        let err = (got.dx.atan2(got.dz) - want).to_degrees();
        assert!(err.abs() < 5.0, "{got:?}: {err}° off");
    }

    #[test]
    fn no_travel_without_feet_below_the_horizon_or_frames_enough() {
        let cam = Camera::new(320, 240, 55.0);
        // Above the horizon (the middle row): no ray meets the ground.
        let high: Vec<(usize, [u32; 4])> = (0..20).map(|i| (i, [100, 10, 120, 100])).collect();
        assert_eq!(ground_travel(&cam, &high, -150.0, 30.0), None);
        let boxes = walking_boxes(&cam, [0.0, -150.0, -600.0], [0.0, -150.0, -500.0], 4);
        assert_eq!(ground_travel(&cam, &boxes, -150.0, 30.0), None);
        // Standing still: no speed.
        let still = walking_boxes(&cam, [0.0, -150.0, -600.0], [0.0, -150.0, -600.0], 30);
        let got = ground_travel(&cam, &still, -150.0, 30.0).expect("points");
        assert!(got.speed() < TRAVEL_SPEED, "{got:?}");
    }

    #[test]
    fn a_near_tie_goes_to_the_pose_facing_the_camera() {
        let cam = Camera::new(320, 240, 55.0);
        let (front, back) = (facing(5.0), facing(175.0));
        // Within 2%: the front wins even though it costs a little more.
        let got = choose_hypothesis(&[(-1000.0, back), (-985.0, front)], &cam);
        assert_eq!(got[ix::ROOT_RY], 5.0);
        // Clearly cheaper: the back stays.
        let got = choose_hypothesis(&[(-1000.0, back), (-975.0, front)], &cam);
        assert_eq!(got[ix::ROOT_RY], 175.0);
        // The cheapest already faces the camera.
        let got = choose_hypothesis(&[(-995.0, back), (-1000.0, front)], &cam);
        assert_eq!(got[ix::ROOT_RY], 5.0);
    }

    fn answer(index: usize, cost: f64) -> TrackedFrame {
        TrackedFrame {
            index,
            person: true,
            pose: [index as f64; MOTION_COUNT],
            cost: Some(cost),
            iou: Some(0.9),
            keyframe: false,
        }
    }

    #[test]
    fn large_frames_have_shorter_blocks() {
        assert_eq!(two_way_block(320, 240), TWO_WAY_BLOCK);
        assert_eq!(two_way_block(512, 288), TWO_WAY_BLOCK);
        assert_eq!(two_way_block(0, 0), TWO_WAY_BLOCK);
        // 640×480 at 8 bytes a pixel: 81 frames within the budget.
        assert_eq!(two_way_block(640, 480), 81);
        assert!(two_way_block(640, 480) * 8 * 640 * 480 <= TWO_WAY_BUDGET);
        assert!((two_way_block(640, 480) + 1) * 8 * 640 * 480 > TWO_WAY_BUDGET);
        assert_eq!(two_way_block(1920, 1080), MIN_TWO_WAY_BLOCK);
    }

    #[test]
    fn the_second_pass_gathers_whole_blocks() {
        let mut two = TwoWay::new(TWO_WAY_BLOCK, None, SWITCH_PENALTY);
        for i in 0..TWO_WAY_BLOCK - 1 {
            assert!(two.keep(None).is_none(), "frame {i}");
        }
        let (from, block) = two.keep(None).expect("a whole block");
        assert_eq!((from, block.len()), (0, TWO_WAY_BLOCK));
        assert!(two.keep(None).is_none());
        let (from, block) = (two.from, std::mem::take(&mut two.kept));
        assert_eq!((from, block.len()), (TWO_WAY_BLOCK, 1));
        // Off: nothing is kept, and every frame passes straight through.
        let mut off = TwoWay::new(0, None, SWITCH_PENALTY);
        assert!((0..2 * TWO_WAY_BLOCK).all(|_| off.keep(None).is_none()));
        assert!(off.kept.is_empty());
        assert_eq!(
            off.merge(vec![answer(0, 10.0)]),
            vec![(answer(0, 10.0), false)]
        );
    }

    #[test]
    fn a_block_is_merged_once_its_passes_and_its_frames_are_all_in() {
        let no_person = |i| TrackedFrame {
            person: false,
            cost: None,
            ..answer(i, 0.0)
        };
        // Without a switch penalty: each frame's cheapest answer.
        let mut two = TwoWay::new(TWO_WAY_BLOCK, Some(4), 0.0);
        // Reported at once, as the first pass left them, and held.
        let first: Vec<_> = (0..6).map(|i| (answer(i, 100.0), false)).collect();
        assert_eq!(
            two.merge(first.iter().map(|f| f.0.clone()).collect()),
            first
        );
        assert!(two.merge(Vec::new()).is_empty(), "each reported once");
        // The later passes' answers, in frame order (two for frame 1).
        let later = vec![
            answer(0, 99.0),
            answer(1, 101.0),
            answer(1, 98.0),
            no_person(2),
            // 3: none (after the block's last person).
            // 4: the given initial pose's frame keeps its first answer.
            answer(4, 1.0),
        ];
        two.accept(5, later);
        // Reported again: only the frames whose answer is replaced.
        assert_eq!(
            two.merge(Vec::new()),
            vec![(answer(0, 99.0), true), (answer(1, 98.0), true)]
        );
        // Frame 5's block (5 and 6) is done, but the first pass has not handed
        // over frame 6: it waits, negative costs and all.
        assert_eq!(two.held.len(), 1);
        two.accept(7, vec![answer(5, -200.0), answer(6, -131.0)]);
        assert!(two.merge(Vec::new()).is_empty());
        // Then frame 5 comes again, and frame 6 once, with the answer it keeps.
        assert_eq!(
            two.merge(vec![answer(6, -100.0)]),
            vec![(answer(5, -200.0), true), (answer(6, -131.0), false)]
        );
        assert!(two.held.is_empty() && two.back.is_empty());
    }

    #[test]
    fn with_a_switch_penalty_a_lone_cheaper_answer_is_not_taken() {
        // Another track (every value 50 away) 1% cheaper on one frame of three.
        let other = |i| TrackedFrame {
            pose: [50.0; MOTION_COUNT],
            ..answer(i, 99.0)
        };
        for (penalty, taken) in [(0.0, true), (SWITCH_PENALTY, false)] {
            let mut two = TwoWay::new(TWO_WAY_BLOCK, None, penalty);
            let first: Vec<_> = (0..3).map(|i| answer(i, 100.0)).collect();
            assert_eq!(two.merge(first).len(), 3);
            two.accept(3, vec![other(1)]);
            let out = two.merge(Vec::new());
            assert_eq!(out == vec![(other(1), true)], taken, "penalty {penalty}");
            assert_eq!(out.is_empty(), !taken, "penalty {penalty}");
        }
    }

    #[test]
    fn a_given_initial_pose_does_not_hold_its_neighbours() {
        // Frame 0's given pose is far from both tracks; the other track (every
        // value 50 away from the first's) is cheaper on frames 1 and 2.
        let mut two = TwoWay::new(TWO_WAY_BLOCK, Some(0), SWITCH_PENALTY);
        let given = TrackedFrame {
            pose: [-50.0; MOTION_COUNT],
            ..answer(0, 100.0)
        };
        let other = |i| TrackedFrame {
            pose: [50.0; MOTION_COUNT],
            ..answer(i, 90.0)
        };
        let first = vec![given.clone(), answer(1, 100.0), answer(2, 100.0)];
        assert_eq!(two.merge(first).len(), 3);
        two.accept(3, vec![other(0), other(1), other(2)]);
        assert_eq!(
            two.merge(Vec::new()),
            vec![(other(1), true), (other(2), true)]
        );
    }

    /// A performer of the typical proportions, smaller than the standard body in
    /// most lengths, mid-stride with one arm out, seen by a 320×240 camera: the
    /// camera, the frame's target and the pose.
    fn typical_performer_frame() -> (Camera, Target, Pose) {
        use crate::body::params::TYPICAL_SHAPE;
        use crate::body::raster::render_mask;
        use crate::vision::features::compute;
        let cam = Camera::new(320, 240, 55.0);
        let performer = Body::new(&TYPICAL_SHAPE);
        let mut pose = rest_pose();
        pose[ix::ROOT_TZ] = -450.0;
        pose[ix::ROOT_RY] = 20.0;
        pose[ix::L_SHOULDER + 1] = 60.0;
        pose[ix::R_ELBOW] = 45.0;
        pose[ix::L_HIP] = -20.0;
        pose[ix::R_KNEE] = 30.0;
        let mut m = Mask::new(cam.width, cam.height);
        render_mask(&performer, &performer.posed(&pose), &cam, &mut m);
        let f = compute(&m, None, None, &FeatureOptions::default());
        (cam, Target::new(&f, &Weights::default()), pose)
    }

    #[test]
    fn the_shading_judge_prices_an_arm_flipped_in_depth() {
        use crate::body::params::STANDARD_SHAPE;
        use crate::body::skeleton::standard_rest;
        use crate::track::flips::FLIPS;
        use crate::vision::features::compute;
        // A shaded colour frame of a person facing the camera, the right arm raised
        // forwards, against the same outline with the arm raised as far backwards.
        let cam = Camera::new(320, 240, 55.0);
        let body = Body::new(&STANDARD_SHAPE);
        let (_, rest) = standard_rest();
        let mut pose = rest_pose();
        // The camera at the height of the chest, the whole body in view.
        pose[ix::ROOT_TY] = rest[ix::ROOT_TY] - 130.0;
        pose[ix::ROOT_TZ] = -350.0;
        pose[ix::R_SHOULDER] = 40.0;
        pose[ix::R_SHOULDER + 1] = 30.0;
        let flip = FLIPS.iter().find(|f| f.name == "right arm").expect("flip");
        let flipped = flip.apply(&body, &pose).expect("the arm is raised");
        let (luma, person) = crate::track::shading::picture(&body, &cam, &pose);
        let picture = image::RgbImage::from_fn(cam.width, cam.height, |x, y| {
            image::Rgb([luma[(y * cam.width + x) as usize]; 3])
        });
        let target = |keep: bool| {
            let opts = FeatureOptions {
                luma: keep,
                ..FeatureOptions::default()
            };
            Target::new(
                &compute(&person, Some(&picture), None, &opts),
                &Weights::default(),
            )
        };
        let mut opts = TrackOptions::default();
        opts.weights.shading = 0.001;
        let tracker = Tracker::new(cam.clone(), opts);
        assert!(
            tracker.features().luma,
            "the brightness is kept when weighed"
        );
        let search = Search::new(&tracker, &body, f64::NEG_INFINITY);
        let kept = target(true);
        assert_eq!(
            kept.luma.as_deref(),
            Some(&luma),
            "grey frames keep their level"
        );
        let right = search.shading_cost(&kept, &pose);
        let wrong = search.shading_cost(&kept, &flipped);
        assert!(
            right >= 0.0 && wrong > 2.0 * right + 1.0,
            "{right} vs {wrong}"
        );
        assert_eq!(
            search.judge_cost(&kept, &flipped),
            search.outline_cost(&kept, &flipped) + wrong
        );
        // Without the frame's brightness, or at weight 0 (the default), nothing.
        assert_eq!(search.shading_cost(&target(false), &flipped), 0.0);
        let off = Tracker::new(cam.clone(), TrackOptions::default());
        assert!(!off.features().luma);
        let search = Search::new(&off, &body, f64::NEG_INFINITY);
        assert_eq!(search.shading_cost(&kept, &flipped), 0.0);
    }

    #[test]
    fn of_the_exemplar_starts_the_one_on_the_frame_costs_least() {
        use crate::body::params::{MOTION, TYPICAL_SHAPE};
        use crate::body::raster::render_mask;
        use crate::vision::features::compute;
        // A person in one of the built-in exemplars' poses, turned 30°: placed and
        // turned as that frame's start, their own pose is the cheapest start.
        let prior = PosePrior::builtin();
        let cam = Camera::new(320, 240, 55.0);
        let body = Body::new(&TYPICAL_SHAPE);
        let mut base = rest_pose();
        base[ix::ROOT_TZ] = -450.0;
        base[ix::ROOT_RY] = 30.0;
        let tracker = Tracker::new(cam.clone(), TrackOptions::default());
        let search = Search::initial(&tracker, &body);
        let poses = prior.exemplar_poses(&base);
        let mut found = 0;
        for (k, pose) in poses.iter().enumerate() {
            // Captured poses, within the joint limits.
            for (i, m) in MOTION.iter().enumerate() {
                assert!(
                    (m.lo..=m.hi).contains(&pose[i]),
                    "exemplar {k}: {} {}",
                    m.name,
                    pose[i]
                );
            }
            let mut m = Mask::new(cam.width, cam.height);
            render_mask(&body, &body.posed(pose), &cam, &mut m);
            let f = compute(&m, None, None, &FeatureOptions::default());
            let target = Target::new(&f, &Weights::default());
            let got = cheapest_start(&search, &target, &base, &prior).expect("exemplars");
            if got == *pose {
                found += 1;
            } else {
                println!("exemplar {k}: another exemplar costs less on its frame");
            }
        }
        assert_eq!(found, poses.len(), "of {} exemplars", poses.len());
        // A prior file whose exemplars all bend a knee past its limit offers no
        // start, rather than one that costs +∞.
        let mut v: serde_json::Value =
            serde_json::from_str(include_str!("pose_prior.json")).expect("JSON");
        let knee = v["params"]
            .as_array()
            .unwrap()
            .iter()
            .position(|p| p == "l_knee")
            .unwrap();
        for e in v["exemplars"].as_array_mut().unwrap() {
            e[knee] = 400.0.into();
        }
        let odd = PosePrior::from_json(&v.to_string()).expect("finite exemplars read");
        let mut m = Mask::new(cam.width, cam.height);
        render_mask(&body, &body.posed(&poses[0]), &cam, &mut m);
        let f = compute(&m, None, None, &FeatureOptions::default());
        let target = Target::new(&f, &Weights::default());
        assert!(cheapest_start(&search, &target, &base, &odd).is_none());
    }

    #[test]
    fn the_joint_fit_explains_a_smaller_performer_better_at_the_same_place() {
        use crate::body::params::STANDARD_SHAPE;
        // The fit starts from the standard body in the performer's pose, placed
        // where the performer stands.
        let (cam, target, pose) = typical_performer_frame();
        let opts = TrackOptions {
            init_joint_evals: 1500,
            ..TrackOptions::default()
        };
        let weights = Weights {
            smooth: true,
            ..opts.weights
        };
        let tracker = Tracker::new(cam.clone(), opts);
        let start = Body::new(&STANDARD_SHAPE);
        let (shape, found) = tracker
            .joint_fit(&target, &STANDARD_SHAPE, &pose)
            .expect("a cheaper shape and pose");
        let body = Body::new(&shape);
        // Judged as the fit judges, with the pose prior.
        let prior = tracker.opts.pose_prior.as_deref();
        let mut before = Evaluator::new(&start, &cam, &target, weights, None).with_prior(prior);
        let mut after = Evaluator::new(&body, &cam, &target, weights, None).with_prior(prior);
        assert!(after.cost(&found) < before.cost(&pose));
        let (iou0, iou1) = (before.iou(&pose), after.iou(&found));
        // (0.600 → 0.882 when written, 0.858 with the pose prior weighed in.)
        println!("IoU {iou0:.3} → {iou1:.3}");
        assert!(
            iou1 > 0.75 && iou1 > iou0 + 0.2,
            "IoU {iou0:.3} → {iou1:.3}"
        );
        for k in 0..SHAPE_COUNT {
            assert!((SHAPE[k].lo..=SHAPE[k].hi).contains(&shape[k]), "{k}");
        }
        // None asked for: nothing found.
        let none = Tracker::new(
            cam,
            TrackOptions {
                init_joint_evals: 0,
                ..TrackOptions::default()
            },
        );
        assert!(none.joint_fit(&target, &STANDARD_SHAPE, &pose).is_none());
    }

    #[test]
    fn a_search_given_up_stops_after_its_first_group_while_too_dear() {
        // The arms and legs far from the frame's: after the first group searched
        // (the right leg) the cost is still above the bar, so no other group is.
        let (cam, target, truth) = typical_performer_frame();
        let tracker = Tracker::new(cam, TrackOptions::default());
        let body = Body::new(&crate::body::params::TYPICAL_SHAPE);
        let search = Search::new(&tracker, &body, f64::NEG_INFINITY);
        let mut ev = search.evaluator(&target);
        let mut start = truth;
        for k in [ix::L_SHOULDER + 1, ix::R_ELBOW, ix::L_HIP, ix::R_KNEE] {
            start[k] = 0.0;
        }
        let (lo, hi) = search.reach_box(&start, &[false; MOTION_COUNT]);
        let f0 = ev.cost(&start);
        let run = |give_up: f64, ev: &mut Evaluator| {
            let (mut pose, mut f) = (start, f0);
            let (spent, done) =
                search.hierarchical_until(ev, &mut pose, &mut f, (&lo, &hi), 1, 12, give_up);
            (spent, done, f)
        };
        let (spent_all, done_all, f_all) = run(f64::INFINITY, &mut ev);
        let (spent_cut, done_cut, f_cut) = run(f0 * 0.5, &mut ev);
        println!("f0 {f0:.1}: in full {f_all:.1} ({spent_all} evaluations), given up {f_cut:.1} ({spent_cut})");
        assert!(done_all && !done_cut);
        let first = 12 * (Group::RightLeg.range().len() + 1) as u64;
        assert!(
            spent_cut <= first,
            "{spent_cut} evaluations after giving up"
        );
        assert!(spent_all > 3 * first, "{spent_all} evaluations in full");
        assert!(
            f_cut > f0 * 0.5 && f_all <= f_cut,
            "{f_all} in full, {f_cut} given up"
        );
    }

    #[test]
    fn the_joint_fit_weighs_the_pose_prior() {
        use crate::body::params::STANDARD_SHAPE;
        // The same frame fitted with a heavily weighed prior and with none: the
        // pose found with it is the likelier one.
        let (cam, target, pose) = typical_performer_frame();
        let prior = PosePrior::builtin();
        let fit = |pose_prior: Option<Arc<PosePrior>>| {
            let opts = TrackOptions {
                init_joint_evals: 1500,
                pose_prior,
                weights: Weights {
                    prior: 200.0,
                    ..Weights::default()
                },
                ..TrackOptions::default()
            };
            Tracker::new(cam.clone(), opts)
                .joint_fit(&target, &STANDARD_SHAPE, &pose)
                .expect("a cheaper shape and pose")
                .1
        };
        let (with, without) = (fit(Some(prior.clone())), fit(None));
        let (a, b) = (prior.cost(&with), prior.cost(&without));
        println!("the prior's cost of the pose found: {a:.2} with it, {b:.2} without");
        assert!(a < b, "{a:.2} with the prior, {b:.2} without");
    }

    #[test]
    fn the_proportions_prior_weighs_a_trade_of_segments_not_the_size() {
        use crate::body::params::sx;
        let start = TYPICAL_SHAPE;
        assert_eq!(ratio_penalty(&start, &start, 200.0), 0.0);
        // The whole body larger or smaller: the same ratios.
        for k in [0.8, 1.2] {
            assert!(ratio_penalty(&start.map(|v| v * k), &start, 200.0) < 1e-9);
        }
        // The upper arm traded for the forearm, their sum held: dearer the further.
        let trade = |d: f64| {
            let mut s = start;
            s[sx::UPPER_ARM] -= d;
            s[sx::FOREARM] += d;
            s
        };
        let (near, far) = (trade(0.05), trade(0.15));
        assert!(ratio_penalty(&near, &start, 200.0) > 0.0);
        assert!(ratio_penalty(&far, &start, 200.0) > 4.0 * ratio_penalty(&near, &start, 200.0));
        // Twice the weight, twice the cost; none at weight 0.
        let one = ratio_penalty(&far, &start, 100.0);
        assert!((ratio_penalty(&far, &start, 200.0) - 2.0 * one).abs() < 1e-9 * one);
        assert_eq!(ratio_penalty(&far, &start, 0.0), 0.0);
        // The values it does not weigh: the head, the widths, the thicknesses.
        let mut other = start;
        for k in [
            sx::HEAD,
            sx::TORSO_WIDTH,
            sx::TORSO_DEPTH,
            sx::ARM_THICKNESS,
        ] {
            other[k] *= 1.3;
        }
        assert_eq!(ratio_penalty(&other, &start, 200.0), 0.0);
    }

    #[test]
    fn a_cost_spike_is_judged_against_the_median_of_the_recent_costs() {
        let recent: VecDeque<f64> = [100.0, 90.0, 5000.0, 110.0, 95.0].into();
        // The median (100) is what counts, not one earlier spike or the mean.
        assert!(cost_spike(&recent, 151.0, 1.5));
        assert!(!cost_spike(&recent, 149.0, 1.5));
        assert!(!cost_spike(&recent, 1e9, 0.0), "0 turns it off");
        let few: VecDeque<f64> = [100.0; SPIKE_MIN - 1].into();
        assert!(!cost_spike(&few, 1e9, 1.5), "too few costs to judge");
        let free: VecDeque<f64> = [0.0; SPIKE_WINDOW].into();
        assert!(!cost_spike(&free, 1.0, 1.5), "no scale from a zero median");
    }
}
