//! Tracks the DAVIS person sequences (lucia, dance-twirl, tennis) from their
//! hand-drawn masks and measures how well the body model's silhouette fits them.
//!
//! Each sequence's mask PNGs are packed into a ZIP (as a user would upload them)
//! and tracked with [`monocap::track::run::track_clip`] with `masks = true`. The
//! model's silhouette is then rendered at the clip's full resolution (854×480) and
//! compared with the input mask (IoU). Prints a table per sequence and writes a
//! picture: one row per sequence, four frames spread through the clip, the video
//! frame with the input mask and the model's silhouette tinted over it.
//!
//! ```text
//! cargo run --release --example davis_track [picture.png] [--track-rewards] [--reward-rim N] [--polish-evals N] [--one-way]
//!     [--recover-spike K] [--w-prior W] [--refit-anchor W] [--refit-rounds N] [--bound N]
//! ```
//!
//! `--track-rewards` pays the edge and region rewards while tracking too (the
//! paper's objective, `Weights::track_rewards`), `--reward-rim N` then withholds them
//! near the outline (`Weights::reward_rim`); `--polish-evals N` sets the joint
//! polish's budget (`TrackOptions::polish_evals`, 0 for none); `--one-way` leaves out
//! the second pass (`TrackOptions::two_way`); `--recover-spike K` sets the cost
//! spike that starts a recovery (`TrackOptions::recover_spike`, 0 for none);
//! `--w-prior W` weighs the built-in pose prior in (`Weights::prior`, 20 by
//! default, 0 for none); `--refit-anchor W` sets the refit's pull toward its start
//! (`TrackOptions::refit_anchor`, 0 for none) and `--refit-rounds N` its rounds
//! (`TrackOptions::refit_rounds`).
//!
//! `--bound N` asks how far the body model itself can go: on every frame with a
//! person, CMA-ES searches for the pose (and, in a second search, the pose and the
//! 12 shape values together) with the highest IoU against the mask at full
//! resolution, N evaluations each, from the tracked answer. The IoU it finds is a
//! floor under the best the spheres and cylinders can do on that frame (a search
//! from elsewhere might find more), printed beside the tracker's own.
//!
//! Data: `../shared/data/davis/<seq>/{masks/*.png, frames/*.jpg}` next to the
//! crate; when absent the example says so and exits successfully.

mod common;
use common::list;

use std::fs::File;
use std::io::{BufWriter, Write};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use image::imageops::{resize, FilterType};
use image::{GrayImage, Rgb, RgbImage};
use monocap::body::params::{MOTION, MOTION_COUNT, SHAPE, SHAPE_COUNT};
use monocap::body::raster::render_mask;
use monocap::body::{Body, Camera, Mask, Pose, ShapeValues};
use monocap::track::run::{track_clip, ClipTrack, ClipTrackOptions};
use monocap::track::tracker::{
    check_refit_anchor, check_refit_rounds, TrackOptions, MAX_REFIT_ANCHOR, MAX_REFIT_ROUNDS,
};

const SEQUENCES: [&str; 3] = ["lucia", "dance-twirl", "tennis"];
/// The project's stated target for the mean IoU of a sequence.
const TARGET_IOU: f64 = 0.85;
/// A frame counts as badly fitted below this IoU.
const BAD_IOU: f64 = 0.5;
/// Frames per row of the picture.
const COLUMNS: usize = 4;
/// Width of one cell of the picture (pixels).
const CELL_W: u32 = 320;

/// What one sequence gave.
struct SeqResult {
    name: String,
    frames: usize,
    person_frames: usize,
    /// IoU per frame at full resolution.
    iou: Vec<f64>,
    /// Per frame: share of the model's pixels inside the mask, share of the mask's
    /// pixels the model covers.
    precision: Vec<f64>,
    recall: Vec<f64>,
    /// With `--bound`: per frame with a person, the best IoU found for the pose
    /// alone and for the pose and shape together.
    bound_pose: Vec<f64>,
    bound_all: Vec<f64>,
    /// Seconds of the tracker's features and search.
    timing: (f64, f64),
    /// IoU per frame at the tracker's working resolution (as it reports).
    work_iou: Vec<Option<f64>>,
    track_seconds: f64,
    init_frame: usize,
    work_size: (u32, u32),
    /// The input masks and the model's silhouettes of the frames in the picture.
    cells: Vec<Cell>,
}

