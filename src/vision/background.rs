//! The background model (method.md §3): per pixel and per RGB channel a mean μ and a
//! standard deviation σ of the empty scene; a pixel is foreground when any channel
//! departs by more than k·max(σ, σ_min), unless it looks like a shadow of the scene
//! (darker by a factor, same chromaticity: Horprasert et al. 1999's brightness and
//! chromaticity distortions).
//!
//! The model is learned in one streaming pass over the clip ([`BackgroundBuilder`]),
//! keeping per pixel:
//!
//! - running mean and variance of the leading frames while they stay still (the
//!   person-free frames, when the clip has them or the user names a range);
//! - up to 32 colours sampled from frames spread evenly over the clip, clustered at
//!   the end; the background is the cluster seen most often (see [`dominant_scene`]
//!   for pixels where the person lingered), then re-learned from what each frame shows
//!   outside its person ([`Refiner`]). Where the person covered a pixel in every
//!   frame the refiner compares, the pixel's colours with the person's and the
//!   scene's around them. Method.md suggests the per-pixel median, right only where
//!   the person is absent in more than half the frames; on the DAVIS benchmark
//!   without person-free frames the median scores IoU 0.689 / 0.880 / 0.919 (lucia,
//!   dance-twirl, tennis) and this model 0.915 / 0.976 / 0.974, with never-seen
//!   pixels held from frame to frame ([`BackgroundModel::hold_unknown`])
//!   (`tests/silhouette_quality.rs` measures both).
//!
//! A shadow must keep the scene's texture as well as its chromaticity
//! ([`BackgroundModel::foreground`]). By colour alone, dark grey clothes over grey
//! ground are a shadow: lucia's dress over the dance-twirl scene's asphalt scored IoU
//! 0.660, 0.765 with the texture test (0.888 with no shadows at all, but the
//! composites have none and real clips do). Without person-free frames the six DAVIS
//! composites went from 0.813 / 0.958 / 0.940 / 0.660 / 0.944 / 0.921 to 0.830 /
//! 0.960 / 0.952 / 0.765 / 0.951 / 0.924 (lucia's two went on to 0.894 and 0.843
//! with more pixels taken for unknown, see [`Refiner`]); on vtest.mp4 the test gives
//! back to the walkers about 70% of the pixels colour alone had called shadow, mostly
//! their dark clothes and blurred outlines. At 0.7 times the noise rather than 1, lucia scored
//! 0.850 and 0.869, but the faint shadows between a walker's feet in vtest.mp4 turned
//! foreground too. Measured again with today's model and not kept: at 0.6, lucia
//! without person-free frames rose from 0.894 to 0.903 over tennis and from 0.843 to
//! 0.891 over dance-twirl (the composites have no shadows, so any weaker shadow test
//! helps them), while over vtest.mp4 (every other frame) 33 000 pixels turned
//! foreground, 5% of its foreground, mostly shadow on the grass around and between
//! the walkers' feet.
//!
//! Memory, whatever the clip's length: about 130 bytes a pixel while learning (32
//! samples of 3 bytes, running statistics of the person-free frames, the first
//! frame), at most about as much again while a whole-clip model finishes: 53 MB at
//! 854×480, some 2 GB at the 3840×2160 cap of [`crate::clip::Limits`]. The refining
//! passes keep each pixel's colour clusters (12 bytes) and, to tell when the model
//! settles, the previous pass's model.

use image::RgbImage;

use super::silhouette::MAX_UNSEEN_SHARE;
use crate::body::Mask;

/// Which frames show the empty scene.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum EmptyFrames {
    /// Leading frames that stay still, when there are at least [`MIN_EMPTY_FRAMES`] and
    /// they agree with the clip's dominant colours.
    Auto,
    /// No person-free frames: the background comes from the whole clip.
    None,
    /// These frames (half-open range) are person-free.
    Range(usize, usize),
}

impl EmptyFrames {
    /// Parses `auto`, `none` or a half-open range `A..B` (the command line's and the
    /// service's spelling).
    pub fn parse(text: &str) -> Result<EmptyFrames, String> {
        Ok(match text {
            "auto" => EmptyFrames::Auto,
            "none" => EmptyFrames::None,
            range => {
                let (a, b) = crate::clip::parse_frame_range(range)?;
                EmptyFrames::Range(a, b)
            }
        })
    }
}

/// Fewest still leading frames taken as person-free.
pub const MIN_EMPTY_FRAMES: usize = 3;

#[derive(Clone, Debug)]
pub struct BackgroundOptions {
    pub empty: EmptyFrames,
    /// Foreground beyond k standard deviations.
    pub k: f32,
    /// Floor on σ (8-bit levels): noise and compression the person-free frames may not
    /// have shown.
    pub sigma_min: f32,
    /// Tell shadows from the person.
    pub shadows: bool,
    /// Shadows are at least this fraction of the scene's brightness …
    pub shadow_min_brightness: f32,
    /// … and their chromaticity distortion (in σ units) is at most this.
    pub shadow_max_chroma: f32,
    /// … and around them the frame is the scene times one factor, up to this many
    /// times the noise (infinite: colour alone decides).
    pub shadow_max_texture: f32,
}

impl Default for BackgroundOptions {
    fn default() -> Self {
        BackgroundOptions {
            empty: EmptyFrames::Auto,
            k: 3.5,
            sigma_min: 5.0,
            shadows: true,
            shadow_min_brightness: 0.55,
            shadow_max_chroma: 2.0,
            shadow_max_texture: 1.0,
        }
    }
}

/// Where the model came from (reported to users).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ModelSource {
    EmptyFrames { first: usize, count: usize },
    WholeClip { frames: usize },
}

/// Per-pixel, per-channel mean and standard deviation of the empty scene.
#[derive(Clone, Debug)]
pub struct BackgroundModel {
    pub width: u32,
    pub height: u32,
    pub mean: Vec<[f32; 3]>,
    pub sigma: Vec<[f32; 3]>,
    pub source: ModelSource,
    /// Pixels the clip never showed empty (the person covered them in every frame):
    /// their `mean` is a guess, and a hole in a silhouette made of them is filled.
    pub unknown: Option<Mask>,
    /// Of those, the pixels never seen outside the person at all (not the ones whose
    /// colour there wandered): [`Self::hold_unknown`] keeps them for the person from
    /// frame to frame.
    pub unseen: Option<Mask>,
    /// Where a person who hardly moved stood all clip long (see [`still_person`]):
    /// foreground in every frame.
    pub still: Option<Mask>,
    /// Where the person lingered and the scene learned there has the person's
    /// colours: its parts that touch a frame's foreground are the person's in that
    /// frame.
    ///
    /// A person who walks towards the camera, or punches on one spot, covers some
    /// pixels in every frame: the scene there is never shown, and the refiner learns
    /// the person's clothes as the scene wherever a first silhouette missed them
    /// (the early, small walker's torso is the later, larger walker's belly). Their
    /// colours give them away: far likelier among the person's colours than among
    /// the scene's around them ([`LINGER_ODDS`]). Only for a clip whose person kept
    /// within their own footprint (the median silhouette over half on never-seen
    /// pixels, [`MAX_UNSEEN_SHARE`]), where the pixel lay within the person's region
    /// in nearly every frame ([`LINGER_PERCENT`]). Without person-free frames the
    /// synthetic walk and run towards the camera went from IoU 0.830 / 0.849 to
    /// 0.969 / 0.991, the punch from 0.883 / 0.936 / 0.972 to 0.990 / 0.993 /
    /// 0.996 (azimuths 0, 60, −120); the DAVIS composites and the other synthetic
    /// clips moved by under 0.01. Without the footprint condition three DAVIS
    /// composites whose people move about lost 0.03–0.3 (scene colours near them
    /// that their clothes share).
    ///
    /// For such a clip it also holds the parts of the learned scene that hang below
    /// the person's region like legs ([`attached_below`]): legs that never moved all
    /// clip long (the synthetic bow without person-free frames: IoU 0.469 / 0.572 /
    /// 0.512 → 0.959 / 0.988 / 0.987 from azimuths 0, 60, −120; → 0.992 / 0.996 /
    /// 0.997 with [`CLEAR_SCENE_ODDS`]). Without the condition that a part reach
    /// down like a leg, DAVIS lucia over the dance-twirl scene fell from 0.915 to
    /// 0.838 (parts of the audience behind her).
    pub linger: Option<Mask>,
    /// Per colour bin ([`colour_bin`]), the odds that a colour is the person's rather
    /// than the scene's, from the colours the refiner saw where the scene is sure:
    /// [`Self::hold_unknown`] does not hold a pixel whose colour is likelier the
    /// scene's.
    pub person_odds: Option<Vec<f64>>,
}

/// Colours sampled per pixel.
pub const SAMPLES: usize = 32;
/// Clusters per pixel.
const K: usize = 3;
/// A sample joins a cluster within this many levels on every channel.
const JOIN: f32 = 24.0;
/// A leading frame is still while fewer than this fraction of sampled pixels differ
/// from the first frame by more than [`STILL_LEVELS`].
const STILL_FRACTION: f32 = 0.003;
const STILL_LEVELS: i32 = 30;
/// The frame ending a person-free run changes at least this fraction of the pixels.
const MIN_ENTRY_CHANGE: f32 = 0.01;

/// Running mean and variance of RGB samples (Welford).
#[derive(Clone, Copy, Default)]
struct Running {
    mean: [f32; 3],
    m2: [f32; 3],
    n: u32,
}

