//! Decoding through an external `ffmpeg` binary, for what the built-in
//! decoders do not cover (HEVC, VP9, ProRes, …).
//!
//! The binaries are looked up on `PATH` directly (no shell). Probing uses
//! `ffprobe` when it is there, else parses the stream summary `ffmpeg -i`
//! prints on stderr. Frames come from
//! `ffmpeg -nostdin -v error -i FILE -map 0:v:0 -noautorotate -f rawvideo -pix_fmt rgb24 -`
//! through a pipe (no temporary files). The child is killed and reaped when
//! the source is dropped; its stderr is drained on a thread (the last 16 KiB
//! are kept for error messages) so that it can never block on a full pipe.
//!
//! Memory: one RGB frame, plus the 16 KiB stderr tail.

use std::ffi::OsStr;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use image::RgbImage;

use super::decode::{ClipInfo, DecodeError, FrameSource, Limits};

/// Most stderr bytes kept for error messages.
const STDERR_TAIL: usize = 16 << 10;

/// Finds an executable named `name` in the directories of `PATH`.
pub fn find_program(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    for dir in std::env::split_paths(&path) {
        if dir.as_os_str().is_empty() {
            continue;
        }
        for candidate in [dir.join(name), dir.join(format!("{name}.exe"))] {
            if is_executable(&candidate) {
                return Some(candidate);
            }
        }
    }
    None
}

#[cfg(unix)]
fn is_executable(p: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    std::fs::metadata(p).is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
}

#[cfg(not(unix))]
fn is_executable(p: &Path) -> bool {
    p.is_file()
}

/// Whether an `ffmpeg` binary is on `PATH`.
pub fn available() -> bool {
    find_program("ffmpeg").is_some()
}

fn not_available(path: &Path) -> DecodeError {
    DecodeError::Other {
        path: path.to_path_buf(),
        what: "ffmpeg is not installed (not found on PATH)".into(),
    }
}

/// The first stream facts parsed from ffmpeg's or ffprobe's output.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StreamSummary {
    pub container: String,
    pub codec: String,
    pub width: u32,
    pub height: u32,
    pub fps: f64,
    pub duration_s: f64,
    /// From ffprobe's `nb_frames` when known.
    pub frames: Option<u64>,
}

/// Parses the `ffmpeg -i FILE` stderr summary, e.g.
///
/// ```text
/// Input #0, mov,mp4,m4a,3gp,3g2,mj2, from 'clip.mp4':
///   Duration: 00:00:02.33, start: 0.000000, bitrate: 475 kb/s
///   Stream #0:0[0x1](und): Video: hevc (Main) (hev1 / 0x31766568), yuv420p(tv, progressive), 428x240, 30 fps, 30 tbr, 15360 tbn (default)
/// ```
///
/// Returns `None` when no video stream is listed.
pub fn parse_ffmpeg_stderr(text: &str) -> Option<StreamSummary> {
    let mut s = StreamSummary::default();
    let mut have_video = false;
    for line in text.lines() {
        let line = line.trim();
        if let Some(rest) = line.strip_prefix("Input #0, ") {
            if s.container.is_empty() {
                s.container = rest.split(',').next().unwrap_or("").trim().to_string();
            }
        } else if let Some(rest) = line.strip_prefix("Duration: ") {
            let stamp = rest.split(',').next().unwrap_or("").trim();
            s.duration_s = parse_timestamp(stamp).unwrap_or(0.0);
        } else if line.starts_with("Stream #") && !have_video {
            let Some((_, video)) = line.split_once(": Video: ") else {
                continue;
            };
            have_video = true;
            s.codec = video.split([' ', ',']).next().unwrap_or("").to_string();
            for part in split_top_level(video) {
                let part = part.trim();
                let first = part.split(' ').next().unwrap_or("");
                if s.width == 0 {
                    if let Some((w, h)) = first.split_once('x') {
                        if let (Ok(w), Ok(h)) = (w.parse(), h.parse()) {
                            s.width = w;
                            s.height = h;
                            continue;
                        }
                    }
                }
                if let Some(v) = part.strip_suffix(" fps") {
                    s.fps = parse_rate(v).unwrap_or(s.fps);
                } else if let Some(v) = part.strip_suffix(" tbr") {
                    if s.fps == 0.0 {
                        s.fps = parse_rate(v).unwrap_or(0.0);
                    }
                }
            }
        }
    }
    have_video.then_some(s)
}

