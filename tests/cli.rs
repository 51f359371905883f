//! The `monocap` binary's contract (contracts.md): exit status 0 and the promised files
//! on success; on failure a non-zero status and ONE line on stderr naming the problem.

mod common;

use common::{monocap, s, TempDir};
use std::path::{Path, PathBuf};
use std::process::Output;

const FIXTURE: &str = "tests/fixtures/bandai_run_normal_001_20f.bvh";

/// `synth` on the fixture into `out`, with `extra` arguments.
fn synth(out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["synth", "--bvh", FIXTURE, "--out", s(out)];
    args.extend_from_slice(extra);
    monocap(&args)
}

fn assert_success(what: &str, out: &Output) {
    assert!(
        out.status.success(),
        "{what}: exit status {:?}, stderr {:?}",
        out.status.code(),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Non-zero exit, exactly one non-empty line on stderr containing `needle`, no panic.
fn assert_fails_with(what: &str, out: &Output, needle: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    println!("{what}: {:?} {}", out.status.code(), stderr.trim_end());
    assert!(
        !out.status.success(),
        "{what}: succeeded, stderr {stderr:?}"
    );
    assert!(!stderr.contains("panicked"), "{what}: panicked: {stderr}");
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(
        lines.len(),
        1,
        "{what}: expected one line on stderr, got {stderr:?}"
    );
    assert!(
        lines[0].trim().len() > "monocap:".len(),
        "{what}: empty message {stderr:?}"
    );
    assert!(
        lines[0].contains(needle),
        "{what}: {stderr:?} does not mention {needle:?}"
    );
}

fn read_json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{} is not JSON: {e}", path.display()))
}

#[test]
fn synth_writes_the_clip_and_its_truth() {
    let tmp = TempDir::new("ok");
    let clip = tmp.path("x.y4m");
    let truth = tmp.path("t.json");
    let out = synth(
        &clip,
        &[
            "--truth",
            s(&truth),
            "--empty-frames",
            "2",
            "--style",
            "color",
        ],
    );
    assert_success("y4m", &out);
    let size = std::fs::metadata(&clip).unwrap().len();
    // 22 frames of 320×240 4:2:0 (115,200 bytes each) plus headers.
    assert!(size > 22 * 115_200, "{} is {size} bytes", clip.display());
    let header = std::fs::read(&clip).unwrap();
    assert!(header.starts_with(b"YUV4MPEG2 "), "not a Y4M file");
    let json = read_json(&truth);
    assert_eq!(json["format"], "monocap.truth/1");
    assert_eq!(json["frame_count"], 22);
    assert_eq!(json["empty_frames"], 2);
    assert_eq!(json["image"]["width"], 320);
    assert_eq!(json["image"]["height"], 240);
    assert_eq!(json["source"]["file"], "bandai_run_normal_001_20f.bvh");
    let frames = json["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 20);
    assert_eq!(frames[0]["index"], 2);
    let joints = json["source_joints"].as_array().unwrap().len();
    assert!(joints > 18);
    assert_eq!(frames[0]["joints3d"].as_array().unwrap().len(), joints);
    assert_eq!(frames[0]["joints2d"].as_array().unwrap().len(), joints);
    // No temporary file is left next to the outputs.
    assert_eq!(tmp.files(), ["t.json", "x.y4m"]);
}

#[test]
fn synth_writes_gif_and_zip_and_takes_negative_azimuths() {
    let tmp = TempDir::new("formats");
    let gif = tmp.path("x.gif");
    let out = synth(
        &gif,
        &["--duration-s", "0.2", "--width", "80", "--height", "60"],
    );
    assert_success("gif", &out);
    assert!(std::fs::read(&gif).unwrap().starts_with(b"GIF8"));

    let zip = tmp.path("x.zip");
    let truth = tmp.path("t.json");
    let out = synth(
        &zip,
        &[
            "--azimuth-deg",
            "-90",
            "--style",
            "silhouette",
            "--truth",
            s(&truth),
            "--empty-frames",
            "1",
        ],
    );
    assert_success("zip with --azimuth-deg -90", &out);
    assert!(std::fs::read(&zip).unwrap().starts_with(b"PK"));
    let json = read_json(&truth);
    assert_eq!(json["camera"]["azimuth_deg"], -90.0);
    assert_eq!(json["frame_count"], 21);

    let out = synth(&tmp.path("y.zip"), &["--azimuth-deg=-90.5", "--seed", "7"]);
    assert_success("--azimuth-deg=-90.5", &out);
}

#[test]
fn help_exits_zero() {
    for args in [&["--help"][..], &["synth", "--help"]] {
        let out = monocap(args);
        assert_success(&format!("{args:?}"), &out);
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.contains("Usage"), "{args:?}: {text}");
    }
}

#[test]
fn bad_input_fails_with_one_line_naming_the_problem() {
    let tmp = TempDir::new("bad");
    let fixture = std::fs::read_to_string(FIXTURE).unwrap();
    let out = tmp.path("x.zip");

    // Input files that are not usable captures.
    let missing = tmp.path("no-such-capture.bvh");
    let garbage = tmp.path("garbage.bvh");
    let bytes: Vec<u8> = (0u32..4096)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    std::fs::write(&garbage, bytes).unwrap();
    let truncated = tmp.path("truncated.bvh");
    std::fs::write(&truncated, &fixture[..fixture.len() / 2]).unwrap();
    let huge = tmp.path("huge.bvh");
    let declared = fixture.replacen("Frames:\t20", "Frames:\t1000000000", 1);
    assert_ne!(declared, fixture, "the fixture's frame count line changed");
    std::fs::write(&huge, declared).unwrap();
    for (what, path, needle) in [
        ("missing BVH", &missing, "no-such-capture.bvh"),
        ("garbage BVH", &garbage, "garbage.bvh"),
        ("truncated BVH", &truncated, "truncated.bvh"),
        ("a billion frames", &huge, "1000000000"),
    ] {
        let result = monocap(&["synth", "--bvh", s(path), "--out", s(&out)]);
        assert_fails_with(what, &result, needle);
    }
    let result = monocap(&["synth", "--bvh", s(&truncated), "--out", s(&out)]);
    assert_fails_with("truncated BVH", &result, "file ends");

    // The system's reason is said once, not repeated after the message as its cause.
    let no_clip = tmp.path("no-such-clip.y4m");
    let bvh = tmp.path("x.bvh");
    let reason = std::fs::File::open(&missing).unwrap_err().to_string();
    for (what, args) in [
        (
            "missing BVH",
            vec!["synth", "--bvh", s(&missing), "--out", s(&out)],
        ),
        ("missing clip", vec!["probe", s(&no_clip)]),
        ("missing clip", vec!["track", s(&no_clip), "-o", s(&bvh)]),
    ] {
        let result = monocap(&args);
        let stderr = String::from_utf8_lossy(&result.stderr);
        assert_fails_with(what, &result, "no-such-");
        assert_eq!(stderr.matches(&reason).count(), 1, "{what}: {stderr:?}");
    }

    // Options.
    let nowhere = tmp.path("no-such-dir").join("x.zip");
    for (what, out, extra, needle) in [
        ("--fps 0", &out, &["--fps", "0"][..], "frame rate"),
        ("--width 0", &out, &["--width", "0"], "image size"),
        (
            "--fov-deg 500",
            &out,
            &["--fov-deg", "500"],
            "field of view",
        ),
        (
            "--first-frame",
            &out,
            &["--first-frame", "100000"],
            "first frame",
        ),
        ("--bogus", &out, &["--bogus"], "unexpected argument"),
        ("--style blue", &out, &["--style", "blue"], "blue"),
        ("--fps abc", &out, &["--fps", "abc"], "--fps"),
        ("--duration-s 0", &out, &["--duration-s", "0"], "duration"),
        ("output extension", &tmp.path("x.xyz"), &[], "extension"),
        ("output directory", &nowhere, &[], "no-such-dir"),
    ] {
        assert_fails_with(what, &synth(out, extra), needle);
    }
    assert!(!out.exists() && !tmp.path("x.xyz").exists());

    // Missing required arguments are named on the one line.
    let result = monocap(&["synth", "--bvh", FIXTURE]);
    assert_fails_with("no --out", &result, "--out");
    let result = monocap(&["frobnicate"]);
    assert_fails_with("unknown command", &result, "frobnicate");
}

#[test]
fn probe_and_silhouettes_on_a_synthetic_clip() {
    let dir = TempDir::new("probe-sil");
    let clip = dir.path("clip.y4m");
    assert_success(
        "synth",
        &synth(&clip, &["--empty-frames", "6", "--style", "color"]),
    );

    let out = monocap(&["probe", s(&clip)]);
    assert_success("probe", &out);
    let info: serde_json::Value = serde_json::from_slice(&out.stdout).expect("probe prints JSON");
    assert_eq!(info["container"], "y4m");
    assert_eq!(info["width"], 320);
    assert_eq!(info["height"], 240);
    assert_eq!(info["fps"], 30.0);
    assert_eq!(info["frame_count"], 26);
    assert!((info["duration_s"].as_f64().unwrap() - 26.0 / 30.0).abs() < 1e-9);
    for key in [
        "codec",
        "container",
        "width",
        "height",
        "fps",
        "frame_count",
        "duration_s",
    ] {
        assert!(info.get(key).is_some(), "probe lacks {key}");
    }

    let masks = dir.path("masks.zip");
    let debug = dir.path("debug.zip");
    let out = monocap(&[
        "silhouettes",
        s(&clip),
        "-o",
        s(&masks),
        "--debug",
        s(&debug),
    ]);
    assert_success("silhouettes", &out);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("person-free frames 0..6"), "{stderr}");
    let mut zip = zip::ZipArchive::new(std::fs::File::open(&masks).unwrap()).unwrap();
    assert_eq!(zip.len(), 26);
    let name = zip.by_index(0).unwrap().name().unwrap().to_string();
    assert_eq!(name, "000000.png");
    let mut last = Vec::new();
    std::io::Read::read_to_end(&mut zip.by_name("000025.png").unwrap(), &mut last).unwrap();
    let img = image::load_from_memory(&last).unwrap().to_luma8();
    assert!(
        img.pixels().all(|p| p.0[0] == 0 || p.0[0] == 255),
        "masks are 0/255"
    );
    let on = img.pixels().filter(|p| p.0[0] == 255).count();
    assert!(on > 500, "the person is found ({on} pixels)");
    let dbg = zip::ZipArchive::new(std::fs::File::open(&debug).unwrap()).unwrap();
    assert_eq!(dbg.len(), 26);

    // The masks read back as a mask clip.
    let out = monocap(&["probe", s(&masks)]);
    assert_success("probe masks", &out);
    let info: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(info["frame_count"], 26);

    let text = dir.path("notes.mp4");
    std::fs::write(&text, "not a video").unwrap();
    assert_fails_with("probe text", &monocap(&["probe", s(&text)]), "notes.mp4");
    assert_fails_with(
        "bad range",
        &monocap(&[
            "silhouettes",
            s(&clip),
            "-o",
            s(&masks),
            "--empty-frames",
            "9..3",
        ]),
        "empty-frames",
    );
    assert_fails_with(
        "bad output",
        &monocap(&["silhouettes", s(&clip), "-o", s(&dir.path("m.xyz"))]),
        "extension",
    );
}

