//! The objective F(β) of method.md §4 (paper §4.2–4.3): how badly the model in pose β
//! explains one frame's silhouette.
//!
//! F = c + e + a + l (+ s, the optional skin reward, [`Weights::skin`]), or +∞
//! outside the joint limits or below the ground (Eq. 7):
//!
//! - c (Eq. 3), the core-weighted XOR: Σ over pixels where exactly one of the input
//!   silhouette S and the model silhouette M is set, of the coremap d;
//! - e (Eq. 4) = −w_e Σ M·T, the edge reward;
//! - a (Eq. 6) = −w_a Σ M·R, the arm and leg region reward;
//! - l (Eq. 5) = w_l Σ over the model's hands, feet and head of the pixel distance to
//!   a detected candidate of its kind, or of either kind for the hands and feet
//!   ([`Weights::shared_ends`]; optionally bounded while tracking,
//!   [`Weights::extremity_reach`]).
//!
//! c + e + a folds into one per-pixel map read only where the model is: since
//! S ⊕ M = S + M − 2·S·M, c = Σ_S d + Σ_M d·(1 − 2S), so
//! c + e + a = Σ_S d + Σ_{x∈M} G(x) with G = d·(1 − 2S) − w_e·T − w_a·R.
//! [`Target`] holds G once per frame; an evaluation renders the model's silhouette
//! as a bit mask and adds G over its set bits. While a search moves one group of
//! parameters ([`Evaluator::focus`]), the parts that group does not move are rendered
//! once, their share of the sum kept, and each evaluation renders and sums only the
//! moving parts' pixels not already covered. Nothing is allocated per evaluation.

use super::outlines::FrameEdges;
use super::prior::{PosePrior, PriorFocus};
use crate::body::params::{within_limits, Pose, MOTION};
use crate::body::parts::Material;
use crate::body::raster::{render_fragments, render_parts, span_parts, Fragments, Mask, PartSpans};
use crate::body::skeleton::{joints_moved_by, Joint, Posed, Tip, JOINT_COUNT};
use crate::body::{Body, Camera, PART_COUNT};
use crate::vision::features::{ExtremityKind, FrameFeatures};
use crate::vision::skin::SkinModel;
use nalgebra::Point3;
use std::sync::{Arc, OnceLock};

/// The largest [`Weights::skin`].
pub const MAX_SKIN_WEIGHT: f64 = 1000.0;

/// Default of [`Weights::outline`].
pub const OUTLINE_WEIGHT: f64 = 8.0;

/// Default of [`Weights::skin`]: on the accuracy benchmark's six runs, against none,
/// PCK@0.1 0.937 → 0.949, PA-MPJPE 71.8 → 66.7 mm, lost frames 5 → 0; 4 gave 0.946
/// and 69.6 mm, 8 gave 0.947 and 71.7 mm (README, "Skin colour on today's tracker"
/// and "A lighter skin weight").
pub const SKIN_WEIGHT: f64 = 2.0;

/// Default of [`Weights::extremity_reach`].
pub const EXTREMITY_REACH: f64 = 0.0;

/// Default of [`Weights::claim_reach`]. Over the accuracy benchmark's six runs
/// against no claims: PCK@0.1 0.953 → 0.958, PA-MPJPE 65.6 → 63.2 mm, lost
/// frames 1 → 0; the DAVIS people's mean IoU 0.811 → 0.812 (README, "Elbows and
/// knees claiming candidates" and "Claims for hidden hands and feet only").
pub const CLAIM_REACH: f64 = 0.02;

/// The largest [`Weights::extremity_reach`] and [`Weights::claim_reach`].
pub const MAX_REACH: f64 = 1.0;

/// Checks that a [`Weights::extremity_reach`] or [`Weights::claim_reach`], named
/// `name` in the message, is at most [`MAX_REACH`] (that it is a number ≥ 0 is
/// checked with the other weights).
pub fn check_reach(reach: f64, name: &str) -> Result<(), String> {
    if reach > MAX_REACH {
        return Err(format!("{name} {reach}: expected at most {MAX_REACH}"));
    }
    Ok(())
}

/// Weights of the objective's terms (the paper's defaults).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Weights {
    /// w_e of Eq. 4 (per edge pixel the model covers).
    pub edge: f64,
    /// w_l of Eq. 5 (per pixel of distance between a model end and its candidate).
    pub extremity: f64,
    /// w_a of Eq. 6 (per region pixel the model covers).
    pub region: f64,
    /// Pixels of the silhouette within this distance (pixels) of its outline earn
    /// neither the edge nor the region reward (0, the paper's objective: they do).
    /// The XOR term already prices the outline; rewarding it as well makes a model
    /// slightly larger than the person cheaper than one of their size, so over
    /// frames the model creeps nearer the camera and bends to keep its image. See
    /// [`crate::track::tracker::TrackOptions::weights`] for where it applies and its
    /// figures. Only with [`Weights::track_rewards`]: without, no pixel earns them
    /// while tracking.
    pub reward_rim: f64,
    /// Pay the edge and region rewards while tracking too, not only in the
    /// initialisation (the paper's objective; off by default). See
    /// [`crate::track::tracker::TrackOptions::weights`].
    pub track_rewards: bool,
    /// Per pixel of disagreement between a pose's inner outlines and the colour
    /// frame's edges ([`super::outlines`]), weighed in when the tracker chooses
    /// between a frame's result and a jump with nearly the same silhouette (a depth
    /// flip, the nod, the left/right swaps); 0 for never. On the accuracy
    /// benchmark (8 against none) PCK@0.1 0.837 → 0.861 with a person-free lead-in
    /// and 0.810 → 0.848 without, PA-MPJPE 138.0 → 129.7 and 133.9 → 125.7 mm
    /// (README, "The colour frame's inner outlines").
    pub outline: f64,
    /// Per level² of brightness misfit summed over the person's pixels
    /// ([`super::shading`]: each material's brightness fitted as a first-order
    /// function of the pose's surface normals), weighed in beside the inner
    /// outlines when the tracker chooses between a frame's result and a jump with
    /// nearly the same silhouette; 0 for never (the default). At 0.001, over the
    /// accuracy benchmark's six runs, PA-MPJPE 66.7 → 65.8 mm, PCK@0.1 0.949 both,
    /// with swaps 0.983 → 0.980, lost frames 0 → 1: within what the runs move by
    /// chance (README, "Shading in the jumps' judge, on today's tracker").
    pub shading: f64,
    /// The skin reward ([`crate::vision::skin`]): each pixel the model's bare parts
    /// (forearms, hands, neck, head) cover earns this × (2p − 1) where its colour
    /// is skin with a probability p above ½; it says where a forearm in front of
    /// the body is, which the silhouette cannot. [`SKIN_WEIGHT`] by default, 0 for
    /// never (at most [`MAX_SKIN_WEIGHT`]); it applies once the tracker has learned
    /// the clip's skin colour ([`Target::add_skin`]), on colour clips only.
    pub skin: f64,
    /// Count the pixels on a part's outline by the share of their row's centre line
    /// the part covers ([`crate::body::raster::PartSpans`]) rather than whole or not
    /// at all, so that the cost changes smoothly as a part moves by less than a
    /// pixel (while tracking; the initialisation counts whole pixels, as the paper
    /// does). On by default: over the accuracy benchmark's six runs (seeds 1–3,
    /// with and without a person-free lead-in) against whole pixels, model IoU
    /// 0.889 → 0.904, PCK@0.1 with swaps 0.946 → 0.955, PA-MPJPE with the
    /// ambiguities allowed 100.4 → 98.6 mm, lost frames 105 → 60, but plain
    /// PA-MPJPE 115.0 → 115.5 mm and PCK@0.1 0.862 → 0.851; a median 1.28 times the
    /// speed (README, "Whole pixels or shares of them").
    pub smooth: bool,
    /// Per unit of the pose prior's cost ([`PosePrior::cost`]), when the tracker has
    /// a prior ([`crate::track::tracker::TrackOptions::pose_prior`]); 0 for none.
    /// [`PRIOR_WEIGHT`] by default.
    pub prior: f64,
    /// How far (a fraction of the person's height) a model hand, foot or head top
    /// may lie from every candidate of its kind and still be pulled to one (Eq. 5);
    /// farther, it counts as having none and pays this distance, whatever the
    /// candidates are. 0: no bound (the paper's term). An outline's sharpest points
    /// are not always hands: in a boxer's guard the fists are in front of the face,
    /// inside the silhouette, and the elbows stick out. Unbounded, the term then
    /// draws a hand to an elbow. While tracking only: the initialisation keeps the
    /// unbounded term ([`Weights::unbounded_ends`]). At 0.05, over five of the
    /// accuracy benchmark's runs against none: PCK@0.1 with swaps 0.982 → 0.986 and
    /// PA-amb 59.7 → 59.2 mm, but PCK@0.1 0.952 → 0.951, PA-MPJPE 66.2 → 67.1 mm
    /// and lost frames 0 → 3 (more clips with their limbs exchanged left for
    /// right), so [`EXTREMITY_REACH`] is 0 (README, "A bound on the extremity
    /// term").
    pub extremity_reach: f64,
    /// Let the model's hands and feet share the outline's hand and foot candidates,
    /// each end pulled to a distinct one ([`shared_distance`]), rather than the
    /// hands taking the hand candidates and the feet the foot candidates, as the
    /// outline's height labels them (a candidate in the lowest quarter of the
    /// person is a foot, any other a hand). A foot raised above the knee in a kick
    /// is labelled a hand: a hand must then reach for it, and the kick's true poses
    /// cost 1,551–2,968 on such frames, under 400 on the frames around them. Off by
    /// default: over the accuracy benchmark's six runs it changed nothing beyond
    /// chance (PCK@0.1 0.953 → 0.954, PA-MPJPE 65.6 mm both), and the DAVIS
    /// people's mean IoU fell 0.811 → 0.806 (README, "The hands and feet sharing
    /// their candidates").
    pub shared_ends: bool,
    /// How far (a fraction of the person's height) beyond its own radius an
    /// elbow or a knee of the model may lie from a hand or foot candidate and
    /// claim it (Eq. 5), while its own hand or foot projects inside the
    /// silhouette, hidden: a claimed candidate is explained by that joint, pays
    /// the distance beyond the radius, and is taken from the hands and feet, which
    /// pair with the rest ([`Evaluator::claimed_distance`]). An outline's sharp
    /// point is not always a hand: in a guard the fist is hidden in front of the
    /// face and the elbow sticks out. 0: no claims (the paper's term); while
    /// tracking only ([`Weights::unbounded_ends`]). With [`Weights::shared_ends`]
    /// no claims are made. [`CLAIM_REACH`] by default.
    pub claim_reach: f64,
}

