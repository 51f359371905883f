//! `monocap::synth::synthesize` against a second, independent path through the math:
//! forward kinematics written out here with explicit rotation matrices, a Kabsch fit
//! from the capture's world to the truth's camera frame, and the pinhole projection.

mod common;

use common::TempDir;
use std::io::Read;
use std::path::{Path, PathBuf};

use monocap::body::skeleton::Joint;
use monocap::motion::bvh::{Bvh, Channel};
use monocap::motion::retarget::JointMap;
use monocap::synth::{synthesize, Style, SynthOptions, Truth};
use nalgebra::{Matrix3, Vector3};

const MOCAP: &str = "../shared/data/mocap";
const FIXTURE: &str = "tests/fixtures/bandai_run_normal_001_20f.bvh";

// ---------------------------------------------------------------------------------------
// The second path: forward kinematics from the channel values.

fn rot_x(deg: f64) -> Matrix3<f64> {
    let (s, c) = deg.to_radians().sin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}

fn rot_y(deg: f64) -> Matrix3<f64> {
    let (s, c) = deg.to_radians().sin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}

fn rot_z(deg: f64) -> Matrix3<f64> {
    let (s, c) = deg.to_radians().sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

/// World positions (file units) of every joint at `frame`, End Sites excluded: each
/// local transform is `T(offset, position channels replacing their axes) · R1·R2·…`
/// with the rotation channels in the order listed (first outermost).
fn forward_kinematics(bvh: &Bvh, frame: usize) -> Vec<Vector3<f64>> {
    let row = bvh.frame(frame);
    let mut rot: Vec<Matrix3<f64>> = Vec::with_capacity(bvh.joints.len());
    let mut pos: Vec<Vector3<f64>> = Vec::with_capacity(bvh.joints.len());
    for joint in &bvh.joints {
        let mut t = Vector3::from(joint.offset);
        let mut r = Matrix3::identity();
        for (k, channel) in joint.channels.iter().enumerate() {
            let v = row[joint.channel_offset + k];
            match channel {
                Channel::Xposition => t.x = v,
                Channel::Yposition => t.y = v,
                Channel::Zposition => t.z = v,
                Channel::Xrotation => r *= rot_x(v),
                Channel::Yrotation => r *= rot_y(v),
                Channel::Zrotation => r *= rot_z(v),
            }
        }
        let (world_r, world_p) = match joint.parent {
            Some(p) => (rot[p] * r, pos[p] + rot[p] * t),
            None => (r, t),
        };
        rot.push(world_r);
        pos.push(world_p);
    }
    pos
}

/// The best rotation and translation with `q ≈ r·p + t` (Kabsch).
fn kabsch(p: &[Vector3<f64>], q: &[Vector3<f64>]) -> (Matrix3<f64>, Vector3<f64>) {
    assert_eq!(p.len(), q.len());
    let n = p.len() as f64;
    let pc = p.iter().sum::<Vector3<f64>>() / n;
    let qc = q.iter().sum::<Vector3<f64>>() / n;
    let mut h = Matrix3::zeros();
    for (a, b) in p.iter().zip(q) {
        h += (a - pc) * (b - qc).transpose();
    }
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u.unwrap(), svd.v_t.unwrap());
    let v = v_t.transpose();
    let d = (v * u.transpose()).determinant().signum();
    let r = v * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
    let t = qc - r * pc;
    (r, t)
}

/// Wraps an angle in degrees to (−180, 180].
fn wrap_deg(a: f64) -> f64 {
    let w = a.rem_euclid(360.0);
    if w > 180.0 {
        w - 360.0
    } else {
        w
    }
}

/// The contract's camera frame (z into the scene) to the internal one (looking down −z).
fn internal(c: &[f64; 3]) -> Vector3<f64> {
    Vector3::new(c[0], c[1], -c[2])
}

// ---------------------------------------------------------------------------------------
// The checks.

struct Case<'a> {
    bvh: &'a Bvh,
    opts: &'a SynthOptions,
    truth: &'a Truth,
    clip: &'a Path,
}

