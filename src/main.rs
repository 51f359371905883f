//! The `monocap` command line (contracts.md): one binary, one line on failure.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};
use monocap::motion::bvh::Bvh;
use monocap::synth::{self, Style, SynthOptions};

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
    /// Render a clip of the body model driven by real motion capture, with its ground truth.
    Synth(SynthArgs),
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
            if matches!(
                e.kind(),
                DisplayHelp | DisplayVersion | DisplayHelpOnMissingArgumentOrSubcommand
            ) {
                let _ = e.print();
                return ExitCode::SUCCESS;
            }
            // One line naming the problem (clap adds usage lines after it).
            let text = e.render().to_string();
            let first = text.lines().next().unwrap_or("invalid arguments");
            eprintln!("monocap: {}", first.trim_start_matches("error: "));
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
        Command::Synth(a) => synth_command(a),
    }
}

fn synth_command(a: SynthArgs) -> Result<()> {
    let bvh = Bvh::read(&a.bvh)?;
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