/// The default [`Weights::prior`] (`--w-prior 20`). Over the accuracy benchmark's
/// six runs (seeds 1–3, with and without a person-free lead-in, each capture's clips
/// tracked with a prior learned from the other captures) against no prior:
/// PA-MPJPE 110.1 → 95.5 mm, PCK@0.1 0.876 → 0.884, model IoU 0.910 → 0.905, lost
/// frames 25 → 40 (33 of them on one clip), 4% more wall time; at 60 the model IoU
/// fell below 0.90 (README, "The pose prior").
pub const PRIOR_WEIGHT: f64 = 20.0;

impl Default for Weights {
    fn default() -> Self {
        Weights {
            edge: 20.0,
            extremity: 20.0,
            region: 20.0,
            reward_rim: 0.0,
            track_rewards: false,
            outline: OUTLINE_WEIGHT,
            shading: 0.0,
            skin: SKIN_WEIGHT,
            smooth: true,
            prior: PRIOR_WEIGHT,
            extremity_reach: EXTREMITY_REACH,
            shared_ends: false,
            claim_reach: CLAIM_REACH,
        }
    }
}

impl Weights {
    /// The paper's objective: edge and region rewards wherever the features put
    /// them, while tracking as in the initialisation, whole pixels, and no pose
    /// prior.
    pub fn paper() -> Weights {
        Weights {
            track_rewards: true,
            smooth: false,
            prior: 0.0,
            extremity_reach: 0.0,
            claim_reach: 0.0,
            ..Weights::default()
        }
    }

    /// These weights with the extremity term unbounded
    /// ([`Weights::extremity_reach`] 0) and no claims ([`Weights::claim_reach`] 0),
    /// as the initialisation weighs it (bounded there too, the punch from 60°
    /// tracked at 85.8 mm of PA-MPJPE against 76.2; with claims there, the bow from
    /// 60° started turned 72° from the truth, 42.5 → 88.7 mm).
    pub fn unbounded_ends(self) -> Weights {
        Weights {
            extremity_reach: 0.0,
            claim_reach: 0.0,
            ..self
        }
    }
}

/// Everything the objective reads from one frame (built once per frame).
#[derive(Clone, Debug)]
pub struct Target {
    pub width: u32,
    pub height: u32,
    /// G: what covering each pixel adds to the cost (row-major): the XOR and edge
    /// terms, for any part of the model …
    gain: Vec<f32>,
    /// … and the region term, for the parts of the arms and legs only.
    limb_gain: Vec<f32>,
    /// Σ_S d: the cost of a model that covers nothing.
    base: f64,
    /// Candidates for the model's hands, feet and head top (pixels): those labelled
    /// hands, those labelled feet, both together, the head's.
    hands: Vec<[f64; 2]>,
    feet: Vec<[f64; 2]>,
    limb_ends: Vec<[f64; 2]>,
    heads: Vec<[f64; 2]>,
    /// The input silhouette S (the person's blobs).
    pub silhouette: Mask,
    /// Height of the person's bounding box in pixels (0 when there is no person).
    pub body_height: f64,
    /// The frame's score as an initial frame (set by the tracker; −∞ until then):
    /// the later passes choose where to start by it.
    pub init_score: f64,
    /// The rewards withheld while tracking (all of them without
    /// [`Weights::track_rewards`], those of the reward rim [`Weights::reward_rim`]
    /// with): pixel index, edge reward, region reward (negative; 0 when none).
    withheld: Vec<(usize, f32, f32)>,
    /// The colour frame's edges, for telling poses with the same silhouette apart
    /// ([`super::outlines`]); None without a colour frame.
    pub edges: Option<FrameEdges>,
    /// The colour bin of each of the person's pixels (None without a colour frame).
    colours: Option<Arc<Vec<u16>>>,
    /// The colour frame's brightness, for the shading judge (None without it).
    pub luma: Option<Arc<Vec<u8>>>,
    /// What a bare part covering each pixel adds (≤ 0); empty until
    /// [`Target::add_skin`].
    skin_gain: Vec<f32>,
    /// The gain maps' row-by-row running sums, for [`Weights::smooth`] (made on
    /// first use).
    sums: OnceLock<RunningSums>,
    /// Whether the limbs' gain map is all zero (found on first use).
    limb_free: OnceLock<bool>,
}

/// Each gain map's running sums along its rows: `width + 1` per row, the entry at
/// x the sum of the row's first x pixels beside pixel x's own gain (0 past the
/// row's end), so that a point inside a pixel is one load ([`integral`]).
#[derive(Clone, Debug)]
struct RunningSums {
    gain: Vec<[f32; 2]>,
    limb: Vec<[f32; 2]>,
    skin: Vec<[f32; 2]>,
}

fn running_sums(map: &[f32], width: usize) -> Vec<[f32; 2]> {
    let mut out = Vec::with_capacity(map.len() / width.max(1) * (width + 1));
    for row in map.chunks(width.max(1)) {
        let mut acc = 0f32;
        for &g in row {
            out.push([acc, g]);
            acc += g;
        }
        out.push([acc, 0.0]);
    }
    out
}

impl Target {
    pub fn new(f: &FrameFeatures, w: &Weights) -> Target {
        let (width, height) = (f.width, f.height);
        let s = &f.person;
        let mut gain = vec![0f32; f.coremap.len()];
        let mut limb_gain = vec![0f32; f.coremap.len()];
        let mut base = 0.0;
        let mut withheld = Vec::new();
        let rim = if w.track_rewards {
            w.reward_rim
        } else {
            f64::INFINITY
        };
        for y in 0..height {
            for x in 0..width {
                let i = (y * width + x) as usize;
                let d = f.coremap[i];
                let inside = s.get(x, y);
                let mut g = if inside {
                    base += d as f64;
                    -d
                } else {
                    d
                };
                let edge = if inside && f.edges.get(x, y) {
                    -w.edge as f32
                } else {
                    0.0
                };
                let region = if f.regions.get(x, y) {
                    -w.region as f32
                } else {
                    0.0
                };
                // Off the outline's rim (all of it when the rim is 0, none of it
                // when rewards are not paid while tracking).
                if f.inside[i] as f64 > rim {
                    g += edge;
                    limb_gain[i] = region;
                } else if edge != 0.0 || region != 0.0 {
                    withheld.push((i, edge, region));
                }
                gain[i] = g;
            }
        }
        let pick = |kinds: &[ExtremityKind]| -> Vec<[f64; 2]> {
            f.extremities
                .iter()
                .filter(|e| kinds.contains(&e.kind))
                .map(|e| e.pos)
                .collect()
        };
        let mut heads = pick(&[ExtremityKind::Head]);
        if let Some(h) = f.head {
            heads = vec![h];
        }
        Target {
            width,
            height,
            gain,
            limb_gain,
            base,
            hands: pick(&[ExtremityKind::Hand, ExtremityKind::Unknown]),
            feet: pick(&[ExtremityKind::Foot, ExtremityKind::Unknown]),
            limb_ends: pick(&[
                ExtremityKind::Hand,
                ExtremityKind::Foot,
                ExtremityKind::Unknown,
            ]),
            heads,
            silhouette: s.clone(),
            body_height: f.body_height,
            init_score: f64::NEG_INFINITY,
            withheld,
            edges: f.colour_edges.then(|| FrameEdges::new(&f.edges, s)),
            colours: f.colours.clone(),
            luma: f.luma.clone(),
            skin_gain: Vec::new(),
            sums: OnceLock::new(),
            limb_free: OnceLock::new(),
        }
    }

    fn sums(&self) -> &RunningSums {
        self.sums.get_or_init(|| {
            let w = self.width as usize;
            RunningSums {
                gain: running_sums(&self.gain, w),
                limb: running_sums(&self.limb_gain, w),
                skin: running_sums(&self.skin_gain, w),
            }
        })
    }

    /// Rewards the model's bare parts for covering pixels of skin colour: −`weight`
    /// (at most [`MAX_SKIN_WEIGHT`]) × (2p − 1) where the skin model gives a
    /// probability p above ½. Nothing without a colour frame or with a weight of 0.
    /// The colours are let go: they are needed no more.
    pub fn add_skin(&mut self, model: &SkinModel, weight: f64) {
        // (NaN is not above 0 either.)
        if weight.is_nan() || weight <= 0.0 {
            return;
        }
        let Some(colours) = self.colours.take() else {
            return;
        };
        let weight = weight.min(MAX_SKIN_WEIGHT);
        self.skin_gain = colours
            .iter()
            .map(|&b| -(weight as f32) * (2.0 * model.p(b) - 1.0).max(0.0))
            .collect();
        self.sums = OnceLock::new();
    }

    /// The same frame under the paper's objective (the initialisation's), the
    /// rewards withheld while tracking given back; None when nothing was withheld
    /// (the target already is).
    pub fn paper(&self) -> Option<Target> {
        if self.withheld.is_empty() {
            return None;
        }
        let mut t = self.clone();
        t.sums = OnceLock::new();
        t.limb_free = OnceLock::new();
        for (i, edge, region) in std::mem::take(&mut t.withheld) {
            t.gain[i] += edge;
            t.limb_gain[i] = region;
        }
        Some(t)
    }

    /// Whether the limbs' gain map is all zero.
    fn limb_free(&self) -> bool {
        *self
            .limb_free
            .get_or_init(|| self.limb_gain.iter().all(|&g| g == 0.0))
    }

    /// Whether the frame shows a person at all.
    pub fn has_person(&self) -> bool {
        self.body_height > 0.0
    }
}

/// The clip's skin colour, learned from one fitted frame: the pixels of the person
/// the model's bare parts are nearest the camera on are skin, those its clothed
/// parts are the rest; pixels with a 4-neighbour of the other kind or off the
/// model, and the image's border, are left out (the fit's outlines are not exact). None without a colour frame or
/// with too few pixels of either kind.
pub fn learn_skin(body: &Body, cam: &Camera, target: &Target, pose: &Pose) -> Option<SkinModel> {
    let colours = target.colours.as_deref()?;
    let (w, h) = (cam.width, cam.height);
    let mut frags = Fragments::new(w, h);
    render_fragments(body, &body.posed(pose), cam, &mut frags);
    let (mut skin, mut other) = (Mask::new(w, h), Mask::new(w, h));
    for y in 0..h {
        for x in 0..w {
            match frags.inner_label((y * w + x) as usize, |p| is_bare(body, p)) {
                Some(true) => skin.set(x, y, true),
                Some(false) => other.set(x, y, true),
                None => {}
            }
        }
    }
    SkinModel::learn(colours, &skin, &other, MIN_SKIN_PIXELS)
}