impl Running {
    fn push(&mut self, x: [u8; 3]) {
        self.n += 1;
        let n = self.n as f32;
        for ((m, m2), v) in self.mean.iter_mut().zip(self.m2.iter_mut()).zip(x) {
            let v = v as f32;
            let d = v - *m;
            *m += d / n;
            *m2 += d * (v - *m);
        }
    }

    /// Sample standard deviation per channel (0 with fewer than two samples).
    fn sigma(&self) -> [f32; 3] {
        if self.n < 2 {
            return [0.0; 3];
        }
        self.m2.map(|m2| (m2 / (self.n - 1) as f32).max(0.0).sqrt())
    }
}

/// A cluster of a pixel's colours.
type Cluster = Running;

/// Learns a [`BackgroundModel`] from frames pushed in order.
pub struct BackgroundBuilder {
    width: u32,
    height: u32,
    empty: EmptyFrames,
    frames: usize,
    /// Up to [`SAMPLES`] colours per pixel from frames evenly spread over the clip
    /// (every `stride`-th frame; when full, every other sample is dropped and the
    /// stride doubles), `kept` samples per pixel, pixel-major.
    samples: Vec<[u8; 3]>,
    kept: usize,
    stride: usize,
    /// Running statistics of the person-free frames.
    still: Vec<Running>,
    still_count: usize,
    still_first: usize,
    /// Whether the leading still run (Auto) is still going.
    still_open: bool,
    /// Fraction of pixels changed at the frame that ended the still run.
    entry_change: f32,
    first: Option<RgbImage>,
}

impl BackgroundBuilder {
    pub fn new(width: u32, height: u32, empty: EmptyFrames) -> BackgroundBuilder {
        let n = width as usize * height as usize;
        BackgroundBuilder {
            width,
            height,
            still_open: empty == EmptyFrames::Auto,
            still_first: match empty {
                EmptyFrames::Range(a, _) => a,
                _ => 0,
            },
            empty,
            frames: 0,
            samples: vec![[0; 3]; n * SAMPLES],
            kept: 0,
            stride: 1,
            still: vec![Running::default(); n],
            still_count: 0,
            entry_change: 0.0,
            first: None,
        }
    }

    /// Adds the next frame.
    ///
    /// # Panics
    /// When the frame's size is not the builder's (callers check decoded frames; see
    /// [`crate::vision::silhouette::clip_silhouettes`]).
    pub fn push(&mut self, frame: &RgbImage) {
        assert_eq!(
            (frame.width(), frame.height()),
            (self.width, self.height),
            "frame size"
        );
        let index = self.frames;
        self.frames += 1;
        let take_still = match self.empty {
            EmptyFrames::Range(a, b) => (a..b).contains(&index),
            EmptyFrames::None => false,
            EmptyFrames::Auto => {
                if self.still_open {
                    match &self.first {
                        None => true,
                        Some(first) => {
                            let change = changed_fraction(first, frame);
                            if change >= STILL_FRACTION {
                                self.entry_change = change;
                            }
                            change < STILL_FRACTION
                        }
                    }
                } else {
                    false
                }
            }
        };
        if self.empty == EmptyFrames::Auto && !take_still {
            self.still_open = false;
        }
        if self.first.is_none() {
            self.first = Some(frame.clone());
        }
        if take_still {
            self.still_count += 1;
            for (r, px) in self.still.iter_mut().zip(frame.pixels()) {
                r.push(px.0);
            }
        }
        if index.is_multiple_of(self.stride) {
            if self.kept == SAMPLES {
                // Keep every other sample, double the stride.
                for px in self.samples.chunks_mut(SAMPLES) {
                    for k in 0..SAMPLES / 2 {
                        px[k] = px[2 * k];
                    }
                }
                self.kept = SAMPLES / 2;
                self.stride *= 2;
            }
            if index.is_multiple_of(self.stride) {
                for (px, p) in self.samples.chunks_mut(SAMPLES).zip(frame.pixels()) {
                    px[self.kept] = p.0;
                }
                self.kept += 1;
            }
        }
    }

    /// The model: from the person-free frames when there are enough of them (and,
    /// when found automatically, they agree with the clip), else from the clusters.
    pub fn finish(self) -> BackgroundModel {
        self.finish_with_candidates().0
    }

    /// [`Self::finish`], with each pixel's colour clusters when the model comes from
    /// the whole clip (for [`Refiner`]).
    pub fn finish_with_candidates(self) -> (BackgroundModel, Option<Candidates>) {
        let usable = match self.empty {
            EmptyFrames::None => false,
            EmptyFrames::Range(..) => self.still_count >= 1,
            // The run must end with a person appearing at once: a person standing
            // still who starts to move changes the image gradually (the Bandai dance
            // capture: under 0.4% of the pixels over its first second) and would
            // otherwise be taken for the scene. A person walking in from the edge
            // also starts gradually; such clips use the whole clip, or a named range.
            EmptyFrames::Auto => {
                self.still_count >= MIN_EMPTY_FRAMES
                    && self.still_count < self.frames
                    && self.entry_change >= MIN_ENTRY_CHANGE
            }
        };
        if usable {
            return (
                BackgroundModel {
                    width: self.width,
                    height: self.height,
                    mean: self.still.iter().map(|r| r.mean).collect(),
                    sigma: self.still.iter().map(Running::sigma).collect(),
                    source: ModelSource::EmptyFrames {
                        first: self.still_first,
                        count: self.still_count,
                    },
                    unknown: None,
                    unseen: None,
                    still: None,
                    linger: None,
                    person_odds: None,
                },
                None,
            );
        }
        let BackgroundBuilder {
            width,
            height,
            frames,
            samples,
            kept,
            still,
            first,
            ..
        } = self;
        // Free what the whole-clip model does not need before clustering.
        drop((still, first));
        let clusters: Vec<[Cluster; K]> = samples
            .chunks(SAMPLES)
            .map(|px| cluster_samples(&px[..kept]))
            .collect();
        drop(samples);
        let (mean, mut sigma) = dominant_scene(&clusters, width, height, kept);
        cap_sigma(&mut sigma);
        let candidates = Candidates {
            per_pixel: clusters
                .iter()
                .map(|cl| {
                    cl.map(|c| Candidate {
                        colour: c.mean.map(|v| v.round().clamp(0.0, 255.0) as u8),
                        n: c.n.min(255) as u8,
                    })
                })
                .collect(),
            samples: kept,
        };
        (
            BackgroundModel {
                width,
                height,
                mean,
                sigma,
                source: ModelSource::WholeClip { frames },
                unknown: None,
                unseen: None,
                still: None,
                linger: None,
                person_odds: None,
            },
            Some(candidates),
        )
    }
}

/// Re-learns a whole-clip model from the pixels each frame shows outside the person:
/// where the person lingers, the clusters may have taken their clothes for the scene;
/// the frames in which the pixel lies outside the (generously grown) silhouette show
/// the scene itself.
///
/// Colour then checks what was learned. Where the scene is sure (one colour nearly
/// all the clip), each frame's foreground shows the person's colours and a band
/// around their region the scene's; the refiner keeps both histograms. A pixel
/// never seen outside the person, or whose colour seen there looks like the
/// person's (clothes the first estimate took for the scene, where the person stood
/// still, so nothing was found there to exclude), takes the most scene-like of its
/// colour clusters when that one looks like the scene: a scene shown in a few frames
/// only (under the 15% a cluster needs to count against the clothes). A pixel never
/// seen outside the person is marked unknown whatever it takes (a hole made mostly
/// of unknown pixels is filled); with no scene-like cluster it keeps the first
/// estimate. So is one whose colour outside the person wandered
/// ([`UNSTEADY_SPREAD`]).
///
/// Without person-free frames this lifted the DAVIS composites from 0.734 / 0.933 /
/// 0.907 to 0.813 / 0.958 / 0.940, the same people over other scenes from 0.587 /
/// 0.917 / 0.913 to 0.660 / 0.944 / 0.921, and the synthetic walk and kick from
/// 0.733 / 0.663 to 0.993 / 0.974. Taking every unknown pixel for the person in
/// every frame lifted lucia to 0.89–0.90 but took three others down to 0.89–0.91
/// (scenes with still people of their own), so unknown pixels only fill holes.
///
/// [`crate::vision::silhouette::Segmenter::learn`] refines the model again with
/// the silhouettes it gives, until it settles.
///
/// A foreground nearly empty in most frames means a person who stayed on one spot
/// (or none): see [`still_person`] and [`refine_still`] (the synthetic dance: IoU
/// 0.017 → 0.816 with the region alone → 0.961 corrected by colour).
pub struct Refiner<'a> {
    base: BackgroundModel,
    acc: Vec<Running>,
    candidates: Option<&'a Candidates>,
    odds: ColourOdds,
    /// Per pixel, the frames whose raw foreground held it …
    moved: Vec<u16>,
    /// … and per frame the cleaned silhouette's share of the image (4 bytes a frame).
    shares: Vec<f32>,
    /// Per pixel, the frames whose person region held it.
    covered: Vec<u16>,
    /// Per frame, the share of its silhouette on the pixels the model being
    /// refined never saw outside the person.
    unseen_shares: Vec<f32>,
}

/// A pixel's colour cluster, compactly: its mean colour and how many samples it holds.
#[derive(Clone, Copy, Default, Debug)]
pub struct Candidate {
    colour: [u8; 3],
    n: u8,
}