struct Cell {
    frame: usize,
    iou: f64,
    image: RgbImage,
}

fn main() -> Result<()> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let shared = root.join("../shared");
    let data = shared.join("data/davis");
    if !shared.is_dir() || !data.is_dir() {
        println!(
            "davis_track: {} not found (the DAVIS sequences are not available here); nothing to do",
            data.display()
        );
        return Ok(());
    }
    let mut picture = root.join("docs/davis_tracking.png");
    let mut reward_rim = 0.0;
    let mut track_rewards = false;
    let mut polish_evals = TrackOptions::default().polish_evals;
    let mut two_way = TrackOptions::default().two_way;
    let mut recover_spike = TrackOptions::default().recover_spike;
    let mut w_prior = TrackOptions::default().weights.prior;
    let mut refit_anchor = TrackOptions::default().refit_anchor;
    let mut refit_rounds = TrackOptions::default().refit_rounds;
    let mut bound = 0usize;
    let mut args = std::env::args_os().skip(1);
    while let Some(a) = args.next() {
        if a == "--track-rewards" {
            track_rewards = true;
        } else if a == "--one-way" {
            two_way = false;
        } else if a == "--reward-rim" {
            let v = args.next().and_then(|v| v.to_str()?.parse::<f64>().ok());
            match v {
                Some(v) if v.is_finite() && v >= 0.0 => reward_rim = v,
                _ => bail!("--reward-rim: expected a number ≥ 0"),
            }
        } else if a == "--polish-evals" {
            match args.next().and_then(|v| v.to_str()?.parse::<usize>().ok()) {
                Some(v) => polish_evals = v,
                None => bail!("--polish-evals: expected a whole number ≥ 0"),
            }
        } else if a == "--recover-spike" {
            let v = args.next().and_then(|v| v.to_str()?.parse::<f64>().ok());
            match v {
                Some(v) if v.is_finite() && v >= 0.0 => recover_spike = v,
                _ => bail!("--recover-spike: expected a number ≥ 0"),
            }
        } else if a == "--bound" {
            match args.next().and_then(|v| v.to_str()?.parse::<usize>().ok()) {
                Some(v) => bound = v,
                None => bail!("--bound: expected a whole number ≥ 0"),
            }
        } else if a == "--w-prior" {
            let v = args.next().and_then(|v| v.to_str()?.parse::<f64>().ok());
            match v {
                Some(v) if v.is_finite() && v >= 0.0 => w_prior = v,
                _ => bail!("--w-prior: expected a number ≥ 0"),
            }
        } else if a == "--refit-anchor" {
            let v = args.next().and_then(|v| v.to_str()?.parse::<f64>().ok());
            match v {
                Some(v) if check_refit_anchor(v, "--refit-anchor").is_ok() => refit_anchor = v,
                _ => bail!("--refit-anchor: expected a number from 0 to {MAX_REFIT_ANCHOR}"),
            }
        } else if a == "--refit-rounds" {
            let v = args.next().and_then(|v| v.to_str()?.parse::<usize>().ok());
            match v {
                Some(v) if check_refit_rounds(v, "--refit-rounds").is_ok() => refit_rounds = v,
                _ => bail!("--refit-rounds: expected a whole number from 1 to {MAX_REFIT_ROUNDS}"),
            }
        } else {
            picture = PathBuf::from(a);
        }
    }
    for readme in ["README", "README.md", "README.txt"] {
        if let Ok(text) = std::fs::read_to_string(data.join(readme)) {
            println!("{}:\n{}\n", readme, text.trim());
        }
    }

    let mut track = TrackOptions::default();
    track.weights.reward_rim = reward_rim;
    track.weights.track_rewards = track_rewards;
    track.polish_evals = polish_evals;
    track.two_way = two_way;
    track.recover_spike = recover_spike;
    track.weights.prior = w_prior;
    track.refit_anchor = refit_anchor;
    track.refit_rounds = refit_rounds;

    let tmp = std::env::temp_dir().join(format!("monocap-davis-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).with_context(|| format!("cannot create {}", tmp.display()))?;
    let started = Instant::now();
    let mut results = Vec::new();
    let mut outcome = Ok(());
    for seq in SEQUENCES {
        let dir = data.join(seq);
        if !dir.is_dir() {
            println!("{seq}: {} not found, skipped", dir.display());
            continue;
        }
        match run_sequence(seq, &dir, &tmp, track.clone(), bound) {
            Ok(r) => results.push(r),
            Err(e) => {
                outcome = Err(e.context(format!("sequence {seq}")));
                break;
            }
        }
    }
    let _ = std::fs::remove_dir_all(&tmp);
    outcome?;
    if results.is_empty() {
        println!("davis_track: no sequence found under {}", data.display());
        return Ok(());
    }

    print_table(&results);
    println!(
        "\nwall time (packing, tracking, full-resolution scoring, picture cells): {:.1} s",
        started.elapsed().as_secs_f64()
    );

    write_picture(&results, &picture)?;
    println!("picture: {}", picture.display());
    Ok(())
}

/// Packs the mask PNGs into `zip_path` as 000000.png, 000001.png, … (stored: the
/// PNGs are compressed already).
fn pack_zip(masks: &[PathBuf], zip_path: &Path) -> Result<()> {
    let file =
        File::create(zip_path).with_context(|| format!("cannot create {}", zip_path.display()))?;
    let mut zip = zip::ZipWriter::new(BufWriter::new(file));
    let options =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    for (i, path) in masks.iter().enumerate() {
        let bytes =
            std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
        zip.start_file(format!("{i:06}.png"), options)?;
        zip.write_all(&bytes)?;
    }
    let mut out = zip.finish()?;
    out.flush()?;
    Ok(())
}

fn read_mask(path: &Path) -> Result<(Mask, [u64; 3])> {
    let gray: GrayImage = image::open(path)
        .with_context(|| format!("cannot read {}", path.display()))?
        .to_luma8();
    // Values seen: 0, 255, anything else.
    let mut hist = [0u64; 3];
    for p in gray.pixels() {
        hist[match p.0[0] {
            0 => 0,
            255 => 1,
            _ => 2,
        }] += 1;
    }
    Ok((Mask::from_gray(&gray, 128), hist))
}

fn run_sequence(
    seq: &str,
    dir: &Path,
    tmp: &Path,
    track: TrackOptions,
    bound: usize,
) -> Result<SeqResult> {
    let masks = list(&dir.join("masks"), "png")?;
    let frames = list(&dir.join("frames"), "jpg")?;
    if masks.is_empty() {
        bail!("no mask PNGs in {}", dir.join("masks").display());
    }
    if frames.len() != masks.len() {
        println!(
            "{seq}: {} masks but {} frames (the picture uses frames by index)",
            masks.len(),
            frames.len()
        );
    }
    let zip_path = tmp.join(format!("{seq}.zip"));
    pack_zip(&masks, &zip_path)?;

    let opts = ClipTrackOptions {
        masks: true,
        track,
        ..ClipTrackOptions::default()
    };
    let t0 = Instant::now();
    let mut done = 0usize;
    let clip: ClipTrack = track_clip(&zip_path, &opts, |_, _| {
        done += 1;
        ControlFlow::Continue(())
    })?;
    let track_seconds = t0.elapsed().as_secs_f64();
    let track = &clip.track;
    if track.frames.len() != masks.len() {
        bail!(
            "{} frames tracked for {} masks",
            track.frames.len(),
            masks.len()
        );
    }
    if (clip.camera.width, clip.camera.height) != (clip.info.width, clip.info.height) {
        bail!("the returned camera is not at the clip's resolution");
    }

    let body = Body::new(&track.shape);
    let cam = &clip.camera;
    let mut model = Mask::new(cam.width, cam.height);
    let mut iou = Vec::with_capacity(masks.len());
    let (mut precision, mut recall) = (Vec::new(), Vec::new());
    let mut bound_frames = Vec::new();
    let mut hist = [0u64; 3];
    let picks = picked_frames(masks.len());
    let mut cells = Vec::new();
    for (i, path) in masks.iter().enumerate() {
        let (input, h) = read_mask(path)?;
        for c in 0..3 {
            hist[c] += h[c];
        }
        if (input.width(), input.height()) != (cam.width, cam.height) {
            bail!("{}: not {}×{}", path.display(), cam.width, cam.height);
        }
        let frame = &track.frames[i];
        render_mask(&body, &body.posed(&frame.pose), cam, &mut model);
        let v = input.iou(&model);
        iou.push(v);
        let inter = input.and_count(&model) as f64;
        precision.push(inter / model.count().max(1) as f64);
        recall.push(inter / input.count().max(1) as f64);
        if bound > 0 && frame.person {
            bound_frames.push((i as u64 + 1, frame.pose, input.clone()));
        }
        if picks.contains(&i) {
            let video = match frames.get(i) {
                Some(p) => image::open(p)
                    .with_context(|| format!("cannot read {}", p.display()))?
                    .to_rgb8(),
                None => RgbImage::from_pixel(cam.width, cam.height, Rgb([40, 40, 40])),
            };
            cells.push(Cell {
                frame: i,
                iou: v,
                image: overlay_cell(&video, &input, &model),
            });
        }
    }
    let (bound_pose, bound_all) = bound_frames_iou(&bound_frames, &track.shape, cam, bound);
    if hist[2] > 0 {
        println!(
            "{seq}: the masks hold {} pixels that are neither 0 nor 255 (thresholded at 128)",
            hist[2]
        );
    }
    Ok(SeqResult {
        name: seq.to_string(),
        frames: masks.len(),
        person_frames: track.frames.iter().filter(|f| f.person).count(),
        iou,
        precision,
        recall,
        bound_pose,
        bound_all,
        timing: (track.timing.features, track.timing.search),
        work_iou: track.frames.iter().map(|f| f.iou).collect(),
        track_seconds,
        init_frame: track.init_frame,
        work_size: (track.camera.width, track.camera.height),
        cells,
    })
}

/// [`best_iou`] for the pose alone and for the pose and shape, on each of `frames`
/// (seed, tracked pose, input mask), spread over the machine's cores.
fn bound_frames_iou(
    frames: &[(u64, Pose, Mask)],
    shape: &ShapeValues,
    cam: &Camera,
    evals: usize,
) -> (Vec<f64>, Vec<f64>) {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let chunk = frames.len().div_ceil(threads).max(1);
    let parts: Vec<Vec<(f64, f64)>> = std::thread::scope(|s| {
        let handles: Vec<_> = frames
            .chunks(chunk)
            .map(|part| {
                s.spawn(move || {
                    part.iter()
                        .map(|(seed, pose, input)| {
                            (
                                best_iou(shape, pose, input, cam, false, evals, *seed),
                                best_iou(shape, pose, input, cam, true, evals, *seed),
                            )
                        })
                        .collect()
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("a bound thread panicked"))
            .collect()
    });
    parts.into_iter().flatten().unzip()
}

/// The highest IoU against `input` that CMA-ES finds from `pose`: over the 30 pose
/// values in units of their length scales (within their limits) and, with
/// `free_shape`, the 12 shape values too in units of twice their fitting steps
/// (within their ranges). Two runs of `evals / 2`: a spread of 1 from the pose,
/// then 0.3 from the best found.
fn best_iou(
    shape: &ShapeValues,
    pose: &Pose,
    input: &Mask,
    cam: &Camera,
    free_shape: bool,
    evals: usize,
    seed: u64,
) -> f64 {
    let n = MOTION_COUNT + if free_shape { SHAPE_COUNT } else { 0 };
    let mut model = Mask::new(cam.width, cam.height);
    let body = Body::new(shape);
    render_mask(&body, &body.posed(pose), cam, &mut model);
    let mut best = (input.iou(&model), vec![0.0; n]);
    for spread in [1.0, 0.3] {
        let start = best.1.clone();
        let cost = |z: &cmaes::DVector<f64>| -> f64 {
            let mut p = *pose;
            for (k, m) in MOTION.iter().enumerate() {
                p[k] = (pose[k] + m.scale * z[k]).clamp(m.lo, m.hi);
            }
            let mut s = *shape;
            if free_shape {
                for (j, a) in SHAPE.iter().enumerate() {
                    s[j] = (shape[j] + 2.0 * a.scale * z[MOTION_COUNT + j]).clamp(a.lo, a.hi);
                }
            }
            let body = Body::new(&s);
            render_mask(&body, &body.posed(&p), cam, &mut model);
            let v = input.iou(&model);
            if v > best.0 {
                best = (v, z.iter().copied().collect());
            }
            1.0 - v
        };
        let run = cmaes::CMAESOptions::new(start, spread)
            .max_function_evals(evals / 2)
            .seed(seed)
            .build(cost);
        if let Ok(mut state) = run {
            state.run();
        }
    }
    best.0
}

/// `COLUMNS` frames evenly spread through a clip of `n` frames (first and last
/// included).
fn picked_frames(n: usize) -> Vec<usize> {
    if n <= COLUMNS {
        return (0..n).collect();
    }
    (0..COLUMNS)
        .map(|c| (c * (n - 1) + (COLUMNS - 1) / 2) / (COLUMNS - 1))
        .collect()
}

fn mean(v: impl IntoIterator<Item = f64>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for x in v {
        s += x;
        n += 1;
    }
    if n == 0 {
        f64::NAN
    } else {
        s / n as f64
    }
}

fn print_table(results: &[SeqResult]) {
    println!();
    println!(
        "{:<12} {:>6} {:>7} {:>9} {:>8} {:>7} {:>9} {:>9} {:>5}  mean IoU ≥ {TARGET_IOU}",
        "sequence",
        "frames",
        "person",
        "mean IoU",
        "min IoU",
        "IoU<0.5",
        "work IoU",
        "track f/s",
        "init",
    );
    for r in results {
        let m = mean(r.iou.iter().copied());
        let min = r.iou.iter().copied().fold(f64::INFINITY, f64::min);
        let bad = r.iou.iter().filter(|&&v| v < BAD_IOU).count();
        let work = mean(r.work_iou.iter().flatten().copied());
        println!(
            "{:<12} {:>6} {:>7} {:>9.3} {:>8.3} {:>7} {:>9.3} {:>9.2} {:>5}  {}",
            r.name,
            r.frames,
            r.person_frames,
            m,
            min,
            bad,
            work,
            r.frames as f64 / r.track_seconds,
            r.init_frame,
            if m >= TARGET_IOU { "yes" } else { "NO" }
        );
    }
    let mean_iou = mean(results.iter().map(|r| mean(r.iou.iter().copied())));
    let frames: usize = results.iter().map(|r| r.frames).sum();
    let seconds: f64 = results.iter().map(|r| r.track_seconds).sum();
    println!(
        "{:<12} {:>6} {:>7} {:>9.3} {:>8} {:>7} {:>9.3} {:>9.2} {:>5}  {}",
        "mean",
        frames,
        "",
        mean_iou,
        "",
        "",
        mean(
            results
                .iter()
                .map(|r| mean(r.work_iou.iter().flatten().copied()))
        ),
        frames as f64 / seconds,
        "",
        if mean_iou >= TARGET_IOU { "yes" } else { "NO" }
    );
    let (w, h) = results[0].work_size;
    println!(
        "\nIoU at the clip's resolution (854×480); \"work IoU\" is the tracker's own, at {w}×{h}. \
         track f/s: frames / wall time of track_clip (decoding the ZIP included). \
         \"mean\" row: mean of the sequences' means."
    );
    println!(
        "\n{:<12} {:>10} {:>8} {:>10} {:>9}",
        "sequence", "precision", "recall", "features s", "search s"
    );
    for r in results {
        println!(
            "{:<12} {:>10.3} {:>8.3} {:>10.2} {:>9.2}",
            r.name,
            mean(r.precision.iter().copied()),
            mean(r.recall.iter().copied()),
            r.timing.0,
            r.timing.1
        );
    }
    if results.iter().any(|r| !r.bound_pose.is_empty()) {
        println!(
            "\n{:<12} {:>9} {:>11} {:>14}",
            "sequence", "tracked", "best pose", "best pose+shape"
        );
        for r in results {
            let tracked = mean(
                r.iou
                    .iter()
                    .zip(&r.work_iou)
                    .filter(|(_, w)| w.is_some())
                    .map(|(v, _)| *v),
            );
            println!(
                "{:<12} {:>9.3} {:>11.3} {:>14.3}",
                r.name,
                tracked,
                mean(r.bound_pose.iter().copied()),
                mean(r.bound_all.iter().copied())
            );
        }
        println!(
            "best: the highest full-resolution IoU CMA-ES found from each tracked answer \
             (--bound evaluations each), means over the frames with a person."
        );
    }
    println!(
        "precision: share of the model's silhouette inside the mask; recall: share of the \
         mask the model covers (means over frames, full resolution)."
    );
    println!("\nper-frame IoU (full resolution):");
    for r in results {
        let line: Vec<String> = r.iou.iter().map(|v| format!("{v:.2}")).collect();
        println!("{}: {}", r.name, line.join(" "));
    }
}

// ---------------------------------------------------------------------------
// The picture.

const INPUT_ONLY: [f32; 3] = [40.0, 110.0, 255.0];
const MODEL_ONLY: [f32; 3] = [255.0, 50.0, 40.0];
const BOTH: [f32; 3] = [40.0, 230.0, 80.0];
const OUTLINE: [u8; 3] = [255, 255, 255];
const TINT: f32 = 0.55;

/// The video frame downscaled to [`CELL_W`] wide, the masks tinted over it by their
/// coverage of each cell pixel (blue: input only, red: model only, green: both), and
/// the model's outline in white.
fn overlay_cell(video: &RgbImage, input: &Mask, model: &Mask) -> RgbImage {
    let (w, h) = (video.width(), video.height());
    let cw = CELL_W;
    let ch = ((h as u64 * cw as u64 + w as u64 / 2) / w as u64) as u32;
    let small = resize(video, cw, ch, FilterType::Triangle);
    // Coverage fractions: [input only, model only, both] per cell pixel.
    let mut cover = vec![[0f32; 3]; (cw * ch) as usize];
    let mut model_small = vec![false; (cw * ch) as usize];
    for cy in 0..ch {
        let y0 = cy * h / ch;
        let y1 = ((cy + 1) * h / ch).max(y0 + 1).min(h);
        for cx in 0..cw {
            let x0 = cx * w / cw;
            let x1 = ((cx + 1) * w / cw).max(x0 + 1).min(w);
            let mut c = [0u32; 3];
            let mut m = 0u32;
            for y in y0..y1 {
                for x in x0..x1 {
                    let (a, b) = (input.get(x, y), model.get(x, y));
                    match (a, b) {
                        (true, false) => c[0] += 1,
                        (false, true) => c[1] += 1,
                        (true, true) => c[2] += 1,
                        _ => {}
                    }
                    m += b as u32;
                }
            }
            let n = ((y1 - y0) * (x1 - x0)) as f32;
            let i = (cy * cw + cx) as usize;
            cover[i] = c.map(|v| v as f32 / n);
            model_small[i] = m as f32 >= n / 2.0;
        }
    }
    let mut out = small.clone();
    for (x, y, p) in out.enumerate_pixels_mut() {
        let i = (y * cw + x) as usize;
        let c = cover[i];
        let mut px = p.0.map(|v| v as f32 * 0.8);
        for (k, colour) in [INPUT_ONLY, MODEL_ONLY, BOTH].iter().enumerate() {
            let a = TINT * c[k];
            for ch in 0..3 {
                px[ch] = px[ch] * (1.0 - a) + colour[ch] * a;
            }
        }
        p.0 = px.map(|v| v.round().clamp(0.0, 255.0) as u8);
    }
    // The model's outline: set pixels with an unset 4-neighbour.
    let at = |x: i64, y: i64| -> bool {
        x >= 0
            && y >= 0
            && x < cw as i64
            && y < ch as i64
            && model_small[(y as u32 * cw + x as u32) as usize]
    };
    for y in 0..ch as i64 {
        for x in 0..cw as i64 {
            if at(x, y) && !(at(x - 1, y) && at(x + 1, y) && at(x, y - 1) && at(x, y + 1)) {
                out.put_pixel(x as u32, y as u32, Rgb(OUTLINE));
            }
        }
    }
    out
}

fn write_picture(results: &[SeqResult], path: &Path) -> Result<()> {
    let gap = 4u32;
    let ch = results
        .iter()
        .flat_map(|r| r.cells.iter().map(|c| c.image.height()))
        .max()
        .unwrap_or(180);
    let legend_h = 24u32;
    let width = COLUMNS as u32 * CELL_W + (COLUMNS as u32 + 1) * gap;
    let height = results.len() as u32 * (ch + gap) + gap + legend_h;
    let mut img = RgbImage::from_pixel(width, height, Rgb([24, 24, 24]));
    for (row, r) in results.iter().enumerate() {
        let y0 = gap + row as u32 * (ch + gap);
        for (col, cell) in r.cells.iter().enumerate() {
            let x0 = gap + col as u32 * (CELL_W + gap);
            image::imageops::replace(&mut img, &cell.image, x0 as i64, y0 as i64);
            let label = format!("{} #{} IoU {:.2}", r.name, cell.frame, cell.iou);
            let colour = if cell.iou >= TARGET_IOU {
                [255, 255, 255]
            } else if cell.iou >= BAD_IOU {
                [255, 220, 120]
            } else {
                [255, 120, 120]
            };
            label_box(&mut img, x0 + 3, y0 + 3, &label, 2, colour);
        }
    }
    // Legend.
    let ly = height - legend_h + 5;
    let mut x = gap + 4;
    let entries: [([f32; 3], &str); 4] = [
        (INPUT_ONLY, "input mask only"),
        (MODEL_ONLY, "model only"),
        (BOTH, "both"),
        (OUTLINE.map(|v| v as f32), "model outline"),
    ];
    for (colour, text) in entries {
        fill_rect(&mut img, x, ly, 14, 14, colour.map(|v| v as u8));
        x += 20;
        draw_text(&mut img, x, ly, text, 2, [220, 220, 220]);
        x += text_width(text, 2) + 22;
    }
    if let Some(dir) = path.parent() {
        if !dir.as_os_str().is_empty() {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
        }
    }
    img.save(path)
        .with_context(|| format!("cannot write {}", path.display()))?;
    let bytes = std::fs::metadata(path)?.len();
    println!(
        "picture {}×{}, {:.0} kB: rows {}, columns = frames spread through each clip",
        width,
        height,
        bytes as f64 / 1024.0,
        results
            .iter()
            .map(|r| r.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}

fn fill_rect(img: &mut RgbImage, x0: u32, y0: u32, w: u32, h: u32, c: [u8; 3]) {
    for y in y0..(y0 + h).min(img.height()) {
        for x in x0..(x0 + w).min(img.width()) {
            img.put_pixel(x, y, Rgb(c));
        }
    }
}

/// Text on a translucent dark box.
fn label_box(img: &mut RgbImage, x: u32, y: u32, text: &str, scale: u32, c: [u8; 3]) {
    let (w, h) = (text_width(text, scale) + 6, 7 * scale + 6);
    for yy in y..(y + h).min(img.height()) {
        for xx in x..(x + w).min(img.width()) {
            let p = img.get_pixel_mut(xx, yy);
            p.0 = p.0.map(|v| (v as u32 * 2 / 7) as u8);
        }
    }
    draw_text(img, x + 3, y + 3, text, scale, c);
}

// A 5×7 bitmap font of the characters the labels use (rows top to bottom, bit 4
// = leftmost column).
fn glyph(ch: char) -> [u8; 7] {
    match ch {
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        'a' => [0x00, 0x00, 0x0E, 0x01, 0x0F, 0x11, 0x0F],
        'b' => [0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x1E],
        'c' => [0x00, 0x00, 0x0E, 0x10, 0x10, 0x11, 0x0E],
        'd' => [0x01, 0x01, 0x0D, 0x13, 0x11, 0x11, 0x0F],
        'e' => [0x00, 0x00, 0x0E, 0x11, 0x1F, 0x10, 0x0E],
        'f' => [0x06, 0x09, 0x08, 0x1C, 0x08, 0x08, 0x08],
        'g' => [0x00, 0x0F, 0x11, 0x11, 0x0F, 0x01, 0x0E],
        'h' => [0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x11],
        'i' => [0x04, 0x00, 0x0C, 0x04, 0x04, 0x04, 0x0E],
        'j' => [0x02, 0x00, 0x06, 0x02, 0x02, 0x12, 0x0C],
        'k' => [0x10, 0x10, 0x12, 0x14, 0x18, 0x14, 0x12],
        'l' => [0x0C, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'm' => [0x00, 0x00, 0x1A, 0x15, 0x15, 0x11, 0x11],
        'n' => [0x00, 0x00, 0x16, 0x19, 0x11, 0x11, 0x11],
        'o' => [0x00, 0x00, 0x0E, 0x11, 0x11, 0x11, 0x0E],
        'p' => [0x00, 0x00, 0x1E, 0x11, 0x1E, 0x10, 0x10],
        'q' => [0x00, 0x00, 0x0D, 0x13, 0x0F, 0x01, 0x01],
        'r' => [0x00, 0x00, 0x16, 0x19, 0x10, 0x10, 0x10],
        's' => [0x00, 0x00, 0x0E, 0x10, 0x0E, 0x01, 0x1E],
        't' => [0x08, 0x08, 0x1C, 0x08, 0x08, 0x09, 0x06],
        'u' => [0x00, 0x00, 0x11, 0x11, 0x11, 0x13, 0x0D],
        'v' => [0x00, 0x00, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'w' => [0x00, 0x00, 0x11, 0x11, 0x15, 0x15, 0x0A],
        'x' => [0x00, 0x00, 0x11, 0x0A, 0x04, 0x0A, 0x11],
        'y' => [0x00, 0x00, 0x11, 0x11, 0x0F, 0x01, 0x0E],
        'z' => [0x00, 0x00, 0x1F, 0x02, 0x04, 0x08, 0x1F],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C],
        '-' => [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00],
        ':' => [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00],
        '#' => [0x0A, 0x0A, 0x1F, 0x0A, 0x1F, 0x0A, 0x0A],
        '=' => [0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00],
        '/' => [0x01, 0x01, 0x02, 0x04, 0x08, 0x10, 0x10],
        c if c.is_ascii_uppercase() => glyph(c.to_ascii_lowercase()),
        _ => [0; 7],
    }
}

fn text_width(text: &str, scale: u32) -> u32 {
    (text.chars().count() as u32 * 6).saturating_sub(1) * scale
}

fn draw_text(img: &mut RgbImage, x0: u32, y0: u32, text: &str, scale: u32, c: [u8; 3]) {
    for (i, ch) in text.chars().enumerate() {
        let g = glyph(ch);
        let gx = x0 + i as u32 * 6 * scale;
        for (row, bits) in g.iter().enumerate() {
            for col in 0..5u32 {
                if bits & (0x10 >> col) != 0 {
                    fill_rect(
                        img,
                        gx + col * scale,
                        y0 + row as u32 * scale,
                        scale,
                        scale,
                        c,
                    );
                }
            }
        }
    }
}