/// The terms of F at one pose (for reports and tests; [`Evaluator::cost`] is the
/// fast path).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Terms {
    /// c (Eq. 3).
    pub xor: f64,
    /// e (Eq. 4), ≤ 0.
    pub edge: f64,
    /// a (Eq. 6), ≤ 0.
    pub region: f64,
    /// l (Eq. 5), ≥ 0.
    pub extremity: f64,
    /// The skin reward ([`Weights::skin`]), ≤ 0.
    pub skin: f64,
    /// The pose prior's cost ([`Weights::prior`]), ≥ 0.
    pub prior: f64,
    pub total: f64,
}

/// Pixels of each kind (skin, the rest) a skin colour model needs to be learned.
const MIN_SKIN_PIXELS: u64 = 20;

/// Ground constraint: the soles may sink at most this far (cm) below the ground.
const GROUND_SLACK: f64 = 4.0;

/// Evaluates F for one frame.
pub struct Evaluator<'a> {
    body: &'a Body,
    cam: &'a Camera,
    target: &'a Target,
    weights: Weights,
    /// World y of the ground (None: no ground constraint).
    ground: Option<f64>,
    /// The whole model (G) and its arms and legs (the region term).
    all: Layer,
    limbs: Layer,
    /// The bare parts (the skin term), when the target has one.
    skin: Option<Layer>,
    posed: Posed,
    /// While focused ([`Evaluator::focus`]): the joints the focused parameters move
    /// (the others take their frames from `base`, the focused pose posed in full:
    /// copied once, then kept in `posed`).
    moved: Option<[bool; JOINT_COUNT]>,
    base: Posed,
    /// `posed` holds `base`'s frames for the joints `moved` leaves out (it was
    /// last posed while focused), so that only the moved ones are posed again.
    posed_on_base: bool,
    /// The layers counted by the share of each row the model covers
    /// ([`Weights::smooth`]), used instead of `all`, `limbs` and `skin`.
    smooth: Option<Box<Smooth>>,
    /// The limbs' gain map is all zero: the limbs are drawn (they are part of the
    /// model) but their own layer is not summed.
    limb_free: bool,
    /// Evaluations so far.
    pub evals: u64,
    /// The elbows' and knees' radii (cm), for their claims on candidates.
    radius: (f64, f64),
    /// The pose prior, weighed by [`Weights::prior`] ([`Evaluator::with_prior`]).
    prior: Option<&'a PosePrior>,
    /// The prior at the focus's base pose ([`Evaluator::focus`]).
    prior_focus: Option<PriorFocus>,
    /// The smoothed refit's pull toward its start ([`Evaluator::with_anchor`]).
    anchor: Option<(Pose, f64)>,
}