/// A reader that stops early (`monocap probe clip | head -c 0`) ends the command
/// quietly, as it would any other command-line tool: no panic, no backtrace.
#[cfg(unix)]
#[test]
fn a_closed_output_pipe_ends_a_command_without_a_panic() {
    use std::os::unix::process::ExitStatusExt;
    use std::process::{Command, Stdio};
    let dir = TempDir::new("closed-pipe");
    let clip = dir.path("clip.y4m");
    assert_success("synth", &synth(&clip, &["--style", "color"]));
    // The pipe's reading end is closed before the command starts.
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    let out = Command::new(env!("CARGO_BIN_EXE_monocap"))
        .args(["probe", s(&clip)])
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .expect("the monocap binary runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "panicked: {stderr}");
    assert_eq!(
        out.status.signal(),
        Some(libc::SIGPIPE),
        "{:?}, stderr {stderr:?}",
        out.status
    );
}

#[test]
fn a_person_who_never_moves_without_person_free_frames_gets_a_warning() {
    // One frame of a person, repeated: no frame shows the scene behind them, so a
    // background learned from the clip is the person, and the silhouettes are empty.
    let dir = TempDir::new("still");
    let moving = dir.path("moving.zip");
    let still = dir.write("still.zip", &common::still_person_clip(&moving));
    let out = monocap(&["silhouettes", s(&still), "-o", s(&dir.path("m.zip"))]);
    assert_success("silhouettes", &out);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("warning: the silhouettes are nearly empty")
            && stderr.contains("--empty-frames"),
        "{stderr}"
    );
    // Tracking finds no person, and says why in its one line.
    assert_fails_with(
        "track a still person",
        &monocap(&["track", s(&still), "-o", s(&dir.path("m.bvh"))]),
        "no person-free frames",
    );
    // The runner running towards the camera keeps within their own footprint: most
    // of their silhouette lies where no frame showed the scene, and they are told.
    let out = monocap(&["silhouettes", s(&moving), "-o", s(&dir.path("n.zip"))]);
    assert_success("silhouettes", &out);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("lies where the clip never showed the scene")
            && stderr.contains("--empty-frames"),
        "{stderr}"
    );
    // Running across the picture, they show the scene behind them: no warning.
    let across = dir.path("across.y4m");
    assert_success(
        "synth across",
        &synth(&across, &["--style", "color", "--azimuth-deg", "90"]),
    );
    let out = monocap(&["silhouettes", s(&across), "-o", s(&dir.path("a.zip"))]);
    assert_success("silhouettes", &out);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("warning"), "{stderr}");
}