/// Every pixel's [`K`] colour clusters from the whole clip, out of `samples` samples.
pub struct Candidates {
    per_pixel: Vec<[Candidate; K]>,
    samples: usize,
}

/// A cluster needs this many samples to be taken for the scene where the person
/// always covered the pixel (one sample may be a blend at the person's edge).
const MIN_CANDIDATE_SAMPLES: u8 = 2;
/// A pixel whose commonest colour holds this percentage of its samples shows the
/// scene nearly all the clip: its foreground is the person.
const SURE_PERCENT: usize = 85;

/// Colour histograms of the person and of the scene just around them, learned where
/// the scene is sure, to tell whether a colour is the person's or the scene's.
struct ColourOdds {
    person: Vec<u64>,
    scene: Vec<u64>,
}

/// Bins per channel of the colour histograms.
const BINS: usize = 16;

/// The bin of the colour histograms a colour falls in (of `BINS`³).
pub fn colour_bin(c: [u8; 3]) -> usize {
    let b = |v: u8| v as usize * BINS / 256;
    (b(c[0]) * BINS + b(c[1])) * BINS + b(c[2])
}

impl ColourOdds {
    fn new() -> ColourOdds {
        ColourOdds {
            person: vec![0; BINS * BINS * BINS],
            scene: vec![0; BINS * BINS * BINS],
        }
    }

    /// Per bin, the odds that a colour in it is the person's rather than the
    /// scene's (equal priors; half a count added to every bin).
    fn table(&self) -> Vec<f64> {
        let cells = self.person.len() as f64;
        let np = self.person.iter().map(|&v| v as f64).sum::<f64>() + 0.5 * cells;
        let ns = self.scene.iter().map(|&v| v as f64).sum::<f64>() + 0.5 * cells;
        let odds = |(&p, &s): (&u64, &u64)| ((p as f64 + 0.5) / np) / ((s as f64 + 0.5) / ns);
        self.person.iter().zip(&self.scene).map(odds).collect()
    }

    /// A function giving the odds of [`Self::table`] for a colour.
    fn odds(&self) -> impl Fn([u8; 3]) -> f64 {
        let table = self.table();
        move |c| table[colour_bin(c)]
    }
}

/// See [`cap_sigma`].
const SIGMA_CAP: f32 = 2.0;
/// Fewest outside-the-person samples that replace the first estimate.
const MIN_REFINE_SAMPLES: u32 = 2;