/// Splits on commas outside parentheses and brackets.
fn split_top_level(text: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let (mut depth, mut start) = (0i32, 0);
    for (i, c) in text.char_indices() {
        match c {
            '(' | '[' => depth += 1,
            ')' | ']' => depth -= 1,
            ',' if depth == 0 => {
                out.push(&text[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    out.push(&text[start..]);
    out
}

/// `29.97`, `30`, `1k` (1000), `30000/1001`.
fn parse_rate(v: &str) -> Option<f64> {
    let v = v.trim();
    if let Some((n, d)) = v.split_once('/') {
        let (n, d): (f64, f64) = (n.parse().ok()?, d.parse().ok()?);
        return (d > 0.0 && n >= 0.0).then(|| n / d);
    }
    if let Some(k) = v.strip_suffix('k') {
        return k.parse::<f64>().ok().map(|x| x * 1000.0);
    }
    v.parse().ok().filter(|x: &f64| x.is_finite() && *x >= 0.0)
}

/// `HH:MM:SS.ss`.
fn parse_timestamp(v: &str) -> Option<f64> {
    let mut parts = v.split(':');
    let h: f64 = parts.next()?.parse().ok()?;
    let m: f64 = parts.next()?.parse().ok()?;
    let s: f64 = parts.next()?.parse().ok()?;
    Some(h * 3600.0 + m * 60.0 + s)
}

/// Parses `ffprobe -of default=noprint_wrappers=1` output (`key=value` lines).
pub fn parse_ffprobe(text: &str) -> Option<StreamSummary> {
    let mut s = StreamSummary::default();
    let mut stream_duration = None;
    for line in text.lines() {
        let Some((key, value)) = line.trim().split_once('=') else {
            continue;
        };
        match key {
            "codec_name" if s.codec.is_empty() => s.codec = value.to_string(),
            "width" if s.width == 0 => s.width = value.parse().unwrap_or(0),
            "height" if s.height == 0 => s.height = value.parse().unwrap_or(0),
            "avg_frame_rate" => {
                if let Some(r) = parse_rate(value).filter(|r| *r > 0.0) {
                    s.fps = r;
                }
            }
            "r_frame_rate" if s.fps == 0.0 => s.fps = parse_rate(value).unwrap_or(0.0),
            "nb_frames" => s.frames = value.parse().ok(),
            "duration" => {
                if let Ok(d) = value.parse::<f64>() {
                    if stream_duration.is_none() {
                        stream_duration = Some(d);
                    }
                }
            }
            "format_name" => s.container = value.split(',').next().unwrap_or("").to_string(),
            _ => {}
        }
    }
    s.duration_s = stream_duration.unwrap_or(0.0);
    (!s.codec.is_empty() && s.width > 0).then_some(s)
}

fn run_capture(program: &Path, args: &[&OsStr]) -> std::io::Result<(String, String)> {
    let out = Command::new(program)
        .args(args)
        .stdin(Stdio::null())
        .output()?;
    Ok((
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    ))
}

fn tail(text: &str) -> String {
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    lines[lines.len().saturating_sub(3)..].join(" / ")
}

/// Probes through `ffprobe` (if on `PATH`) or `ffmpeg -i`.
pub fn probe(path: &Path, limits: &Limits) -> Result<ClipInfo, DecodeError> {
    let ffmpeg = find_program("ffmpeg").ok_or_else(|| not_available(path))?;
    let summary = if let Some(ffprobe) = find_program("ffprobe") {
        let args: [&OsStr; 9] = [
            "-v".as_ref(),
            "error".as_ref(),
            "-select_streams".as_ref(),
            "v:0".as_ref(),
            "-show_entries".as_ref(),
            "stream=codec_name,width,height,avg_frame_rate,r_frame_rate,nb_frames,duration:format=format_name,duration".as_ref(),
            "-of".as_ref(),
            "default=noprint_wrappers=1".as_ref(),
            path.as_os_str(),
        ];
        let (out, err) = run_capture(&ffprobe, &args).map_err(|e| DecodeError::io(path, e))?;
        parse_ffprobe(&out).ok_or_else(|| DecodeError::UnknownFormat {
            path: path.to_path_buf(),
            what: format!("ffprobe finds no video stream ({})", tail(&err)),
        })?
    } else {
        let args: [&OsStr; 4] = [
            "-hide_banner".as_ref(),
            "-nostdin".as_ref(),
            "-i".as_ref(),
            path.as_os_str(),
        ];
        let (_, err) = run_capture(&ffmpeg, &args).map_err(|e| DecodeError::io(path, e))?;
        parse_ffmpeg_stderr(&err).ok_or_else(|| DecodeError::UnknownFormat {
            path: path.to_path_buf(),
            what: format!("ffmpeg finds no video stream ({})", tail(&err)),
        })?
    };
    limits.check_size(path, summary.width, summary.height)?;
    let frame_count = summary
        .frames
        .unwrap_or_else(|| (summary.duration_s * summary.fps).round().max(0.0) as u64);
    let duration_s = if summary.duration_s > 0.0 {
        summary.duration_s
    } else if summary.fps > 0.0 {
        frame_count as f64 / summary.fps
    } else {
        0.0
    };
    Ok(ClipInfo {
        container: summary.container,
        codec: summary.codec,
        width: summary.width,
        height: summary.height,
        fps: summary.fps,
        frame_count,
        duration_s,
        is_mask: false,
    })
}

/// Opens any clip ffmpeg can read, streaming RGB frames from its stdout.
pub fn open(path: &Path, limits: &Limits) -> Result<Box<dyn FrameSource>, DecodeError> {
    let info = probe(path, limits)?;
    let ffmpeg = find_program("ffmpeg").ok_or_else(|| not_available(path))?;
    let mut command = Command::new(&ffmpeg);
    command
        .args(["-nostdin", "-v", "error", "-noautorotate", "-i"])
        .arg(path)
        .args(["-map", "0:v:0", "-f", "rawvideo", "-pix_fmt", "rgb24", "-"]);
    Ok(Box::new(spawn_source(command, path, info, limits)?))
}

/// Runs `command`, reading `info`-sized RGB frames from its stdout.
fn spawn_source(
    mut command: Command,
    path: &Path,
    info: ClipInfo,
    limits: &Limits,
) -> Result<FfmpegSource, DecodeError> {
    let mut child = command
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| DecodeError::io(path, e))?;
    let stdout = child.stdout.take().expect("stdout is piped");
    let mut stderr = child.stderr.take().expect("stderr is piped");
    let log = Arc::new(Mutex::new(Vec::new()));
    let log_writer = Arc::clone(&log);
    let drain = std::thread::Builder::new()
        .name("monocap-ffmpeg-stderr".into())
        .spawn(move || {
            let mut buf = [0u8; 4096];
            while let Ok(n) = stderr.read(&mut buf) {
                if n == 0 {
                    break;
                }
                let mut log = log_writer.lock().unwrap_or_else(|p| p.into_inner());
                log.extend_from_slice(&buf[..n]);
                if log.len() > STDERR_TAIL {
                    let cut = log.len() - STDERR_TAIL;
                    log.drain(..cut);
                }
            }
        });
    let drain = match drain {
        Ok(h) => h,
        Err(e) => {
            let _ = child.kill();
            let _ = child.wait();
            return Err(DecodeError::io(path, e));
        }
    };
    Ok(FfmpegSource {
        path: path.to_path_buf(),
        frame_bytes: info.width as usize * info.height as usize * 3,
        info,
        child: Some(child),
        stdout: Some(stdout),
        log,
        drain: Some(drain),
        index: 0,
        max_frames: limits.max_frames,
    })
}

/// Frames from an ffmpeg child process (see the module notes).
pub struct FfmpegSource {
    path: PathBuf,
    info: ClipInfo,
    frame_bytes: usize,
    child: Option<Child>,
    stdout: Option<ChildStdout>,
    log: Arc<Mutex<Vec<u8>>>,
    drain: Option<JoinHandle<()>>,
    index: u64,
    max_frames: u64,
}

impl FfmpegSource {
    /// Waits for the child after its stdout ended; an error status becomes an error.
    fn finish(&mut self, partial: usize) -> Result<Option<RgbImage>, DecodeError> {
        self.stdout = None;
        let status = match self.child.take() {
            Some(mut c) => c.wait().map_err(|e| DecodeError::io(&self.path, e))?,
            None => return Ok(None),
        };
        if let Some(d) = self.drain.take() {
            let _ = d.join();
        }
        let log = String::from_utf8_lossy(&self.log.lock().unwrap_or_else(|p| p.into_inner()))
            .into_owned();
        if !status.success() {
            return Err(DecodeError::Corrupt {
                path: self.path.clone(),
                what: format!("ffmpeg failed ({status}): {}", tail(&log)),
            });
        }
        if partial > 0 {
            return Err(DecodeError::Truncated {
                path: self.path.clone(),
                what: format!("ffmpeg's output ends inside frame {}", self.index),
            });
        }
        Ok(None)
    }

    fn kill(&mut self) {
        self.stdout = None;
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
        if let Some(d) = self.drain.take() {
            let _ = d.join();
        }
    }
}

impl FrameSource for FfmpegSource {
    fn info(&self) -> &ClipInfo {
        &self.info
    }

    fn next_frame(&mut self) -> Result<Option<RgbImage>, DecodeError> {
        let Some(stdout) = self.stdout.as_mut() else {
            return Ok(None);
        };
        let mut buf = vec![0u8; self.frame_bytes];
        let mut filled = 0;
        while filled < buf.len() {
            match stdout.read(&mut buf[filled..]) {
                Ok(0) => return self.finish(filled),
                Ok(n) => filled += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    self.kill();
                    return Err(DecodeError::io(&self.path, e));
                }
            }
        }
        if self.index >= self.max_frames {
            self.kill();
            return Err(DecodeError::TooLarge {
                path: self.path.clone(),
                what: format!("more than {} frames", self.max_frames),
            });
        }
        self.index += 1;
        Ok(RgbImage::from_raw(self.info.width, self.info.height, buf))
    }
}

impl Drop for FfmpegSource {
    fn drop(&mut self) {
        self.kill();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SAMPLE: &str = "\
Input #0, mov,mp4,m4a,3gp,3g2,mj2, from 'lucia_hevc.mp4':
  Metadata:
    major_brand     : isom
    encoder         : Lavf59.27.100
  Duration: 00:00:02.33, start: 0.000000, bitrate: 473 kb/s
  Stream #0:0[0x1](und): Audio: aac (LC) (mp4a / 0x6134706D), 44100 Hz, stereo, fltp, 2 kb/s (default)
  Stream #0:1[0x2](und): Video: hevc (Main) (hev1 / 0x31766568), yuv420p(tv, progressive), 428x240 [SAR 1:1 DAR 107:60], 470 kb/s, 29.97 fps, 29.97 tbr, 30k tbn (default)
    Metadata:
      handler_name    : VideoHandler
At least one output file must be specified
";

    fn info(w: u32, h: u32) -> ClipInfo {
        ClipInfo {
            container: "test".into(),
            codec: "rawvideo".into(),
            width: w,
            height: h,
            fps: 1.0,
            frame_count: 0,
            duration_s: 0.0,
            is_mask: false,
        }
    }

    #[cfg(unix)]
    fn shell(script: &str) -> Command {
        let mut c = Command::new("/bin/sh");
        c.args(["-c", script]);
        c
    }

    /// A stand-in for ffmpeg: frames on stdout, a message on stderr.
    #[cfg(unix)]
    #[test]
    fn child_frames_errors_and_kill() {
        let p = Path::new("clip.mkv");
        let limits = Limits::default();
        // Two 2×2 frames, then a failure with a message.
        let cmd = shell("head -c 24 /dev/zero; echo 'Invalid data found' >&2; exit 1");
        let mut s = spawn_source(cmd, p, info(2, 2), &limits).unwrap();
        assert_eq!(s.next_frame().unwrap().unwrap().dimensions(), (2, 2));
        assert!(s.next_frame().unwrap().is_some());
        let e = s.next_frame().unwrap_err();
        assert!(e.to_string().contains("Invalid data found"), "{e}");
        assert!(s.next_frame().unwrap().is_none());
        // A frame cut short by a clean exit.
        let cmd = shell("head -c 15 /dev/zero");
        let mut s = spawn_source(cmd, p, info(2, 2), &limits).unwrap();
        assert!(s.next_frame().unwrap().is_some());
        assert!(matches!(s.next_frame(), Err(DecodeError::Truncated { .. })));
        // An endless child is killed and reaped on drop, promptly.
        let cmd = shell("exec cat /dev/zero");
        let mut s = spawn_source(cmd, p, info(64, 64), &limits).unwrap();
        assert!(s.next_frame().unwrap().is_some());
        let start = std::time::Instant::now();
        drop(s);
        assert!(start.elapsed().as_secs_f64() < 2.0);
        // The frame limit holds.
        let small = Limits {
            max_frames: 2,
            ..Limits::default()
        };
        let cmd = shell("exec cat /dev/zero");
        let mut s = spawn_source(cmd, p, info(4, 4), &small).unwrap();
        assert!(s.next_frame().unwrap().is_some());
        assert!(s.next_frame().unwrap().is_some());
        assert!(matches!(s.next_frame(), Err(DecodeError::TooLarge { .. })));
    }

    #[test]
    fn parses_ffmpeg_stderr() {
        let s = parse_ffmpeg_stderr(SAMPLE).unwrap();
        assert_eq!(s.container, "mov");
        assert_eq!(s.codec, "hevc");
        assert_eq!((s.width, s.height), (428, 240));
        assert!((s.fps - 29.97).abs() < 1e-9);
        assert!((s.duration_s - 2.33).abs() < 1e-9);
        assert_eq!(parse_ffmpeg_stderr("no such file"), None);
    }

    #[test]
    fn parses_tbr_only_and_rates() {
        let text = "Input #0, gif, from 'a.gif':\n  Duration: N/A, bitrate: N/A\n  Stream #0:0: Video: gif, bgra, 214x120, 15 tbr, 100 tbn\n";
        let s = parse_ffmpeg_stderr(text).unwrap();
        assert_eq!((s.container.as_str(), s.codec.as_str()), ("gif", "gif"));
        assert_eq!(s.fps, 15.0);
        assert_eq!(s.duration_s, 0.0);
        assert_eq!(
            parse_rate("30000/1001").map(|r| (r * 1000.0).round()),
            Some(29970.0)
        );
        assert_eq!(parse_rate("0/0"), None);
    }

    #[test]
    fn parses_ffprobe() {
        let text = "codec_name=hevc\nwidth=428\nheight=240\nr_frame_rate=30/1\navg_frame_rate=30/1\nduration=2.333333\nnb_frames=70\nformat_name=mov,mp4,m4a,3gp,3g2,mj2\nduration=2.345\n";
        let s = parse_ffprobe(text).unwrap();
        assert_eq!(s.codec, "hevc");
        assert_eq!(s.container, "mov");
        assert_eq!(s.frames, Some(70));
        assert_eq!(s.fps, 30.0);
        assert!((s.duration_s - 2.333333).abs() < 1e-9);
    }
}
