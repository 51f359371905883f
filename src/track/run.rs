//! Tracking a clip file end to end: probe, silhouettes, working resolution, tracker.
//! The command line (`monocap track`) and the service's workers both call
//! [`track_clip`], so the same clip and options give the same motion either way.
//!
//! The silhouettes are extracted on a second thread and handed to the tracker through
//! a small bounded channel (a few frames in flight), so decoding and segmenting one
//! frame overlaps tracking the previous one, and memory stays bounded.

use std::ops::ControlFlow;
use std::path::Path;
use std::sync::mpsc::sync_channel;

use anyhow::{Context, Result};
use image::RgbImage;

use super::tracker::{
    FrameInput, Progress, Track, TrackError, TrackOptions, TrackedFrame, Tracker,
};
use crate::body::{Camera, Mask};
use crate::clip::{ClipInfo, Limits};
use crate::vision::silhouette::{clip_silhouettes, SilhouetteOptions};

/// Largest working height (the tracker's memory and time grow with its square).
pub const MAX_WORK_HEIGHT: u32 = 1080;

/// Options of [`track_clip`].
#[derive(Clone, Debug)]
pub struct ClipTrackOptions {
    /// Horizontal field of view of the camera, degrees.
    pub fov_deg: f64,
    /// The clip is a sequence of masks (no background subtraction).
    pub masks: bool,
    pub silhouettes: SilhouetteOptions,
    pub track: TrackOptions,
    /// The tracker works on frames scaled down by a whole factor until they are at
    /// most this many rows high (silhouettes are extracted at full resolution).
    pub work_height: u32,
    pub limits: Limits,
    /// Track only these clip frames (half-open). Frame numbers in the options
    /// (initial frame, keyframes) and in the result stay the clip's.
    pub frames: Option<(usize, usize)>,
}

impl Default for ClipTrackOptions {
    fn default() -> Self {
        ClipTrackOptions {
            fov_deg: 55.0,
            masks: false,
            silhouettes: SilhouetteOptions::default(),
            track: TrackOptions::default(),
            work_height: 288,
            limits: Limits::default(),
            frames: None,
        }
    }
}

/// A tracked clip file.
pub struct ClipTrack {
    pub info: ClipInfo,
    /// The camera at the clip's own resolution (for reporting in its pixels).
    pub camera: Camera,
    /// Frames per second used (the clip's, or 30 when it does not say).
    pub fps: f64,
    pub track: Track,
    /// What the user should know about the result (see
    /// [`crate::vision::silhouette::ClipSilhouettes::warning`]).
    pub warnings: Vec<String>,
}

/// The camera of a `width`×`height` clip and the whole factor the tracker scales
/// it down by.
pub fn working_scale(width: u32, height: u32, work_height: u32) -> u32 {
    height.div_ceil(work_height.max(1)).max(1).min(width.max(1))
}

/// `cam` seen at 1/`k` of its resolution.
pub fn scaled_camera(cam: &Camera, k: u32) -> Camera {
    let kf = k as f64;
    Camera {
        width: (cam.width / k).max(1),
        height: (cam.height / k).max(1),
        fx: cam.fx / kf,
        fy: cam.fy / kf,
        cx: cam.cx / kf,
        cy: cam.cy / kf,
        ..cam.clone()
    }
}

/// A mask scaled down by `k`: a pixel is set when at least half of its k×k block is.
pub fn downscale_mask(m: &Mask, k: u32) -> Mask {
    if k == 1 {
        return m.clone();
    }
    let (w, h) = ((m.width() / k).max(1), (m.height() / k).max(1));
    let mut out = Mask::new(w, h);
    let need = (k * k).div_ceil(2);
    for y in 0..h {
        for x in 0..w {
            let mut n = 0;
            for dy in 0..k {
                for dx in 0..k {
                    let (sx, sy) = (x * k + dx, y * k + dy);
                    if sx < m.width() && sy < m.height() && m.get(sx, sy) {
                        n += 1;
                    }
                }
            }
            if n >= need {
                out.set(x, y, true);
            }
        }
    }
    out
}

/// A frame scaled down by `k` (mean of each k×k block).
pub fn downscale_image(img: &RgbImage, k: u32) -> RgbImage {
    if k == 1 {
        return img.clone();
    }
    let (w, h) = ((img.width() / k).max(1), (img.height() / k).max(1));
    RgbImage::from_fn(w, h, |x, y| {
        let mut sum = [0u32; 3];
        let mut n = 0;
        for dy in 0..k {
            for dx in 0..k {
                let (sx, sy) = (x * k + dx, y * k + dy);
                if sx < img.width() && sy < img.height() {
                    let p = img.get_pixel(sx, sy).0;
                    for c in 0..3 {
                        sum[c] += p[c] as u32;
                    }
                    n += 1;
                }
            }
        }
        image::Rgb(sum.map(|s| (s / n.max(1)) as u8))
    })
}

