//! The `monocap` command line (contracts.md): one binary, one line on failure.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{anyhow, Context, Result};
use clap::{Args, Parser, Subcommand};
use monocap::clip::{write, Limits};
use monocap::motion::bvh::{Bvh, BvhError};
use monocap::synth::{self, Style, SynthOptions};
use monocap::vision::background::{EmptyFrames, ModelSource};
use monocap::vision::features::{self, FeatureOptions, FrameFeatures};
use monocap::vision::silhouette::{clip_silhouettes, SilhouetteOptions};

#[derive(Parser)]
#[command(
    name = "monocap",
    version,
    about = "Markerless monocular motion capture"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The HTTP service: uploads, a job queue, progress over server-sent events, motion files.
    Serve(ServeArgs),
    /// API keys of the service.
    Keys {
        #[command(subcommand)]
        command: KeysCommand,
    },
    /// Print what a clip is (JSON: container, codec, width, height, fps, frame_count, duration_s).
    Probe(ProbeArgs),
    /// Extract the person's silhouette from every frame of a clip.
    Silhouettes(SilhouettesArgs),
    /// Render a clip of the body model driven by real motion capture, with its ground truth.
    Synth(SynthArgs),
    /// Track a clip: fit the body model to every frame, write the motion (BVH, JSON).
    Track(TrackArgs),
    /// Accuracy benchmark: synthesise clips from motion capture, track them, compare.
    Bench(BenchArgs),
    /// Learn a pose prior (how usual each pose is) from a folder of BVH files, for
    /// `track --pose-prior`.
    Prior(PriorArgs),
}

#[derive(Args)]
struct PriorArgs {
    /// Folder of BVH files (every one is used, at most 400 poses of each).
    #[arg(long)]
    mocap: PathBuf,
    /// Output prior (JSON, monocap.pose-prior/1).
    #[arg(short = 'o', long = "out")]
    out: PathBuf,
}

#[derive(Args, serde::Serialize)]
struct ServeArgs {
    /// Address and port to listen on [default: 127.0.0.1:8080].
    #[arg(long)]
    #[serde(skip_serializing_if = "Option::is_none")]
    listen: Option<String>,
    /// Folder of the database and files [default: ./monocap-data].
    #[arg(long)]
    #[serde(skip_serializing_if = "Option::is_none")]
    data_dir: Option<PathBuf>,
    /// PostgreSQL instead of the data folder's SQLite file (postgres://USER@HOST/DB).
    #[arg(long)]
    #[serde(skip_serializing_if = "Option::is_none")]
    database_url: Option<String>,
    /// Jobs tracking at once [default and most: the machine's cores].
    #[arg(long)]
    #[serde(skip_serializing_if = "Option::is_none")]
    workers: Option<usize>,
    /// Largest upload in MiB [default: 2048].
    #[arg(long)]
    #[serde(skip_serializing_if = "Option::is_none")]
    max_upload_mb: Option<u64>,
    /// Most jobs waiting in the queue [default: 1000].
    #[arg(long)]
    #[serde(skip_serializing_if = "Option::is_none")]
    max_queue: Option<u64>,
    /// Attempts before a job that keeps dying with the process fails [default: 3].
    #[arg(long)]
    #[serde(skip_serializing_if = "Option::is_none")]
    max_attempts: Option<u32>,
    /// Longest a job may track in seconds, 0 for no limit [default: 21600].
    #[arg(long)]
    #[serde(skip_serializing_if = "Option::is_none")]
    job_timeout_s: Option<u64>,
    /// Most frames a clip may have.
    #[arg(long)]
    #[serde(skip_serializing_if = "Option::is_none")]
    max_frames: Option<u64>,
    /// Most pixels a frame may have.
    #[arg(long)]
    #[serde(skip_serializing_if = "Option::is_none")]
    max_pixels: Option<u64>,
    /// Log JSON lines instead of text.
    #[arg(long)]
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    log_json: bool,
    /// A TOML file with any of these settings (flags and MONOCAP_* variables win).
    #[arg(long)]
    #[serde(skip)]
    config: Option<PathBuf>,
}

#[derive(Subcommand)]
enum KeysCommand {
    /// Create an API key; its token is printed once, alone on the last line.
    Create {
        /// Who the key is for (e.g. ci-bot).
        #[arg(long)]
        name: String,
        /// Folder of the database [default: ./monocap-data, or MONOCAP_DATA_DIR].
        #[arg(long, env = "MONOCAP_DATA_DIR", default_value = "monocap-data")]
        data_dir: PathBuf,
        /// The service's PostgreSQL database, when it uses one.
        #[arg(long, env = "MONOCAP_DATABASE_URL")]
        database_url: Option<String>,
    },
}

