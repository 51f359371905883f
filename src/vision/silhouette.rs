//! Silhouettes of a clip: learn the background in a first pass over the frames
//! (and, without person-free frames, refine it in up to [`MAX_REFINE_PASSES`]
//! more), then segment and clean each frame in a last pass (method.md §3). Every
//! pass streams: between them only the background model is kept (see its memory
//! note), never the frames; within a pass, the previous frame and its silhouette
//! (the pixels the clip never showed empty are judged from frame to frame,
//! [`Sequence`]). A clip of masks skips background subtraction: its frames are
//! thresholded as they are.

use image::RgbImage;

use super::background::{
    BackgroundBuilder, BackgroundModel, BackgroundOptions, ModelSource, Refiner,
    MIN_MEDIAN_FOREGROUND,
};
use super::cleanup::{clean_with_unknown, person_region, CleanupOptions};
use crate::body::Mask;

#[derive(Clone, Debug)]
pub struct SilhouetteOptions {
    pub background: BackgroundOptions,
    pub cleanup: CleanupOptions,
    /// Without person-free frames: re-learn the scene from what each frame shows
    /// outside its person, grown by this fraction of the image height (None: no
    /// refining pass).
    pub refine_grow: Option<f64>,
    /// When set (by another thread), [`clip_silhouettes`] stops at the next frame
    /// with an error: how a service cancels a job during the decoding passes, which
    /// call nothing per frame.
    pub stop: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
}

impl Default for SilhouetteOptions {
    fn default() -> Self {
        SilhouetteOptions {
            background: BackgroundOptions::default(),
            cleanup: CleanupOptions::default(),
            refine_grow: Some(0.03),
            stop: None,
        }
    }
}

/// Most refining passes over the clip ([`Refiner`]) when it has no person-free
/// frames. Each pass takes the person out of the scene's statistics where the
/// previous pass's model found them, so the next finds more of them: an
/// alternation between background and silhouettes, which settles in two or three
/// passes. Without person-free frames, one pass against up to four (settled
/// within 0.1% of the pixels, see [`SETTLED_SHARE`]): the DAVIS composites from
/// IoU 0.894 / 0.974 / 0.967 / 0.843 / 0.966 / 0.944 to 0.898 / 0.978 / 0.974 /
/// 0.890 / 0.969 / 0.966 (lucia over tennis, dance-twirl over lucia, tennis over
/// dance-twirl, lucia over dance-twirl, dance-twirl over tennis, tennis over
/// lucia), the synthetic walk and kick from 0.992 / 0.971 to 0.997 / 0.979. A
/// person who stood still (see [`BackgroundModel::still`]) is found in the first
/// pass only: a second saw their whole region as foreground in every frame (the
/// synthetic dance 0.970 → 0.961).
pub const MAX_REFINE_PASSES: usize = 4;
/// The refining stops once a pass changes the model on fewer than this share of the
/// pixels ([`BackgroundModel::changed_share`]): on the clips above the third pass
/// changed under 0.05% where the second had changed 1–3.5%, except lucia's, which
/// took all four (over dance-twirl 0.871, 0.886, 0.890 after two, three and four);
/// on vtest.mp4 the second changed 0.7% and the third 0.07%.
const SETTLED_SHARE: f64 = 0.001;

/// Segments frames against a learned background.
pub struct Segmenter {
    pub model: BackgroundModel,
    opts: SilhouetteOptions,
}