/// Tracks the clip at `path`, calling `on_frame` after each frame (see
/// [`Tracker::track`]).
pub fn track_clip(
    path: &Path,
    opts: &ClipTrackOptions,
    on_frame: impl FnMut(&TrackedFrame, &Progress) -> ControlFlow<()>,
) -> Result<ClipTrack> {
    Camera::validate(1, 1, opts.fov_deg).map_err(anyhow::Error::msg)?;
    if !(32..=MAX_WORK_HEIGHT).contains(&opts.work_height) {
        anyhow::bail!(
            "working height {} must lie between 32 and {MAX_WORK_HEIGHT} rows",
            opts.work_height
        );
    }
    let info = crate::clip::open::probe(path, &opts.limits)?;
    let fps = if info.fps.is_finite() && info.fps > 0.0 {
        info.fps
    } else {
        30.0
    };
    let camera = Camera::new(info.width, info.height, opts.fov_deg);
    let k = working_scale(info.width, info.height, opts.work_height);
    let work = scaled_camera(&camera, k);
    let mut track_opts = opts.track.clone();
    track_opts.fps = fps;
    let (first, end) = opts.frames.unwrap_or((0, usize::MAX));
    if let Some((a, b)) = opts.frames {
        if info.frame_count > 0 && a as u64 >= info.frame_count {
            anyhow::bail!(
                "frames {a}..{b}: the clip has only {} frames",
                info.frame_count
            );
        }
        if let Some(f) = track_opts.init_frame {
            if !(a..b).contains(&f) {
                anyhow::bail!("initial frame {f} lies outside the tracked frames {a}..{b}");
            }
            track_opts.init_frame = Some(f - a);
        }
        if a > 0 {
            track_opts.keyframes = track_opts
                .keyframes
                .shifted(a)
                .map_err(anyhow::Error::msg)?;
        }
    }
    let tracker = Tracker::new(work, track_opts);
    let total =
        (info.frame_count > 0).then(|| (info.frame_count as usize).min(end).saturating_sub(first));
    // Options that are wrong for this clip fail before anything is decoded.
    tracker.check(total)?;
    let masks = opts.masks || info.is_mask;

    let (tx, rx) = sync_channel::<Result<FrameInput>>(4);
    let past_end = std::sync::atomic::AtomicBool::new(false);
    let past_end = &past_end;
    let mut on_frame = on_frame;
    let result = std::thread::scope(|scope| {
        let producer = scope.spawn(move || {
            let sent = clip_silhouettes(
                path,
                &opts.limits,
                &opts.silhouettes,
                opts.masks,
                |i, frame, mask| {
                    if i < first {
                        return Ok(());
                    }
                    if i >= end {
                        past_end.store(true, std::sync::atomic::Ordering::Relaxed);
                        anyhow::bail!("past the last tracked frame");
                    }
                    let input = FrameInput {
                        silhouette: downscale_mask(mask, k),
                        image: (!masks).then(|| downscale_image(frame, k)),
                    };
                    // The tracker stopped (an error or a cancel): stop decoding.
                    tx.send(Ok(input))
                        .map_err(|_| anyhow::anyhow!("tracking stopped"))
                },
            );
            match sent {
                Ok(done) => done.warning(),
                Err(e) => {
                    if !past_end.load(std::sync::atomic::Ordering::Relaxed) {
                        let _ = tx.send(Err(e));
                    }
                    None
                }
            }
        });
        let tracked = tracker.track(rx.iter(), total, |f, p| {
            if first == 0 {
                return on_frame(f, p);
            }
            let mut f = f.clone();
            f.index += first;
            on_frame(&f, p)
        });
        drop(rx);
        match producer.join() {
            Ok(warning) => (tracked, warning),
            // A bug, not bad input; never a silently shortened motion.
            Err(_) => (
                Err(TrackError::Input(anyhow::anyhow!(
                    "silhouette extraction failed unexpectedly"
                ))),
                None,
            ),
        }
    });
    let (tracked, warning) = result;
    let mut track = tracked.map_err(|e| {
        let e = match e {
            TrackError::Input(e) => e,
            e => anyhow::Error::from(e),
        };
        // Why no person was found, when the silhouettes tell.
        match &warning {
            Some(w) => anyhow::anyhow!("{e:#}; {w}"),
            None => e,
        }
    })?;
    for f in &mut track.frames {
        f.index += first;
    }
    track.init_frame += first;
    Ok(ClipTrack {
        info,
        camera,
        fps,
        track,
        warnings: warning.into_iter().collect(),
    })
}

/// Reads a keyframes file (contracts.md).
pub fn read_keyframes(path: &Path) -> Result<super::keyframes::Keyframes> {
    let meta =
        std::fs::metadata(path).with_context(|| format!("cannot read {}", path.display()))?;
    if meta.len() > super::keyframes::MAX_BYTES as u64 {
        anyhow::bail!(
            "{}: {} bytes, more than the limit of {} for a keyframes file",
            path.display(),
            meta.len(),
            super::keyframes::MAX_BYTES
        );
    }
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    super::keyframes::Keyframes::parse(&text)
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}
