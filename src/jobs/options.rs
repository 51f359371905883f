//! A job's options: what `monocap track` takes as flags, as JSON (the `options`
//! part of an upload, or query parameters).

use serde::{Deserialize, Serialize};

use crate::track::keyframes::Keyframes;
use crate::track::run::{ClipTrackOptions, MAX_WORK_HEIGHT};
use crate::track::tracker::{
    check_middle_starts, check_parted_middle_starts, check_refit, check_refit_again_iou,
    check_refit_anchor, check_refit_rounds, check_switch_penalty, MAX_POLISH_EVALS,
};
use crate::vision::background::EmptyFrames;

/// Every field is optional; an unknown field is an error, not silently ignored.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JobOptions {
    /// Horizontal field of view of the camera, degrees (default 55).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fov_deg: Option<f64>,
    /// Runs of the hierarchical simplex per frame, 1 to 20 (default 3).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub restarts: Option<usize>,
    /// Evaluations of the joint polish on a poorly fitted frame, 0 to 10,000
    /// (default 0: none; see `TrackOptions::polish_evals`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub polish_evals: Option<usize>,
    /// The smoothed refit's width in frames, 0 (none) to 10 (default 1.5; see
    /// `TrackOptions::refit_sigma`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refit_sigma: Option<f64>,
    /// Runs of the search in each frame's refit at most, 1 to 20 (default 2; the
    /// runs after the first only while the frame's model IoU is under
    /// `refit_again_iou`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refit_runs: Option<usize>,
    /// The model IoU under which a frame's refit searches again, 0 (one run
    /// everywhere) to 1 (every run on every frame; default 0.85).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refit_again_iou: Option<f64>,
    /// The refit's pull toward the neighbours' average it starts from, 0 (none)
    /// to 10,000 (default 16; see `TrackOptions::refit_anchor`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refit_anchor: Option<f64>,
    /// Rounds of the smoothed refit, 1 to 4 (default 2; see
    /// `TrackOptions::refit_rounds`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refit_rounds: Option<usize>,
    /// The second pass, backwards over each block of up to 150 frames (default true;
    /// see `TrackOptions::two_way`): more accurate; false (no middle pass either)
    /// is about twice as fast.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub two_way: Option<bool>,
    /// The middle passes, beside the second one (default true; see
    /// `TrackOptions::middle_pass` and `middle_starts`): more accurate; false is
    /// faster.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub middle_pass: Option<bool>,
    /// Middle passes, 1 to 4 (default 1; see `TrackOptions::middle_starts`): with
    /// n, each block's frames with a person are cut into n + 1 equal runs and a
    /// pass starts where each run meets the next, each about one pass's work more.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub middle_starts: Option<usize>,
    /// Middle passes in all on a block whose passes part, 0 to 4 (default 3; 0:
    /// never; see `TrackOptions::parted_middle_starts`): where a middle pass's
    /// answers lie apart from the backwards pass's, but not far apart over most of
    /// the block, the block is given this many, started as `middle_starts` would
    /// start them.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parted_middle_starts: Option<usize>,
    /// A second initialisation from the start shape with a round trunk, the start
    /// that tracks the next 40 frames at the lower cost kept (default true; see
    /// `TrackOptions::round_start`): more accurate; false starts faster.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub round_start: Option<bool>,
    /// Each of the initialisation's headings also fitted from the pose prior's
    /// cheapest exemplar, a typical captured whole pose (default true; see
    /// `TrackOptions::exemplar_starts`): more accurate; false starts faster.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exemplar_starts: Option<bool>,
    /// Each start of a person in place also tried as its depth mirror, front to
    /// back across the line of sight, the start that tracks the next 40 frames at
    /// the lowest cost kept (default true; see `TrackOptions::mirror_starts`): more
    /// accurate; false starts faster.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mirror_starts: Option<bool>,
    /// The initial candidates probed with every restart and jump, as the frames are
    /// tracked (default false; see `TrackOptions::full_probes`): slower.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub full_probes: Option<bool>,
    /// Every frame also tries the whole body mirrored in depth as a jump (default
    /// false; see `TrackOptions::mirror_jumps`): slower.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mirror_jumps: Option<bool>,
    /// How each frame chooses among the passes' answers, 0 to 1000 (default 0.03;
    /// see `TrackOptions::switch_penalty`): the price of moving from one pass's
    /// track to another's; 0 takes each frame's cheapest answer.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub switch_penalty: Option<f64>,
    /// Keyframes as contracts.md: `{"keyframes": [{"frame": 42, ...}]}`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub keyframes: Option<serde_json::Value>,
    /// Weights of the objective's terms (paper defaults 20, 20, 20 and 1).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub w_edge: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub w_extremity: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub w_region: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub w_core: Option<f64>,
    /// Weight of the inner outlines against the colour frame's edges (default 8,
    /// see `Weights::outline`; 0 for never).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub w_outline: Option<f64>,
    /// Weight of the shading beside the inner outlines, per level² of brightness
    /// misfit over the person's pixels (default 0, see `Weights::shading`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub w_shading: Option<f64>,
    /// Reward per pixel of skin colour the model's bare parts cover (default 2,
    /// see `Weights::skin`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub w_skin: Option<f64>,
    /// Weight of the built-in pose prior (default 20, 0 for none; see
    /// `Weights::prior`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub w_prior: Option<f64>,
    /// While tracking, how far (a fraction of the person's height) a model hand,
    /// foot or head top may lie from every candidate of its kind and still be
    /// pulled to one (default 0, no bound; see `Weights::extremity_reach`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub extremity_reach: Option<f64>,
    /// Let the model's hands and feet share the outline's hand and foot candidates
    /// (default false: each takes those of its kind; see `Weights::shared_ends`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shared_ends: Option<bool>,
    /// While tracking, how far (a fraction of the person's height) beyond its own
    /// radius a model elbow or knee may lie from a hand or foot candidate and
    /// claim it while its hand or foot is hidden (default 0.02; 0 for no claims;
    /// see `Weights::claim_reach`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub claim_reach: Option<f64>,
    /// Pay the edge and region rewards while tracking too, not only in the
    /// initialisation (the paper's objective; default false, see
    /// `Weights::track_rewards`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub track_rewards: Option<bool>,
    /// With `track_rewards`: pixels near the silhouette's outline that earn no edge
    /// or region reward while tracking (default 0; see `Weights::reward_rim`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reward_rim: Option<f64>,
    /// Frame to initialise on (default: chosen automatically).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub init_frame: Option<usize>,
    /// Frames to track, `A..B` (half-open; default: all).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frames: Option<String>,
    /// Person-free frames: `auto`, `none` or `A..B`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub empty_frames: Option<String>,
    /// The clip is a sequence of masks.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub masks: Option<bool>,
    /// Most rows the tracker works at (default 288).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub work_height: Option<u32>,
}