impl Segmenter {
    /// Learns the background. `pass` must run through the whole clip once, calling
    /// its argument on every frame in order; it is called once, or up to
    /// 1 + [`MAX_REFINE_PASSES`] times when the clip has no person-free frames (the
    /// later passes refine the model, see [`Refiner`]).
    pub fn learn<E>(
        width: u32,
        height: u32,
        opts: &SilhouetteOptions,
        mut pass: impl FnMut(&mut dyn FnMut(&RgbImage)) -> Result<(), E>,
    ) -> Result<Segmenter, E> {
        let mut builder = BackgroundBuilder::new(width, height, opts.background.empty.clone());
        pass(&mut |f| builder.push(f))?;
        let (mut model, candidates) = builder.finish_with_candidates();
        if let (ModelSource::WholeClip { .. }, Some(grow)) = (&model.source, opts.refine_grow) {
            let grow = ((height as f64 * grow).round().min(255.0) as u8).max(1);
            let mut raw = Mask::new(width, height);
            for _ in 0..MAX_REFINE_PASSES {
                // From the second pass on, the silhouettes the previous pass's model
                // gives (unknown bays filled) tell the person from the scene.
                let mut refiner = Refiner::new(model, candidates.as_ref());
                // Each frame's silhouette as the final pass gives it: with the
                // previous frame's ([`Sequence`]).
                let mut prev: Option<(RgbImage, Mask)> = None;
                let holds = refiner
                    .base()
                    .unseen
                    .as_ref()
                    .is_some_and(|u| u.count() > 0);
                pass(&mut |f| {
                    let base = refiner.base();
                    base.foreground(f, &opts.background, &mut raw);
                    let mut clean = raw.clone();
                    if let Some((prev_frame, prev_mask)) = &prev {
                        base.hold_unknown(f, prev_frame, prev_mask, &opts.background, &mut clean);
                    }
                    clean_with_unknown(&mut clean, &opts.cleanup, base.unknown.as_ref());
                    let share = clean.count() as f32 / (width as f32 * height as f32).max(1.0);
                    if holds {
                        remember(&mut prev, f, &clean);
                    }
                    let person = person_region(&clean, grow);
                    let around = person.dilated_square(grow as u32);
                    refiner.push(f, &raw, &clean, &person, &around, share);
                })?;
                let before = refiner.base().clone();
                model = refiner.finish();
                // A person who stood still is found in the first pass, by what its raw
                // foreground never showed; a second pass would see their region as
                // foreground throughout.
                if model.still.is_some() || model.changed_share(&before) < SETTLED_SHARE {
                    break;
                }
            }
        }
        Ok(Segmenter {
            model,
            opts: opts.clone(),
        })
    }

    /// The cleaned silhouette of one frame, judged alone (a clip's frames in order:
    /// [`Segmenter::sequence`]).
    pub fn silhouette(&self, frame: &RgbImage, out: &mut Mask) {
        self.model.foreground(frame, &self.opts.background, out);
        clean_with_unknown(out, &self.opts.cleanup, self.model.unknown.as_ref());
    }

    /// Segments a clip's frames in order, each with what the previous one showed
    /// ([`BackgroundModel::hold_unknown`]).
    pub fn sequence(&self) -> Sequence<'_> {
        Sequence {
            seg: self,
            holds: self.model.unseen.as_ref().is_some_and(|u| u.count() > 0),
            prev: None,
        }
    }
}

/// A clip's frames segmented in order ([`Segmenter::sequence`]). Keeps the previous
/// frame and its silhouette when the model has pixels it never saw outside the
/// person (a background learned from the whole clip); nothing otherwise.
pub struct Sequence<'a> {
    seg: &'a Segmenter,
    /// The model has pixels it never saw outside the person.
    holds: bool,
    prev: Option<(RgbImage, Mask)>,
}

impl Sequence<'_> {
    /// The cleaned silhouette of the clip's next frame.
    pub fn next(&mut self, frame: &RgbImage, out: &mut Mask) {
        let (model, opts) = (&self.seg.model, &self.seg.opts);
        model.foreground(frame, &opts.background, out);
        if let Some((prev_frame, prev_mask)) = &self.prev {
            model.hold_unknown(frame, prev_frame, prev_mask, &opts.background, out);
        }
        clean_with_unknown(out, &opts.cleanup, model.unknown.as_ref());
        if self.holds {
            remember(&mut self.prev, frame, out);
        }
    }
}

/// Keeps `frame` and its silhouette in `prev`, reusing its buffers.
fn remember(prev: &mut Option<(RgbImage, Mask)>, frame: &RgbImage, mask: &Mask) {
    match prev {
        Some((f, m)) => {
            f.clone_from(frame);
            m.clone_from(mask);
        }
        None => *prev = Some((frame.clone(), mask.clone())),
    }
}

/// A mask frame (a silhouette clip) as a [`Mask`], by the rule mask clips are read
/// with ([`crate::clip::open::mask_on`]).
pub fn mask_from_frame(frame: &RgbImage) -> Mask {
    let mut m = Mask::new(frame.width(), frame.height());
    for (x, y, p) in frame.enumerate_pixels() {
        if crate::clip::open::mask_on(p.0) {
            m.set(x, y, true);
        }
    }
    m
}