#[test]
fn tiny_images_and_ranges_past_the_end_fail_cleanly_or_work() {
    let dir = TempDir::new("tiny");
    // Tiny frames are legal: they must render, not panic.
    for (w, h) in [("3", "3"), ("1", "2"), ("2", "1")] {
        let out = dir.path(&format!("tiny_{w}x{h}.y4m"));
        let res = synth(&out, &["--width", w, "--height", h, "--duration-s", "0.2"]);
        assert_success(&format!("synth {w}×{h}"), &res);
    }
    let clip = dir.path("clip.y4m");
    assert_success("synth", &synth(&clip, &["--empty-frames", "4"]));
    assert_fails_with(
        "person-free range past the end",
        &monocap(&[
            "silhouettes",
            s(&clip),
            "-o",
            s(&dir.path("m.zip")),
            "--empty-frames",
            "5..200",
        ]),
        "run past the clip",
    );
}

/// A mocap folder in `dir` holding the fixture capture alone, for `bench --mocap`.
fn fixture_mocap(dir: &TempDir) -> PathBuf {
    let mocap = dir.path("mocap");
    std::fs::create_dir_all(&mocap).unwrap();
    std::fs::copy(FIXTURE, mocap.join("run.bvh")).unwrap();
    mocap
}

/// A short `bench` on the `mocap` folder (one run per frame, `extra` arguments
/// last), writing its per-frame figures to `csv`.
fn short_bench(
    mocap: &Path,
    azimuths: &str,
    lead_in: &str,
    duration_s: &str,
    csv: &Path,
    extra: &[&str],
) -> Output {
    let mut args = vec![
        "bench",
        "--mocap",
        s(mocap),
        "--azimuths",
        azimuths,
        "--lead-in",
        lead_in,
        "--duration-s",
        duration_s,
        "--restarts",
        "1",
        "--per-frame",
        s(csv),
    ];
    args.extend_from_slice(extra);
    monocap(&args)
}