/// The objective's weights (the paper's defaults).
#[derive(Args)]
struct WeightArgs {
    /// Weight of the edge term (Eq. 4).
    #[arg(long, default_value_t = 20.0)]
    w_edge: f64,
    /// Weight of the hand/foot/head term (Eq. 5).
    #[arg(long, default_value_t = 20.0)]
    w_extremity: f64,
    /// Weight of the arm/leg region term (Eq. 6).
    #[arg(long, default_value_t = 20.0)]
    w_region: f64,
    /// Pay the edge and region rewards while tracking too, not only in the
    /// initialisation (the paper's objective)
    #[arg(long)]
    track_rewards: bool,
    /// With --track-rewards: pixels of the silhouette this close to its outline
    /// earn no edge or region reward while tracking (2 keeps the model at the
    /// person's depth from a right start)
    #[arg(long, default_value_t = 0.0)]
    reward_rim: f64,
    /// Weight of the inner outlines against the colour frame's edges, per pixel,
    /// when choosing between a frame's result and a jump with the same silhouette
    /// (a depth flip, the legs or arms swapped left for right); 0 for never
    #[arg(long, default_value_t = monocap::track::objective::OUTLINE_WEIGHT)]
    w_outline: f64,
    /// Weight of the shading (per level² of brightness misfit over the person's
    /// pixels, each material's brightness fitted to the pose's surface normals),
    /// beside the inner outlines when choosing between a frame's result and a jump;
    /// 0 for never
    #[arg(long, default_value_t = 0.0)]
    w_shading: f64,
    /// Reward per pixel of skin colour (learned on the initial frame) that the
    /// model's bare parts cover (forearms, hands, neck, head); 0 for none
    #[arg(long, default_value_t = monocap::track::objective::SKIN_WEIGHT)]
    w_skin: f64,
    /// Count whole pixels while tracking, as the paper does, instead of a pixel on
    /// the model's outline by the share of its row the model covers (the default,
    /// whose cost changes smoothly as a part moves by less than a pixel: a closer
    /// fit to the silhouettes)
    #[arg(long)]
    whole_pixels: bool,
    /// Weight of the pose prior (how unusual the pose's joint angles are, learned
    /// from motion capture); 0 for none
    #[arg(long, default_value_t = monocap::track::objective::PRIOR_WEIGHT)]
    w_prior: f64,
    /// While tracking, how far (a fraction of the person's height) a model hand,
    /// foot or head top may lie from every candidate of its kind and still be
    /// pulled to one; farther, it pays this distance (0 to 1; 0: no bound, the
    /// paper's term)
    #[arg(long, default_value_t = monocap::track::objective::EXTREMITY_REACH)]
    extremity_reach: f64,
    /// Let the model's hands and feet share the outline's hand and foot
    /// candidates (each end pulled to a distinct one) instead of the hands taking
    /// those labelled hands and the feet those labelled feet by their height: a
    /// foot raised in a kick is labelled a hand
    #[arg(long)]
    shared_ends: bool,
    /// While tracking, how far (a fraction of the person's height) beyond its own
    /// radius a model elbow or knee may lie from a hand or foot candidate and
    /// claim it while its own hand or foot is hidden inside the silhouette,
    /// leaving the hands and feet the rest: a fist hidden in front of the face is
    /// not pulled to the elbow that sticks out (0 to 1; 0: no claims, the paper's
    /// term)
    #[arg(long, default_value_t = monocap::track::objective::CLAIM_REACH)]
    claim_reach: f64,
}

impl WeightArgs {
    fn apply(&self, w: &mut monocap::track::objective::Weights) -> Result<()> {
        for (flag, v) in [
            ("--w-edge", self.w_edge),
            ("--w-extremity", self.w_extremity),
            ("--w-region", self.w_region),
            ("--reward-rim", self.reward_rim),
            ("--w-outline", self.w_outline),
            ("--w-shading", self.w_shading),
            ("--w-skin", self.w_skin),
            ("--w-prior", self.w_prior),
            ("--extremity-reach", self.extremity_reach),
            ("--claim-reach", self.claim_reach),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                anyhow::bail!("{flag} {v}: expected a number ≥ 0");
            }
        }
        let max = monocap::track::objective::MAX_SKIN_WEIGHT;
        if self.w_skin > max {
            anyhow::bail!("--w-skin {}: expected at most {max}", self.w_skin);
        }
        use monocap::track::objective::check_reach;
        check_reach(self.extremity_reach, "--extremity-reach").map_err(anyhow::Error::msg)?;
        check_reach(self.claim_reach, "--claim-reach").map_err(anyhow::Error::msg)?;
        w.edge = self.w_edge;
        w.extremity = self.w_extremity;
        w.region = self.w_region;
        w.reward_rim = self.reward_rim;
        w.track_rewards = self.track_rewards;
        w.outline = self.w_outline;
        w.shading = self.w_shading;
        w.skin = self.w_skin;
        w.smooth = !self.whole_pixels;
        w.prior = self.w_prior;
        w.extremity_reach = self.extremity_reach;
        w.shared_ends = self.shared_ends;
        w.claim_reach = self.claim_reach;
        Ok(())
    }
}

