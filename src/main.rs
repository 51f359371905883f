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
    /// Print what a clip is (JSON: container, codec, width, height, fps, frame_count, duration_s).
    Probe(ProbeArgs),
    /// Extract the person's silhouette from every frame of a clip.
    Silhouettes(SilhouettesArgs),
    /// Render a clip of the body model driven by real motion capture, with its ground truth.
    Synth(SynthArgs),
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

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Probe(a) => probe_command(a),
        Command::Silhouettes(a) => silhouettes_command(a),
        Command::Synth(a) => synth_command(a),
    }
}

fn probe_command(a: ProbeArgs) -> Result<()> {
    let info = monocap::clip::open::probe(&a.clip, &Limits::default())?;
    println!("{}", serde_json::to_string_pretty(&info)?);
    Ok(())
}

fn parse_empty_frames(text: &str) -> Result<EmptyFrames> {
    Ok(match text {
        "auto" => EmptyFrames::Auto,
        "none" => EmptyFrames::None,
        range => {
            let (a, b) = range.split_once("..").with_context(|| {
                format!("--empty-frames {range:?}: expected auto, none or a range A..B")
            })?;
            let parse = |v: &str| {
                v.trim().parse::<usize>().with_context(|| {
                    format!("--empty-frames {range:?}: {v:?} is not a frame number")
                })
            };
            let (a, b) = (parse(a)?, parse(b)?);
            if a >= b {
                anyhow::bail!("--empty-frames {range:?}: the range is empty");
            }
            EmptyFrames::Range(a, b)
        }
    })
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