/// Steps 2–4: camera pose, truth joints, projection, framing and frame bookkeeping.
fn check_geometry(c: &Case<'_>) {
    let (bvh, opts, truth) = (c.bvh, c.opts, c.truth);
    let n = bvh.frame_count();
    assert_eq!(truth.format, "monocap.truth/1");
    assert_eq!(truth.fps, opts.fps);
    assert_eq!(truth.empty_frames, opts.empty_frames);
    assert_eq!(
        (truth.image.width, truth.image.height),
        (opts.width, opts.height)
    );
    let names: Vec<&str> = bvh.joints.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(truth.source_joints, names);
    assert!((truth.source.fps - 1.0 / bvh.frame_time).abs() < 1e-9);
    // Source frames per clip frame, snapped to a whole number when within 0.1% of
    // one (frame times are written with few digits: CMU's .0083333 for 120 fps).
    let ratio = truth.source.fps / opts.fps;
    let step = if ratio.round() >= 1.0 && (ratio - ratio.round()).abs() < 1e-3 * ratio.round() {
        ratio.round()
    } else {
        ratio
    };
    assert!((truth.source.frame_step - step).abs() < 1e-12);
    assert_eq!(truth.source.first_frame, opts.first_frame);

    // Step 4: frame bookkeeping and intrinsics.
    let wanted = opts
        .duration_s
        .map_or(usize::MAX, |d| (d * opts.fps).round() as usize);
    let available = (0..)
        .take_while(|&k| opts.first_frame + ((k as f64 * step).round() as usize) < n)
        .count();
    assert_eq!(truth.frames.len(), wanted.min(available));
    assert_eq!(truth.frame_count, opts.empty_frames + truth.frames.len());
    for (k, f) in truth.frames.iter().enumerate() {
        assert_eq!(f.index, opts.empty_frames + k, "index of person frame {k}");
        let expected = opts.first_frame + (k as f64 * truth.source.frame_step).round() as usize;
        assert_eq!(f.source_frame, expected, "source frame of person frame {k}");
        assert!(f.source_frame < n);
        assert_eq!(f.joints3d.len(), bvh.joints.len());
        assert_eq!(f.joints2d.len(), bvh.joints.len());
        assert_eq!(f.model_joints3d.len(), 18);
        assert_eq!(f.model_joints2d.len(), 18);
        assert_eq!(f.params.len(), truth.parameters.len());
    }
    let cam = &truth.camera;
    let fx = opts.width as f64 / 2.0 / (opts.fov_deg.to_radians() / 2.0).tan();
    assert!((cam.fx - fx).abs() < 1e-9, "fx {} vs {fx}", cam.fx);
    assert!((cam.fy - fx).abs() < 1e-9, "fy {} vs {fx}", cam.fy);
    assert_eq!(cam.cx, opts.width as f64 / 2.0);
    assert_eq!(cam.cy, opts.height as f64 / 2.0);
    assert_eq!(cam.fov_deg, opts.fov_deg);
    assert_eq!(cam.azimuth_deg, opts.azimuth_deg);

    // Step 2: one rigid transform takes the independently computed world positions (cm)
    // to the truth's joints of every frame.
    let cm = truth.source.cm_per_unit;
    let mut world = Vec::new();
    let mut camera = Vec::new();
    for f in &truth.frames {
        world.extend(
            forward_kinematics(bvh, f.source_frame)
                .into_iter()
                .map(|p| p * cm),
        );
        camera.extend(f.joints3d.iter().map(internal));
    }
    let (r, t) = kabsch(&world, &camera);
    let per_frame = bvh.joints.len();
    for (k, f) in truth.frames.iter().enumerate() {
        let range = k * per_frame..(k + 1) * per_frame;
        let worst = world[range.clone()]
            .iter()
            .zip(&camera[range])
            .map(|(p, q)| (r * p + t - q).norm())
            .fold(0.0, f64::max);
        assert!(
            worst < 1e-4,
            "frame {} (source {}): rigid fit residual {worst} cm",
            f.index,
            f.source_frame
        );
    }
    assert!(
        (r * Vector3::y() - Vector3::y()).norm() < 1e-9,
        "camera is not level: world up goes to {:?}",
        r * Vector3::y()
    );
    let centre = -(r.transpose() * t);
    let stated = Vector3::from(cam.position_world);
    assert!(
        (centre - stated).norm() < 1e-6,
        "camera centre {centre:?} vs position_world {stated:?}"
    );
    // The stated distance to the point looked at is about the performer's depth.
    let depths: Vec<f64> = truth.frames.iter().map(|f| f.joints3d[0][2]).collect();
    let mean_depth = depths.iter().sum::<f64>() / depths.len() as f64;
    assert!(
        (mean_depth / cam.distance_cm - 1.0).abs() < 0.25,
        "distance {} cm, mean root depth {mean_depth} cm",
        cam.distance_cm
    );
    assert!(
        (cam.ground_y + centre.y).abs() < 1e-6,
        "ground_y {}",
        cam.ground_y
    );

    // Azimuth: the horizontal direction from the scene to the camera against the
    // first frame's facing, (left hip − right hip) × up.
    let map = JointMap::detect(bvh).unwrap();
    let first = forward_kinematics(bvh, truth.frames[0].source_frame);
    let lr =
        first[map.source[Joint::LeftUpLeg.index()]] - first[map.source[Joint::RightUpLeg.index()]];
    let facing = lr.cross(&Vector3::y());
    let to_camera = r.transpose() * Vector3::z();
    let angle = (facing.z * to_camera.x - facing.x * to_camera.z)
        .atan2(facing.x * to_camera.x + facing.z * to_camera.z)
        .to_degrees();
    let off = wrap_deg(angle - opts.azimuth_deg);
    assert!(
        off.abs() < 1e-6,
        "camera at {angle}° around the performer, asked for {}°",
        opts.azimuth_deg
    );

    // Step 3: projection and framing.
    let (w, h) = (opts.width as f64, opts.height as f64);
    for f in &truth.frames {
        for (j, (p, uv)) in f.joints3d.iter().zip(&f.joints2d).enumerate() {
            assert!(
                p[2] > 0.0,
                "joint {j} of frame {} behind the camera",
                f.index
            );
            let u = cam.cx + cam.fx * p[0] / p[2];
            let v = cam.cy - cam.fy * p[1] / p[2];
            assert!(
                (u - uv[0]).abs() < 1e-6 && (v - uv[1]).abs() < 1e-6,
                "joint {j} of frame {}: {uv:?} vs projected [{u}, {v}]",
                f.index
            );
            assert!(
                (0.0..=w).contains(&u) && (0.0..=h).contains(&v),
                "joint {} of frame {} at [{u}, {v}] is outside the {w}×{h} image",
                names[j],
                f.index
            );
        }
        for (p, uv) in f.model_joints3d.iter().zip(&f.model_joints2d) {
            let u = cam.cx + cam.fx * p[0] / p[2];
            let v = cam.cy - cam.fy * p[1] / p[2];
            assert!((u - uv[0]).abs() < 1e-6 && (v - uv[1]).abs() < 1e-6);
        }
    }
}