/// The flags of the passes after the first (`track` and `bench`).
#[derive(Args)]
struct RefitArgs {
    /// No second pass (on by default: each block of 150 frames tracked again
    /// backwards from its end, initialised afresh, a frame taking that answer where
    /// the choice of `--switch-penalty` says; and the middle pass). About twice as
    /// fast, less accurate.
    #[arg(long)]
    one_way: bool,
    /// No middle passes (on by default with the second pass: each block tracked
    /// again, initialised afresh on inner frames with a person, see
    /// --middle-starts, and searched from there both ways). Faster, less accurate.
    #[arg(long)]
    no_middle_pass: bool,
    /// Middle passes (1 to 4, 1 by default): with n, each block's frames with a
    /// person are cut into n + 1 equal runs and a pass starts where each run meets
    /// the next, each about one pass's work more.
    #[arg(long, default_value_t = monocap::track::tracker::TrackOptions::default().middle_starts)]
    middle_starts: usize,
    /// Middle passes in all on a block whose passes part (0 to 4; 0, or no more
    /// than --middle-starts: never): where a middle pass's answers lie apart from
    /// the backwards pass's on over 5% of the joints and no more than
    /// --parted-share-max, the block is given this many, as --middle-starts would
    /// start them.
    #[arg(long, default_value_t = monocap::track::tracker::TrackOptions::default().parted_middle_starts)]
    parted_middle_starts: usize,
    /// The most of the joints a middle pass may put apart for its block to be given
    /// --parted-middle-starts (above 0.05, 1 at most: no bound).
    #[arg(long, default_value_t = monocap::track::tracker::PARTED_SHARE_MAX)]
    parted_share_max: f64,
    /// One initialisation, from the start shape (by default a second one starts
    /// from it with a round trunk, and the start that tracks the next 40 frames at
    /// the lower cost is kept). Faster to start, less accurate.
    #[arg(long)]
    one_start: bool,
    /// Fit each of the initialisation's headings from the rest pose alone (by
    /// default also from the pose prior's exemplar, a typical captured whole pose,
    /// that costs least there, the cheaper fit kept). Faster to start, less
    /// accurate.
    #[arg(long)]
    no_exemplar_starts: bool,
    /// Leave out the starts' depth mirrors (by default, unless the person travels,
    /// each start is also tried mirrored front to back across the line of sight,
    /// refined, and the start that tracks the next 40 frames at the lowest cost is
    /// kept). Faster to start, less accurate.
    #[arg(long)]
    no_mirror_starts: bool,
    /// Probe the initial candidates as the frames are tracked, with every restart
    /// and jump (by default once per frame and without jumps). Slower.
    #[arg(long)]
    full_probes: bool,
    /// Also try the whole body mirrored in depth as a jump on every frame (off by
    /// default: measured and not kept, README "The whole body mirrored in depth,
    /// as a jump"). Slower.
    #[arg(long)]
    mirror_jumps: bool,
    /// Where the second pass starts: the best-scoring initial frame among each
    /// block's last this many frames with a person (1 to 150; 1: the last one).
    #[arg(long, default_value_t = 1)]
    second_pass_window: usize,
    /// How each frame chooses among the passes' answers: over each block, the
    /// sequence with the least summed cost plus this many times the median
    /// frame's cost for each length scale the pose moves from a frame to the next
    /// (0 to 1000; 0 takes each frame's cheapest answer).
    #[arg(long, default_value_t = monocap::track::tracker::SWITCH_PENALTY)]
    switch_penalty: f64,
    /// A jump (a depth flip, the nod into the trunk, the crouch) whose refinement
    /// still costs more than this many times the frame's result after one of its
    /// groups is given up (0: never; 1 to 100).
    #[arg(long, default_value_t = monocap::track::tracker::JUMP_GIVE_UP)]
    jump_give_up: f64,
    /// The smoothed refit: each frame searched again from the Gaussian average of
    /// its neighbours' poses, this many frames wide (0 for none); on a helper
    /// thread behind the search when there are two threads or more.
    #[arg(long, default_value_t = monocap::track::tracker::TrackOptions::default().refit_sigma)]
    refit_sigma: f64,
    /// Runs of the search in each frame's refit, at most (see --refit-again-iou).
    #[arg(long, default_value_t = monocap::track::tracker::TrackOptions::default().refit_runs)]
    refit_runs: usize,
    /// A frame's refit runs the search again only while its model IoU is under
    /// this (0: one run everywhere; 1: all of --refit-runs on every frame).
    #[arg(long, default_value_t = monocap::track::tracker::REFIT_AGAIN_IOU)]
    refit_again_iou: f64,
    /// The refit's pull toward the neighbours' average it starts from, per squared
    /// length scale each parameter moves from it (0 for none; 0 to 10000): what
    /// the silhouette leaves free stays smooth.
    #[arg(long, default_value_t = monocap::track::tracker::REFIT_ANCHOR)]
    refit_anchor: f64,
    /// Rounds of the smoothed refit, 1 to 4: each after the first searches every
    /// frame again from the average of the round before's answers.
    #[arg(long, default_value_t = monocap::track::tracker::REFIT_ROUNDS)]
    refit_rounds: usize,
}

impl RefitArgs {
    /// The flags, checked, into `track`.
    fn apply(&self, track: &mut monocap::track::tracker::TrackOptions) -> Result<()> {
        track.two_way = !self.one_way;
        track.middle_pass = !self.no_middle_pass;
        monocap::track::tracker::check_middle_starts(self.middle_starts, "--middle-starts")
            .map_err(anyhow::Error::msg)?;
        track.middle_starts = self.middle_starts;
        monocap::track::tracker::check_parted_middle_starts(
            self.parted_middle_starts,
            "--parted-middle-starts",
        )
        .map_err(anyhow::Error::msg)?;
        track.parted_middle_starts = self.parted_middle_starts;
        monocap::track::tracker::check_parted_share_max(
            self.parted_share_max,
            "--parted-share-max",
        )
        .map_err(anyhow::Error::msg)?;
        track.parted_share_max = self.parted_share_max;
        track.round_start = !self.one_start;
        track.exemplar_starts = !self.no_exemplar_starts;
        track.mirror_starts = !self.no_mirror_starts;
        track.full_probes = self.full_probes;
        track.mirror_jumps = self.mirror_jumps;
        monocap::track::tracker::check_second_pass_window(
            self.second_pass_window,
            "--second-pass-window",
        )
        .map_err(anyhow::Error::msg)?;
        track.second_pass_window = self.second_pass_window;
        monocap::track::tracker::check_switch_penalty(self.switch_penalty, "--switch-penalty")
            .map_err(anyhow::Error::msg)?;
        track.switch_penalty = self.switch_penalty;
        monocap::track::tracker::check_jump_give_up(self.jump_give_up, "--jump-give-up")
            .map_err(anyhow::Error::msg)?;
        track.jump_give_up = self.jump_give_up;
        let (sigma, runs) = (self.refit_sigma, self.refit_runs);
        monocap::track::tracker::check_refit(sigma, runs, ("--refit-sigma", "--refit-runs"))
            .map_err(anyhow::Error::msg)?;
        track.refit_sigma = sigma;
        track.refit_runs = runs;
        monocap::track::tracker::check_refit_again_iou(self.refit_again_iou, "--refit-again-iou")
            .map_err(anyhow::Error::msg)?;
        track.refit_again_iou = self.refit_again_iou;
        monocap::track::tracker::check_refit_anchor(self.refit_anchor, "--refit-anchor")
            .map_err(anyhow::Error::msg)?;
        track.refit_anchor = self.refit_anchor;
        monocap::track::tracker::check_refit_rounds(self.refit_rounds, "--refit-rounds")
            .map_err(anyhow::Error::msg)?;
        track.refit_rounds = self.refit_rounds;
        Ok(())
    }
}