/// `bench --per-frame` writes one CSV row per frame with a person, after a header,
/// for every clip it prints; a path it cannot create is one clear line.
#[test]
fn bench_writes_its_per_frame_figures() {
    let dir = TempDir::new("cli-bench");
    let mocap = fixture_mocap(&dir);
    let csv = dir.path("frames.csv");
    let bench = |csv: &Path| short_bench(&mocap, "0", "0,3", "0.3", csv, &[]);
    let out = bench(&csv);
    assert_success("bench", &out);
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("clip,frame,pck,pck_swapped,pa_mpjpe_mm,pa_ambiguous_mm,iou,cost,truth_cost,heading_error_deg,depth_ratio")
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert!(rows.iter().all(|r| r.len() == 11), "{text}");
    // Allowing limb swaps and the depth mirror never raises PA-MPJPE.
    for r in &rows {
        let (pa, amb): (f64, f64) = (r[4].parse().unwrap(), r[5].parse().unwrap());
        assert!(amb >= 0.0 && amb <= pa, "{r:?}");
    }
    // Each clip's printed frame count is its number of rows.
    let stdout = String::from_utf8_lossy(&out.stdout);
    for lead in ["lead 0", "lead 3"] {
        let printed: usize = stdout
            .lines()
            .find_map(|l| l.split(lead).nth(1))
            .and_then(|rest| rest.split_whitespace().next())
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("no {lead} line in {stdout}"));
        let written = rows.iter().filter(|r| r[0].ends_with(lead)).count();
        assert_eq!((printed, written > 0), (written, true), "{lead}");
        // With a lead-in the frames counted are those with the person.
        if lead == "lead 3" {
            assert_eq!(rows.iter().find(|r| r[0].ends_with(lead)).unwrap()[1], "3");
        }
    }
    let out = bench(&dir.path("missing/frames.csv"));
    assert_fails_with("bench to a missing folder", &out, "cannot create");

    // Started from the true shape and pose, the first frame's tracked pose is the
    // truth: its cost and the truth's, scored by the benchmark on its own, agree.
    let oracle = dir.path("oracle.csv");
    let out = short_bench(&mocap, "60", "2", "0.2", &oracle, &["--oracle-init"]);
    assert_success("bench --oracle-init", &out);
    let text = std::fs::read_to_string(&oracle).unwrap();
    let first: Vec<&str> = text.lines().nth(1).unwrap().split(',').collect();
    let (cost, truth): (f64, f64) = (first[7].parse().unwrap(), first[8].parse().unwrap());
    assert!((cost - truth).abs() < 0.2, "tracked {cost}, truth {truth}");
    for line in text.lines().skip(2) {
        let r: Vec<&str> = line.split(',').collect();
        let t: f64 = r[8].parse().unwrap();
        assert!(t.is_finite(), "{line}");
    }
    assert!(String::from_utf8_lossy(&out.stdout).contains("missed: "));
}