/// Step 5: the retargeted model's limbs follow the capture's mapped joints.
fn check_retarget(c: &Case<'_>, tolerance_cm: f64) {
    let truth = c.truth;
    let map = JointMap::detect(c.bvh).unwrap();
    assert!(
        truth.retarget.mean_cm < 2.0,
        "retarget mean residual {} cm",
        truth.retarget.mean_cm
    );
    use Joint::*;
    let limbs = [
        LeftHand,
        RightHand,
        LeftFoot,
        RightFoot,
        LeftLeg,
        RightLeg,
        LeftForeArm,
        RightForeArm,
    ];
    let mut worst = (0.0, "", 0);
    for f in &truth.frames {
        for j in limbs {
            let model = Vector3::from(f.model_joints3d[j.index()]);
            let source = Vector3::from(f.joints3d[map.source[j.index()]]);
            let d = (model - source).norm();
            if d > worst.0 {
                worst = (d, j.name(), f.index);
            }
        }
    }
    println!(
        "{}: retarget mean {:.2} cm, max {:.2} cm; worst limb joint {} of frame {} at {:.2} cm",
        truth.source.file, truth.retarget.mean_cm, truth.retarget.max_cm, worst.1, worst.2, worst.0
    );
    assert!(
        worst.0 < tolerance_cm,
        "model joint {} of frame {} is {:.2} cm from its source joint",
        worst.1,
        worst.2,
        worst.0
    );
}