#[derive(Args)]
struct TrackArgs {
    /// MP4/AVI (H.264, MJPEG), Y4M, GIF/APNG/WebP, ZIP/TAR of frames or of masks.
    clip: PathBuf,
    /// Output motion; the extension picks the format: .bvh or .json.
    #[arg(short = 'o', long = "out")]
    out: PathBuf,
    /// Also write the motion JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Horizontal field of view of the camera in degrees.
    #[arg(long, default_value_t = 55.0)]
    fov_deg: f64,
    /// Keyframes JSON ({"keyframes": [{"frame": 42, "range": 10, "params": {...}}]}).
    #[arg(long)]
    keyframes: Option<PathBuf>,
    /// Write the model's silhouette per frame (a .zip of PNGs, or .tar/.gif/.y4m).
    #[arg(long)]
    model_masks: Option<PathBuf>,
    /// Runs of the hierarchical simplex per frame.
    #[arg(long, default_value_t = 3)]
    restarts: usize,
    /// Evaluations of the joint polish (CMA-ES over all parameters at once) on a
    /// frame the model fits poorly (IoU under 0.85); 0 for none. Fewer lost
    /// frames, a sixth to a quarter of the speed.
    #[arg(long, default_value_t = monocap::track::tracker::TrackOptions::default().polish_evals)]
    polish_evals: usize,
    #[command(flatten)]
    refit: RefitArgs,
    /// Threads the tracker may use (0: one per core; 1: none beside the search).
    /// Features are computed ahead of the search and the initialisation's fits
    /// run side by side; the result is the same for any number.
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Frame to initialise on (default: chosen automatically).
    #[arg(long)]
    init_frame: Option<usize>,
    /// Person-free frames: auto (still leading frames), none, or a range A..B.
    #[arg(long, default_value = "auto")]
    empty_frames: String,
    /// The clip is a sequence of masks: no background subtraction.
    #[arg(long)]
    masks: bool,
    #[command(flatten)]
    weights: WeightArgs,
    /// A pose prior learned by `monocap prior`, weighed in by --w-prior (which must
    /// then be above 0), instead of the built-in prior, learned from the
    /// benchmark's captures.
    #[arg(long)]
    pose_prior: Option<PathBuf>,
    /// Weight w of the inside distance in the coremap (Eq. 3).
    #[arg(long, default_value_t = 1.0)]
    w_core: f64,
    /// The tracker works at a whole fraction of the clip's size, at most this many rows.
    #[arg(long, default_value_t = 288)]
    work_height: u32,
}

#[derive(Args)]
struct BenchArgs {
    /// Folder of BVH files (every one is used).
    #[arg(long, default_value = "../shared/data/mocap")]
    mocap: PathBuf,
    /// Only files whose name contains this.
    #[arg(long)]
    only: Option<String>,
    /// Camera azimuths in degrees, comma-separated.
    #[arg(long, default_value = "0,60,-120", allow_hyphen_values = true)]
    azimuths: String,
    /// Person-free lead-in frames, comma-separated (one clip per value).
    #[arg(long, default_value = "10,0")]
    lead_in: String,
    /// Seconds of motion per clip.
    #[arg(long, default_value_t = 3.5)]
    duration_s: f64,
    /// Runs of the hierarchical search per frame.
    #[arg(long, default_value_t = 3)]
    restarts: usize,
    /// Evaluations of the joint polish (CMA-ES over all parameters at once) on a
    /// frame the group search and the jumps leave poorly fitted; 0 for none.
    #[arg(long, default_value_t = monocap::track::tracker::TrackOptions::default().polish_evals)]
    polish_evals: usize,
    #[command(flatten)]
    refit: RefitArgs,
    /// Threads the tracker may use (0: one per core; 1: none beside the search).
    /// Features are computed ahead of the search and the initialisation's fits
    /// run side by side; the result is the same for any number.
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// The joint polish runs on frames whose model covers the silhouette with an IoU
    /// under this (above 1 for every frame).
    #[arg(long, default_value_t = monocap::track::tracker::TrackOptions::default().polish_iou)]
    polish_iou: f64,
    /// Whether the joint polish also runs on a frame whose cost spikes (over
    /// `--recover-spike` times the recent median), whatever its IoU.
    #[arg(long, default_value_t = monocap::track::tracker::TrackOptions::default().polish_spike, action = clap::ArgAction::Set)]
    polish_spike: bool,
    /// Weight of the proportions prior in the initialisation's joint fit (the
    /// ratios upper arm / forearm, thigh / shin, trunk / thigh held near the start
    /// shape's); 0 for none (the default; README "The proportions prior").
    #[arg(long, default_value_t = monocap::track::tracker::TrackOptions::default().shape_ratio_prior)]
    w_ratio: f64,
    /// Search a frame again widely when the model covers its silhouette with an IoU
    /// under this (at most every fifth frame); 0 for never.
    #[arg(long, default_value_t = monocap::track::tracker::TrackOptions::default().recover_iou)]
    recover_iou: f64,
    /// Search a frame again widely when its cost is over this many times the median
    /// of the last ten frames' (at most every fifth frame); 0 for never.
    #[arg(long, default_value_t = monocap::track::tracker::TrackOptions::default().recover_spike)]
    recover_spike: f64,
    /// Track the true silhouettes instead of the extracted ones.
    #[arg(long)]
    true_silhouettes: bool,
    /// Start from the true shape and pose (measures tracking apart from initialisation).
    #[arg(long)]
    oracle_init: bool,
    /// Give the initialisation the true shape: it fits the pose alone (measures
    /// what the shape fit costs).
    #[arg(long)]
    oracle_shape: bool,
    /// Start each frame's search from the previous pose moved by every parameter's
    /// velocity, as the paper has it (by default the root position's alone).
    #[arg(long)]
    joint_velocity: bool,
    /// Start from the initial candidate the front/back choice does not take (shows
    /// what the choice is worth: run the benchmark with and without it).
    #[arg(long)]
    other_candidate: bool,
    /// Also write every frame's figures to this CSV file (PCK, PA-MPJPE, IoU, cost,
    /// the truth's cost, heading error, depth ratio).
    #[arg(long, value_name = "CSV")]
    per_frame: Option<PathBuf>,
    /// Seed of the clips' background and sensor noise: the same motions rendered
    /// with other noise, to see how far the figures move by chance.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Every N frames with a person (0: never), also find the bottom of the truth's
    /// basin under the fitted shape and say whether it costs less than the tracked
    /// answer (two searches of up to 9,000 evaluations per probed frame).
    #[arg(long, default_value_t = 0, value_name = "N")]
    basin_probe: usize,
    /// The pose prior: held-out (for each capture, one learned from the other
    /// files in the folder), builtin (learned from these captures themselves:
    /// flattering) or none.
    #[arg(long, default_value = "held-out")]
    prior: String,
    /// The shape the initialisation starts from: held-out (for each capture, the
    /// typical performer of the captures from other sources in the folder),
    /// typical (the tracker's default, measured from these captures: flattering)
    /// or standard (every shape value 1).
    #[arg(long, default_value = "held-out")]
    start_shape: String,
    /// Evaluations of the initialisation's joint fit (CMA-ES over the shape and the
    /// pose at once, after the simplex has fitted them in turn); 0 for none.
    #[arg(long, default_value_t = monocap::track::tracker::TrackOptions::default().init_joint_evals)]
    init_joint_evals: usize,
    #[command(flatten)]
    weights: WeightArgs,
}