/// `bench --basin-probe N` compares the tracked answer with the bottom of the
/// truth's basin on every Nth frame with a person. Started from the true shape and
/// pose, that bottom is next to the truth, and the table counts the probed frames.
#[test]
fn bench_probes_the_truths_basin() {
    let dir = TempDir::new("cli-bench-basin");
    let mocap = fixture_mocap(&dir);
    let csv = dir.path("frames.csv");
    let out = short_bench(
        &mocap,
        "60",
        "2",
        "0.2",
        &csv,
        &["--oracle-init", "--basin-probe", "3"],
    );
    assert_success("bench --basin-probe", &out);
    let rows = std::fs::read_to_string(&csv).unwrap().lines().count() - 1;
    let stdout = String::from_utf8_lossy(&out.stdout);
    let table = stdout
        .split("the truth's basin under the fitted shape")
        .nth(1)
        .unwrap_or_else(|| panic!("no basin table in {stdout}"));
    let overall: Vec<&str> = table
        .lines()
        .find(|l| l.starts_with("overall"))
        .unwrap_or_else(|| panic!("no overall line in {table}"))
        .split_whitespace()
        .collect();
    // overall, probed, cheaper, >20%, PA tracked, mm, PA truth, mm, PA cheaper, mm
    let n = |i: usize| -> f64 { overall[i].parse().unwrap() };
    assert_eq!(n(1) as usize, rows.div_ceil(3), "{table}");
    assert!(n(3) <= n(2) && n(2) <= n(1), "{table}");
    assert!(n(6) < 15.0, "the truth's basin from the truth: {table}");
    let (lo, hi) = (n(4).min(n(6)), n(4).max(n(6)));
    assert!(n(8) >= lo - 0.05 && n(8) <= hi + 0.05, "{table}");
    assert_fails_with(
        "a probe interval that is not a number",
        &monocap(&["bench", "--mocap", s(&mocap), "--basin-probe", "often"]),
        "--basin-probe",
    );
}