impl<'a> Refiner<'a> {
    pub fn new(base: BackgroundModel, candidates: Option<&'a Candidates>) -> Refiner<'a> {
        let n = base.mean.len();
        Refiner {
            base,
            acc: vec![Running::default(); n],
            candidates,
            odds: ColourOdds::new(),
            moved: vec![0; n],
            shares: Vec::new(),
            covered: vec![0; n],
            unseen_shares: Vec::new(),
        }
    }

    /// The model being refined (for computing each frame's silhouette).
    pub fn base(&self) -> &BackgroundModel {
        &self.base
    }

    /// Adds a frame with its raw foreground (against the first estimate), the region
    /// its person may occupy, a band around that region and the share of the image
    /// its cleaned silhouette covers.
    pub fn push(
        &mut self,
        frame: &RgbImage,
        raw: &Mask,
        clean: &Mask,
        person: &Mask,
        around: &Mask,
        share: f32,
    ) {
        let w = self.base.width as usize;
        self.shares.push(share);
        if let Some(unseen) = &self.base.unseen {
            let on = clean.count_and(unseen);
            self.unseen_shares
                .push(on as f32 / clean.count().max(1) as f32);
        }
        for (i, px) in frame.pixels().enumerate() {
            let (x, y) = ((i % w) as u32, (i / w) as u32);
            if raw.get(x, y) {
                self.moved[i] = self.moved[i].saturating_add(1);
            }
            if let Some(c) = self.candidates {
                // Where one colour holds nearly all the clip the scene is sure: the
                // foreground there is the person, the band around them the scene.
                let top = c.per_pixel[i].iter().map(|c| c.n as usize).max();
                if top.unwrap_or(0) * 100 >= c.samples * SURE_PERCENT {
                    if raw.get(x, y) {
                        self.odds.person[colour_bin(px.0)] += 1;
                    } else if around.get(x, y) && !person.get(x, y) {
                        self.odds.scene[colour_bin(px.0)] += 1;
                    }
                }
            }
            if person.get(x, y) {
                self.covered[i] = self.covered[i].saturating_add(1);
                continue;
            }
            self.acc[i].push(px.0);
        }
    }

    pub fn finish(self) -> BackgroundModel {
        let table = self.odds.table();
        let odds = |c: [u8; 3]| table[colour_bin(c)];
        let mut model = self.base;
        let mut unknown = Mask::new(model.width, model.height);
        let mut unseen = Mask::new(model.width, model.height);
        let mut clear_scene = Mask::new(model.width, model.height);
        let w = model.width as usize;
        for (i, r) in self.acc.iter().enumerate() {
            let learned = (r.n >= MIN_REFINE_SAMPLES).then_some(r);
            // The most scene-like of the pixel's colour clusters, if it looks like
            // the scene rather than the person.
            let scene_like = self.candidates.and_then(|c| {
                c.per_pixel[i]
                    .iter()
                    .filter(|c| c.n >= MIN_CANDIDATE_SAMPLES)
                    .map(|c| (odds(c.colour), c.colour))
                    .min_by(|a, b| a.0.total_cmp(&b.0))
                    .filter(|(o, _)| *o < 1.0)
            });
            let looks_like_scene =
                |r: &Running| odds(r.mean.map(|v| v.round().clamp(0.0, 255.0) as u8)) < 1.0;
            match (learned, scene_like) {
                (Some(r), Some(_)) if looks_like_scene(r) => {
                    model.mean[i] = r.mean;
                    model.sigma[i] = r.sigma();
                }
                // What was seen looks like the person (clothes the first estimate
                // took for the scene, where the person stood still): the scene-like
                // cluster.
                (Some(_), Some((_, colour))) => model.mean[i] = colour.map(|v| v as f32),
                // Never seen outside the person: the scene-like cluster is a guess
                // (the person's histogram may lack the clothes that covered the pixel
                // all along), so the pixel is unknown as well, unless its colour is
                // clearly the scene's ([`CLEAR_SCENE_ODDS`]).
                (None, Some((o, colour))) => {
                    model.mean[i] = colour.map(|v| v as f32);
                    unseen.set((i % w) as u32, (i / w) as u32, true);
                    if o >= CLEAR_SCENE_ODDS {
                        unknown.set((i % w) as u32, (i / w) as u32, true);
                    } else {
                        clear_scene.set((i % w) as u32, (i / w) as u32, true);
                    }
                }
                (Some(r), None) => {
                    model.mean[i] = r.mean;
                    model.sigma[i] = r.sigma();
                }
                (None, None) => {
                    unknown.set((i % w) as u32, (i / w) as u32, true);
                    unseen.set((i % w) as u32, (i / w) as u32, true);
                }
            }
        }
        // A pixel whose frames outside the person varied far more than the camera's
        // noise did not show a still scene there: the person's clothes, taken for
        // outside them where a first silhouette missed them (lucia's dress).
        let spread = |r: &Running| r.sigma().into_iter().fold(0.0, f32::max);
        let learned = self.acc.iter().filter(|r| r.n >= MIN_REFINE_SAMPLES);
        let mut spreads: Vec<f32> = learned.map(spread).collect();
        if let Some(typical) = median(&mut spreads) {
            for (i, r) in self.acc.iter().enumerate() {
                if r.n >= MIN_REFINE_SAMPLES && spread(r) > UNSTEADY_SPREAD * typical.max(1.0) {
                    unknown.set((i % w) as u32, (i / w) as u32, true);
                }
            }
        }
        cap_sigma(&mut model.sigma);
        let mut shares = self.shares;
        if median(&mut shares).is_some_and(|m| (m as f64) < MIN_MEDIAN_FOREGROUND) {
            model.still = still_person(&self.moved, model.width, model.height);
            if let (Some(still), Some(c)) = (model.still.as_mut(), self.candidates) {
                refine_still(still, &self.moved, c, &mut model.mean, &mut unknown);
            }
        }
        // A person who kept within their own footprint (most of their silhouette on
        // pixels never seen outside them) may have been learned as the scene where
        // they lingered: see [`BackgroundModel::linger`].
        let mut unseen_shares = self.unseen_shares;
        let within_footprint =
            median(&mut unseen_shares).is_some_and(|m| m as f64 > MAX_UNSEEN_SHARE);
        if model.still.is_none() && within_footprint {
            let frames = shares.len();
            // Within the person's (grown) region in nearly every frame.
            let persistent = |i: usize| self.covered[i] as usize * 100 >= frames * LINGER_PERCENT;
            let mut linger = Mask::new(model.width, model.height);
            for i in 0..self.covered.len() {
                let colour = model.mean[i].map(|v| v.round().clamp(0.0, 255.0) as u8);
                if persistent(i) && odds(colour) > LINGER_ODDS {
                    linger.set((i % w) as u32, (i / w) as u32, true);
                }
            }
            linger.or_with(&attached_below(
                &model.mean,
                model.width,
                model.height,
                persistent,
            ));
            model.linger = (linger.count() > 0).then_some(linger);
        }
        model.person_odds = Some(table);
        // Never seen stays never seen but for the pixels a still person's region
        // gave back to the scene (refine_still took them out of `unknown`): those
        // are not held.
        let mut not_given_back = clear_scene;
        not_given_back.or_with(&unknown);
        unseen.and_with(&not_given_back);
        model.unknown = Some(unknown);
        model.unseen = Some(unseen);
        model
    }
}

/// A pixel inside the person's (grown) region in at least this percentage of the
/// frames …
const LINGER_PERCENT: usize = 90;
/// … whose learned scene colour is this many times likelier the person's than the
/// scene's is where the person lingered and was taken for the scene (see
/// [`BackgroundModel::linger`]; at odds of 2 or 10 rather than 20 the synthetic
/// clips scored the same and DAVIS lucia without person-free frames fell from
/// 0.915 / 0.916 to 0.811 / 0.876 and 0.911 / 0.914).
const LINGER_ODDS: f64 = 20.0;

/// The parts of the scene, as learned, that hang below a person who kept within
/// their own footprint: legs that never moved all clip long (the bow) are in the
/// whole-clip background like the wall, and only their shape tells them from it.
///
/// The learned scene outside the region the person nearly always covered
/// (`persistent`) falls into parts of one colour (4-neighbours within
/// [`ATTACH_LEVELS`] on every channel). A part is the person's when it touches the
/// region (or a part already taken), starts no higher than the region's centre
/// (legs hang below the torso; the picture on the wall behind the head does not),
/// reaches down at least half the region's height when it touches the region itself
/// (a leg, not a stool beside the person; what hangs from a taken part, a shoe, may
/// be small), keeps off the image's border (the floor and the wall reach it) and the
/// parts taken stay within [`ATTACH_SIZE`] times the region's area. Like the rest of
/// [`BackgroundModel::linger`], a part joins a frame's foreground only where it
/// touches it.
fn attached_below(
    mean: &[[f32; 3]],
    width: u32,
    height: u32,
    persistent: impl Fn(usize) -> bool,
) -> Mask {
    let (w, h) = (width as usize, height as usize);
    let n = w * h;
    let mut out = Mask::new(width, height);
    let region: Vec<usize> = (0..n).filter(|&i| persistent(i)).collect();
    if region.is_empty() {
        return out;
    }
    let centre = region.iter().map(|&i| i / w).sum::<usize>() / region.len();
    let (first, last) = (region[0] / w, region[region.len() - 1] / w);
    let reach = (last - first) / 2;
    // Parts of one colour: union–find over the 4-neighbours outside the region.
    let mut parent: Vec<usize> = (0..n).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let alike =
        |a: usize, b: usize| (0..3).all(|k| (mean[a][k] - mean[b][k]).abs() <= ATTACH_LEVELS);
    for i in 0..n {
        if persistent(i) {
            continue;
        }
        let right = (i % w + 1 < w).then(|| i + 1);
        let below = (i + w < n).then(|| i + w);
        for j in [right, below].into_iter().flatten() {
            if !persistent(j) && alike(i, j) {
                let (a, b) = (root(&mut parent, i), root(&mut parent, j));
                if a != b {
                    parent[a] = b;
                }
            }
        }
    }
    struct Part {
        size: usize,
        top: usize,
        bottom: usize,
        border: bool,
    }
    let mut parts: std::collections::HashMap<usize, Part> = std::collections::HashMap::new();
    let mut label = vec![usize::MAX; n];
    for (i, l) in label.iter_mut().enumerate() {
        if persistent(i) {
            continue;
        }
        let r = root(&mut parent, i);
        *l = r;
        let (x, y) = (i % w, i / w);
        let part = parts.entry(r).or_insert(Part {
            size: 0,
            top: y,
            bottom: y,
            border: false,
        });
        part.size += 1;
        part.top = part.top.min(y);
        part.bottom = part.bottom.max(y);
        part.border |= x == 0 || y == 0 || x + 1 == w || y + 1 == h;
    }
    // Taken parts grow from the region, a layer of touching parts at a time.
    let mut taken: std::collections::HashSet<usize> = std::collections::HashSet::new();
    let mut budget = region.len() * ATTACH_SIZE;
    loop {
        let mut next: Vec<usize> = Vec::new();
        for i in 0..n {
            if label[i] != usize::MAX && !taken.contains(&label[i]) {
                continue;
            }
            for j in neighbours(i, w, h) {
                let l = label[j];
                if l == usize::MAX || taken.contains(&l) || next.contains(&l) {
                    continue;
                }
                let part = &parts[&l];
                // What touches the region itself reaches down like legs.
                let hangs = label[i] != usize::MAX || part.bottom - part.top >= reach;
                if !part.border && part.top >= centre && hangs && part.size <= budget {
                    budget -= part.size;
                    next.push(l);
                }
            }
        }
        if next.is_empty() {
            break;
        }
        taken.extend(next);
    }
    for (i, l) in label.iter().enumerate() {
        if *l != usize::MAX && taken.contains(l) {
            out.set((i % w) as u32, (i / w) as u32, true);
        }
    }
    out
}

/// Most difference (8-bit levels, any channel) between neighbouring pixels of one
/// part of the learned scene in [`attached_below`].
const ATTACH_LEVELS: f32 = 10.0;
/// The parts [`attached_below`] takes cover at most this many times the area the
/// person nearly always covered.
const ATTACH_SIZE: usize = 2;

/// A pixel never seen outside the person whose most scene-like colour is this many
/// times likelier the scene's than the person's (1/100) is not unknown: a hole made of
/// such pixels is not filled. The gap between arms held akimbo and the body, which a
/// person who kept within their own footprint covered in every frame's grown region
/// (the synthetic bow without person-free frames: IoU 0.959 → 0.992 from the front).
/// At 1/20 DAVIS lucia over the dance-twirl scene fell from 0.915 to 0.907, at 1/50
/// to 0.909; at 1/100 no DAVIS composite moved.
const CLEAR_SCENE_ODDS: f64 = 0.01;

/// A pixel seen outside the person whose colour there spread over more than this many
/// times the image's median spread (the largest channel's σ) is marked unknown: a
/// hole mostly made of such pixels is filled. Without person-free frames, lucia over
/// the tennis and dance-twirl scenes: IoU 0.830 → 0.861 and 0.765 → 0.778, the other
/// DAVIS composites unchanged (at 2 times: 0.863 and 0.806, at 5: 0.845 and 0.765).
/// Marking unknown every pixel never seen outside the person took them on to 0.863
/// and 0.821, and filling unknown bays as well as holes
/// ([`crate::vision::cleanup::clean_with_unknown`]) to 0.894 and 0.843; the other
/// composites moved by 0.002 at most, and so did the synthetic clips (the walk
/// without person-free frames 0.993 → 0.991; vtest.mp4 unchanged).
const UNSTEADY_SPREAD: f32 = 3.0;

/// Below this median share of the image, the foreground of a background learned
/// from the whole clip is taken for a failure: a person this small (some 14×14 pixels
/// of a 320×240 frame) cannot be tracked anyway, and one who stood still all clip
/// long is the likelier reading.
pub const MIN_MEDIAN_FOREGROUND: f64 = 0.0025;

/// Where a person who hardly moved stood, from the pixels that ever changed: a person
/// who stays on one spot all clip long is in the whole-clip background, and only
/// their outline, as they sway, and their limbs, as they move, ever show as
/// foreground. That outline encloses them: the region it closes (outline included)
/// is the person (the synthetic dance: 78% of it never changed). None when nothing
/// changed, or when more than half the region did: people who crossed the scene now
/// and then, not one who stood still.
fn still_person(moved: &[u16], width: u32, height: u32) -> Option<Mask> {
    let mut outline = Mask::new(width, height);
    for (i, &n) in moved.iter().enumerate() {
        if n > 0 {
            outline.set(i as u32 % width, i as u32 / width, true);
        }
    }
    if outline.count() == 0 {
        return None;
    }
    let r = outline_radius(height);
    let closed = imageproc::morphology::close(
        &outline.to_gray(),
        imageproc::distance_transform::Norm::LInf,
        r,
    );
    let mut person = Mask::from_gray(&closed, 128);
    super::cleanup::fill_holes(&mut person, f64::INFINITY, None);
    // A person's interior never changes; what passers-by sweep (a mostly empty clip
    // with people crossing now and then) changed nearly everywhere.
    let unchanged = (0..height)
        .flat_map(|y| (0..width).map(move |x| (x, y)))
        .filter(|&(x, y)| person.get(x, y) && moved[(y * width + x) as usize] == 0)
        .count();
    (unchanged as u64 * 2 >= person.count()).then_some(person)
}

/// How far [`still_person`] closes the outline: 1/40 of the image height.
fn outline_radius(height: u32) -> u8 {
    (height / 40).clamp(1, 24) as u8
}

/// Corrects a still person's region by colour, judged against the colours of the
/// region's pixels that never changed (the person) and of every pixel outside it (the
/// scene, which the person covers little of), from each pixel's commonest colour:
///
/// - a part of the person whose outline never moved (a leg planted all clip long)
///   is outside the region: the region grows into pixels next to it whose colour is
///   the person's, up to [`GROW_RADII`] outline radii;
/// - the region's pixels that changed and showed the scene's colours in some frames
///   (the scene between the limbs, or where the person swayed off) leave it, with
///   their background set to that colour: each frame's own test tells there whether
///   the person covers them; so do those that never changed and clearly show the
///   scene (a gap between an arm and the body that the outline enclosed; see
///   [`FREE_ODDS`]).
///
/// The pixels that left it for a colour the scene showed are no longer `unknown`:
/// that colour was seen there and judged against this person's own colours, so a
/// gap between an arm and the body made of them is not filled as an unknown bay
/// (the synthetic dance without person-free frames: IoU 0.967 → 0.970).
fn refine_still(
    still: &mut Mask,
    moved: &[u16],
    candidates: &Candidates,
    mean: &mut [[f32; 3]],
    unknown: &mut Mask,
) {
    let (w, h) = (still.width(), still.height());
    let top = |i: usize| {
        candidates.per_pixel[i]
            .iter()
            .filter(|c| c.n > 0)
            .max_by_key(|c| c.n)
            .map(|c| c.colour)
    };
    let mut counts = ColourOdds::new();
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            match (still.get(x, y), top(i)) {
                (true, Some(c)) if moved[i] == 0 => counts.person[colour_bin(c)] += 1,
                (false, Some(c)) => counts.scene[colour_bin(c)] += 1,
                _ => {}
            }
        }
    }
    let odds = counts.odds();
    // Growing: breadth first from the region, through pixels whose commonest colour
    // is clearly the person's.
    let reach = outline_radius(h) as u32 * GROW_RADII;
    let mut grown = still.clone();
    let mut front: Vec<(u32, u32)> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter(|&(x, y)| still.get(x, y))
        .collect();
    for _ in 0..reach {
        let mut next = Vec::new();
        for (x, y) in front {
            for i in neighbours((y * w + x) as usize, w as usize, h as usize) {
                let (nx, ny) = ((i % w as usize) as u32, (i / w as usize) as u32);
                if grown.get(nx, ny) {
                    continue;
                }
                if top(i).is_some_and(|c| odds(c) > GROW_ODDS) {
                    grown.set(nx, ny, true);
                    next.push((nx, ny));
                }
            }
        }
        front = next;
    }
    // Freeing: the most scene-like of a changed pixel's colours, if the scene showed
    // it and it is likelier the scene's than the person's; a pixel that never changed
    // and shows the scene clearly (a gap between arm and body).
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            if !still.get(x, y) {
                continue;
            }
            if moved[i] == 0 {
                if top(i).is_some_and(|c| odds(c) < FREE_ODDS) {
                    grown.set(x, y, false);
                }
                continue;
            }
            let best = candidates.per_pixel[i]
                .iter()
                .filter(|c| c.n >= MIN_CANDIDATE_SAMPLES && counts.scene[colour_bin(c.colour)] > 0)
                .map(|c| (odds(c.colour), c.colour))
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .filter(|(o, _)| *o < 1.0);
            if let Some((_, colour)) = best {
                mean[i] = colour.map(|v| v as f32);
                grown.set(x, y, false);
                unknown.set(x, y, false);
            }
        }
    }
    *still = grown;
}