impl JobOptions {
    /// Options from JSON, with a message naming what is wrong.
    pub fn from_json(v: serde_json::Value) -> Result<JobOptions, String> {
        if !v.is_object() {
            return Err("options must be a JSON object".into());
        }
        let opts: JobOptions = serde_json::from_value(v).map_err(|e| format!("options: {e}"))?;
        opts.to_track()?;
        Ok(opts)
    }

    /// Options from query parameters: numbers and booleans as written, `keyframes`
    /// as JSON text.
    pub fn from_query(pairs: &[(String, String)]) -> Result<JobOptions, String> {
        let mut map = serde_json::Map::new();
        for (k, v) in pairs {
            if map.contains_key(k) {
                return Err(format!("option {k} is given twice"));
            }
            let value = match k.as_str() {
                "frames" | "empty_frames" => serde_json::Value::String(v.clone()),
                "keyframes" => serde_json::from_str(v)
                    .map_err(|e| format!("option keyframes is not JSON: {e}"))?,
                _ => {
                    serde_json::from_str(v).unwrap_or_else(|_| serde_json::Value::String(v.clone()))
                }
            };
            map.insert(k.clone(), value);
        }
        JobOptions::from_json(serde_json::Value::Object(map))
    }

    /// Replaces the fields `other` sets (a rerun's new options over the old).
    pub fn merged(&self, other: &JobOptions) -> JobOptions {
        let mut a = serde_json::to_value(self).unwrap_or_default();
        if let (Some(a), serde_json::Value::Object(b)) = (
            a.as_object_mut(),
            serde_json::to_value(other).unwrap_or_default(),
        ) {
            a.extend(b);
        }
        serde_json::from_value(a).unwrap_or_default()
    }

