//! Retargeting the real motion capture in ../shared/data/mocap onto the model.

use std::path::Path;

use monocap::body::params::{SHAPE, TYPICAL_SHAPE};
use monocap::motion::bvh::Bvh;
use monocap::motion::retarget::{
    detect_unit_scale, fit_shape, target_joints, JointMap, Retargeter,
};
use monocap::track::prior::{captures_in, typical_shape, Capture};
use nalgebra::IsometryMatrix3;

const MOCAP: &str = "../shared/data/mocap";

/// The shared motion capture folder, or `None` (after saying why) when it is absent.
fn mocap_dir() -> Option<&'static Path> {
    let dir = Path::new(MOCAP);
    if dir.is_dir() {
        Some(dir)
    } else {
        println!("skipped: {MOCAP} is absent (a fresh clone has no ../shared)");
        None
    }
}

#[test]
fn every_shared_mocap_file_retargets_within_a_few_centimetres() {
    let Some(dir) = mocap_dir() else { return };
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .collect();
    files.retain(|p| p.extension().is_some_and(|e| e == "bvh"));
    files.sort();
    assert!(
        files.len() >= 9,
        "expected the 9 shared files, found {}",
        files.len()
    );
    for path in files {
        let bvh = Bvh::read(&path).unwrap();
        let map = JointMap::detect(&bvh).unwrap();
        let scale = detect_unit_scale(&bvh, &map);
        // 30 frames per second of capture, at most 10 s.
        let step = (bvh.fps() / 30.0).round().max(1.0) as usize;
        let frames: Vec<usize> = (0..bvh.frame_count()).step_by(step).take(300).collect();
        let id = IsometryMatrix3::identity();
        let targets: Vec<_> = frames
            .iter()
            .map(|&f| target_joints(&bvh, &map, f, scale, &id))
            .collect();
        let shape = fit_shape(&targets);
        let mut rt = Retargeter::new(&shape);
        let (mut mean, mut worst, mut p95) = (0.0, 0.0f64, Vec::new());
        for t in &targets {
            let (_, r) = rt.solve(t);
            mean += r.mean_cm / targets.len() as f64;
            worst = worst.max(r.max_cm);
            p95.push(r.max_cm);
        }
        p95.sort_by(f64::total_cmp);
        let p95 = p95[p95.len() * 95 / 100];
        let name = path.file_name().unwrap().to_string_lossy();
        println!(
            "{name}: {} frames, {scale:.3} cm/unit, mean joint residual {mean:.2} cm, \
             95th percentile of the per-frame max {p95:.2} cm, max {worst:.2} cm",
            targets.len()
        );
        assert!(mean < 1.5, "{name}: mean residual {mean:.2} cm");
        assert!(worst < 7.0, "{name}: worst joint residual {worst:.2} cm");
    }
}

/// The same skeleton under Mixamo's names must map onto the same joints, although
/// Mixamo calls the collar bone `LeftShoulder` (CMU's shoulder joint) and the shoulder
/// joint `LeftArm`.
#[test]
fn mixamo_names_map_onto_the_same_joints_as_cmu_names() {
    let text = std::fs::read_to_string("tests/fixtures/cmu_131_01_10f.bvh").unwrap();
    let cmu = Bvh::parse(&text).unwrap();
    let renames = [
        ("Hips", "Hips"),
        ("LeftHip", "LeftUpLeg"),
        ("LeftKnee", "LeftLeg"),
        ("LeftAnkle", "LeftFoot"),
        ("LeftToe", "LeftToeBase"),
        ("RightHip", "RightUpLeg"),
        ("RightKnee", "RightLeg"),
        ("RightAnkle", "RightFoot"),
        ("RightToe", "RightToeBase"),
        ("lowerback", "Spine"),
        ("Chest", "Spine1"),
        ("Chest2", "Spine2"),
        ("Neck", "Neck"),
        ("Head", "Head"),
        ("LeftCollar", "LeftShoulder"),
        ("LeftShoulder", "LeftArm"),
        ("LeftElbow", "LeftForeArm"),
        ("LeftWrist", "LeftHand"),
        ("RightCollar", "RightShoulder"),
        ("RightShoulder", "RightArm"),
        ("RightElbow", "RightForeArm"),
        ("RightWrist", "RightHand"),
    ];
    let mut mixamo = cmu.clone();
    for j in &mut mixamo.joints {
        let new = renames
            .iter()
            .find(|(old, _)| *old == j.name)
            .map(|(_, new)| *new);
        // Joints Mixamo has no name for keep a neutral one.
        j.name = match new {
            Some(n) => format!("mixamorig:{n}"),
            None => format!("mixamorig:extra_{}", j.name),
        };
    }
    let a = JointMap::detect(&cmu).unwrap();
    let b = JointMap::detect(&mixamo).unwrap();
    assert_eq!(a.source, b.source);
    let name = |i: usize| cmu.joints[i].name.as_str();
    let left_arm = monocap::body::Joint::LeftArm.index();
    assert_eq!(name(a.source[left_arm]), "LeftShoulder");
    assert_eq!(name(b.source[left_arm]), "LeftShoulder");
}

/// [`TYPICAL_SHAPE`] is what [`typical_shape`] measures from the real captures
/// (the constant is rounded to 0.001).
#[test]
fn the_typical_shape_is_measured_from_the_captures() {
    let Some(dir) = mocap_dir() else { return };
    let captures = captures_in(dir).expect("the captures retarget");
    let all: Vec<&Capture> = captures.iter().collect();
    let shape = typical_shape(&all).expect("captures");
    println!("typical shape: {shape:.3?}");
    for (k, (got, want)) in shape.iter().zip(TYPICAL_SHAPE).enumerate() {
        assert!(
            (got - want).abs() <= 0.0005 + 1e-9,
            "{}: measured {got:.3}, TYPICAL_SHAPE has {want}",
            SHAPE[k].name
        );
    }
}