/// The odds of a colour being the person's rather than the scene's below which a
/// pixel of a still person's region that never changed leaves it, when that colour
/// is its commonest: the scene showing through a slit between an arm held still and
/// the body. The synthetic dance without person-free frames from the front: IoU 0.969
/// at odds under 1/4 → 0.993 at odds under 0.35–0.7 (0.987 at 1, 0.967 at 2); from
/// the other azimuths 0.976 / 0.996 unchanged.
const FREE_ODDS: f64 = 0.5;

/// How far [`refine_still`] grows the region, in outline radii.
const GROW_RADII: u32 = 3;
/// The odds of a colour being the person's rather than the scene's above which
/// [`refine_still`] grows the region over it.
const GROW_ODDS: f64 = 4.0;

/// A cluster seen in at least this fraction of the frames is a candidate for the
/// scene; a pixel with two candidates is one where the person lingered.
const CANDIDATE_FRACTION: f32 = 0.15;

/// The scene's colour per pixel from its clusters. Where one cluster clearly
/// dominates it is the scene. Where the person lingered long enough to make a second
/// sizeable cluster, the count cannot tell scene from clothes; the candidate closest
/// to the scene around that region wins (the scene's colours propagated inwards from
/// the unambiguous pixels, breadth first).
fn dominant_scene(
    clusters: &[[Cluster; K]],
    width: u32,
    height: u32,
    frames: usize,
) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let n = clusters.len();
    let min_count = ((CANDIDATE_FRACTION * frames as f32).ceil() as u32).max(1);
    let mut reference: Vec<Option<[f32; 3]>> = vec![None; n];
    let mut ambiguous = Vec::new();
    for (i, cl) in clusters.iter().enumerate() {
        let candidates = cl.iter().filter(|c| c.n >= min_count).count();
        if candidates >= 2 {
            ambiguous.push(i);
        } else {
            reference[i] = cl.iter().max_by_key(|c| c.n).map(|c| c.mean);
        }
    }
    // Propagate the unambiguous colours into the ambiguous pixels, breadth first.
    let (w, h) = (width as usize, height as usize);
    let mut queue: std::collections::VecDeque<usize> = ambiguous
        .iter()
        .copied()
        .filter(|&i| neighbours(i, w, h).any(|j| reference[j].is_some()))
        .collect();
    let mut queued = vec![false; n];
    for &i in &queue {
        queued[i] = true;
    }
    while let Some(i) = queue.pop_front() {
        let (mut sum, mut k) = ([0f32; 3], 0.0);
        for j in neighbours(i, w, h) {
            if let Some(c) = reference[j] {
                for ch in 0..3 {
                    sum[ch] += c[ch];
                }
                k += 1.0;
            }
        }
        if k > 0.0 {
            reference[i] = Some(sum.map(|v| v / k));
        }
        for j in neighbours(i, w, h) {
            if reference[j].is_none() && !queued[j] {
                queued[j] = true;
                queue.push_back(j);
            }
        }
    }
    let mut mean = vec![[0f32; 3]; n];
    let mut sigma = vec![[0f32; 3]; n];
    for (i, cl) in clusters.iter().enumerate() {
        let best = match reference[i] {
            Some(r) if ambiguous.binary_search(&i).is_ok() => cl
                .iter()
                .filter(|c| c.n >= min_count)
                .min_by(|a, b| linf(&a.mean, &r).total_cmp(&linf(&b.mean, &r)))
                .copied(),
            _ => cl.iter().max_by_key(|c| c.n).copied(),
        }
        .unwrap_or_default();
        mean[i] = best.mean;
        sigma[i] = best.sigma();
    }
    (mean, sigma)
}

/// Adds to `out` every 8-connected part of `within` that touches or neighbours a
/// pixel of `out`.
fn grow_within(out: &mut Mask, within: &Mask) {
    let (w, h) = (out.width() as usize, out.height() as usize);
    let mut stack: Vec<(u32, u32)> = Vec::new();
    let neighbours8 = |x: u32, y: u32| {
        let (x, y) = (x as i64, y as i64);
        (-1..=1i64)
            .flat_map(move |dy| (-1..=1i64).map(move |dx| (x + dx, y + dy)))
            .filter(move |&(a, b)| a >= 0 && b >= 0 && (a as usize) < w && (b as usize) < h)
            .map(|(a, b)| (a as u32, b as u32))
    };
    for y in 0..h as u32 {
        for (k, &word) in within.row(y).iter().enumerate() {
            let mut bits = word & !out.row(y)[k];
            while bits != 0 {
                let x = k as u32 * 64 + bits.trailing_zeros();
                bits &= bits - 1;
                if neighbours8(x, y).any(|(a, b)| out.get(a, b)) {
                    stack.push((x, y));
                }
            }
        }
    }
    while let Some((x, y)) = stack.pop() {
        if out.get(x, y) {
            continue;
        }
        out.set(x, y, true);
        for (a, b) in neighbours8(x, y) {
            if within.get(a, b) && !out.get(a, b) {
                stack.push((a, b));
            }
        }
    }
}

/// Caps each pixel's σ at [`SIGMA_CAP`] times the image's median σ (per channel).
/// A whole clip's spread of colours at a pixel mixes the scene's noise with the
/// person's colours near the scene's, which inflates σ where the person lingers and
/// hides them there (lucia on the DAVIS benchmark: IoU 0.527 uncapped); camera noise
/// is much the same over the image, so the median σ bounds it. Ignoring σ altogether
/// (σ_min alone) was too tight for a real camera: vtest.mp4's static scene turned
/// 0.9% foreground.
fn cap_sigma(sigma: &mut [[f32; 3]]) {
    for c in 0..3 {
        let mut v: Vec<f32> = sigma.iter().map(|s| s[c]).collect();
        let Some(median) = median(&mut v) else {
            return;
        };
        for s in sigma.iter_mut() {
            s[c] = s[c].min(SIGMA_CAP * median);
        }
    }
}

/// The median of `v` (the upper one of an even count; None when empty). Reorders `v`.
pub(crate) fn median(v: &mut [f32]) -> Option<f32> {
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    Some(*v.select_nth_unstable_by(mid, f32::total_cmp).1)
}

fn linf(a: &[f32; 3], b: &[f32; 3]) -> f32 {
    (0..3).map(|c| (a[c] - b[c]).abs()).fold(0.0, f32::max)
}

/// 4-neighbours of pixel `i` in a `w`×`h` image.
fn neighbours(i: usize, w: usize, h: usize) -> impl Iterator<Item = usize> {
    let (x, y) = (i % w, i / w);
    [
        (x > 0).then(|| i - 1),
        (x + 1 < w).then(|| i + 1),
        (y > 0).then(|| i - w),
        (y + 1 < h).then(|| i + w),
    ]
    .into_iter()
    .flatten()
}