/// What [`clip_silhouettes`] found.
#[derive(Clone, Debug)]
pub struct ClipSilhouettes {
    pub info: crate::clip::ClipInfo,
    /// Where the background came from (None for a mask clip).
    pub source: Option<ModelSource>,
    pub frames: usize,
    /// The median over the frames of the silhouette's share of the image.
    pub median_foreground: f64,
    /// The person seemed to stand still all clip long and was found as the region
    /// their outline encloses ([`BackgroundModel::still`]).
    pub still_person: bool,
    /// The median over the frames with a silhouette of the share of its pixels that
    /// lie where the clip never showed the scene ([`BackgroundModel::unseen`]; 0
    /// with person-free frames or a mask clip).
    pub unseen_share: f64,
}

impl ClipSilhouettes {
    /// What the user should know about silhouettes that look wrong. A background
    /// learned from the whole clip is the scene only where the person moves off it:
    /// a person who stands still in every frame is taken for the scene and their
    /// silhouette is nearly empty, or, when they moved enough to outline themselves,
    /// mostly the same region in every frame; a person who keeps within their own
    /// footprint (walking towards the camera, punching on one spot) leaves most of
    /// the scene behind them unseen ([`MAX_UNSEEN_SHARE`]).
    pub fn warning(&self) -> Option<String> {
        match self.source {
            Some(ModelSource::WholeClip { .. })
                if self.frames > 0 && self.median_foreground < MIN_MEDIAN_FOREGROUND =>
            {
                Some(format!(
                    "the silhouettes are nearly empty (median {:.2}% of the image): the clip \
                     has no person-free frames and the person seems to stay on the same spot, \
                     so they were taken for the scene; name the clip's person-free frames \
                     (--empty-frames A..B; the job option empty_frames), film a few seconds \
                     of the empty scene before the person steps in, or give the silhouettes \
                     as a mask clip",
                    100.0 * self.median_foreground
                ))
            }
            Some(ModelSource::WholeClip { .. }) if self.still_person => Some(
                "the clip has no person-free frames and the person seems to stay on the same \
                 spot: their silhouette is the region their outline enclosed as they moved, \
                 corrected by colour, and where they never moved it is the same in every \
                 frame (a limb held still against the body merges with it); for \
                 exact silhouettes name the clip's person-free frames (--empty-frames A..B; \
                 the job option empty_frames) or film a few seconds of the empty scene first"
                    .to_string(),
            ),
            Some(ModelSource::WholeClip { .. }) if self.unseen_share > MAX_UNSEEN_SHARE => {
                Some(format!(
                    "{:.0}% of the person's silhouette (median frame) lies where the clip \
                     never showed the scene: the clip has no person-free frames and the \
                     person covered those pixels in every frame, so the silhouettes there \
                     are inferred; for exact silhouettes name the clip's person-free frames \
                     (--empty-frames A..B; the job option empty_frames) or film a few \
                     seconds of the empty scene first",
                    100.0 * self.unseen_share
                ))
            }
            _ => None,
        }
    }
}

/// Above this [`ClipSilhouettes::unseen_share`] the silhouettes come with a warning.
/// Measured without person-free frames: the person's share on never-seen pixels is
/// 0.79–0.99 where they stay within their own footprint (the synthetic walk and run
/// towards the camera, the punch and the bow on one spot: silhouettes IoU 0.47–0.99
/// with [`crate::vision::background::BackgroundModel::linger`];
/// DAVIS lucia over a still scene: 0.85, IoU 0.915) and 0–0.45 where they move across
/// the scene (IoU 0.95–0.99).
pub const MAX_UNSEEN_SHARE: f64 = 0.5;

/// The median of a list of shares (0 when empty).
fn median_share(mut v: Vec<f32>) -> f64 {
    super::background::median(&mut v).unwrap_or(0.0) as f64
}