impl<'a> Evaluator<'a> {
    pub fn new(
        body: &'a Body,
        cam: &'a Camera,
        target: &'a Target,
        weights: Weights,
        ground: Option<f64>,
    ) -> Evaluator<'a> {
        assert_eq!(
            (cam.width, cam.height),
            (target.width, target.height),
            "camera and frame sizes differ"
        );
        // Tracking without rewards leaves the limbs' map all zero: their layer
        // would add nothing.
        let limb_free = target.limb_free();
        let with_masks = !weights.smooth;
        Evaluator {
            body,
            cam,
            target,
            weights,
            ground,
            all: Layer::new(
                cam,
                (0..PART_COUNT).filter(|&i| !is_limb(i)).collect(),
                with_masks,
            ),
            limbs: Layer::new(
                cam,
                (0..PART_COUNT).filter(|&i| is_limb(i)).collect(),
                with_masks,
            ),
            skin: (!target.skin_gain.is_empty()).then(|| {
                let bare = (0..PART_COUNT).filter(|&i| is_bare(body, i)).collect();
                Layer::new(cam, bare, with_masks)
            }),
            posed: Posed::default(),
            moved: None,
            base: Posed::default(),
            posed_on_base: false,
            smooth: weights
                .smooth
                .then(|| Box::new(Smooth::new(body, cam, target, !limb_free))),
            limb_free,
            evals: 0,
            radius: joint_radii(body),
            prior: None,
            prior_focus: None,
            anchor: None,
        }
    }

    /// Weighs `prior` in (by [`Weights::prior`]; none when 0).
    pub fn with_prior(mut self, prior: Option<&'a PosePrior>) -> Self {
        self.prior = prior.filter(|_| self.weights.prior > 0.0);
        self
    }

    /// This evaluator with a pull toward `anchor` added to its cost: `weight` ×
    /// Σ_k ((β_k − a_k) / λ_k)², each parameter's distance in its length scales λ
    /// ([`crate::body::params::MotionParam::scale`]); none at a weight of 0. The
    /// smoothed refit anchors each frame at the Gaussian average of its
    /// neighbours' poses it starts from
    /// ([`crate::track::tracker::TrackOptions::refit_anchor`]), so that what the
    /// silhouette leaves free stays smooth.
    pub fn with_anchor(mut self, anchor: Pose, weight: f64) -> Self {
        self.anchor = (weight > 0.0).then_some((anchor, weight));
        self
    }

    /// The anchor's share of the cost at `pose` ([`Evaluator::with_anchor`]; 0
    /// without one).
    pub fn anchor_cost(&self, pose: &Pose) -> f64 {
        let Some((a, w)) = &self.anchor else {
            return 0.0;
        };
        let sum: f64 = MOTION
            .iter()
            .enumerate()
            .map(|(k, m)| ((pose[k] - a[k]) / m.scale).powi(2))
            .sum();
        w * sum
    }

    /// The pose prior's share of F at `pose`.
    fn prior_cost(&self, pose: &Pose) -> f64 {
        let Some(p) = self.prior else {
            return 0.0;
        };
        let cost = match &self.prior_focus {
            Some(focus) => p.focused_cost(focus, pose),
            None => p.cost(pose),
        };
        self.weights.prior * cost
    }

    /// From now on only the parameters `params` change (the others keep their values
    /// in `pose`): the parts they do not move are rendered once here.
    pub fn focus(&mut self, pose: &Pose, params: &[usize]) {
        let moves = joints_moved_by(params);
        let moving = |i: usize| moves[self.body.parts[i].joint.index()];
        let fixed_all: Vec<usize> = (0..PART_COUNT).filter(|&i| !moving(i)).collect();
        let fixed_limbs: Vec<usize> = fixed_all.iter().copied().filter(|&i| is_limb(i)).collect();
        self.all.moving = (0..PART_COUNT)
            .filter(|&i| moving(i) && !is_limb(i))
            .collect();
        self.limbs.moving = (0..PART_COUNT)
            .filter(|&i| moving(i) && is_limb(i))
            .collect();
        self.body.skeleton.pose(pose, &mut self.base);
        self.moved = Some(moves);
        self.posed_on_base = false;
        self.prior_focus = self.prior.map(|p| p.focus(pose, params));
        if let Some(sm) = &mut self.smooth {
            sm.focus(self.body, &self.base, self.cam, self.target, &moves);
            return;
        }
        self.all.fix(
            self.body,
            &self.base,
            self.cam,
            &fixed_all,
            &self.target.gain,
        );
        if !self.limb_free {
            self.limbs.fix(
                self.body,
                &self.base,
                self.cam,
                &fixed_limbs,
                &self.target.limb_gain,
            );
        }
        if let Some(skin) = &mut self.skin {
            let body = self.body;
            skin.moving = (0..PART_COUNT)
                .filter(|&i| moving(i) && is_bare(body, i))
                .collect();
            let fixed: Vec<usize> = fixed_all
                .iter()
                .copied()
                .filter(|&i| is_bare(body, i))
                .collect();
            skin.fix(body, &self.base, self.cam, &fixed, &self.target.skin_gain);
        }
    }

    /// Every part moves again.
    pub fn unfocus(&mut self) {
        self.moved = None;
        self.posed_on_base = false;
        self.prior_focus = None;
        if let Some(sm) = &mut self.smooth {
            sm.unfocus();
            return;
        }
        self.all.unfix((0..PART_COUNT).filter(|&i| !is_limb(i)));
        self.limbs.unfix((0..PART_COUNT).filter(|&i| is_limb(i)));
        let body = self.body;
        if let Some(skin) = &mut self.skin {
            skin.unfix((0..PART_COUNT).filter(|&i| is_bare(body, i)));
        }
    }

    /// F(β) (+∞ when a constraint is violated).
    pub fn cost(&mut self, pose: &Pose) -> f64 {
        self.evals += 1;
        if !within_limits(pose) {
            return f64::INFINITY;
        }
        let skeleton = &self.body.skeleton;
        match &self.moved {
            Some(moved) if self.posed_on_base => {
                skeleton.repose_moved(pose, moved, &mut self.posed)
            }
            Some(moved) => skeleton.pose_moved(pose, &self.base, moved, &mut self.posed),
            None => skeleton.pose(pose, &mut self.posed),
        }
        self.posed_on_base = self.moved.is_some();
        if self.below_ground() {
            return f64::INFINITY;
        }
        if let Some(sm) = &mut self.smooth {
            let covered = sm.sum(self.body, &self.posed, self.cam, self.target);
            return self.target.base
                + covered
                + self.weights.extremity * self.end_distances()
                + self.prior_cost(pose)
                + self.anchor_cost(pose);
        }
        let mut total = self.target.base + self.all.fixed_sum + self.limbs.fixed_sum;
        if let Some(skin) = &mut self.skin {
            total += skin.fixed_sum;
            skin.clear();
            let rows = render_parts(
                self.body,
                &self.posed,
                self.cam,
                &skin.moving,
                &mut skin.scratch,
            );
            if let Some((y0, y1)) = rows {
                total += sum_over(
                    &self.target.skin_gain,
                    &skin.scratch,
                    Some(&skin.fixed),
                    y0,
                    y1,
                );
            }
            skin.drawn = rows;
        }
        // The moving limbs first, on their own layer; then the rest of the moving
        // parts, and the limbs' pixels, on the whole model's layer.
        self.limbs.clear();
        let limb_rows = render_parts(
            self.body,
            &self.posed,
            self.cam,
            &self.limbs.moving,
            &mut self.limbs.scratch,
        );
        if let (Some((y0, y1)), false) = (limb_rows, self.limb_free) {
            total += sum_over(
                &self.target.limb_gain,
                &self.limbs.scratch,
                Some(&self.limbs.fixed),
                y0,
                y1,
            );
        }
        self.limbs.drawn = limb_rows;
        self.all.clear();
        let rows = render_parts(
            self.body,
            &self.posed,
            self.cam,
            &self.all.moving,
            &mut self.all.scratch,
        );
        let rows = match (rows, limb_rows) {
            (Some((a, b)), Some((c, d))) => Some((a.min(c), b.max(d))),
            (r, None) | (None, r) => r,
        };
        self.all.drawn = rows;
        if let Some((y0, y1)) = rows {
            if let Some((l0, l1)) = limb_rows {
                for y in l0..=l1 {
                    let src = self.limbs.scratch.row(y);
                    for (d, s) in self.all.scratch.row_mut(y).iter_mut().zip(src) {
                        *d |= s;
                    }
                }
            }
            total += sum_over(
                &self.target.gain,
                &self.all.scratch,
                Some(&self.all.fixed),
                y0,
                y1,
            );
        }
        total
            + self.weights.extremity * self.end_distances()
            + self.prior_cost(pose)
            + self.anchor_cost(pose)
    }

    /// The model's whole silhouette at `pose`.
    pub fn render(&mut self, pose: &Pose, out: &mut Mask) {
        self.body.skeleton.pose(pose, &mut self.posed);
        self.posed_on_base = false;
        out.clear();
        let all: [usize; PART_COUNT] = std::array::from_fn(|i| i);
        render_parts(self.body, &self.posed, self.cam, &all, out);
    }

    /// The terms of the paper's F at `pose` (every edge and region pixel rewarded, as
    /// in the initialisation), computed pixel by pixel (slow; for reports and tests).
    pub fn terms(&mut self, pose: &Pose, features: &FrameFeatures) -> Terms {
        let mut m = Mask::new(self.cam.width, self.cam.height);
        self.render(pose, &mut m);
        let mut limbs = Mask::new(self.cam.width, self.cam.height);
        let limb_parts: Vec<usize> = (0..PART_COUNT).filter(|&i| is_limb(i)).collect();
        render_parts(self.body, &self.posed, self.cam, &limb_parts, &mut limbs);
        let mut t = Terms::default();
        let s = &self.target.silhouette;
        for y in 0..self.cam.height {
            for x in 0..self.cam.width {
                let (a, b) = (m.get(x, y), s.get(x, y));
                if a != b {
                    t.xor += features.core(x, y) as f64;
                }
                if a && b && features.edges.get(x, y) {
                    t.edge -= self.weights.edge;
                }
                if limbs.get(x, y) && features.regions.get(x, y) {
                    t.region -= self.weights.region;
                }
            }
        }
        t.extremity = self.weights.extremity * self.end_distances();
        if !self.target.skin_gain.is_empty() {
            let bare: Vec<usize> = (0..PART_COUNT).filter(|&i| is_bare(self.body, i)).collect();
            let mut skin = Mask::new(self.cam.width, self.cam.height);
            if let Some((y0, y1)) = render_parts(self.body, &self.posed, self.cam, &bare, &mut skin)
            {
                t.skin = sum_over(&self.target.skin_gain, &skin, None, y0, y1);
            }
        }
        t.prior = self.prior_cost(pose);
        let ok = within_limits(pose) && !self.below_ground();
        t.total = if ok {
            t.xor + t.edge + t.region + t.extremity + t.skin + t.prior
        } else {
            f64::INFINITY
        };
        t
    }

    /// IoU of the model's silhouette at `pose` with the input silhouette.
    pub fn iou(&mut self, pose: &Pose) -> f64 {
        let mut m = Mask::new(self.cam.width, self.cam.height);
        self.render(pose, &mut m);
        m.iou(&self.target.silhouette)
    }

    /// Lowest point of the soles (world y) of the posed body in `self.posed`.
    fn below_ground(&self) -> bool {
        let Some(g) = self.ground else {
            return false;
        };
        sole_height(self.body, &self.posed) < g - GROUND_SLACK
    }

    /// The hands' and feet's pairing ([`pair_distance`]) after the elbows and
    /// knees claim what candidates they may ([`Weights::claim_reach`]; each only
    /// while its hand or foot is hidden): the least total over every way of
    /// claiming, none included. At most [`MAX_CLAIM_CANDIDATES`] / 2 candidates
    /// of each kind.
    fn claimed_distance(
        &self,
        hands: &[Option<[f64; 2]>; 2],
        feet: &[Option<[f64; 2]>; 2],
        reach: f64,
    ) -> f64 {
        let t = self.target;
        let (nh, nf) = (t.hands.len(), t.feet.len());
        let cands = |i: usize| if i < nh { t.hands[i] } else { t.feet[i - nh] };
        let n = nh + nf;
        let slack = self.weights.claim_reach * t.body_height;
        // Each middle joint's claims: (candidate, cost).
        let mut claims = [[(0usize, 0.0f64); MAX_CLAIM_CANDIDATES]; 4];
        let mut counts = [0usize; 4];
        let middle = [
            (Joint::LeftForeArm, self.radius.0),
            (Joint::RightForeArm, self.radius.0),
            (Joint::LeftLeg, self.radius.1),
            (Joint::RightLeg, self.radius.1),
        ];
        // A middle joint claims only while its own hand or foot is hidden: it
        // projects inside the silhouette, where no candidate can mark it.
        let ends = [hands[0], hands[1], feet[0], feet[1]];
        let hidden = |e: &Option<[f64; 2]>| {
            e.is_some_and(|[x, y]| {
                let m = &t.silhouette;
                x >= 0.0
                    && y >= 0.0
                    && x < m.width() as f64
                    && y < m.height() as f64
                    && m.get(x as u32, y as u32)
            })
        };
        for (k, (j, r)) in middle.iter().enumerate() {
            if !hidden(&ends[k]) {
                continue;
            }
            let c = self.cam.to_camera(&self.posed.joint(*j));
            let Some(q) = self.cam.project_camera(&c) else {
                continue;
            };
            let r_px = r * self.cam.fx / -c.z;
            for i in 0..n {
                let over = dist(&q, &cands(i)) - r_px;
                if over <= slack {
                    claims[k][counts[k]] = (i, over.max(0.0));
                    counts[k] += 1;
                }
            }
        }
        let rest = |used: u32| {
            let mut h = [[0.0; 2]; MAX_CLAIM_CANDIDATES];
            let mut f = [[0.0; 2]; MAX_CLAIM_CANDIDATES];
            let (mut a, mut b) = (0, 0);
            for i in (0..n).filter(|i| used & (1 << i) == 0) {
                if i < nh {
                    h[a] = cands(i);
                    a += 1;
                } else {
                    f[b] = cands(i);
                    b += 1;
                }
            }
            pair_distance(hands, &h[..a], reach) + pair_distance(feet, &f[..b], reach)
        };
        fn each(
            k: usize,
            used: u32,
            sum: f64,
            claims: &[[(usize, f64); MAX_CLAIM_CANDIDATES]; 4],
            counts: &[usize; 4],
            best: &mut f64,
            rest: &dyn Fn(u32) -> f64,
        ) {
            if sum >= *best {
                return;
            }
            if k == 4 {
                *best = best.min(sum + rest(used));
                return;
            }
            each(k + 1, used, sum, claims, counts, best, rest);
            for &(i, c) in &claims[k][..counts[k]] {
                if used & (1 << i) == 0 {
                    each(k + 1, used | 1 << i, sum + c, claims, counts, best, rest);
                }
            }
        }
        let mut best = f64::INFINITY;
        each(0, 0, 0.0, &claims, &counts, &mut best, &rest);
        best
    }

    /// Σ over the model's hands, feet and head top of the pixel distance to a
    /// detected candidate of the same kind (Eq. 5). Left and right cannot be told
    /// apart, so the two hands (feet) take the pairing with the candidates that
    /// makes the sum smallest ([`pair_distance`]); with a single candidate only the
    /// nearer end is pulled to it (the other is probably hidden), and with none the
    /// term is off. With [`Weights::shared_ends`] the four ends pair in the same way
    /// with the hand and foot candidates together ([`shared_distance`]). Each
    /// distance counts at most [`Weights::extremity_reach`] times the person's
    /// height, when that is above 0. Otherwise, with [`Weights::claim_reach`] above
    /// 0, the elbows and knees may first claim candidates
    /// ([`Evaluator::claimed_distance`]).
    fn end_distances(&self) -> f64 {
        let reach = match self.weights.extremity_reach {
            r if r > 0.0 => r * self.target.body_height,
            _ => f64::INFINITY,
        };
        let tip = |t: Tip| {
            let p = self.posed.tips[t as usize];
            self.cam.project(&p)
        };
        let hands = [tip(Tip::LeftHandTip), tip(Tip::RightHandTip)];
        let feet = [tip(Tip::LeftToeTip), tip(Tip::RightToeTip)];
        let mut sum = if self.weights.shared_ends {
            let ends = [hands[0], hands[1], feet[0], feet[1]];
            shared_distance(&ends, &self.target.limb_ends, reach)
        } else if self.weights.claim_reach > 0.0
            && self.target.hands.len().max(self.target.feet.len()) <= MAX_CLAIM_CANDIDATES / 2
        {
            self.claimed_distance(&hands, &feet, reach)
        } else {
            pair_distance(&hands, &self.target.hands, reach)
                + pair_distance(&feet, &self.target.feet, reach)
        };
        if let (Some(h), false) = (tip(Tip::HeadTop), self.target.heads.is_empty()) {
            sum += self
                .target
                .heads
                .iter()
                .map(|c| dist(&h, c))
                .fold(f64::INFINITY, f64::min)
                .min(reach);
        }
        sum
    }
}

/// A set of parts whose silhouette is summed against one gain map: those that move
/// (rendered per evaluation) and those that stay put while a search is focused
/// (rendered once, their sum kept).
struct Layer {
    moving: Vec<usize>,
    fixed: Mask,
    fixed_sum: f64,
    scratch: Mask,
    /// Rows of `scratch` the last evaluation drew (only these need clearing).
    drawn: Option<(u32, u32)>,
}