/// The K densest clusters of a pixel's samples: repeatedly, the sample with the
/// most others within [`JOIN`] on every channel and those others form a cluster.
fn cluster_samples(px: &[[u8; 3]]) -> [Cluster; K] {
    let mut out = [Cluster::default(); K];
    let mut taken = [false; SAMPLES];
    let near = |a: &[u8; 3], b: &[u8; 3]| (0..3).all(|c| (a[c] as f32 - b[c] as f32).abs() <= JOIN);
    for slot in out.iter_mut() {
        let best = (0..px.len()).filter(|&i| !taken[i]).max_by_key(|&i| {
            (0..px.len())
                .filter(|&j| !taken[j] && near(&px[i], &px[j]))
                .count()
        });
        let Some(best) = best else { break };
        let centre = px[best];
        for j in 0..px.len() {
            if !taken[j] && near(&centre, &px[j]) {
                taken[j] = true;
                slot.push(px[j]);
            }
        }
    }
    out
}

/// Fraction of pixels (sampled on a grid) on which `frame` differs from `first`.
fn changed_fraction(first: &RgbImage, frame: &RgbImage) -> f32 {
    let (w, h) = frame.dimensions();
    let step = 3;
    let (mut changed, mut total) = (0usize, 0usize);
    for y in (0..h).step_by(step) {
        for x in (0..w).step_by(step) {
            let a = first.get_pixel(x, y).0;
            let b = frame.get_pixel(x, y).0;
            total += 1;
            if (0..3).any(|c| (a[c] as i32 - b[c] as i32).abs() > STILL_LEVELS) {
                changed += 1;
            }
        }
    }
    changed as f32 / total.max(1) as f32
}

/// What a pixel's colour says it shows.
enum Class {
    Scene,
    Person,
    /// The scene, darker: a shadow, unless its neighbourhood's texture says otherwise.
    Shadow,
}

/// Half the side of the window [`BackgroundModel::textured_shadows`] looks at.
const TEXTURE_RADIUS: usize = 3;

impl BackgroundModel {
    /// Marks the foreground pixels of `frame` in `out` (cleared first).
    ///
    /// # Panics
    /// When `frame` or `out` is not the model's size.
    pub fn foreground(&self, frame: &RgbImage, opts: &BackgroundOptions, out: &mut Mask) {
        assert_eq!(
            (frame.width(), frame.height()),
            (self.width, self.height),
            "frame size"
        );
        assert_eq!(
            (out.width(), out.height()),
            (self.width, self.height),
            "mask size"
        );
        out.clear();
        let w = self.width as usize;
        let mut shadows = Vec::new();
        for (i, px) in frame.pixels().enumerate() {
            match self.classify(i, px.0, opts) {
                Class::Scene => {}
                Class::Person => out.set((i % w) as u32, (i / w) as u32, true),
                Class::Shadow => shadows.push(i),
            }
        }
        if !shadows.is_empty() && opts.shadow_max_texture.is_finite() {
            for i in self.textured_shadows(frame, &shadows, opts) {
                out.set((i % w) as u32, (i / w) as u32, true);
            }
        }
        if let Some(still) = &self.still {
            out.or_with(still);
        }
        if let Some(linger) = &self.linger {
            grow_within(out, linger);
        }
    }

    /// Adds to `out` (a frame's foreground) the [`Self::unknown`] pixels that the
    /// previous frame's silhouette `prev_mask` held and whose colour has not changed
    /// since `prev_frame`, by the foreground test's own measure (every channel within
    /// k·max(σ, σ_min)).
    ///
    /// An unknown pixel was never seen outside the person, so the model cannot say
    /// whether it shows the scene; where its colour stays put from frame to frame,
    /// whatever covered it then covers it still. Without it each frame judges such a
    /// pixel afresh, from a guessed scene colour and whether the gap its region opens
    /// to the scene happens to close ([`crate::vision::cleanup::clean_with_unknown`]),
    /// and a silhouette that was whole in one frame lost a quarter of itself in the
    /// next (lucia over the tennis scene, frames 63 and 64: IoU 0.959 and 0.710).
    /// With it, and the refining passes learning from silhouettes made the same way,
    /// lucia over the tennis and dance-twirl scenes without person-free frames went
    /// from IoU 0.898 / 0.890 to 0.915 / 0.916. Only pixels never seen outside the
    /// person are held ([`Self::unseen`]): holding every unknown pixel held
    /// vtest.mp4's walkway too (unknown for the spread its many walkers leave, a
    /// quarter of the image), and its silhouettes grew by 39%, walkers' ghosts
    /// included.
    ///
    /// Nor is a pixel held whose colour is likelier the scene's than the person's
    /// ([`Self::person_odds`] under 1): the scene that an arm swinging off the body
    /// uncovers stays put too, and once a gap-filling step took it for the person it
    /// was held for as long as the gap stayed open (the synthetic walk towards the
    /// camera without person-free frames: IoU 0.969 → 0.987; the DAVIS composites
    /// without person-free frames 0.915 / 0.976 / 0.974 / 0.915 / 0.963 / 0.948 →
    /// 0.921 / 0.978 / 0.974 / 0.915 / 0.968 / 0.966; at odds under 0.25 or 4 rather
    /// than 1, lucia over the dance-twirl scene 0.921 and 0.891).
    pub fn hold_unknown(
        &self,
        frame: &RgbImage,
        prev_frame: &RgbImage,
        prev_mask: &Mask,
        opts: &BackgroundOptions,
        out: &mut Mask,
    ) {
        let Some(unknown) = &self.unseen else {
            return;
        };
        let likelier_scene = |c: [u8; 3]| {
            self.person_odds
                .as_ref()
                .and_then(|odds| odds.get(colour_bin(c)))
                .is_some_and(|&o| o < 1.0)
        };
        let w = self.width as usize;
        for y in 0..self.height {
            for (k, &word) in unknown.row(y).iter().enumerate() {
                let mut bits = word & prev_mask.row(y)[k] & !out.row(y)[k];
                while bits != 0 {
                    let x = k as u32 * 64 + bits.trailing_zeros();
                    bits &= bits - 1;
                    let i = y as usize * w + x as usize;
                    let (a, b) = (frame.get_pixel(x, y).0, prev_frame.get_pixel(x, y).0);
                    let sd = self.sigma[i];
                    let same = (0..3).all(|c| {
                        (a[c] as f32 - b[c] as f32).abs() <= opts.k * sd[c].max(opts.sigma_min)
                    });
                    if same && !likelier_scene(a) {
                        out.set(x, y, true);
                    }
                }
            }
        }
    }

    /// Of the pixels whose colour says shadow, those whose neighbourhood does not:
    /// a shadow darkens the scene and keeps its texture, so over the shadow pixels
    /// around it the frame's brightness is the scene's times one factor, up to noise.
    /// Dark clothes over a textured ground (grey dress over asphalt) have their own
    /// texture, and what is left after the best factor is the ground's.
    fn textured_shadows(
        &self,
        frame: &RgbImage,
        shadows: &[usize],
        opts: &BackgroundOptions,
    ) -> Vec<usize> {
        let w = self.width as usize;
        let luma = |c: [f32; 3]| 0.299 * c[0] + 0.587 * c[1] + 0.114 * c[2];
        // The shadow pixels' bounding box, grown by the window: all that is summed.
        let r = TEXTURE_RADIUS;
        let (mut bx0, mut by0, mut bx1, mut by1) = (usize::MAX, usize::MAX, 0, 0);
        for &i in shadows {
            let (x, y) = (i % w, i / w);
            (bx0, by0) = (bx0.min(x.saturating_sub(r)), by0.min(y.saturating_sub(r)));
            (bx1, by1) = (bx1.max(x + r + 1), by1.max(y + r + 1));
        }
        let (bx1, by1) = (bx1.min(w), by1.min(self.height as usize));
        let (bw, bh) = (bx1 - bx0, by1 - by0);
        // Integral images over the shadow pixels of n, f, b, f², b², f·b (f the
        // frame's brightness, b the scene's), one row and column of zeros first.
        let stride = bw + 1;
        let mut sums = vec![[0f64; 6]; stride * (bh + 1)];
        let mut is_shadow = vec![false; bw * bh];
        for &i in shadows {
            is_shadow[(i / w - by0) * bw + i % w - bx0] = true;
        }
        let raw = frame.as_raw();
        for y in 0..bh {
            let mut row = [0f64; 6];
            for x in 0..bw {
                if is_shadow[y * bw + x] {
                    let i = (y + by0) * w + x + bx0;
                    let px = [raw[3 * i], raw[3 * i + 1], raw[3 * i + 2]];
                    let f = luma(px.map(f32::from)) as f64;
                    let b = luma(self.mean[i]) as f64;
                    for (r, v) in row.iter_mut().zip([1.0, f, b, f * f, b * b, f * b]) {
                        *r += v;
                    }
                }
                let above = sums[y * stride + x + 1];
                let cell = &mut sums[(y + 1) * stride + x + 1];
                for k in 0..6 {
                    cell[k] = above[k] + row[k];
                }
            }
        }
        let mut out = Vec::new();
        for &i in shadows {
            let (x, y) = (i % w - bx0, i / w - by0);
            let (x0, x1) = (x.saturating_sub(r), (x + r + 1).min(bw));
            let (y0, y1) = (y.saturating_sub(r), (y + r + 1).min(bh));
            let at = |xx: usize, yy: usize| sums[yy * stride + xx];
            let (a, b, c, d) = (at(x1, y1), at(x0, y1), at(x1, y0), at(x0, y0));
            let [n, sf, sb, sff, sbb, sfb]: [f64; 6] =
                std::array::from_fn(|k| a[k] - b[k] - c[k] + d[k]);
            if sb <= 0.0 {
                continue;
            }
            // The factor between their mean brightnesses, and the spread it leaves.
            let ratio = sf / sb;
            let residual = ((sff - 2.0 * ratio * sfb + ratio * ratio * sbb) / n)
                .max(0.0)
                .sqrt();
            let noise = luma(self.sigma[i]).max(opts.sigma_min) as f64;
            if residual > opts.shadow_max_texture as f64 * noise {
                out.push(i);
            }
        }
        out
    }