/// The silhouette of every frame of the clip at `path`, handed to `each` with the
/// frame, in order. A mask clip (`masks`, or a ZIP/TAR of binary frames) is read as
/// it is; any other clip is decoded once (with person-free frames) or two to five
/// times (without) to learn the background, and once more to segment it.
pub fn clip_silhouettes(
    path: &std::path::Path,
    limits: &crate::clip::Limits,
    opts: &SilhouetteOptions,
    masks: bool,
    mut each: impl FnMut(usize, &RgbImage, &Mask) -> anyhow::Result<()>,
) -> anyhow::Result<ClipSilhouettes> {
    use crate::clip::open::{open, open_with, probe};
    let info = probe(path, limits)?;
    if let super::background::EmptyFrames::Range(a, b) = opts.background.empty {
        if info.frame_count > 0 && b as u64 > info.frame_count {
            anyhow::bail!(
                "{}: person-free frames {a}..{b} run past the clip's {} frames",
                path.display(),
                info.frame_count
            );
        }
    }
    let (w, h) = (info.width, info.height);
    let stopped = || {
        opts.stop
            .as_ref()
            .is_some_and(|s| s.load(std::sync::atomic::Ordering::Relaxed))
    };
    let check_frame = |f: &RgbImage| -> anyhow::Result<()> {
        if stopped() {
            anyhow::bail!("stopped");
        }
        if f.dimensions() != (w, h) {
            anyhow::bail!(
                "{}: a frame of {}×{} in a clip of {w}×{h} (frame sizes must not change)",
                path.display(),
                f.width(),
                f.height()
            );
        }
        Ok(())
    };
    let mut frames = 0;
    // 4 bytes a frame: a 10-minute clip at 30 frames/s keeps 72 kB.
    let mut shares = Vec::new();
    let area = (w as f32 * h as f32).max(1.0);
    if masks || info.is_mask {
        let mut src = open_with(path, limits, true)?;
        while let Some(f) = src.next_frame()? {
            check_frame(&f)?;
            let mask = mask_from_frame(&f);
            shares.push(mask.count() as f32 / area);
            each(frames, &f, &mask)?;
            frames += 1;
        }
        return Ok(ClipSilhouettes {
            info,
            source: None,
            frames,
            median_foreground: median_share(shares),
            still_person: false,
            unseen_share: 0.0,
        });
    }
    let seg = Segmenter::learn(w, h, opts, |visit| {
        let mut src = open(path, limits)?;
        while let Some(f) = src.next_frame()? {
            check_frame(&f)?;
            visit(&f);
        }
        Ok::<_, anyhow::Error>(())
    })?;
    let mut src = open(path, limits)?;
    let mut mask = Mask::new(w, h);
    let mut sequence = seg.sequence();
    let unseen = seg.model.unseen.as_ref().filter(|u| u.count() > 0);
    // 4 bytes a frame, as `shares`.
    let mut unseen_shares = Vec::new();
    while let Some(f) = src.next_frame()? {
        check_frame(&f)?;
        sequence.next(&f, &mut mask);
        let count = mask.count();
        if let (Some(u), true) = (unseen, count > 0) {
            unseen_shares.push(mask.and_count(u) as f32 / count as f32);
        }
        shares.push(count as f32 / area);
        each(frames, &f, &mask)?;
        frames += 1;
    }
    Ok(ClipSilhouettes {
        info,
        source: Some(seg.model.source.clone()),
        frames,
        median_foreground: median_share(shares),
        still_person: seg.model.still.is_some(),
        unseen_share: median_share(unseen_shares),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vision::background::EmptyFrames;

    /// Noise of pixel (x, y) in frame f: 0 to 4 levels.
    fn noise(x: u32, y: u32, f: u32) -> u8 {
        ((x * 7 + y * 13 + f * 31) % 5) as u8
    }

    /// The textured scene's colour at (x, y) in frame f.
    fn scene(x: u32, y: u32, f: u32) -> image::Rgb<u8> {
        let n = noise(x, y, f);
        image::Rgb([150 + n, 140 + (x % 9) as u8 + n, 120 + n])
    }

    /// A 120×90 textured scene with a person (a 14×40 block in two colours) standing
    /// at (50, 30) in every frame, a pixel to the right in one frame of eight and a
    /// pixel lower in another; noise varying per frame.
    fn frame(f: u32) -> RgbImage {
        let (x0, y0) = match f % 8 {
            3 => (51, 30),
            6 => (50, 31),
            _ => (50, 30),
        };
        RgbImage::from_fn(120, 90, |x, y| {
            if (x0..x0 + 14).contains(&x) && (y0..y0 + 40).contains(&y) {
                let c = if y < y0 + 20 {
                    [40, 80, 170]
                } else {
                    [90, 70, 60]
                };
                image::Rgb(c.map(|v| v + noise(x, y, f)))
            } else {
                scene(x, y, f)
            }
        })
    }

    /// A segmenter learned without person-free frames from frames 0..count of `at`.
    fn learn(count: u32, at: impl Fn(u32) -> RgbImage) -> Segmenter {
        let opts = SilhouetteOptions {
            background: BackgroundOptions {
                empty: EmptyFrames::None,
                ..BackgroundOptions::default()
            },
            ..SilhouetteOptions::default()
        };
        Segmenter::learn(120, 90, &opts, |visit| {
            (0..count).for_each(|f| visit(&at(f)));
            Ok::<_, ()>(())
        })
        .unwrap()
    }

    /// The pixels of `inside` that `mask` holds.
    fn held(mask: &Mask, inside: impl Fn(u32, u32) -> bool) -> usize {
        (0..mask.height())
            .flat_map(|y| (0..mask.width()).map(move |x| (x, y)))
            .filter(|&(x, y)| inside(x, y) && mask.get(x, y))
            .count()
    }

    #[test]
    fn a_person_who_never_leaves_their_spot_is_found_by_the_outline_they_sway() {
        let seg = learn(30, frame);
        // The whole-clip background took the person for the scene; only the
        // outline changed.
        let still = seg.model.still.as_ref().expect("a still person");
        let mut out = Mask::new(120, 90);
        seg.silhouette(&frame(31), &mut out);
        let truth = |x: u32, y: u32| (50..64).contains(&x) && (30..70).contains(&y);
        let inter = held(&out, truth);
        let union = 14 * 40 + out.count() as usize - inter;
        let iou = inter as f64 / union as f64;
        assert!(
            iou > 0.85,
            "IoU {iou:.3}, still region of {} px",
            still.count()
        );
    }

    #[test]
    fn a_still_persons_region_is_corrected_by_colour() {
        // The person of `frame` with a leg below them that never moves (its outline
        // never changes, so the outline's region misses it; narrower than the
        // closing, which bridges the gap it leaves in the outline) and a notch in their
        // side that always shows the scene (which the closed outline fills; a hole
        // would be filled by the clean-up anyway).
        let leg = |x: u32, y: u32| (54..58).contains(&x) && (70..76).contains(&y);
        let gap = |x: u32, y: u32| (60..64).contains(&x) && (40..52).contains(&y);
        let at = |f: u32| {
            let mut img = frame(f);
            for (x, y, px) in img.enumerate_pixels_mut() {
                if leg(x, y) {
                    *px = image::Rgb([90, 70, 60].map(|v| v + noise(x, y, f)));
                } else if gap(x, y) {
                    *px = scene(x, y, f);
                }
            }
            img
        };
        let seg = learn(30, at);
        assert!(seg.model.still.is_some());
        let mut out = Mask::new(120, 90);
        seg.silhouette(&at(31), &mut out);
        let (leg_found, gap_taken) = (held(&out, leg), held(&out, gap));
        assert!(leg_found >= 20, "{leg_found} of the leg's 24 pixels");
        assert!(gap_taken <= 8, "{gap_taken} of the notch's 48 pixels");
    }

    #[test]
    fn someone_crossing_a_mostly_empty_scene_is_not_a_still_person() {
        // Empty but for frames 20..26, in which a block crosses from left to right.
        let at = |f: u32| {
            RgbImage::from_fn(120, 90, |x, y| {
                let crossing = (20..26).contains(&f)
                    && (f * 18 - 350..f * 18 - 336).contains(&x)
                    && (30..70).contains(&y);
                if crossing {
                    image::Rgb([40, 80, 170].map(|v| v + noise(x, y, f)))
                } else {
                    scene(x, y, f)
                }
            })
        };
        let seg = learn(40, at);
        assert!(seg.model.still.is_none());
        let mut out = Mask::new(120, 90);
        seg.silhouette(&at(30), &mut out);
        assert_eq!(out.count(), 0);
        seg.silhouette(&at(22), &mut out);
        assert!(out.get(52, 50) && !out.get(80, 50));
    }
}