impl Layer {
    /// A layer of the parts `moving`; its masks are the camera's size when it is
    /// drawn into (`with_masks`: by the pixel objective), and empty for the smooth
    /// objective ([`Weights::smooth`]), which draws none.
    fn new(cam: &Camera, moving: Vec<usize>, with_masks: bool) -> Layer {
        let mask = || match with_masks {
            true => Mask::new(cam.width, cam.height),
            false => Mask::new(0, 0),
        };
        Layer {
            moving,
            fixed: mask(),
            fixed_sum: 0.0,
            scratch: mask(),
            drawn: None,
        }
    }

    /// Nothing fixed any more; `moving` are all the layer's parts (the masks are
    /// kept: an evaluator is re-focused many times per frame).
    fn unfix(&mut self, moving: impl Iterator<Item = usize>) {
        self.moving.clear();
        self.moving.extend(moving);
        self.fixed.clear();
        self.fixed_sum = 0.0;
    }

    /// Clears what the last evaluation drew.
    fn clear(&mut self) {
        if let Some((y0, y1)) = self.drawn.take() {
            self.scratch.clear_rows(y0, y1);
        }
    }

    fn fix(&mut self, body: &Body, posed: &Posed, cam: &Camera, parts: &[usize], gain: &[f32]) {
        self.fixed.clear();
        self.fixed_sum = 0.0;
        if let Some((y0, y1)) = render_parts(body, posed, cam, parts, &mut self.fixed) {
            self.fixed_sum = sum_over(gain, &self.fixed, None, y0, y1);
        }
    }
}

/// The parts' silhouettes summed against the gain maps by the share of each row's
/// centre line they cover ([`Weights::smooth`]).
struct Smooth {
    spans: PartSpans,
    rows: RowBuckets,
    /// The parts that move (all of them unless focused).
    moving: Vec<usize>,
    /// The whole model (G); its arms and legs (the region term) unless their gain
    /// map is all zero (tracking without rewards); its bare parts (the skin term)
    /// when the target has one.
    layers: Vec<SpanLayer>,
}

impl Smooth {
    fn new(body: &Body, cam: &Camera, target: &Target, limbs: bool) -> Smooth {
        let layer =
            |map, f: &dyn Fn(usize) -> bool| SpanLayer::new(cam, map, std::array::from_fn(f));
        let mut layers = vec![layer(Map::All, &|_| true)];
        if limbs {
            layers.push(layer(Map::Limbs, &is_limb));
        }
        if !target.skin_gain.is_empty() {
            layers.push(layer(Map::Skin, &|i| is_bare(body, i)));
        }
        Smooth {
            spans: PartSpans::new(cam.width, cam.height),
            rows: RowBuckets::new(cam.height),
            moving: (0..PART_COUNT).collect(),
            layers,
        }
    }

    fn focus(
        &mut self,
        body: &Body,
        base: &Posed,
        cam: &Camera,
        target: &Target,
        moves: &[bool; JOINT_COUNT],
    ) {
        let moving = |i: usize| moves[body.parts[i].joint.index()];
        let fixed: Vec<usize> = (0..PART_COUNT).filter(|&i| !moving(i)).collect();
        self.moving = (0..PART_COUNT).filter(|&i| moving(i)).collect();
        span_parts(body, base, cam, &fixed, &mut self.spans);
        let sums = target.sums();
        for layer in &mut self.layers {
            layer.fix(&self.spans, &fixed, layer.map.of(sums));
        }
    }

    fn unfocus(&mut self) {
        self.moving = (0..PART_COUNT).collect();
        for layer in &mut self.layers {
            layer.unfix();
        }
    }

    /// Σ of the gain maps over the model at `posed` (without the base).
    fn sum(&mut self, body: &Body, posed: &Posed, cam: &Camera, target: &Target) -> f64 {
        span_parts(body, posed, cam, &self.moving, &mut self.spans);
        let sums = target.sums();
        let mut total = 0.0;
        for layer in &self.layers {
            let run = layer.map.of(sums);
            total += layer.fixed_sum + layer.sum(&self.spans, &self.moving, &mut self.rows, run);
        }
        total
    }
}

/// Which of the target's gain maps a layer sums.
#[derive(Clone, Copy, Debug)]
enum Map {
    All,
    Limbs,
    Skin,
}

impl Map {
    /// The gain map's running sums.
    fn of(self, sums: &RunningSums) -> &[[f32; 2]] {
        match self {
            Map::All => &sums.gain,
            Map::Limbs => &sums.limb,
            Map::Skin => &sums.skin,
        }
    }
}

/// Most intervals one row of a layer can hold: every part's, moving and fixed.
const ROW_CAP: usize = 2 * PART_COUNT;

/// One gain map's share of the smooth objective: its parts, the union of those that
/// stay put while a search is focused, row by row, and that union's sum.
struct SpanLayer {
    map: Map,
    members: [bool; PART_COUNT],
    width: usize,
    /// The fixed parts' union: row y's disjoint intervals, in order, are
    /// `fixed[off[y]..off[y + 1]]`, and their sum `fixed_row[y]`.
    fixed: Vec<[f32; 2]>,
    off: Vec<u32>,
    fixed_row: Vec<f32>,
    fixed_sum: f64,
}

impl SpanLayer {
    fn new(cam: &Camera, map: Map, members: [bool; PART_COUNT]) -> SpanLayer {
        let h = cam.height as usize;
        SpanLayer {
            map,
            members,
            width: cam.width as usize,
            fixed: Vec::new(),
            off: vec![0; h + 1],
            fixed_row: vec![0.0; h],
            fixed_sum: 0.0,
        }
    }

    fn unfix(&mut self) {
        self.fixed.clear();
        self.off.fill(0);
        self.fixed_row.fill(0.0);
        self.fixed_sum = 0.0;
    }

    fn fix(&mut self, spans: &PartSpans, fixed: &[usize], run: &[[f32; 2]]) {
        self.unfix();
        let h = self.fixed_row.len();
        let mut buf = [[0f32; 2]; ROW_CAP];
        let mut total = 0.0;
        for y in 0..h {
            let mut n = 0;
            for &i in fixed {
                if !self.members[i] {
                    continue;
                }
                if let Some((y0, y1)) = spans.rows(i) {
                    if (y0..=y1).contains(&(y as u32)) {
                        if let Some(s) = spans.span(i, y as u32) {
                            buf[n] = s;
                            n += 1;
                        }
                    }
                }
            }
            sort_spans(&mut buf[..n]);
            let row_sum = union_sum(&buf[..n], &[], |a, b| {
                self.fixed.push([a, b]);
                integral(run, self.width, y, a, b)
            });
            self.off[y + 1] = self.fixed.len() as u32;
            self.fixed_row[y] = row_sum;
            total += row_sum as f64;
        }
        self.fixed_sum = total;
    }

    /// What the moving parts add to the fixed parts' sum; `rows` is scratch.
    fn sum(
        &self,
        spans: &PartSpans,
        moving: &[usize],
        rows: &mut RowBuckets,
        run: &[[f32; 2]],
    ) -> f64 {
        let Some((y0, y1)) = rows.gather(spans, moving, &self.members) else {
            return 0.0;
        };
        let mut total = 0f32;
        for y in y0..=y1 {
            let yi = y as usize;
            let Some(moving) = rows.sorted_row(yi) else {
                continue;
            };
            let fixed = &self.fixed[self.off[yi] as usize..self.off[yi + 1] as usize];
            let row = union_sum(moving, fixed, |a, b| integral(run, self.width, yi, a, b));
            total += row - self.fixed_row[yi];
        }
        total as f64
    }
}

/// The moving parts' spans sorted into their rows (scratch, reused).
struct RowBuckets {
    count: Vec<u8>,
    spans: Vec<[f32; 2]>,
}

impl RowBuckets {
    fn new(height: u32) -> RowBuckets {
        RowBuckets {
            count: vec![0; height as usize],
            spans: vec![[0.0; 2]; height as usize * PART_COUNT],
        }
    }

    /// Buckets the spans of the parts of `moving` that are `members`; the rows
    /// they span (None when none is on screen).
    fn gather(
        &mut self,
        spans: &PartSpans,
        moving: &[usize],
        members: &[bool; PART_COUNT],
    ) -> Option<(u32, u32)> {
        let mut rows: Option<(u32, u32)> = None;
        for &i in moving {
            if let (true, Some((a, b))) = (members[i], spans.rows(i)) {
                match rows {
                    Some((lo, hi)) => {
                        // Rows not yet touched start empty (with any gap between).
                        for y in (a..lo).chain(hi + 1..=b) {
                            self.count[y as usize] = 0;
                        }
                        rows = Some((lo.min(a), hi.max(b)));
                    }
                    None => {
                        self.count[a as usize..=b as usize].fill(0);
                        rows = Some((a, b));
                    }
                }
                for y in a..=b {
                    if let Some(s) = spans.span(i, y) {
                        let c = &mut self.count[y as usize];
                        self.spans[y as usize * PART_COUNT + *c as usize] = s;
                        *c += 1;
                    }
                }
            }
        }
        rows
    }

    /// Row `y`'s spans in order, if it has any.
    fn sorted_row(&mut self, y: usize) -> Option<&[[f32; 2]]> {
        let n = self.count[y] as usize;
        if n == 0 {
            return None;
        }
        let row = &mut self.spans[y * PART_COUNT..y * PART_COUNT + n];
        sort_spans(row);
        Some(row)
    }
}

/// Sorts spans by their start (insertion sort: a row holds a few).
#[inline]
fn sort_spans(iv: &mut [[f32; 2]]) {
    for i in 1..iv.len() {
        let mut j = i;
        while j > 0 && iv[j - 1][0] > iv[j][0] {
            iv.swap(j - 1, j);
            j -= 1;
        }
    }
}

/// Σ of `f` over the union of two lists of intervals, each in order of their
/// starts, each disjoint piece of the union once.
#[inline]
fn union_sum(a: &[[f32; 2]], b: &[[f32; 2]], mut f: impl FnMut(f32, f32) -> f32) -> f32 {
    let (mut i, mut j) = (0, 0);
    let mut next = || {
        let take_a = j >= b.len() || (i < a.len() && a[i][0] <= b[j][0]);
        if take_a {
            i += 1;
            a.get(i - 1).copied()
        } else {
            j += 1;
            b.get(j - 1).copied()
        }
    };
    let Some([mut lo, mut hi]) = next() else {
        return 0.0;
    };
    let mut total = 0.0;
    while let Some([l, h]) = next() {
        if l > hi {
            total += f(lo, hi);
            (lo, hi) = (l, h);
        } else if h > hi {
            hi = h;
        }
    }
    total + f(lo, hi)
}