    fn classify(&self, i: usize, px: [u8; 3], opts: &BackgroundOptions) -> Class {
        let mu = self.mean[i];
        let sd = self.sigma[i].map(|s| s.max(opts.sigma_min));
        let x = px.map(|v| v as f32);
        if !(0..3).any(|c| (x[c] - mu[c]).abs() > opts.k * sd[c]) {
            return Class::Scene;
        }
        if !opts.shadows {
            return Class::Person;
        }
        // Brightness distortion α (the scale of μ closest to x, σ-weighted) and
        // chromaticity distortion (what remains, in σ units).
        let (mut num, mut den) = (0.0, 0.0);
        for c in 0..3 {
            num += x[c] * mu[c] / (sd[c] * sd[c]);
            den += mu[c] * mu[c] / (sd[c] * sd[c]);
        }
        if den <= 0.0 {
            return Class::Person;
        }
        let alpha = num / den;
        let chroma: f32 = (0..3)
            .map(|c| ((x[c] - alpha * mu[c]) / sd[c]).powi(2))
            .sum::<f32>()
            .sqrt();
        if alpha >= opts.shadow_min_brightness && alpha < 1.0 && chroma <= opts.shadow_max_chroma {
            Class::Shadow
        } else {
            Class::Person
        }
    }

    /// The share of the pixels on which `other` differs from this model: unknown in
    /// one of them only, or a mean apart by more than [`JOIN`] on some channel.
    pub fn changed_share(&self, other: &BackgroundModel) -> f64 {
        let unknown = |m: &BackgroundModel, i: usize| {
            m.unknown
                .as_ref()
                .is_some_and(|u| u.get(i as u32 % m.width, i as u32 / m.width))
        };
        let changed = (0..self.mean.len())
            .filter(|&i| {
                unknown(self, i) != unknown(other, i) || linf(&self.mean[i], &other.mean[i]) > JOIN
            })
            .count();
        changed as f64 / self.mean.len().max(1) as f64
    }