/// `bench --seed` renders the same motions with other background and sensor noise:
/// the same seed gives the same figures, line for line (tracking is deterministic),
/// another seed other silhouettes and so other truth costs.
#[test]
fn bench_seeds_the_clips_noise() {
    let dir = TempDir::new("cli-bench-seed");
    let mocap = fixture_mocap(&dir);
    let run = |seed: Option<&str>, name: &str| {
        let csv = dir.path(name);
        let extra = match seed {
            Some(seed) => vec!["--seed", seed],
            None => vec![],
        };
        assert_success("bench", &short_bench(&mocap, "0", "3", "0.3", &csv, &extra));
        std::fs::read_to_string(&csv).unwrap()
    };
    let default = run(None, "default.csv");
    assert!(default.lines().count() > 2, "{default}");
    assert_eq!(run(Some("1"), "one.csv"), default, "seed 1 is the default");
    let other = run(Some("2"), "two.csv");
    assert_eq!(other.lines().count(), default.lines().count());
    // The truth cost is scored on the extracted silhouettes, which the noise moves.
    let truth = |text: &str| -> Vec<String> {
        text.lines()
            .skip(1)
            .map(|l| l.split(',').nth(8).unwrap().to_string())
            .collect()
    };
    assert_ne!(truth(&other), truth(&default), "{other}\n{default}");
    assert_fails_with(
        "a seed that is not a number",
        &monocap(&["bench", "--mocap", s(&mocap), "--seed", "many"]),
        "--seed",
    );
}

/// `monocap prior` learns a pose prior from a folder of BVH files, which `track
/// --pose-prior` tracks with; too few poses, an empty folder, a file that is not a
/// prior or a prior weighed by 0 are refused in one line.
#[test]
fn prior_learns_from_a_folder_and_track_reads_it() {
    let dir = TempDir::new("cli-prior");
    let mocap = fixture_mocap(&dir);
    let out = dir.path("prior.json");
    // The fixture's 20 frames are fewer poses than the prior's 26 angles.
    assert_fails_with(
        "one short capture",
        &monocap(&["prior", "--mocap", s(&mocap), "-o", s(&out)]),
        "at least 26 captured poses",
    );
    std::fs::copy(FIXTURE, mocap.join("run-again.bvh")).unwrap();
    let learned = monocap(&["prior", "--mocap", s(&mocap), "-o", s(&out)]);
    assert_success("prior", &learned);
    assert!(String::from_utf8_lossy(&learned.stdout).contains("from 2 captures (40 poses"));
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(text.contains("\"monocap.pose-prior/1\""), "{text}");
    let empty = dir.path("empty");
    std::fs::create_dir_all(&empty).unwrap();
    assert_fails_with(
        "an empty folder",
        &monocap(&["prior", "--mocap", s(&empty), "-o", s(&out)]),
        "no BVH files",
    );
    let bad = dir.write("bad.json", b"{\"format\": \"monocap.truth/1\"}");
    let m = dir.path("m.bvh");
    let clip = dir.path("clip.y4m");
    assert_success("synth", &synth(&clip, &["--style", "silhouette"]));
    let track = |extra: &[&str]| {
        let mut args = vec!["track", s(&clip), "--masks", "-o", s(&m)];
        args.extend_from_slice(extra);
        monocap(&args)
    };
    assert_success(
        "track with the learned prior",
        &track(&["--pose-prior", s(&out)]),
    );
    assert!(m.is_file());
    assert_fails_with(
        "a file that is not a prior",
        &track(&["--pose-prior", s(&bad), "--w-prior", "20"]),
        "bad.json",
    );
    assert_fails_with(
        "a prior that would weigh nothing",
        &track(&["--pose-prior", s(&out), "--w-prior", "0"]),
        "--w-prior 0",
    );
    assert_fails_with("a negative weight", &track(&["--w-prior=-1"]), "--w-prior");
}