#[derive(Args)]
struct ProbeArgs {
    /// MP4/AVI (H.264, MJPEG), Y4M, GIF/APNG/WebP, ZIP/TAR of frames; anything else via ffmpeg.
    clip: PathBuf,
}

#[derive(Args)]
struct SilhouettesArgs {
    clip: PathBuf,
    /// Output: one 0/255 PNG per frame in a .zip or .tar (or a .gif/.y4m clip).
    #[arg(short = 'o', long = "out")]
    out: PathBuf,
    /// Person-free frames: auto (still leading frames), none, or a range A..B.
    #[arg(long, default_value = "auto")]
    empty_frames: String,
    /// The clip already is a sequence of masks: threshold it, no background subtraction.
    #[arg(long)]
    masks: bool,
    /// Also write what the tracker sees per frame (silhouette, coremap, edges, outline
    /// features) as a clip (.zip of PNGs, .gif, ...).
    #[arg(long)]
    debug: Option<PathBuf>,
}

#[derive(Args)]
struct SynthArgs {
    /// Motion capture to play (BVH: CMU, Bandai Namco, Mixamo, Unreal names).
    #[arg(long)]
    bvh: PathBuf,
    /// Output clip; the extension picks the format: .y4m, .zip (PNG frames), .tar, .gif.
    #[arg(long)]
    out: PathBuf,
    /// Ground truth JSON (monocap.truth/1).
    #[arg(long)]
    truth: Option<PathBuf>,
    #[arg(long, default_value_t = 320)]
    width: u32,
    #[arg(long, default_value_t = 240)]
    height: u32,
    /// Horizontal field of view in degrees.
    #[arg(long, default_value_t = 55.0)]
    fov_deg: f64,
    /// Frames per second of the clip (the capture is resampled to it).
    #[arg(long, default_value_t = 30.0)]
    fps: f64,
    #[arg(long, value_enum, default_value_t = Style::Color)]
    style: Style,
    /// Person-free frames before the motion starts.
    #[arg(long, default_value_t = 0)]
    empty_frames: usize,
    /// Camera direction around the performer: 0 = in front, 90 = at their left.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    azimuth_deg: f64,
    /// First frame of the capture to use.
    #[arg(long, default_value_t = 0)]
    first_frame: usize,
    /// Seconds of motion to render (default: to the end of the capture).
    #[arg(long)]
    duration_s: Option<f64>,
    /// Seed of the background and the sensor noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind::*;
            match e.kind() {
                DisplayHelp | DisplayVersion => {
                    let _ = e.print();
                    return ExitCode::SUCCESS;
                }
                // `monocap` alone: the help, but as a usage error.
                DisplayHelpOnMissingArgumentOrSubcommand => {
                    let _ = e.print();
                    return ExitCode::from(2);
                }
                _ => {}
            }
            // One line naming the problem: clap's first paragraph (which lists missing
            // arguments on lines of their own), without the usage and tips after it.
            let text = e.render().to_string();
            let first: Vec<&str> = text
                .lines()
                .map(str::trim)
                .take_while(|l| !l.is_empty())
                .collect();
            let first = first.join(" ");
            let first = first.trim_start_matches("error: ");
            eprintln!(
                "monocap: {}",
                if first.is_empty() {
                    "invalid arguments"
                } else {
                    first
                }
            );
            return ExitCode::from(2);
        }
    };
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("monocap: {}", format!("{e:#}").replace('\n', " "));
            ExitCode::FAILURE
        }
    }
}

/// The one-shot commands end quietly, as other command-line tools do, when the
/// program reading their output stops (`monocap bench | head`): Rust ignores
/// SIGPIPE, and every later print to the closed pipe would panic. The service
/// keeps ignoring it: a client hanging up must not stop the server.
fn end_on_closed_pipe() {
    #[cfg(unix)]
    // SAFETY: called at start-up, before any other thread exists; restores the
    // signal's default disposition and touches no memory.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

fn run(cli: Cli) -> Result<()> {
    if !matches!(cli.command, Command::Serve(_) | Command::Keys { .. }) {
        end_on_closed_pipe();
    }
    match cli.command {
        Command::Probe(a) => probe_command(a),
        Command::Silhouettes(a) => silhouettes_command(a),
        Command::Synth(a) => synth_command(a),
        Command::Track(a) => track_command(a),
        Command::Serve(a) => serve_command(a),
        Command::Keys {
            command:
                KeysCommand::Create {
                    name,
                    data_dir,
                    database_url,
                },
        } => runtime()?.block_on(async {
            let (id, token) =
                monocap::api::server::create_key(&data_dir, database_url.as_deref(), &name).await?;
            println!(
                "created API key {name:?} (id {id}) in {}; its token, shown only now:",
                data_dir.display()
            );
            println!("{token}");
            Ok(())
        }),
        Command::Bench(a) => bench_command(a),
        Command::Prior(a) => prior_command(a),
    }
}

fn probe_command(a: ProbeArgs) -> Result<()> {
    let info = monocap::clip::open::probe(&a.clip, &Limits::default())?;
    println!("{}", serde_json::to_string_pretty(&info)?);
    Ok(())
}

fn runtime() -> Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("cannot start the async runtime")
}