/// ∫ of row `y` of the gain map over columns `[a, b]` (0 ≤ a ≤ b ≤ width), a pixel
/// counting by the share of it the interval covers; `run` as [`RunningSums`] keeps it.
#[inline]
fn integral(run: &[[f32; 2]], width: usize, y: usize, a: f32, b: f32) -> f32 {
    let at = |u: f32| {
        let x = (u as usize).min(width);
        let [p, g] = run[y * (width + 1) + x];
        // Past the row's end g is 0 and u is the width: p itself.
        p + (u - x as f32) * g
    };
    at(b) - at(a)
}

/// Whether part `i` belongs to an arm or a leg (the parts the region term rewards,
/// Eq. 6: the arm and leg regions are where the model's limbs should be).
fn is_limb(i: usize) -> bool {
    i >= crate::body::parts::TRUNK_PARTS
}

/// Whether part `i` is bare skin (the parts the skin term rewards).
fn is_bare(body: &Body, i: usize) -> bool {
    body.parts[i].material == Material::Skin
}

/// The radii (cm) of `body`'s elbow and knee spheres.
fn joint_radii(body: &Body) -> (f64, f64) {
    let r = |j: Joint| {
        body.parts
            .iter()
            .find(|p| p.joint == j && p.kind == crate::body::parts::Kind::Ellipsoid)
            .map_or(0.0, |p| p.radii.x)
    };
    (r(Joint::LeftForeArm), r(Joint::LeftLeg))
}

fn dist(a: &[f64; 2], b: &[f64; 2]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

/// The elbows and knees claim candidates ([`Weights::claim_reach`]) only while
/// there are at most half this many of each kind (hands, feet); an outline with
/// more is paired without claims.
const MAX_CLAIM_CANDIDATES: usize = 16;

/// At most this many candidates are paired with the four ends in
/// [`shared_distance`] (the rest are ignored).
const MAX_SHARED_CANDIDATES: usize = 8;

/// The smallest Σ of the distances (each at most `reach`) from `ends` to distinct
/// candidates among the first [`MAX_SHARED_CANDIDATES`] of `cands`, pairing as many
/// ends as there are candidates (up to all four); the ends left over pay nothing.
/// An end that does not project costs nothing.
fn shared_distance(ends: &[Option<[f64; 2]>; 4], cands: &[[f64; 2]], reach: f64) -> f64 {
    let k = cands.len().min(MAX_SHARED_CANDIDATES);
    let mut d = [[0.0; MAX_SHARED_CANDIDATES]; 4];
    for (e, row) in ends.iter().zip(&mut d) {
        if let Some(e) = e {
            for (c, v) in cands[..k].iter().zip(row.iter_mut()) {
                *v = dist(e, c).min(reach);
            }
        }
    }
    struct Pairing<'a> {
        d: &'a [[f64; MAX_SHARED_CANDIDATES]; 4],
        k: usize,
        best: f64,
    }
    impl Pairing<'_> {
        /// Pairs ends `end..` with candidates not in `used`, leaving `spare` of them
        /// unpaired, on top of `sum` so far.
        fn from(&mut self, end: usize, used: u32, spare: usize, sum: f64) {
            if sum >= self.best {
                return;
            }
            if end == self.d.len() {
                self.best = sum;
                return;
            }
            for c in (0..self.k).filter(|c| used & (1 << c) == 0) {
                self.from(end + 1, used | 1 << c, spare, sum + self.d[end][c]);
            }
            if spare > 0 {
                self.from(end + 1, used, spare - 1, sum);
            }
        }
    }
    let mut p = Pairing {
        d: &d,
        k,
        best: f64::INFINITY,
    };
    p.from(0, 0, ends.len().saturating_sub(k), 0.0);
    p.best
}

/// Smallest total distance pairing two model ends with distinct candidates (one end
/// when there is one candidate; 0 with none), each distance at most `reach`. An end
/// off-screen counts nothing.
fn pair_distance(ends: &[Option<[f64; 2]>; 2], cands: &[[f64; 2]], reach: f64) -> f64 {
    let d = |e: &Option<[f64; 2]>, c: &[f64; 2]| e.map_or(0.0, |e| dist(&e, c).min(reach));
    match cands.len() {
        0 => 0.0,
        1 => d(&ends[0], &cands[0]).min(d(&ends[1], &cands[0])),
        n => {
            let mut best = f64::INFINITY;
            for i in 0..n {
                for j in 0..n {
                    if i != j {
                        best = best.min(d(&ends[0], &cands[i]) + d(&ends[1], &cands[j]));
                    }
                }
            }
            best
        }
    }
}

/// Σ of `gain` over the set pixels of `m` in rows y0..=y1, skipping those set in
/// `except`.
fn sum_over(gain: &[f32], m: &Mask, except: Option<&Mask>, y0: u32, y1: u32) -> f64 {
    let w = m.width() as usize;
    let mut total = 0f32;
    for y in y0..=y1.min(m.height().saturating_sub(1)) {
        let row = m.row(y);
        let skip = except.map(|e| e.row(y));
        let base = y as usize * w;
        let mut acc = 0f32;
        for (k, &word) in row.iter().enumerate() {
            let mut bits = match skip {
                Some(s) => word & !s[k],
                None => word,
            };
            while bits != 0 {
                let b = bits.trailing_zeros() as usize;
                acc += gain[base + k * 64 + b];
                bits &= bits - 1;
            }
        }
        total += acc;
    }
    total as f64
}