    /// The engine's options, checked.
    pub fn to_track(&self) -> Result<ClipTrackOptions, String> {
        let mut o = ClipTrackOptions::default();
        if let Some(f) = self.fov_deg {
            // The camera's own rule, so a job is never accepted only to fail.
            crate::body::camera::Camera::validate(1, 1, f).map_err(|e| format!("fov_deg: {e}"))?;
            o.fov_deg = f;
        }
        if let Some(r) = self.restarts {
            if !(1..=20).contains(&r) {
                return Err(format!("restarts {r}: expected 1 to 20"));
            }
            o.track.restarts = r;
        }
        if let Some(n) = self.polish_evals {
            if n > MAX_POLISH_EVALS {
                return Err(format!(
                    "polish_evals {n}: expected 0 to {MAX_POLISH_EVALS}"
                ));
            }
            o.track.polish_evals = n;
        }
        let sigma = self.refit_sigma.unwrap_or(o.track.refit_sigma);
        let runs = self.refit_runs.unwrap_or(o.track.refit_runs);
        check_refit(sigma, runs, ("refit_sigma", "refit_runs"))?;
        (o.track.refit_sigma, o.track.refit_runs) = (sigma, runs);
        if let Some(iou) = self.refit_again_iou {
            check_refit_again_iou(iou, "refit_again_iou")?;
            o.track.refit_again_iou = iou;
        }
        if let Some(w) = self.refit_anchor {
            check_refit_anchor(w, "refit_anchor")?;
            o.track.refit_anchor = w;
        }
        if let Some(n) = self.refit_rounds {
            check_refit_rounds(n, "refit_rounds")?;
            o.track.refit_rounds = n;
        }
        if let Some(t) = self.middle_pass {
            o.track.middle_pass = t;
        }
        if let Some(n) = self.middle_starts {
            check_middle_starts(n, "middle_starts")?;
            o.track.middle_starts = n;
        }
        if let Some(n) = self.parted_middle_starts {
            check_parted_middle_starts(n, "parted_middle_starts")?;
            o.track.parted_middle_starts = n;
        }
        if let Some(t) = self.round_start {
            o.track.round_start = t;
        }
        if let Some(t) = self.exemplar_starts {
            o.track.exemplar_starts = t;
        }
        if let Some(t) = self.mirror_starts {
            o.track.mirror_starts = t;
        }
        if let Some(t) = self.full_probes {
            o.track.full_probes = t;
        }
        if let Some(t) = self.mirror_jumps {
            o.track.mirror_jumps = t;
        }
        if let Some(t) = self.two_way {
            o.track.two_way = t;
        }
        if let Some(p) = self.switch_penalty {
            check_switch_penalty(p, "switch_penalty")?;
            o.track.switch_penalty = p;
        }
        let w = &mut o.track.weights;
        for (name, v, slot) in [
            ("w_edge", self.w_edge, &mut w.edge),
            ("w_extremity", self.w_extremity, &mut w.extremity),
            ("w_region", self.w_region, &mut w.region),
            ("w_core", self.w_core, &mut o.track.features.core_weight),
            ("reward_rim", self.reward_rim, &mut w.reward_rim),
            ("w_outline", self.w_outline, &mut w.outline),
            ("w_shading", self.w_shading, &mut w.shading),
            ("w_skin", self.w_skin, &mut w.skin),
            ("w_prior", self.w_prior, &mut w.prior),
            (
                "extremity_reach",
                self.extremity_reach,
                &mut w.extremity_reach,
            ),
            ("claim_reach", self.claim_reach, &mut w.claim_reach),
        ] {
            if let Some(v) = v {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(format!("{name} {v}: expected a number ≥ 0"));
                }
                *slot = v;
            }
        }
        let max = crate::track::objective::MAX_SKIN_WEIGHT;
        if o.track.weights.skin > max {
            return Err(format!(
                "w_skin {}: expected at most {max}",
                o.track.weights.skin
            ));
        }
        use crate::track::objective::check_reach;
        check_reach(o.track.weights.extremity_reach, "extremity_reach")?;
        check_reach(o.track.weights.claim_reach, "claim_reach")?;
        if let Some(t) = self.track_rewards {
            o.track.weights.track_rewards = t;
        }
        if let Some(k) = self.shared_ends {
            o.track.weights.shared_ends = k;
        }
        o.track.init_frame = self.init_frame;
        if let Some(text) = &self.frames {
            o.frames =
                Some(crate::clip::parse_frame_range(text).map_err(|e| format!("frames {e}"))?);
        }
        if let Some(e) = &self.empty_frames {
            o.silhouettes.background.empty =
                EmptyFrames::parse(e).map_err(|e| format!("empty_frames {e}"))?;
        }
        o.masks = self.masks.unwrap_or(false);
        if let Some(h) = self.work_height {
            if !(32..=MAX_WORK_HEIGHT).contains(&h) {
                return Err(format!(
                    "work_height {h}: expected 32 to {MAX_WORK_HEIGHT} rows"
                ));
            }
            o.work_height = h;
        }
        if let Some(k) = &self.keyframes {
            let text = k.to_string();
            if text.len() > crate::track::keyframes::MAX_BYTES {
                return Err(format!(
                    "keyframes: {} bytes, more than the limit of {}",
                    text.len(),
                    crate::track::keyframes::MAX_BYTES
                ));
            }
            o.track.keyframes = Keyframes::parse(&text).map_err(|e| format!("keyframes: {e}"))?;
        }
        Ok(o)
    }
}