fn serve_command(a: ServeArgs) -> Result<()> {
    use monocap::api::server::{serve, ServeConfig};
    let overrides = serde_json::to_value(&a)?;
    let cfg = ServeConfig::load(a.config.as_deref(), overrides)?;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info,sqlx=warn,tower_http=info"));
    let logs = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr);
    if cfg.log_json {
        logs.json().init();
    } else {
        logs.init();
    }
    runtime()?.block_on(serve(cfg))
}

fn parse_empty_frames(text: &str) -> Result<EmptyFrames> {
    EmptyFrames::parse(text).map_err(|e| anyhow!("--empty-frames {e}"))
}

fn silhouettes_command(a: SilhouettesArgs) -> Result<()> {
    let limits = Limits::default();
    let mut opts = SilhouetteOptions::default();
    opts.background.empty = parse_empty_frames(&a.empty_frames)?;
    let info = monocap::clip::open::probe(&a.clip, &limits)?;
    let fps = if info.fps > 0.0 { info.fps } else { 30.0 };
    let mut out = write::create(&a.out, info.width, info.height, fps)?;
    let mut debug = match &a.debug {
        Some(p) => Some(write::create(p, info.width * 2, info.height, fps)?),
        None => None,
    };
    let feature_opts = FeatureOptions::default();
    let mut previous: Option<FrameFeatures> = None;
    let start = std::time::Instant::now();
    let done = clip_silhouettes(&a.clip, &limits, &opts, a.masks, |_, frame, mask| {
        out.push(write::Frame::Gray(&mask.to_gray()))?;
        if let Some(debug) = debug.as_mut() {
            let f = features::compute(mask, Some(frame), previous.as_ref(), &feature_opts);
            debug.push(write::Frame::Rgb(&features::debug_image(
                Some(frame),
                mask,
                &f,
            )))?;
            previous = Some(f);
        }
        Ok(())
    })?;
    out.finish()?;
    if let Some(debug) = debug {
        debug.finish()?;
    }
    let secs = start.elapsed().as_secs_f64();
    let how = match &done.source {
        None => "a mask clip, read as it is".to_string(),
        Some(ModelSource::EmptyFrames { first, count }) => {
            format!(
                "background from person-free frames {first}..{}",
                first + count
            )
        }
        Some(ModelSource::WholeClip { frames }) => {
            format!("background from the whole clip ({frames} frames)")
        }
    };
    eprintln!(
        "monocap: wrote {} ({} silhouettes, {how}; {:.1} frames/s)",
        a.out.display(),
        done.frames,
        done.frames as f64 / secs.max(1e-9)
    );
    if let Some(w) = done.warning() {
        eprintln!("monocap: warning: {w}");
    }
    Ok(())
}