/// World y of the lowest sole point (heel or toe of either foot).
pub fn sole_height(body: &Body, posed: &Posed) -> f64 {
    let foot = body.shape()[crate::body::params::sx::FOOT];
    let mut lowest = f64::INFINITY;
    for j in [Joint::LeftFoot, Joint::RightFoot] {
        let frame = posed.joints[j.index()];
        for z in [-2.0, 18.0 * foot] {
            let p = frame * Point3::new(0.0, -8.0, z);
            lowest = lowest.min(p.y);
        }
    }
    lowest
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::params::{ix, rest_pose, STANDARD_SHAPE};
    use crate::vision::features::{compute, FeatureOptions};

    fn scene() -> (Body, Camera, Pose) {
        let body = Body::new(&STANDARD_SHAPE);
        let cam = Camera::new(320, 240, 55.0);
        let mut pose = rest_pose();
        pose[ix::ROOT_TY] -= 100.0;
        pose[ix::ROOT_TZ] = -400.0;
        pose[ix::L_SHOULDER + 1] = 40.0;
        pose[ix::R_SHOULDER + 1] = 30.0;
        pose[ix::L_HIP + 1] = 15.0;
        (body, cam, pose)
    }

    fn target_of(body: &Body, cam: &Camera, pose: &Pose) -> (FrameFeatures, Target) {
        let posed = body.posed(pose);
        let mut m = Mask::new(cam.width, cam.height);
        crate::body::raster::render_mask(body, &posed, cam, &mut m);
        let f = compute(&m, None, None, &FeatureOptions::default());
        let t = Target::new(&f, &Weights::paper());
        (f, t)
    }

    #[test]
    fn fast_cost_matches_the_pixel_by_pixel_terms() {
        let (body, cam, pose) = scene();
        let (f, target) = target_of(&body, &cam, &pose);
        let mut ev = Evaluator::new(&body, &cam, &target, Weights::paper(), None);
        let mut other = pose;
        other[ix::L_ELBOW] = 60.0;
        other[ix::ROOT_TX] += 7.0;
        for p in [pose, other] {
            let fast = ev.cost(&p);
            let slow = ev.terms(&p, &f).total;
            assert!(
                (fast - slow).abs() < 1e-3 * slow.abs().max(1.0),
                "{fast} vs {slow}"
            );
        }
        // Focused on the left arm, the cost is the same function.
        let arm: Vec<usize> = (ix::L_SHOULDER..ix::L_SHOULDER + 4).collect();
        ev.focus(&pose, &arm);
        let mut bent = pose;
        bent[ix::L_ELBOW] = 90.0;
        let focused = ev.cost(&bent);
        ev.unfocus();
        let full = ev.cost(&bent);
        assert!(
            (focused - full).abs() < 1e-6 * full.abs(),
            "{focused} vs {full}"
        );
    }

    #[test]
    fn a_reach_bounds_what_a_candidate_far_from_the_hands_costs() {
        let (body, cam, pose) = scene();
        let (_, mut target) = target_of(&body, &cam, &pose);
        let h = target.body_height;
        assert!(h > 100.0, "{h}");
        let posed = body.posed(&pose);
        let tip = |t: Tip| cam.project(&posed.tips[t as usize]).unwrap();
        let (left, right) = (tip(Tip::LeftHandTip), tip(Tip::RightHandTip));
        target.feet.clear();
        target.heads.clear();
        // The same with the ends by kind and sharing their candidates.
        for shared_ends in [false, true] {
            let cost = |target: &Target, reach: f64| {
                let w = Weights {
                    extremity_reach: reach,
                    shared_ends,
                    ..Weights::default()
                };
                Evaluator::new(&body, &cam, target, w, None).cost(&pose)
            };
            let hands = |target: &mut Target, cands: Vec<[f64; 2]>| {
                target.limb_ends = cands.clone();
                target.hands = cands;
            };
            // Candidates on the hands: nothing to pay, bounded or not.
            hands(&mut target, vec![left, right]);
            let base = cost(&target, 0.0);
            assert_eq!(cost(&target, 0.05), base);
            // One candidate 0.02 of the height from its hand: within the reach, the
            // same pull either way.
            hands(&mut target, vec![left, [right[0] + 0.02 * h, right[1]]]);
            let near = cost(&target, 0.0) - base;
            assert!((near - 20.0 * 0.02 * h).abs() < 1e-6 * h, "{near}");
            assert!((cost(&target, 0.05) - base - near).abs() < 1e-6 * h);
            // 0.3 of the height away (an elbow sticking out of a boxer's guard, say):
            // unbounded it costs the whole distance, bounded the reach alone.
            hands(&mut target, vec![left, [right[0] + 0.3 * h, right[1]]]);
            let far = cost(&target, 0.0) - base;
            assert!((far - 20.0 * 0.3 * h).abs() < 1e-6 * h, "{far}");
            let bounded = cost(&target, 0.05) - base;
            assert!((bounded - 20.0 * 0.05 * h).abs() < 1e-6 * h, "{bounded}");
        }
        // The initialisation's weights are unbounded.
        let w = Weights {
            extremity_reach: 0.05,
            ..Weights::default()
        };
        assert_eq!(w.unbounded_ends().extremity_reach, 0.0);
    }

    #[test]
    fn with_shared_ends_a_raised_foot_labelled_a_hand_pulls_the_foot() {
        // A kick's outline: the raised left foot is above the person's lowest
        // quarter, so it is labelled a hand; the right hand is hidden in front of
        // the body.
        let (body, cam, pose) = scene();
        let (_, mut target) = target_of(&body, &cam, &pose);
        let h = target.body_height;
        let posed = body.posed(&pose);
        let tip = |t: Tip| cam.project(&posed.tips[t as usize]).unwrap();
        let (lh, rh) = (tip(Tip::LeftHandTip), tip(Tip::RightHandTip));
        let (lf, rf) = (tip(Tip::LeftToeTip), tip(Tip::RightToeTip));
        target.heads.clear();
        let cost = |target: &Target, shared_ends: bool| {
            let w = Weights {
                shared_ends,
                ..Weights::default()
            };
            Evaluator::new(&body, &cam, target, w, None).cost(&pose)
        };
        let set = |target: &mut Target, hands: &[[f64; 2]], feet: &[[f64; 2]]| {
            target.hands = hands.to_vec();
            target.feet = feet.to_vec();
            target.limb_ends = [hands, feet].concat();
        };
        set(&mut target, &[], &[]);
        let none = cost(&target, false);
        assert_eq!(cost(&target, true), none);
        set(&mut target, &[lh, lf], &[rf]);
        // Shared, each of the three candidates is on an end of the model: nothing
        // to pay, the hidden right hand left out.
        assert!(
            (cost(&target, true) - none).abs() < 1e-6,
            "{}",
            cost(&target, true) - none
        );
        // By kind, one hand must take the foot.
        let by_kind = cost(&target, false) - none;
        let gap = dist(&rh, &lf).min(dist(&lh, &lf) + dist(&rh, &lh));
        assert!(gap > 0.2 * h, "{gap} {h}");
        assert!((by_kind - 20.0 * gap).abs() < 1e-6 * h, "{by_kind} {gap}");
        // Each end takes the nearest free candidate: four candidates a little off
        // the four ends cost the four offsets, one candidate only its nearest end's.
        let off = |p: [f64; 2], dx: f64| [p[0] + dx, p[1]];
        set(
            &mut target,
            &[off(rh, 3.0), off(lh, 1.0)],
            &[off(rf, -2.0), off(lf, 4.0)],
        );
        assert!((cost(&target, true) - none - 20.0 * 10.0).abs() < 1e-6);
        set(&mut target, &[], &[off(rf, 5.0)]);
        assert!((cost(&target, true) - none - 20.0 * 5.0).abs() < 1e-6);
    }

    #[test]
    fn an_elbow_claims_the_candidate_it_sticks_out_to() {
        // A guard: the right fist is hidden in front of the body, and the right
        // elbow sticks out to the outline, where a hand candidate is found.
        // (The scene's hand is at its side; the test marks its tip hidden or not.)
        let (body, cam, pose) = scene();
        let (_, mut target) = target_of(&body, &cam, &pose);
        target.heads.clear();
        let posed = body.posed(&pose);
        let tip = |t: Tip| cam.project(&posed.tips[t as usize]).unwrap();
        let (lh, rh) = (tip(Tip::LeftHandTip), tip(Tip::RightHandTip));
        let (lf, rf) = (tip(Tip::LeftToeTip), tip(Tip::RightToeTip));
        let elbow = posed.joint(Joint::RightForeArm);
        let e = cam.project(&elbow).unwrap();
        let r_px = joint_radii(&body).0 * cam.fx / -cam.to_camera(&elbow).z;
        // Level with the elbow's centre, out to the side: its radius and a
        // little more away.
        let beyond = 0.01 * target.body_height;
        let rim = [e[0] - r_px - beyond, e[1]];
        let cost = |target: &Target, claim_reach: f64| {
            let w = Weights {
                claim_reach,
                ..Weights::default()
            };
            Evaluator::new(&body, &cam, target, w, None).cost(&pose)
        };
        target.feet = vec![lf, rf];
        target.hands = vec![];
        let none = cost(&target, 0.0);
        assert_eq!(cost(&target, 0.02), none);
        // Without claims the right hand must reach for the elbow's candidate.
        target.hands = vec![lh, rim];
        let unclaimed = cost(&target, 0.0) - none;
        let gap = dist(&rh, &rim).min(dist(&lh, &rim) + dist(&rh, &lh));
        assert!(gap > 5.0 * beyond, "{gap}");
        assert!(
            (unclaimed - 20.0 * gap).abs() < 1e-6 * gap,
            "{unclaimed} {gap}"
        );
        // The right hand shows on the outline: its elbow makes no claim.
        let (x, y) = (rh[0] as u32, rh[1] as u32);
        target.silhouette.set(x, y, false);
        assert!((cost(&target, 0.02) - none - unclaimed).abs() < 1e-6 * gap);
        // Hidden inside the silhouette, it is claimed: the elbow pays what it lies
        // beyond its radius, and the hands pair with what is left: the left hand's
        // candidate, on it.
        target.silhouette.set(x, y, true);
        let claimed = cost(&target, 0.02) - none;
        assert!((claimed - 20.0 * beyond).abs() < 1e-6 * gap, "{claimed}");
        // Beyond the reach, no claim.
        assert!((cost(&target, 0.005) - none - unclaimed).abs() < 1e-6 * gap);
        // The hands on their candidates: a claim has nothing to gain.
        target.hands = vec![lh, rh];
        assert_eq!(cost(&target, 0.02), cost(&target, 0.0));
        // The initialisation's weights make no claims.
        assert_eq!(Weights::default().unbounded_ends().claim_reach, 0.0);
    }

    #[test]
    fn without_rewards_the_cost_is_the_core_weighted_xor_and_the_ends() {
        // Tracking's default target pays no edge or region reward, so the limbs'
        // layer is not summed; nothing else may go missing with it.
        let (body, cam, pose) = scene();
        let (f, _) = target_of(&body, &cam, &pose);
        let target = Target::new(&f, &Weights::default());
        let whole = Weights {
            smooth: false,
            ..Weights::default()
        };
        let mut ev = Evaluator::new(&body, &cam, &target, whole, None);
        let mut other = pose;
        other[ix::L_ELBOW] = 60.0;
        other[ix::ROOT_TX] += 7.0;
        for p in [pose, other] {
            let cost = ev.cost(&p);
            let t = ev.terms(&p, &f);
            let want = t.xor + t.extremity;
            assert!(
                (cost - want).abs() < 1e-3 * want.max(1.0),
                "{cost} vs {want}"
            );
        }
        assert!(ev.cost(&other) > ev.cost(&pose) + 100.0);
    }

    #[test]
    fn the_pose_prior_adds_its_weighted_cost_to_f() {
        let (body, cam, pose) = scene();
        let (f, target) = target_of(&body, &cam, &pose);
        let prior = crate::track::prior::PosePrior::builtin();
        let mut odd = pose;
        odd[ix::L_HIP + 2] = 50.0;
        for smooth in [true, false] {
            let w = Weights {
                smooth,
                prior: PRIOR_WEIGHT,
                ..Weights::default()
            };
            let off = Weights { prior: 0.0, ..w };
            for p in [pose, odd] {
                let none = Evaluator::new(&body, &cam, &target, w, None).cost(&p);
                let zero = Evaluator::new(&body, &cam, &target, off, None)
                    .with_prior(Some(&prior))
                    .cost(&p);
                assert_eq!(none, zero);
                let mut ev = Evaluator::new(&body, &cam, &target, w, None).with_prior(Some(&prior));
                let with = ev.cost(&p);
                let want = w.prior * prior.cost(&p);
                assert!(want > 0.0);
                assert!(
                    (with - none - want).abs() < 1e-6 * want,
                    "{with} - {none} vs {want}"
                );
                assert!((ev.terms(&p, &f).prior - want).abs() < 1e-9 * want);
                // Focused on the left leg (which `odd` moves), the same.
                let leg: Vec<usize> = (ix::L_HIP..ix::L_HIP + 4).collect();
                ev.focus(&pose, &leg);
                let focused = ev.cost(&p);
                ev.unfocus();
                assert!(
                    (focused - with).abs() < 1e-6 * with.abs().max(1.0),
                    "{focused} vs {with}"
                );
            }
        }
    }

    #[test]
    fn the_anchor_adds_its_pull_in_length_scales() {
        let (body, cam, pose) = scene();
        let (_, target) = target_of(&body, &cam, &pose);
        let mut moved = pose;
        moved[ix::L_HIP + 2] += 2.0 * MOTION[ix::L_HIP + 2].scale;
        moved[ix::R_KNEE] += MOTION[ix::R_KNEE].scale;
        for smooth in [true, false] {
            let w = Weights {
                smooth,
                ..Weights::default()
            };
            let plain = |p: &Pose| Evaluator::new(&body, &cam, &target, w, None).cost(p);
            let mut ev = Evaluator::new(&body, &cam, &target, w, None).with_anchor(pose, 3.0);
            // (2² + 1²) squared length scales at 3 each.
            assert!((ev.anchor_cost(&moved) - 15.0).abs() < 1e-9);
            assert_eq!(ev.anchor_cost(&pose), 0.0);
            for p in [pose, moved] {
                let got = ev.cost(&p);
                let want = plain(&p) + ev.anchor_cost(&p);
                assert!(
                    (got - want).abs() < 1e-9 * want.abs().max(1.0),
                    "{got} vs {want}"
                );
            }
            // A weight of 0 is no anchor.
            let none = Evaluator::new(&body, &cam, &target, w, None).with_anchor(pose, 0.0);
            assert_eq!(none.anchor_cost(&moved), 0.0);
        }
    }

    #[test]
    fn the_smooth_cost_is_the_pixel_cost_without_its_steps() {
        let (body, cam, pose) = scene();
        let (_, target) = target_of(&body, &cam, &pose);
        let smooth = Weights {
            smooth: true,
            ..Weights::paper()
        };
        let mut px = Evaluator::new(&body, &cam, &target, Weights::paper(), None);
        let mut sm = Evaluator::new(&body, &cam, &target, smooth, None);
        // Near the pixel cost, at the truth and away from it: where a row of the
        // pixel render goes in or out, the smooth one covers a share of the two
        // pixels either side instead, so it differs by at most their gains.
        let mut away = pose;
        away[ix::L_ELBOW] = 60.0;
        away[ix::ROOT_TX] += 7.0;
        for p in [pose, away] {
            let (a, b) = (px.cost(&p), sm.cost(&p));
            let mut m = Mask::new(cam.width, cam.height);
            px.render(&p, &mut m);
            let g = |x: u32, y: u32| (target.gain[(y * cam.width + x) as usize]).abs() as f64;
            let mut bound = 0.0;
            for y in 0..cam.height {
                for x in 1..cam.width {
                    if m.get(x - 1, y) != m.get(x, y) {
                        bound += g(x - 1, y) + g(x, y);
                    }
                }
            }
            assert!(a != b, "the smooth cost is the pixel cost");
            assert!((a - b).abs() <= bound, "{a} vs {b}, at most {bound} apart");
        }
        // Focused on the left arm, the same function.
        let arm: Vec<usize> = (ix::L_SHOULDER..ix::L_SHOULDER + 4).collect();
        sm.focus(&pose, &arm);
        let mut bent = pose;
        bent[ix::L_ELBOW] = 90.0;
        let focused = sm.cost(&bent);
        sm.unfocus();
        let full = sm.cost(&bent);
        assert!(
            (focused - full).abs() < 1e-4 * full.abs(),
            "{focused} vs {full}"
        );
        // Slid sideways by 1/50 cm at a time (about 1/65 of a pixel): the pixel
        // cost jumps as outlines cross pixel centres; the smooth one moves a little
        // every step, by far less.
        let (mut px_jump, mut sm_jump) = (0f64, 0f64);
        let mut last: Option<(f64, f64)> = None;
        for k in 0..100 {
            let mut p = away;
            p[ix::ROOT_TX] += 0.02 * k as f64;
            let (a, b) = (px.cost(&p), sm.cost(&p));
            if let Some((la, lb)) = last {
                px_jump = px_jump.max((a - la).abs());
                sm_jump = sm_jump.max((b - lb).abs());
                assert!(b != lb, "step {k}: the smooth cost did not move");
            }
            last = Some((a, b));
        }
        assert!(
            sm_jump < 0.2 * px_jump,
            "largest step {sm_jump} smooth against {px_jump} in pixels"
        );
    }

    #[test]
    fn the_skin_term_rewards_bare_parts_on_skin_coloured_pixels() {
        let (body, cam, pose) = scene();
        let posed = body.posed(&pose);
        let mut m = Mask::new(cam.width, cam.height);
        crate::body::raster::render_mask(&body, &posed, &cam, &mut m);
        // A colour frame: skin where the nearest part is bare, a blue shirt elsewhere
        // on the body, a grey room behind.
        let mut frags = Fragments::new(cam.width, cam.height);
        render_fragments(&body, &posed, &cam, &mut frags);
        let frame = image::RgbImage::from_fn(cam.width, cam.height, |x, y| {
            let i = (y * cam.width + x) as usize;
            image::Rgb(if !frags.depth[i].is_finite() {
                [150, 150, 150]
            } else if is_bare(&body, frags.part[i] as usize) {
                [210, 165, 135]
            } else {
                [50, 95, 170]
            })
        });
        let kept = FeatureOptions {
            colours: true,
            ..FeatureOptions::default()
        };
        // Colours are kept only when asked for.
        let f = compute(&m, Some(&frame), None, &FeatureOptions::default());
        assert!(f.colours.is_none());
        let f = compute(&m, Some(&frame), None, &kept);
        // The paper's weights, whose terms() are the fast cost's.
        let w = Weights {
            skin: 4.0,
            ..Weights::paper()
        };
        let mut target = Target::new(&f, &w);
        let model = learn_skin(&body, &cam, &target, &pose).expect("skin and shirt seen");
        assert!(
            model.learned.0 > 100 && model.learned.1 > 1000,
            "{:?}",
            model.learned
        );
        let plain = Evaluator::new(&body, &cam, &target, w, None).cost(&pose);
        target.add_skin(&model, w.skin);
        let mut ev = Evaluator::new(&body, &cam, &target, w, None);
        // The reward: 4 per skin pixel the bare parts cover.
        let skin_pixels = (0..frags.depth.len())
            .filter(|&i| frags.depth[i].is_finite() && is_bare(&body, frags.part[i] as usize))
            .count() as f64;
        let at_truth = ev.terms(&pose, &f);
        assert!(
            (at_truth.skin + 4.0 * skin_pixels).abs() < 0.02 * 4.0 * skin_pixels,
            "{} for {skin_pixels} skin pixels",
            at_truth.skin
        );
        // The fast path agrees, whole or focused on the arm.
        let mut bent = pose;
        bent[ix::L_ELBOW] = 100.0;
        for p in [pose, bent] {
            let fast = ev.cost(&p);
            let slow = ev.terms(&p, &f).total;
            assert!(
                (fast - slow).abs() < 1e-3 * slow.abs().max(1.0),
                "{fast} vs {slow}"
            );
        }
        assert!((ev.cost(&pose) - (plain + at_truth.skin)).abs() < 1e-3 * plain.abs());
        let arm: Vec<usize> = (ix::L_SHOULDER..ix::L_SHOULDER + 4).collect();
        ev.focus(&pose, &arm);
        let focused = ev.cost(&bent);
        ev.unfocus();
        assert!((focused - ev.cost(&bent)).abs() < 1e-6 * focused.abs());
        // The forearm bent off its skin pixels earns less.
        assert!(ev.terms(&bent, &f).skin > at_truth.skin + 4.0 * 20.0);
        // Without a colour frame there is nothing to learn from or to reward.
        let mut grey = Target::new(&compute(&m, None, None, &kept), &w);
        assert!(learn_skin(&body, &cam, &grey, &pose).is_none());
        grey.add_skin(&model, w.skin);
        assert!(grey.skin_gain.is_empty());
    }

    #[test]
    fn own_render_is_near_the_minimum_and_cost_grows_as_a_limb_moves_away() {
        let (body, cam, pose) = scene();
        let (f, target) = target_of(&body, &cam, &pose);
        let mut ev = Evaluator::new(&body, &cam, &target, Weights::paper(), None);
        let own = ev.terms(&pose, &f);
        assert_eq!(own.xor, 0.0, "the model's own silhouette has no mismatch");
        assert!(ev.iou(&pose) > 0.999);
        let mut prev = ev.cost(&pose);
        for step in 1..=6 {
            let mut p = pose;
            p[ix::L_SHOULDER + 1] = 40.0 + 12.0 * step as f64;
            let c = ev.cost(&p);
            assert!(c > prev, "step {step}: {c} ≤ {prev}");
            prev = c;
        }
        let mut moved = pose;
        moved[ix::ROOT_TX] += 10.0;
        assert!(ev.cost(&moved) > ev.cost(&pose));
    }

    #[test]
    fn a_reward_rim_takes_the_rewards_off_the_outline_only() {
        let (body, cam, pose) = scene();
        let (f, paper) = target_of(&body, &cam, &pose);
        let w = Weights {
            reward_rim: 2.0,
            ..Weights::paper()
        };
        let rim = Target::new(&f, &w);
        let (mut outline_rewards, mut deep_regions) = (0, 0);
        for (i, &depth) in f.inside.iter().enumerate() {
            let d = f.coremap[i];
            if depth > 0.0 && depth <= 2.0 {
                // Without a colour frame the edges are the outline itself.
                if paper.gain[i] < -d {
                    outline_rewards += 1;
                }
                assert_eq!(rim.gain[i], -d, "pixel {i}: an outline pixel keeps its XOR");
                assert_eq!(rim.limb_gain[i], 0.0, "pixel {i}");
            } else {
                assert_eq!(rim.gain[i], paper.gain[i], "pixel {i}");
                assert_eq!(rim.limb_gain[i], paper.limb_gain[i], "pixel {i}");
                deep_regions += usize::from(rim.limb_gain[i] < 0.0);
            }
        }
        assert!(
            outline_rewards > 100,
            "{outline_rewards} rewarded outline pixels"
        );
        assert!(
            deep_regions > 100,
            "{deep_regions} region pixels off the rim"
        );
        assert_eq!(rim.base, paper.base);
        let back = rim.paper().expect("rewards withheld");
        assert_eq!(back.gain, paper.gain);
        assert_eq!(back.limb_gain, paper.limb_gain);
        assert!(paper.paper().is_none(), "nothing withheld without a rim");
    }

    #[test]
    fn by_default_tracking_pays_no_rewards_and_the_initialisation_all() {
        let (body, cam, pose) = scene();
        let (f, paper) = target_of(&body, &cam, &pose);
        let tracking = Target::new(&f, &Weights::default());
        let mut rewarded = 0;
        for (i, &d) in f.coremap.iter().enumerate() {
            let inside = paper
                .silhouette
                .get(i as u32 % cam.width, i as u32 / cam.width);
            // Only the XOR term: −d inside the silhouette, d outside.
            assert_eq!(tracking.gain[i], if inside { -d } else { d }, "pixel {i}");
            assert_eq!(tracking.limb_gain[i], 0.0, "pixel {i}");
            rewarded += usize::from(paper.gain[i] != tracking.gain[i] || paper.limb_gain[i] < 0.0);
        }
        assert!(rewarded > 500, "{rewarded} rewarded pixels");
        let back = tracking.paper().expect("rewards withheld");
        assert_eq!(back.gain, paper.gain);
        assert_eq!(back.limb_gain, paper.limb_gain);
        // The reward rim has no say without rewards.
        let rim = Weights {
            reward_rim: 2.0,
            ..Weights::default()
        };
        assert_eq!(Target::new(&f, &rim).gain, tracking.gain);
    }

    #[test]
    fn constraints_make_the_cost_infinite() {
        let (body, cam, pose) = scene();
        let (_, target) = target_of(&body, &cam, &pose);
        let posed = body.posed(&pose);
        let ground = sole_height(&body, &posed);
        let mut ev = Evaluator::new(&body, &cam, &target, Weights::paper(), Some(ground));
        assert!(ev.cost(&pose).is_finite());
        let mut bad = pose;
        bad[ix::L_ELBOW] = 170.0; // beyond the elbow's limit
        assert_eq!(ev.cost(&bad), f64::INFINITY);
        let mut sunk = pose;
        sunk[ix::ROOT_TY] -= 10.0;
        assert_eq!(ev.cost(&sunk), f64::INFINITY);
        let mut jumped = pose;
        jumped[ix::ROOT_TY] += 10.0;
        assert!(ev.cost(&jumped).is_finite());
    }
}