/// Step 6: the silhouettes in the ZIP agree with the truth.
fn check_masks(c: &Case<'_>) {
    let truth = c.truth;
    let file = std::fs::File::open(c.clip).unwrap();
    let mut zip = zip::ZipArchive::new(file).unwrap();
    assert_eq!(
        zip.len(),
        truth.frame_count,
        "frames in {}",
        c.clip.display()
    );
    let (w, h) = (truth.image.width, truth.image.height);
    let (mut inside, mut checked) = (0usize, 0usize);
    for i in 0..truth.frame_count {
        let mut bytes = Vec::new();
        zip.by_name(&format!("{i:06}.png"))
            .unwrap()
            .read_to_end(&mut bytes)
            .unwrap();
        let mask = image::load_from_memory(&bytes).unwrap().to_luma8();
        assert_eq!(mask.dimensions(), (w, h), "size of frame {i}");
        assert!(
            mask.pixels().all(|p| p.0[0] == 0 || p.0[0] == 255),
            "frame {i} is not a 0/255 mask"
        );
        let on = mask.pixels().filter(|p| p.0[0] == 255).count();
        if i < truth.empty_frames {
            assert_eq!(on, 0, "empty frame {i} shows something");
            continue;
        }
        assert!(on > 0, "person frame {i} has an empty mask");
        let f = &truth.frames[i - truth.empty_frames];
        assert_eq!(f.index, i);
        use Joint::*;
        for j in [
            Hips,
            LeftUpLeg,
            RightUpLeg,
            LeftLeg,
            RightLeg,
            LeftForeArm,
            RightForeArm,
        ] {
            let [u, v] = f.model_joints2d[j.index()];
            checked += 1;
            let (x, y) = (u.floor(), v.floor());
            if x >= 0.0 && y >= 0.0 && x < w as f64 && y < h as f64 {
                inside += (mask.get_pixel(x as u32, y as u32).0[0] == 255) as usize;
            }
        }
    }
    let share = inside as f64 / checked as f64;
    println!(
        "{}: {inside} of {checked} hip, knee and elbow points on the mask ({:.1}%)",
        truth.source.file,
        share * 100.0
    );
    assert!(
        share >= 0.8,
        "only {inside} of {checked} model joints fall on the mask"
    );
}

fn synth_silhouettes(
    bvh: &Bvh,
    name: &str,
    opts: &SynthOptions,
    dir: &TempDir,
) -> (Truth, PathBuf) {
    let clip = dir.path("clip.zip");
    let truth = synthesize(bvh, name, opts, &clip).unwrap();
    assert!(clip.is_file(), "{} was not written", clip.display());
    // The truth survives a JSON round trip (to within serde_json's float parsing).
    let json = serde_json::to_string(&truth).unwrap();
    let back: Truth = serde_json::from_str(&json).unwrap();
    assert_eq!(back.frame_count, truth.frame_count);
    assert_eq!(back.source_joints, truth.source_joints);
    for (a, b) in back.frames.iter().zip(&truth.frames) {
        assert_eq!((a.index, a.source_frame), (b.index, b.source_frame));
        for (p, q) in a.joints3d.iter().zip(&b.joints3d) {
            assert!((0..3).all(|i| (p[i] - q[i]).abs() <= 1e-9 * q[i].abs().max(1.0)));
        }
    }
    (truth, clip)
}

#[test]
fn shared_captures_agree_with_an_independent_computation() {
    let dir = Path::new(MOCAP);
    if !dir.is_dir() {
        println!("skipped: {MOCAP} is absent (a fresh clone has no ../shared)");
        return;
    }
    for (file, azimuth, first_frame) in [
        ("cmu_131_01.bvh", 30.0, 40),
        ("bandai_walk_normal_001.bvh", -75.0, 0),
    ] {
        let bvh = Bvh::read(&dir.join(file)).unwrap();
        let tmp = TempDir::new(file.trim_end_matches(".bvh"));
        let opts = SynthOptions {
            style: Style::Silhouette,
            empty_frames: 3,
            azimuth_deg: azimuth,
            first_frame,
            duration_s: Some(1.0),
            ..SynthOptions::default()
        };
        let (truth, clip) = synth_silhouettes(&bvh, file, &opts, &tmp);
        assert_eq!(truth.frames.len(), 30, "{file}: 1 s at 30 fps");
        assert_eq!(truth.source.file, file);
        let case = Case {
            bvh: &bvh,
            opts: &opts,
            truth: &truth,
            clip: &clip,
        };
        check_geometry(&case);
        check_retarget(&case, 8.0);
        check_masks(&case);
    }
}

#[test]
fn fixture_agrees_with_an_independent_computation() {
    let bvh = Bvh::read(Path::new(FIXTURE)).unwrap();
    assert_eq!(bvh.frame_count(), 20);
    let tmp = TempDir::new("fixture");
    for (azimuth, fps, empty) in [(0.0, 30.0, 2), (135.0, 12.0, 0), (-170.0, 30.0, 1)] {
        let opts = SynthOptions {
            style: Style::Silhouette,
            empty_frames: empty,
            azimuth_deg: azimuth,
            fps,
            width: 200,
            height: 150,
            fov_deg: 60.0,
            ..SynthOptions::default()
        };
        let (truth, clip) = synth_silhouettes(&bvh, "fixture.bvh", &opts, &tmp);
        let case = Case {
            bvh: &bvh,
            opts: &opts,
            truth: &truth,
            clip: &clip,
        };
        check_geometry(&case);
        check_masks(&case);
    }
}