fn synth_command(a: SynthArgs) -> Result<()> {
    // Parse errors name the line but not the file; I/O errors name the file and
    // would repeat their cause if kept as an error chain.
    let bvh = Bvh::read(&a.bvh).map_err(|e| match e {
        BvhError::Io { .. } | BvhError::FileTooLarge { .. } => anyhow!("{e}"),
        e => anyhow!("{}: {e}", a.bvh.display()),
    })?;
    let opts = SynthOptions {
        width: a.width,
        height: a.height,
        fov_deg: a.fov_deg,
        fps: a.fps,
        style: a.style,
        empty_frames: a.empty_frames,
        azimuth_deg: a.azimuth_deg,
        first_frame: a.first_frame,
        duration_s: a.duration_s,
        seed: a.seed,
    };
    let name = a
        .bvh
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let truth = synth::synthesize(&bvh, &name, &opts, &a.out)?;
    if let Some(path) = &a.truth {
        let file =
            File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
        let mut w = BufWriter::new(file);
        serde_json::to_writer(&mut w, &truth)?;
        w.write_all(b"\n")?;
        w.flush()
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    eprintln!(
        "monocap: wrote {} ({} frames, {} person-free; camera {:.0} cm away; retarget residual mean {:.2} cm, max {:.2} cm)",
        a.out.display(),
        truth.frame_count,
        truth.empty_frames,
        truth.camera.distance_cm,
        truth.retarget.mean_cm,
        truth.retarget.max_cm
    );
    Ok(())
}

fn parse_list<T: std::str::FromStr>(flag: &str, text: &str) -> Result<Vec<T>> {
    text.split(',')
        .map(|v| {
            v.trim()
                .parse::<T>()
                .map_err(|_| anyhow!("{flag} {text:?}: {v:?} is not a number"))
        })
        .collect()
}

/// `--threads`: 0 (one per core) to the tracker's most.
fn check_threads(n: usize) -> Result<usize> {
    let most = monocap::track::tracker::MAX_THREADS;
    if n > most {
        anyhow::bail!("--threads {n}: expected 0 (one per core) to {most}");
    }
    Ok(n)
}

/// `--polish-evals` within [`monocap::track::tracker::MAX_POLISH_EVALS`].
fn check_polish_evals(n: usize) -> Result<()> {
    use monocap::track::tracker::MAX_POLISH_EVALS;
    if n > MAX_POLISH_EVALS {
        anyhow::bail!("--polish-evals {n}: expected 0 to {MAX_POLISH_EVALS}");
    }
    Ok(())
}

fn bench_command(a: BenchArgs) -> Result<()> {
    use monocap::track::bench::{self, BenchOptions};
    use monocap::track::metrics::Accumulator;
    let mut opts = BenchOptions {
        mocap_dir: a.mocap,
        filter: a.only,
        azimuths: parse_list("--azimuths", &a.azimuths)?,
        lead_in: parse_list("--lead-in", &a.lead_in)?,
        duration_s: a.duration_s,
        true_silhouettes: a.true_silhouettes,
        oracle_init: a.oracle_init,
        oracle_shape: a.oracle_shape,
        seed: a.seed,
        basin_probe: a.basin_probe,
        prior: match a.prior.as_str() {
            "held-out" => bench::PriorChoice::HeldOut,
            "builtin" => bench::PriorChoice::Builtin,
            "none" => bench::PriorChoice::None,
            other => anyhow::bail!("--prior {other}: expected held-out, builtin or none"),
        },
        start_shape: match a.start_shape.as_str() {
            "held-out" => bench::StartShape::HeldOut,
            "typical" => bench::StartShape::Typical,
            "standard" => bench::StartShape::Standard,
            other => {
                anyhow::bail!("--start-shape {other}: expected held-out, typical or standard")
            }
        },
        ..BenchOptions::default()
    };
    opts.track.restarts = a.restarts;
    opts.track.joint_velocity = a.joint_velocity;
    opts.track.other_candidate = a.other_candidate;
    check_polish_evals(a.polish_evals)?;
    opts.track.polish_evals = a.polish_evals;
    let most = monocap::track::tracker::MAX_INIT_JOINT_EVALS;
    if a.init_joint_evals > most {
        anyhow::bail!(
            "--init-joint-evals {}: expected 0 to {most}",
            a.init_joint_evals
        );
    }
    opts.track.init_joint_evals = a.init_joint_evals;
    a.refit.apply(&mut opts.track)?;
    opts.track.threads = check_threads(a.threads)?;
    if a.polish_iou.is_nan() || a.polish_iou < 0.0 {
        anyhow::bail!(
            "--polish-iou {}: expected a number from 0 (never) up",
            a.polish_iou
        );
    }
    opts.track.polish_iou = a.polish_iou;
    opts.track.polish_spike = a.polish_spike;
    if !a.w_ratio.is_finite() || a.w_ratio < 0.0 {
        anyhow::bail!(
            "--w-ratio {}: expected a weight from 0 (none) up",
            a.w_ratio
        );
    }
    opts.track.shape_ratio_prior = a.w_ratio;
    if !(0.0..=1.0).contains(&a.recover_iou) {
        anyhow::bail!(
            "--recover-iou {}: expected an IoU from 0 to 1",
            a.recover_iou
        );
    }
    opts.track.recover_iou = a.recover_iou;
    if a.recover_spike.is_nan() || a.recover_spike < 0.0 {
        anyhow::bail!(
            "--recover-spike {}: expected a factor from 0 (never) up",
            a.recover_spike
        );
    }
    opts.track.recover_spike = a.recover_spike;
    a.weights.apply(&mut opts.track.weights)?;
    let mut per_frame = match &a.per_frame {
        Some(path) => {
            let mut f = BufWriter::new(
                std::fs::File::create(path)
                    .with_context(|| format!("cannot create {}", path.display()))?,
            );
            writeln!(f, "{}", bench::FrameReport::CSV_HEADER)?;
            Some(f)
        }
        None => None,
    };
    println!(
        "{:44} {:>6} {:>7} {:>8} {:>7} {:>9} {:>9} {:>6} {:>6} {:>5} {:>6} {:>7} {:>6} {:>6}",
        "clip",
        "frames",
        "PCK0.1",
        "PCK-swap",
        "err%",
        "PA-MPJPE",
        "PA-amb",
        "IoU",
        "silIoU",
        "lost",
        "missed",
        "fps",
        "search",
        "shape"
    );
    let mut all = Accumulator::default();
    let mut fps = Vec::new();
    let mut lost = 0;
    let mut missed = 0;
    let mut shape_error = 0.0;
    let mut write_error = None;
    let reports = bench::run(&opts, |r| {
        if let Some(f) = per_frame.as_mut() {
            for fr in &r.frames {
                if let Err(e) = writeln!(f, "{}", fr.csv_row(&r.name)) {
                    write_error.get_or_insert(e);
                }
            }
        }
        println!(
            "{:44} {:>6} {:>7.3} {:>8.3} {:>7.2} {:>6.1} mm {:>6.1} mm {:>6.3} {:>6.3} {:>5} {:>6} {:>7.1} {:>5.0}% {:>6.3}",
            r.name,
            r.acc.frames(),
            r.acc.pck(),
            r.acc.pck_swapped(),
            100.0 * r.acc.mean_error_frac(),
            r.acc.pa_mpjpe(),
            r.acc.pa_mpjpe_ambiguous(),
            r.acc.iou(),
            r.silhouette_iou,
            r.lost,
            r.missed,
            r.track_fps,
            100.0 * r.search_share,
            r.shape_error
        );
    })?;
    for r in &reports {
        all.merge(&r.acc);
        fps.push(r.track_fps);
        lost += r.lost;
        missed += r.missed;
        shape_error += r.shape_error;
    }
    fps.sort_by(f64::total_cmp);
    println!(
        "{:44} {:>6} {:>7.3} {:>8.3} {:>7.2} {:>6.1} mm {:>6.1} mm {:>6.3} {:>6} {:>5} {:>6} {:>7.1} {:>6} {:>6.3}",
        format!("overall ({} clips; fps: median)", reports.len()),
        all.frames(),
        all.pck(),
        all.pck_swapped(),
        100.0 * all.mean_error_frac(),
        all.pa_mpjpe(),
        all.pa_mpjpe_ambiguous(),
        all.iou(),
        "",
        lost,
        missed,
        fps[fps.len() / 2],
        "",
        shape_error / reports.len().max(1) as f64
    );
    let unprimed = reports.iter().filter(|r| !r.prior).count();
    if opts.prior == bench::PriorChoice::HeldOut && opts.track.weights.prior > 0.0 && unprimed > 0 {
        println!(
            "note: {unprimed} clips tracked without a pose prior (no other capture in {} to learn one from)",
            opts.mocap_dir.display()
        );
    }
    let mut joints = [0.0; bench::JOINTS.len()];
    for r in &reports {
        for (j, e) in joints.iter_mut().zip(&r.joint_error_mm) {
            *j += e;
        }
    }
    println!(
        "PA-MPJPE by joint (mm): {}",
        bench::JOINTS
            .iter()
            .zip(joints)
            .map(|(j, e)| format!("{} {:.0}", j.name(), e / all.frames().max(1) as f64))
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!(
        "missed: {:.1}% of frames, where the true shape and pose cost over {:.0}% less than \
         the tracked result (the search fell short of an answer the objective prefers)",
        100.0 * missed as f64 / all.frames().max(1) as f64,
        100.0 * bench::MISSED_GAP
    );
    if a.basin_probe > 0 {
        print_basins(&reports, a.basin_probe);
    }
    if let (Some(path), Some(mut f)) = (&a.per_frame, per_frame) {
        if let Some(e) = write_error {
            return Err(e).with_context(|| format!("writing {}", path.display()));
        }
        f.flush()
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// `monocap bench --basin-probe`'s table: per clip and overall.
fn print_basins(reports: &[monocap::track::bench::ClipReport], every: usize) {
    use monocap::track::bench::BasinProbe;
    println!(
        "the truth's basin under the fitted shape, every {every} frames with a person \
         (both it and the tracked answer refined alike):"
    );
    println!(
        "{:44} {:>6} {:>8} {:>8} {:>10} {:>10} {:>10}",
        "clip", "probed", "cheaper", ">20%", "PA tracked", "PA truth", "PA cheaper"
    );
    let line = |name: &str, b: &BasinProbe| {
        let n = b.frames.max(1) as f64;
        println!(
            "{:44} {:>6} {:>8} {:>8} {:>7.1} mm {:>7.1} mm {:>7.1} mm",
            name,
            b.frames,
            b.truth_cheaper,
            b.truth_much_cheaper,
            b.pa_tracked / n,
            b.pa_truth / n,
            b.pa_cheaper / n
        );
    };
    let mut all = BasinProbe::default();
    for r in reports {
        if let Some(b) = &r.basin {
            line(&r.name, b);
            all.merge(b);
        }
    }
    line("overall", &all);
}

/// `monocap prior`: learns a pose prior from a folder of BVH files.
fn prior_command(a: PriorArgs) -> Result<()> {
    use monocap::track::prior::{captures_in, PosePrior};
    let captures = captures_in(&a.mocap)?;
    let prior = PosePrior::learn(&captures)?;
    prior.write(&a.out)?;
    let poses: usize = captures.iter().map(|c| c.poses.len()).sum();
    println!(
        "{}: a pose prior from {} captures ({poses} poses at 30 frames/s)",
        a.out.display(),
        captures.len()
    );
    Ok(())
}

/// What `-o` writes, from its extension.
fn track_command(a: TrackArgs) -> Result<()> {
    use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
    use monocap::motion::files::{write_model_masks, write_motion, MotionFormat};
    use monocap::track::run::{read_keyframes, track_clip, ClipTrackOptions};
    use std::io::IsTerminal;

    let format = MotionFormat::from_path(&a.out)?;
    if let Some(p) = &a.json {
        if MotionFormat::from_path(p)? != MotionFormat::Json {
            anyhow::bail!("--json {}: expected a .json file", p.display());
        }
    }
    if let Some(p) = &a.model_masks {
        write::ClipFormat::from_path(p)?;
    }
    if a.restarts == 0 || a.restarts > 20 {
        anyhow::bail!("--restarts {}: expected 1 to 20", a.restarts);
    }
    check_polish_evals(a.polish_evals)?;
    if !(a.w_core.is_finite() && a.w_core >= 0.0) {
        anyhow::bail!("--w-core {}: expected a number ≥ 0", a.w_core);
    }
    let mut opts = ClipTrackOptions {
        fov_deg: a.fov_deg,
        masks: a.masks,
        work_height: a.work_height,
        ..ClipTrackOptions::default()
    };
    opts.silhouettes.background.empty = parse_empty_frames(&a.empty_frames)?;
    opts.track.restarts = a.restarts;
    opts.track.polish_evals = a.polish_evals;
    a.refit.apply(&mut opts.track)?;
    opts.track.threads = check_threads(a.threads)?;
    opts.track.init_frame = a.init_frame;
    a.weights.apply(&mut opts.track.weights)?;
    opts.track.features.core_weight = a.w_core;
    if let Some(p) = &a.pose_prior {
        if opts.track.weights.prior == 0.0 {
            anyhow::bail!(
                "--pose-prior {}: the prior weighs nothing with --w-prior 0",
                p.display()
            );
        }
        let prior = monocap::track::prior::PosePrior::read(p)?;
        opts.track.pose_prior = Some(std::sync::Arc::new(prior));
    }
    if let Some(k) = &a.keyframes {
        opts.track.keyframes = read_keyframes(k)?;
    }

    let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
    if !std::io::stderr().is_terminal() {
        bar.set_draw_target(ProgressDrawTarget::hidden());
    }
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} frames  {msg}  ETA {eta}",
        )
        .expect("a valid template"),
    );
    let start = std::time::Instant::now();
    let done = track_clip(&a.clip, &opts, |f, p| {
        if let Some(t) = p.frames_total {
            bar.set_length(t as u64);
        }
        bar.set_position(p.frames_done as u64);
        let cost = f
            .cost
            .map_or("no person".to_string(), |c| format!("cost {c:.0}"));
        bar.set_message(format!("{:.1} frames/s  {cost}", p.fps));
        std::ops::ControlFlow::Continue(())
    })?;
    bar.finish_and_clear();
    let secs = start.elapsed().as_secs_f64();

    write_motion(&done, format, &a.out)?;
    if let Some(p) = &a.json {
        write_motion(&done, MotionFormat::Json, p)?;
    }
    if let Some(p) = &a.model_masks {
        write_model_masks(&done, p)?;
    }
    for w in &done.warnings {
        eprintln!("monocap: warning: {w}");
    }
    let frames = done.track.frames.len();
    let people = done.track.frames.iter().filter(|f| f.person).count();
    let ious: Vec<f64> = done.track.frames.iter().filter_map(|f| f.iou).collect();
    let mean_iou = ious.iter().sum::<f64>() / ious.len().max(1) as f64;
    eprintln!(
        "monocap: wrote {} ({frames} frames, {people} with a person, initialised on frame {}; mean IoU {mean_iou:.3}; {:.1} frames/s)",
        a.out.display(),
        done.track.init_frame,
        frames as f64 / secs.max(1e-9)
    );
    Ok(())
}