    /// The model's mean as an image (for debugging and reports).
    pub fn mean_image(&self) -> RgbImage {
        let w = self.width as usize;
        RgbImage::from_fn(self.width, self.height, |x, y| {
            let m = self.mean[y as usize * w + x as usize];
            image::Rgb(m.map(|v| v.round().clamp(0.0, 255.0) as u8))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(w: u32, h: u32, noise: u8, seed: u32) -> RgbImage {
        RgbImage::from_fn(w, h, |x, y| {
            let n = ((x * 7 + y * 13 + seed * 31) % (2 * noise as u32 + 1)) as u8;
            image::Rgb([100 + n, 120 + n, (x * 3 % 200) as u8 + n])
        })
    }

    fn with_person(mut img: RgbImage, x0: u32) -> RgbImage {
        for y in 10..30 {
            for x in x0..x0 + 6 {
                img.put_pixel(x, y, image::Rgb([20, 200, 40]));
            }
        }
        img
    }

    #[test]
    fn leading_still_frames_are_found_and_used() {
        let mut b = BackgroundBuilder::new(40, 40, EmptyFrames::Auto);
        for s in 0..5 {
            b.push(&scene(40, 40, 2, s));
        }
        for x in 0..10 {
            b.push(&with_person(scene(40, 40, 2, 9), 2 + 3 * x));
        }
        let m = b.finish();
        assert_eq!(m.source, ModelSource::EmptyFrames { first: 0, count: 5 });
        let mut out = Mask::new(40, 40);
        m.foreground(
            &with_person(scene(40, 40, 2, 3), 20),
            &BackgroundOptions::default(),
            &mut out,
        );
        assert_eq!(out.count(), 6 * 20);
    }

    #[test]
    fn without_empty_frames_the_dominant_colour_wins_even_under_a_lingering_person() {
        // The person stands over x = 10..16 in 60% of the frames but moves elsewhere
        // in the rest: a median would keep the person, the clusters do not.
        let mut b = BackgroundBuilder::new(40, 40, EmptyFrames::None);
        for f in 0..20 {
            let x0 = if f % 5 < 3 { 10 } else { 22 + (f % 5) * 3 };
            // Vary the person's colour over time, as clothes under changing light do.
            let mut img = scene(40, 40, 2, f);
            for y in 10..30 {
                for x in x0..x0 + 6 {
                    img.put_pixel(
                        x,
                        y,
                        image::Rgb([20 + (f * 11 % 120) as u8, 200 - (f * 7 % 90) as u8, 40]),
                    );
                }
            }
            b.push(&img);
        }
        let m = b.finish();
        assert!(matches!(m.source, ModelSource::WholeClip { frames: 20 }));
        let scene_px = scene(40, 40, 2, 0).get_pixel(12, 20).0;
        let got = m.mean[20 * 40 + 12];
        for c in 0..3 {
            assert!(
                (got[c] - scene_px[c] as f32).abs() < 4.0,
                "{got:?} vs {scene_px:?}"
            );
        }
    }

    #[test]
    fn a_scene_shown_in_few_frames_is_told_from_clothes_by_colour() {
        use crate::vision::silhouette::{Segmenter, SilhouetteOptions};
        // A torso stands over x = 14..20 in 18 of 20 frames, in a ring of limbs
        // whose colours change from frame to frame; in the other 2 frames it steps
        // aside, showing the scene behind in 10% of the frames: too few for that
        // colour to count against the clothes.
        let clothes = |f: u32| image::Rgb([20 + (f * 5 % 20) as u8, 200, 40]);
        let limbs = |f: u32| {
            image::Rgb([
                (f * 53 % 256) as u8,
                (f * 97 + 80) as u8,
                (f * 31 + 160) as u8,
            ])
        };
        let frames: Vec<RgbImage> = (0..20u32)
            .map(|f| {
                let mut img = scene(48, 40, 2, f);
                let x0 = if f == 7 || f == 15 { 5 } else { 14 };
                for y in 10..30 {
                    for x in x0 - 2..x0 + 8 {
                        let core = (12..28).contains(&y) && (x0..x0 + 6).contains(&x);
                        img.put_pixel(x, y, if core { clothes(f) } else { limbs(f) });
                    }
                }
                img
            })
            .collect();
        let seg = Segmenter::learn(48, 40, &SilhouetteOptions::default(), |visit| {
            frames.iter().for_each(&mut *visit);
            Ok::<_, ()>(())
        })
        .unwrap();
        let scene_px = scene(48, 40, 2, 0).get_pixel(16, 20).0;
        let got = seg.model.mean[20 * 48 + 16];
        for c in 0..3 {
            assert!(
                (got[c] - scene_px[c] as f32).abs() < 6.0,
                "{got:?} vs {scene_px:?}"
            );
        }
        // The torso is foreground where it stands.
        let mut out = Mask::new(48, 40);
        seg.silhouette(&frames[0], &mut out);
        assert!(out.get(16, 20) && out.get(19, 27));
    }

    #[test]
    fn changed_share_counts_moved_means_and_flipped_unknowns() {
        let mut builder = BackgroundBuilder::new(10, 10, EmptyFrames::None);
        builder.push(&scene(10, 10, 2, 0));
        let a = builder.finish();
        assert_eq!(a.changed_share(&a), 0.0);
        let mut b = a.clone();
        b.mean[3][1] += JOIN + 1.0;
        b.mean[4][0] += JOIN - 1.0;
        let mut unknown = Mask::new(10, 10);
        unknown.set(7, 7, true);
        b.unknown = Some(unknown);
        assert_eq!(a.changed_share(&b), 0.02);
        assert_eq!(b.changed_share(&a), 0.02);
    }

    #[test]
    fn a_pixel_whose_colour_outside_the_person_wanders_is_unknown() {
        // A first silhouette missed a dress over x = 10..20 (its colour shifts by up
        // to 60 levels from frame to frame): the refiner sees it "outside the person"
        // there, but no still scene; it must mark those pixels unknown and leave the
        // steady scene known.
        let base = BackgroundBuilder::new(40, 30, EmptyFrames::None);
        let (model, candidates) = base.finish_with_candidates();
        let mut refiner = Refiner::new(model, candidates.as_ref());
        let empty = Mask::new(40, 30);
        for f in 0..12u32 {
            let mut img = scene(40, 30, 2, f);
            for y in 5..25 {
                for x in 10..20 {
                    let v = 40 + (f * 37 % 60) as u8;
                    img.put_pixel(x, y, image::Rgb([v, v, v + 5]));
                }
            }
            refiner.push(&img, &empty, &empty, &empty, &empty, 0.1);
        }
        let model = refiner.finish();
        let unknown = model.unknown.unwrap();
        assert!((5..25).all(|y| (10..20).all(|x| unknown.get(x, y))));
        assert_eq!(unknown.count(), 20 * 10);
        // Seen outside the person, only not as a still scene: not held from frame to
        // frame as the person's.
        assert_eq!(model.unseen.unwrap().count(), 0);
    }

    #[test]
    fn an_unseen_pixel_stays_the_persons_while_its_colour_stays() {
        // A grey scene (100); where the person stood all clip long (x = 10..20) the
        // model guessed their clothes' colour (60) for the scene.
        let (w, h) = (30u32, 20u32);
        let n = (w * h) as usize;
        let mut model = BackgroundModel {
            width: w,
            height: h,
            mean: vec![[100.0; 3]; n],
            sigma: vec![[2.0; 3]; n],
            source: ModelSource::WholeClip { frames: 10 },
            unknown: None,
            unseen: None,
            still: None,
            linger: None,
            person_odds: None,
        };
        let mut unseen = Mask::new(w, h);
        let mut frame = RgbImage::from_pixel(w, h, image::Rgb([100, 100, 100]));
        for y in 0..h {
            for x in 10..20 {
                unseen.set(x, y, true);
                model.mean[(y * w + x) as usize] = [60.0; 3];
                frame.put_pixel(x, y, image::Rgb([61, 59, 60]));
            }
        }
        model.unknown = Some(unseen.clone());
        model.unseen = Some(unseen);
        let opts = BackgroundOptions::default();
        // The previous frame's silhouette held the top half of the clothes, and a
        // pixel of the scene beside them (x = 5).
        let mut prev = frame.clone();
        prev.put_pixel(12, 3, image::Rgb([90, 90, 90]));
        let mut prev_mask = Mask::new(w, h);
        for y in 0..10 {
            for x in 5..20 {
                prev_mask.set(x, y, true);
            }
        }
        let mut out = Mask::new(w, h);
        model.foreground(&frame, &opts, &mut out);
        assert_eq!(out.count(), 0, "the clothes match the guessed scene");
        model.hold_unknown(&frame, &prev, &prev_mask, &opts, &mut out);
        for y in 0..h {
            for x in 0..w {
                // Held: the unseen pixels of the previous silhouette whose colour
                // stayed; not the one that changed by 30 levels, nor the unseen
                // pixels the previous silhouette did not hold, nor the known scene.
                let held = (10..20).contains(&x) && y < 10 && (x, y) != (12, 3);
                assert_eq!(out.get(x, y), held, "({x}, {y})");
            }
        }
        // Where the unseen pixels show a colour likelier the scene's than the
        // person's (the wall an arm uncovered), none is held.
        let mut odds = vec![1.0; BINS * BINS * BINS];
        odds[colour_bin([61, 59, 60])] = 0.5;
        model.person_odds = Some(odds);
        out.clear();
        model.hold_unknown(&frame, &prev, &prev_mask, &opts, &mut out);
        assert_eq!(out.count(), 0);
        // At even odds they are.
        model.person_odds.as_mut().unwrap()[colour_bin([61, 59, 60])] = 1.0;
        model.hold_unknown(&frame, &prev, &prev_mask, &opts, &mut out);
        assert_eq!(out.count(), 10 * 10 - 1);
    }

    /// A ground with a grain of ±20 levels, darkened to 60% in columns 10..30 of
    /// `shadow` rows, covered by flat dark grey cloth (the ground's own grey at 60%,
    /// a shadow's colour) in the same columns of `cloth` rows.
    fn grained(shadow: std::ops::Range<u32>, cloth: std::ops::Range<u32>, seed: u32) -> RgbImage {
        RgbImage::from_fn(40, 40, |x, y| {
            let grain = ((x * 37 + y * 91) % 41) as f32 - 20.0;
            let noise = ((x * 7 + y * 13 + seed * 5) % 3) as f32 - 1.0;
            let ground = 140.0 + grain + noise;
            let v = if (10..30).contains(&x) && cloth.contains(&y) {
                0.6 * 140.0 + noise
            } else if (10..30).contains(&x) && shadow.contains(&y) {
                0.6 * ground
            } else {
                ground
            };
            let v = v.round() as u8;
            image::Rgb([v, v, v])
        })
    }

    #[test]
    fn only_the_lingering_parts_touching_the_foreground_join_it() {
        let mut linger = Mask::new(100, 40);
        let mut out = Mask::new(100, 40);
        // A torso's region next to the arm that showed, and a patch far from it.
        for y in 5..30 {
            for x in 10..20 {
                linger.set(x, y, true);
            }
            out.set(20, y, true);
        }
        for y in 5..10 {
            for x in 60..70 {
                linger.set(x, y, true);
            }
        }
        grow_within(&mut out, &linger);
        assert!(out.get(10, 5) && out.get(15, 29));
        assert!(!out.get(65, 7));
        assert_eq!(out.count(), 25 * 11);
        // With nothing in the frame, nothing is added.
        let mut empty = Mask::new(100, 40);
        grow_within(&mut empty, &linger);
        assert_eq!(empty.count(), 0);
    }

    #[test]
    fn a_shadow_keeps_the_grounds_texture_and_grey_cloth_does_not() {
        let mut b = BackgroundBuilder::new(40, 40, EmptyFrames::Range(0, 6));
        for s in 0..6 {
            b.push(&grained(0..0, 0..0, s));
        }
        let m = b.finish();
        let frame = grained(2..18, 22..38, 9);
        let mut out = Mask::new(40, 40);
        let colour_only = BackgroundOptions {
            shadow_max_texture: f32::INFINITY,
            ..BackgroundOptions::default()
        };
        m.foreground(&frame, &colour_only, &mut out);
        let cloth_by_colour = (22..38).filter(|&y| out.get(20, y)).count();
        m.foreground(&frame, &BackgroundOptions::default(), &mut out);
        let shadow = (2..18).flat_map(|y| (10..30).map(move |x| (x, y)));
        let cloth = (22..38).flat_map(|y| (10..30).map(move |x| (x, y)));
        let shadow_fg = shadow.filter(|&(x, y)| out.get(x, y)).count();
        let cloth_fg = cloth.filter(|&(x, y)| out.get(x, y)).count();
        // By colour alone most of the cloth is a shadow; with its texture it is not.
        assert!(cloth_by_colour < 8, "{cloth_by_colour} of 16 cloth pixels");
        assert!(cloth_fg >= 300, "{cloth_fg} of 320 cloth pixels");
        assert!(shadow_fg <= 16, "{shadow_fg} of 320 shadow pixels");
    }

    #[test]
    fn shadows_are_not_foreground_but_dark_clothes_are() {
        let mut b = BackgroundBuilder::new(8, 8, EmptyFrames::Range(0, 4));
        for s in 0..4 {
            b.push(&RgbImage::from_pixel(
                8,
                8,
                image::Rgb([150, 140, 120 + s as u8]),
            ));
        }
        let m = b.finish();
        let opts = BackgroundOptions::default();
        let mut out = Mask::new(8, 8);
        // A shadow: 70% brightness, same chromaticity.
        m.foreground(
            &RgbImage::from_pixel(8, 8, image::Rgb([105, 98, 85])),
            &opts,
            &mut out,
        );
        assert_eq!(out.count(), 0);
        // Dark blue clothes: foreground.
        m.foreground(
            &RgbImage::from_pixel(8, 8, image::Rgb([40, 50, 110])),
            &opts,
            &mut out,
        );
        assert_eq!(out.count(), 64);
        // Near-black: far darker than any shadow the options allow.
        m.foreground(
            &RgbImage::from_pixel(8, 8, image::Rgb([30, 28, 24])),
            &opts,
            &mut out,
        );
        assert_eq!(out.count(), 64);
    }

    #[test]
    fn legs_that_never_moved_hang_below_the_region_the_person_covered() {
        // A wall over a floor (both reaching the image's border), a picture on the
        // wall behind the head, the region the person covered in nearly every frame
        // (head and torso), legs and shoes below it, and a stool touching its side.
        let (w, h) = (40usize, 40usize);
        let inside = |x: usize, y: usize, x0: usize, x1: usize, y0: usize, y1: usize| {
            (x0..x1).contains(&x) && (y0..y1).contains(&y)
        };
        let region = |x: usize, y: usize| inside(x, y, 15, 25, 6, 20);
        let mut mean = vec![[0f32; 3]; w * h];
        for y in 0..h {
            for x in 0..w {
                mean[y * w + x] = if inside(x, y, 17, 23, 20, 34) {
                    [66.0, 53.0, 43.0] // trousers
                } else if inside(x, y, 16, 24, 34, 36) {
                    [20.0, 20.0, 22.0] // shoes
                } else if inside(x, y, 12, 28, 2, 8) {
                    [206.0, 65.0, 161.0] // the picture
                } else if inside(x, y, 25, 30, 15, 19) {
                    [120.0, 160.0, 60.0] // a stool
                } else if y < 24 {
                    [190.0, 170.0, 150.0] // wall
                } else {
                    [110.0, 115.0, 150.0 + (x % 3) as f32] // floor
                };
            }
        }
        let got = attached_below(&mean, w as u32, h as u32, |i| region(i % w, i / w));
        for y in 0..h {
            for x in 0..w {
                let legs = inside(x, y, 17, 23, 20, 34) || inside(x, y, 16, 24, 34, 36);
                assert_eq!(got.get(x as u32, y as u32), legs, "({x}, {y})");
            }
        }
        // A region low in the picture: the trousers start above its centre, the
        // floor reaches the border.
        let low = attached_below(&mean, w as u32, h as u32, |i| {
            inside(i % w, i / w, 15, 25, 30, 39)
        });
        assert_eq!(low.count(), 0);
    }
}