#[test]
fn fixture_frame_picking_follows_first_frame_and_duration() {
    let bvh = Bvh::read(Path::new(FIXTURE)).unwrap();
    let tmp = TempDir::new("picking");
    let opts = SynthOptions {
        style: Style::Silhouette,
        first_frame: 7,
        duration_s: Some(0.25),
        fps: 20.0,
        ..SynthOptions::default()
    };
    let truth = synthesize(&bvh, "f.bvh", &opts, &tmp.path("c.zip")).unwrap();
    let picked: Vec<usize> = truth.frames.iter().map(|f| f.source_frame).collect();
    // A 30.00003 fps source at 20 fps: steps of just over 1.5 source frames.
    assert_eq!(picked, [7, 9, 10, 12, 13]);
    assert_eq!(truth.source.first_frame, 7);
    // The camera faces the performer as they stand in the first frame used.
    let case = Case {
        bvh: &bvh,
        opts: &opts,
        truth: &truth,
        clip: &tmp.path("c.zip"),
    };
    check_geometry(&case);
}

#[test]
fn synthesize_rejects_bad_options_with_a_message() {
    let bvh = Bvh::read(Path::new(FIXTURE)).unwrap();
    let tmp = TempDir::new("errors");
    let good = SynthOptions {
        style: Style::Silhouette,
        duration_s: Some(0.1),
        ..SynthOptions::default()
    };
    let cases: [(&str, SynthOptions, &str, &str); 7] = [
        (
            "first frame past the end",
            SynthOptions {
                first_frame: 20,
                ..good.clone()
            },
            "a.zip",
            "first frame 20",
        ),
        (
            "zero fps",
            SynthOptions {
                fps: 0.0,
                ..good.clone()
            },
            "a.zip",
            "frame rate",
        ),
        (
            "zero width",
            SynthOptions {
                width: 0,
                ..good.clone()
            },
            "a.zip",
            "image size",
        ),
        (
            "zero field of view",
            SynthOptions {
                fov_deg: 0.0,
                ..good.clone()
            },
            "a.zip",
            "field of view",
        ),
        (
            "200° field of view",
            SynthOptions {
                fov_deg: 200.0,
                ..good.clone()
            },
            "a.zip",
            "field of view",
        ),
        ("unknown extension", good.clone(), "a.xyz", "extension"),
        (
            "negative duration",
            SynthOptions {
                duration_s: Some(-1.0),
                ..good.clone()
            },
            "a.zip",
            "duration",
        ),
    ];
    for (what, opts, out, needle) in cases {
        let out = tmp.path(out);
        let result = std::panic::catch_unwind(|| synthesize(&bvh, "f.bvh", &opts, &out));
        let Ok(result) = result else {
            panic!("{what}: synthesize panicked");
        };
        let Err(e) = result else {
            panic!("{what}: synthesize succeeded");
        };
        let message = format!("{e:#}");
        println!("{what}: {message}");
        assert!(
            message.contains(needle),
            "{what}: message {message:?} does not mention {needle:?}"
        );
        assert!(!message.contains('\n'), "{what}: message has several lines");
        assert!(!out.exists(), "{what}: {} was written", out.display());
    }
}

/// A capture whose Frame Time is absurdly small has an absurdly large step between
/// clip frames: only the first frame exists, and nothing overflows.
#[test]
fn a_tiny_frame_time_picks_one_frame_without_overflow() {
    let text = std::fs::read_to_string(FIXTURE).unwrap();
    let line = text.lines().find(|l| l.starts_with("Frame Time")).unwrap();
    let tiny = text.replacen(line, "Frame Time: 1e-300", 1);
    let bvh = Bvh::parse(&tiny).unwrap();
    let opts = SynthOptions {
        first_frame: 1,
        style: Style::Silhouette,
        ..SynthOptions::default()
    };
    let mut frames = 0;
    let truth = monocap::synth::synthesize_with(&bvh, "tiny.bvh", &opts, |_| {
        frames += 1;
        Ok(())
    })
    .unwrap();
    assert_eq!(frames, 1);
    assert_eq!(truth.frames.len(), 1);
    assert_eq!(truth.frames[0].source_frame, 1);
}
