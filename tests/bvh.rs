//! Tests of the BVH reader, forward kinematics and writer against real files, hand-checked
//! tiny files, an independent forward-kinematics path, malformed input and fuzzing.

use std::alloc::{GlobalAlloc, Layout, System};
use std::fs;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use monocap::motion::bvh::{Bvh, BvhError, BvhJoint, Channel, MAX_FILE_BYTES};
use nalgebra::Point3;
use proptest::prelude::*;

// ---------------------------------------------------------------------------------------
// Largest single allocation request, to prove that declared sizes are not trusted.

struct LargestRequest;

static LARGEST_REQUEST: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for LargestRequest {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LARGEST_REQUEST.fetch_max(layout.size(), Ordering::Relaxed);
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LARGEST_REQUEST.fetch_max(new_size, Ordering::Relaxed);
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: LargestRequest = LargestRequest;

/// No other test in this binary asks for anywhere near this much at once.
const HUGE_REQUEST: usize = 100 * 1024 * 1024;

// ---------------------------------------------------------------------------------------
// Helpers

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

const BANDAI_FIXTURE: &str = "bandai_run_normal_001_20f.bvh";
const CMU_FIXTURE: &str = "cmu_131_01_10f.bvh";

fn read_fixture(name: &str) -> (String, Bvh) {
    let path = fixture(name);
    let text = fs::read_to_string(&path).expect("fixture is readable");
    let bvh = Bvh::read(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
    (text, bvh)
}

/// The shared real-data folder, or `None` (after saying why) when it is absent.
fn mocap_dir() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/mocap");
    if dir.is_dir() {
        Some(dir)
    } else {
        println!(
            "skipped: real mocap folder {} is absent (only present next to the project's \
             shared data)",
            dir.display()
        );
        None
    }
}

/// `Frames:` as written in the file header, read without the parser under test.
fn header_frames(text: &str) -> usize {
    let line = text
        .lines()
        .find(|l| l.trim_start().starts_with("Frames:"))
        .expect("Frames: line");
    line.trim_start()["Frames:".len()..]
        .trim()
        .parse()
        .expect("Frames: value")
}

/// Frame `i` as written in the file, read without the parser under test (one row per line).
fn raw_frame(text: &str, i: usize) -> Vec<f64> {
    let mut lines = text.lines();
    lines
        .by_ref()
        .find(|l| l.trim_start().starts_with("Frame Time"))
        .expect("Frame Time line");
    lines
        .nth(i)
        .expect("frame line")
        .split_whitespace()
        .map(|t| t.parse().expect("number"))
        .collect()
}

fn position(bvh: &Bvh, frame: usize, joint: &str) -> Point3<f64> {
    let j = bvh
        .find(joint)
        .unwrap_or_else(|| panic!("no joint {joint}"));
    bvh.joint_positions(frame)[j]
}

fn assert_close(actual: Point3<f64>, expected: [f64; 3], tolerance: f64, what: &str) {
    let expected = Point3::from(expected);
    assert!(
        (actual - expected).norm() < tolerance,
        "{what}: got {actual:?}, expected {expected:?}"
    );
}

/// Parses `text` expecting an error whose message contains `needle`.
fn parse_err(text: &str, needle: &str) -> BvhError {
    match Bvh::parse(text) {
        Ok(bvh) => panic!("expected an error containing {needle:?}, parsed {bvh:?}"),
        Err(e) => {
            let message = e.to_string();
            assert!(
                message.contains(needle),
                "error {message:?} does not contain {needle:?}"
            );
            assert_one_line(&message);
            e
        }
    }
}

fn assert_one_line(message: &str) {
    assert!(!message.contains('\n') && !message.contains('\r'));
    assert!(message.len() < 300, "message too long: {message:?}");
}

/// Parse → write → parse keeps the skeleton and reproduces every joint and End Site
/// position within 1e-4 units.
fn assert_round_trip(bvh: &Bvh) {
    let text = bvh.to_bvh_string();
    let mut written = Vec::new();
    bvh.write(&mut written).expect("writing to a Vec");
    assert_eq!(written, text.as_bytes(), "write and to_bvh_string differ");
    let back = Bvh::parse(&text).unwrap_or_else(|e| panic!("re-reading written BVH: {e}"));
    assert_eq!(back.joints.len(), bvh.joints.len());
    for (a, b) in back.joints.iter().zip(&bvh.joints) {
        assert_eq!(a.name, b.name);
        assert_eq!(a.parent, b.parent);
        assert_eq!(a.channels, b.channels);
        assert_eq!(a.channel_offset, b.channel_offset);
        assert_eq!(a.end_site.is_some(), b.end_site.is_some());
    }
    assert_eq!(back.frame_count(), bvh.frame_count());
    assert_eq!(back.channel_count(), bvh.channel_count());
    assert_eq!(back.frame_time, bvh.frame_time);
    for f in 0..bvh.frame_count() {
        for (p, q) in back.joint_positions(f).iter().zip(bvh.joint_positions(f)) {
            assert!((p - q).norm() < 1e-4, "frame {f}: {p:?} vs {q:?}");
        }
        for (p, q) in back
            .end_site_positions(f)
            .iter()
            .zip(bvh.end_site_positions(f))
        {
            if let (Some(p), Some(q)) = (p, q) {
                assert!((p - q).norm() < 1e-4, "frame {f}: end {p:?} vs {q:?}");
            }
        }
    }
}

/// The first `frames` frames of `bvh`, rebuilt through `from_parts`.
fn first_frames(bvh: &Bvh, frames: usize) -> Bvh {
    let frames = frames.min(bvh.frame_count());
    let data = bvh.data()[..frames * bvh.channel_count()].to_vec();
    Bvh::from_parts(bvh.joints.clone(), bvh.frame_time, data).expect("valid parts")
}

// ---------------------------------------------------------------------------------------
// Independent forward kinematics: explicit 3×3 matrices composed by hand.

type Mat = [[f64; 3]; 3];

const IDENTITY: Mat = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// Right-handed rotation by `degrees` about axis 0 (X), 1 (Y) or 2 (Z).
fn rotation(axis: usize, degrees: f64) -> Mat {
    let (s, c) = degrees.to_radians().sin_cos();
    match axis {
        0 => [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]],
        1 => [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]],
        _ => [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
    }
}

fn mat_mul(a: &Mat, b: &Mat) -> Mat {
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, cell) in row.iter_mut().enumerate() {
            *cell = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    m
}

fn mat_vec(a: &Mat, v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| (0..3).map(|k| a[i][k] * v[k]).sum())
}

/// World position of `joint` at `frame`, walking the chain from the root. Channel columns
/// are counted here from the joints before, not taken from `channel_offset`.
fn independent_position(bvh: &Bvh, joint: usize, frame: usize) -> [f64; 3] {
    let mut chain = Vec::new();
    let mut next = Some(joint);
    while let Some(j) = next {
        chain.push(j);
        next = bvh.joints[j].parent;
    }
    chain.reverse();
    let row = bvh.frame(frame);
    let mut world_rotation = IDENTITY;
    let mut world_position = [0.0; 3];
    for j in chain {
        let joint = &bvh.joints[j];
        let first_column: usize = bvh.joints[..j].iter().map(|o| o.channels.len()).sum();
        let mut translation = joint.offset;
        let mut local_rotation = IDENTITY;
        for (k, channel) in joint.channels.iter().enumerate() {
            let value = row[first_column + k];
            match channel {
                Channel::Xposition => translation[0] = value,
                Channel::Yposition => translation[1] = value,
                Channel::Zposition => translation[2] = value,
                Channel::Xrotation => {
                    local_rotation = mat_mul(&local_rotation, &rotation(0, value))
                }
                Channel::Yrotation => {
                    local_rotation = mat_mul(&local_rotation, &rotation(1, value))
                }
                Channel::Zrotation => {
                    local_rotation = mat_mul(&local_rotation, &rotation(2, value))
                }
            }
        }
        let moved = mat_vec(&world_rotation, translation);
        world_position = [0, 1, 2].map(|i| world_position[i] + moved[i]);
        world_rotation = mat_mul(&world_rotation, &local_rotation);
    }
    world_position
}

fn check_independent_fk(text: &str, bvh: &Bvh, wrist: &str, frame: usize) {
    assert_eq!(bvh.frame(frame), raw_frame(text, frame).as_slice());
    let j = bvh
        .find(wrist)
        .unwrap_or_else(|| panic!("no joint {wrist}"));
    let expected = independent_position(bvh, j, frame);
    let actual = bvh.joint_positions(frame)[j];
    assert_close(actual, expected, 1e-6, wrist);
    // A meaningful chain: the wrist is well away from the root.
    assert!(actual.coords.norm() > 1.0);
}

// ---------------------------------------------------------------------------------------
// Real files

#[test]
fn real_files_parse_with_plausible_anatomy() {
    let Some(dir) = mocap_dir() else { return };
    let mut files: Vec<PathBuf> = fs::read_dir(&dir)
        .expect("mocap folder is readable")
        .map(|e| e.expect("directory entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "bvh"))
        .collect();
    files.sort();
    assert!(files.len() >= 9, "expected the 9 real BVH files");
    for path in files {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let text = fs::read_to_string(&path).unwrap();
        let bvh = Bvh::read(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(bvh.frame_count(), header_frames(&text), "{name}");
        if name.starts_with("cmu_") {
            let expected = if name == "cmu_131_01.bvh" { 994 } else { 1247 };
            assert_eq!(bvh.frame_count(), expected, "{name}");
            assert!((bvh.fps() - 120.0).abs() < 1e-3, "{name}: {}", bvh.fps());
            assert_eq!(bvh.joints.len(), 31, "{name}");
            assert_eq!(bvh.channel_count(), 6 + 30 * 3, "{name}");
            let y = |j: &str| position(&bvh, 0, j).y;
            assert!(y("Head") > y("Hips"), "{name}");
            assert!(y("Hips") > y("LeftAnkle"), "{name}");
            assert!(y("Hips") > y("RightAnkle"), "{name}");
            assert!(y("Neck") > y("Chest"), "{name}");
        } else {
            assert!(name.starts_with("bandai_"), "{name}");
            assert!((24..=1901).contains(&bvh.frame_count()), "{name}");
            assert!((bvh.fps() - 30.0).abs() < 1e-3, "{name}: {}", bvh.fps());
            assert_eq!(bvh.joints.len(), 22, "{name}");
            assert_eq!(bvh.channel_count(), 22 * 6, "{name}");
            let y = |j: &str| position(&bvh, 0, j).y;
            assert!((80.0..=100.0).contains(&y("Hips")), "{name}: {}", y("Hips"));
            assert!(y("Head") > y("Chest") && y("Chest") > y("Hips"), "{name}");
            assert!(y("Hips") > y("Foot_L") && y("Hips") > y("Foot_R"), "{name}");
        }
    }
}

#[test]
fn real_files_forward_kinematics_matches_independent_path() {
    let Some(dir) = mocap_dir() else { return };
    let text = fs::read_to_string(dir.join("cmu_131_01.bvh")).unwrap();
    let bvh = Bvh::parse(&text).unwrap();
    check_independent_fk(&text, &bvh, "LeftWrist", 500);
    let text = fs::read_to_string(dir.join("bandai_walk_normal_001.bvh")).unwrap();
    let bvh = Bvh::parse(&text).unwrap();
    check_independent_fk(&text, &bvh, "Hand_L", 100);
}

#[test]
fn real_files_round_trip() {
    let Some(dir) = mocap_dir() else { return };
    for name in ["cmu_131_02.bvh", "bandai_dance-short_normal_001.bvh"] {
        let bvh = Bvh::read(&dir.join(name)).unwrap();
        assert_round_trip(&first_frames(&bvh, 50));
    }
}

// ---------------------------------------------------------------------------------------
// Fixtures (always run)

#[test]
fn bandai_fixture() {
    let (text, bvh) = read_fixture(BANDAI_FIXTURE);
    assert_eq!(bvh.frame_count(), 20);
    assert_eq!(bvh.joints.len(), 22);
    assert_eq!(bvh.channel_count(), 132);
    assert!((bvh.fps() - 30.0).abs() < 1e-3);
    assert_eq!(bvh.joints[0].name, "joint_Root");
    assert_eq!(bvh.joints[0].parent, None);
    let hips = bvh.find("Hips").unwrap();
    assert_eq!(bvh.joints[hips].parent, Some(0));
    assert_eq!(bvh.joints[hips].channel_offset, 6);
    assert_eq!(
        bvh.joints[hips].channels,
        [
            Channel::Xposition,
            Channel::Yposition,
            Channel::Zposition,
            Channel::Zrotation,
            Channel::Xrotation,
            Channel::Yrotation
        ]
    );
    // Position channels carry the full local translation: Spine's equals its offset.
    let spine = &bvh.joints[bvh.find("Spine").unwrap()];
    assert_eq!(spine.offset, [15.7357, 0.0, 0.0]);
    assert!((bvh.frame(0)[spine.channel_offset] - 15.7357).abs() < 1e-3);
    assert_eq!(
        bvh.joints[bvh.find("Head").unwrap()].end_site,
        Some([10.0, 0.0, 0.0])
    );
    let y = |j: &str| position(&bvh, 0, j).y;
    assert!((80.0..=100.0).contains(&y("Hips")), "{}", y("Hips"));
    assert!(y("Head") > y("Hips") && y("Hips") > y("Toes_L"));
    check_independent_fk(&text, &bvh, "Hand_L", 7);
    check_independent_fk(&text, &bvh, "Toes_R", 19);
    assert_round_trip(&bvh);
}

#[test]
fn cmu_fixture() {
    let (text, bvh) = read_fixture(CMU_FIXTURE);
    assert_eq!(bvh.frame_count(), 10);
    assert_eq!(bvh.joints.len(), 31);
    assert_eq!(bvh.channel_count(), 96);
    assert!((bvh.fps() - 120.0).abs() < 1e-3);
    assert_eq!(
        bvh.joints[0].channels,
        [
            Channel::Xposition,
            Channel::Yposition,
            Channel::Zposition,
            Channel::Zrotation,
            Channel::Yrotation,
            Channel::Xrotation
        ]
    );
    // Some joints use another rotation order, on unindented CHANNELS lines.
    let shoulder = &bvh.joints[bvh.find("LeftShoulder").unwrap()];
    assert_eq!(
        shoulder.channels,
        [Channel::Zrotation, Channel::Xrotation, Channel::Yrotation]
    );
    assert_eq!(
        bvh.joints[bvh.find("LeftElbow").unwrap()].offset,
        [0.0, -4.25106, 0.0]
    );
    let y = |j: &str| position(&bvh, 0, j).y;
    assert!(y("Head") > y("Hips") && y("Hips") > y("LeftAnkle"));
    check_independent_fk(&text, &bvh, "LeftWrist", 3);
    check_independent_fk(&text, &bvh, "RightToe", 9);
    assert_round_trip(&bvh);
}

#[test]
fn world_transforms_reuse_the_buffer_and_agree_with_positions() {
    let (_, bvh) = read_fixture(CMU_FIXTURE);
    let mut world = Vec::new();
    bvh.world_transforms(0, &mut world);
    let capacity = world.capacity();
    let pointer = world.as_ptr();
    for f in 0..bvh.frame_count() {
        bvh.world_transforms(f, &mut world);
        assert_eq!(world.len(), bvh.joints.len());
        let positions = bvh.joint_positions(f);
        let ends = bvh.end_site_positions(f);
        for (j, iso) in world.iter().enumerate() {
            assert!((Point3::from(iso.translation.vector) - positions[j]).norm() < 1e-12);
            let end = bvh.joints[j].end_site.map(|e| iso * Point3::from(e));
            assert_eq!(end, ends[j]);
        }
    }
    assert_eq!(world.capacity(), capacity);
    assert_eq!(world.as_ptr(), pointer);
    assert_eq!(ends_count(&bvh), 7, "CMU has 7 End Sites");
}

fn ends_count(bvh: &Bvh) -> usize {
    bvh.joints.iter().filter(|j| j.end_site.is_some()).count()
}

// ---------------------------------------------------------------------------------------
// Hand-checked tiny files

/// Root order Z Y X with Z = X = 90: R = Rz(90)·Rx(90) takes +Y to +Z.
const TINY_ZYX: &str = "HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT Chest
  {
    OFFSET 0 1 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    End Site
    {
      OFFSET 0 2 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.5
1 2 3 90 0 90 0 0 0
0 0 0 0 0 0 0 0 90
";

#[test]
fn tiny_zyx_order() {
    let bvh = Bvh::parse(TINY_ZYX).unwrap();
    assert_eq!(bvh.frame_count(), 2);
    assert_eq!(bvh.channel_count(), 9);
    assert_eq!(bvh.fps(), 2.0);
    assert_eq!(bvh.joints[1].channel_offset, 6);
    let p = bvh.joint_positions(0);
    let e = bvh.end_site_positions(0);
    assert_close(p[0], [1.0, 2.0, 3.0], 1e-12, "Hips");
    // Rx(90) takes the offset (0,1,0) to (0,0,1); Rz(90) leaves that alone.
    assert_close(p[1], [1.0, 2.0, 4.0], 1e-12, "Chest");
    assert_close(e[1].unwrap(), [1.0, 2.0, 6.0], 1e-12, "Chest end");
    assert_eq!(e[0], None);
    // Frame 1: only the chest turns, 90° about X: its End Site (0,2,0) goes to (0,0,2).
    let p = bvh.joint_positions(1);
    let e = bvh.end_site_positions(1);
    assert_close(p[0], [0.0, 0.0, 0.0], 1e-12, "Hips");
    assert_close(p[1], [0.0, 1.0, 0.0], 1e-12, "Chest");
    assert_close(e[1].unwrap(), [0.0, 1.0, 2.0], 1e-12, "Chest end");
}

#[test]
fn tiny_xyz_order_differs() {
    // Same numbers, order X Y Z: R = Rx(90)·Rz(90); Rz(90) takes (0,1,0) to (-1,0,0),
    // which Rx leaves alone.
    let text = TINY_ZYX
        .replace(
            "Zposition Zrotation Yrotation Xrotation",
            "Zposition Xrotation Yrotation Zrotation",
        )
        .replace("1 2 3 90 0 90", "0 0 0 90 0 90");
    let bvh = Bvh::parse(&text).unwrap();
    let p = bvh.joint_positions(0);
    assert_close(p[1], [-1.0, 0.0, 0.0], 1e-12, "Chest");
    assert_close(
        bvh.end_site_positions(0)[1].unwrap(),
        [-3.0, 0.0, 0.0],
        1e-12,
        "Chest end",
    );
}

#[test]
fn tiny_zxy_order_on_a_child_joint() {
    // Arm order Z X Y with X = Y = 90: R = Rx(90)·Ry(90). Ry(90) takes (1,0,0) to
    // (0,0,-1), Rx(90) takes that to (0,1,0). (The other order would give (0,0,-1).)
    let text = "HIERARCHY
ROOT Hips
{
\tOFFSET 0 0 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
\tJOINT Arm
\t{
OFFSET 0 1 0
CHANNELS 3 Zrotation Xrotation Yrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 1 0 0
\t\t}
\t}
}
MOTION
Frames: 1
Frame Time: 0.04
0 0 0 0 0 0 0 90 90
";
    let bvh = Bvh::parse(text).unwrap();
    assert_eq!(bvh.fps(), 25.0);
    assert_close(bvh.joint_positions(0)[1], [0.0, 1.0, 0.0], 1e-12, "Arm");
    assert_close(
        bvh.end_site_positions(0)[1].unwrap(),
        [0.0, 2.0, 0.0],
        1e-12,
        "Arm end",
    );
}

const TINY_POSITIONS: &str = "HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Chest
  {
    OFFSET 5 1 7
    CHANNELS 4 Yposition Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 1 0 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.0333333
0 0 0 0 0 0 3 0 0 0
0 0 0 90 0 0 3 90 0 0
";

#[test]
fn tiny_position_channels_on_a_child_replace_only_their_axis() {
    let bvh = Bvh::parse(TINY_POSITIONS).unwrap();
    // Yposition 3 replaces the offset's Y; X and Z keep the offset.
    assert_close(bvh.joint_positions(0)[1], [5.0, 3.0, 7.0], 1e-12, "Chest");
    assert_close(
        bvh.end_site_positions(0)[1].unwrap(),
        [6.0, 3.0, 7.0],
        1e-12,
        "Chest end",
    );
    // Root Rz(90) takes (5,3,7) to (-3,5,7); the End Site turns by 180° in total.
    assert_close(bvh.joint_positions(1)[1], [-3.0, 5.0, 7.0], 1e-12, "Chest");
    assert_close(
        bvh.end_site_positions(1)[1].unwrap(),
        [-4.0, 5.0, 7.0],
        1e-12,
        "Chest end",
    );
    assert_round_trip(&bvh);
}

#[test]
fn tiny_files_round_trip() {
    assert_round_trip(&Bvh::parse(TINY_ZYX).unwrap());
    let bvh = Bvh::parse(TINY_ZYX).unwrap();
    let text = bvh.to_bvh_string();
    assert!(text.starts_with("HIERARCHY\nROOT Hips\n{\n\tOFFSET 0 0 0\n"));
    assert!(text.contains("\t\tEnd Site\n\t\t{\n\t\t\tOFFSET 0 2 0\n\t\t}\n\t}\n}\nMOTION\n"));
    assert!(text.ends_with("Frames: 2\nFrame Time: 0.5\n1 2 3 90 0 90 0 0 0\n0 0 0 0 0 0 0 0 90\n"));
}

#[test]
fn tolerates_common_variations() {
    let reference = Bvh::parse(TINY_ZYX).unwrap();
    let wrapped = TINY_ZYX
        .replace("1 2 3 90 0 90 0 0 0\n", "1 2 3 90\n0 90 0 0 0\n")
        .replace("0 0 0 0 0 0 0 0 90\n", "0 0 0 0 0\n0 0\n0 90\n");
    let variants = [
        ("CRLF", TINY_ZYX.replace('\n', "\r\n")),
        ("lone CR", TINY_ZYX.replace('\n', "\r")),
        ("tabs", TINY_ZYX.replace("  ", "\t")),
        (
            "unindented",
            TINY_ZYX
                .lines()
                .map(str::trim)
                .collect::<Vec<_>>()
                .join("\n"),
        ),
        ("no final newline", TINY_ZYX.trim_end().to_owned()),
        ("trailing whitespace", TINY_ZYX.replace('\n', " \t \n")),
        ("BOM", format!("\u{feff}{TINY_ZYX}")),
        ("leading dot", TINY_ZYX.replace("0.5", ".5")),
        ("glued Frames", TINY_ZYX.replace("Frames: 2", "Frames:2")),
        ("no-colon Frames", TINY_ZYX.replace("Frames: 2", "Frames 2")),
        (
            "spaced colon",
            TINY_ZYX.replace("Frame Time: 0.5", "Frame Time : 0.5"),
        ),
        (
            "glued brace",
            TINY_ZYX.replace("ROOT Hips\n{", "ROOT Hips {"),
        ),
        (
            "lowercase",
            TINY_ZYX
                .replace("End Site", "end site")
                .replace("Zrotation", "zrotation"),
        ),
        ("wrapped rows", wrapped),
        ("blank lines", TINY_ZYX.replace('\n', "\n\n")),
    ];
    for (what, text) in variants {
        let bvh = Bvh::parse(&text).unwrap_or_else(|e| panic!("{what}: {e}"));
        assert_eq!(bvh.frame_count(), 2, "{what}");
        assert_eq!(bvh.frame_time, 0.5, "{what}");
        for f in 0..2 {
            assert_eq!(bvh.frame(f), reference.frame(f), "{what}");
            assert_eq!(
                bvh.end_site_positions(f),
                reference.end_site_positions(f),
                "{what}"
            );
        }
    }
}

#[test]
fn zero_frames_is_a_valid_skeleton() {
    let text =
        TINY_ZYX.split("Frames:").next().unwrap().to_owned() + "Frames: 0\nFrame Time: 0.5\n";
    let bvh = Bvh::parse(&text).unwrap();
    assert_eq!(bvh.frame_count(), 0);
    assert_eq!(bvh.joints.len(), 2);
    assert_round_trip(&bvh);
}

// ---------------------------------------------------------------------------------------
// from_parts

fn tiny_parts() -> (Vec<BvhJoint>, f64, Vec<f64>) {
    let bvh = Bvh::parse(TINY_ZYX).unwrap();
    (bvh.joints.clone(), bvh.frame_time, bvh.data().to_vec())
}

#[test]
fn from_parts_accepts_parsed_parts() {
    let (joints, frame_time, data) = tiny_parts();
    let bvh = Bvh::from_parts(joints, frame_time, data).unwrap();
    assert_close(bvh.joint_positions(0)[1], [1.0, 2.0, 4.0], 1e-12, "Chest");
}

#[test]
fn from_parts_rejects_inconsistent_parts() {
    let check = |joints: Vec<BvhJoint>, frame_time: f64, data: Vec<f64>, needle: &str| {
        let e = Bvh::from_parts(joints, frame_time, data).expect_err(needle);
        let message = e.to_string();
        assert!(message.contains(needle), "{message:?} lacks {needle:?}");
        assert_one_line(&message);
    };
    let (joints, t, data) = tiny_parts();

    let mut j = joints.clone();
    j[0].parent = Some(1);
    check(j, t, data.clone(), "root joint Hips has parent 1");

    let mut j = joints.clone();
    j[1].parent = None;
    check(j, t, data.clone(), "only joint 0 may be the root");

    let mut j = joints.clone();
    j[1].parent = Some(1);
    check(j, t, data.clone(), "depth-first order");

    let mut j = joints.clone();
    j[1].channel_offset = 5;
    check(j, t, data.clone(), "channel_offset 5, expected 6");

    let mut j = joints.clone();
    j[1].channels.push(Channel::Zrotation);
    check(j, t, data.clone(), "twice");

    let mut j = joints.clone();
    j[1].name = "Hips".into();
    check(j, t, data.clone(), "both called Hips");

    let mut j = joints.clone();
    j[1].name = "Left Arm".into();
    check(j, t, data.clone(), "not one token");

    let mut j = joints.clone();
    j[1].end_site = Some([0.0, f64::NAN, 0.0]);
    check(j, t, data.clone(), "non-finite offset");

    check(Vec::new(), t, Vec::new(), "no joints");
    check(
        joints.clone(),
        0.0,
        data.clone(),
        "frame_time 0 must be positive",
    );
    check(
        joints.clone(),
        f64::INFINITY,
        data.clone(),
        "must be positive",
    );
    check(
        joints.clone(),
        t,
        data[..10].to_vec(),
        "not whole frames of 9",
    );
    let mut d = data.clone();
    d[11] = f64::NAN;
    check(joints.clone(), t, d, "frame 1 channel 2 is NaN");

    let mut j = joints;
    for joint in &mut j {
        joint.channels.clear();
    }
    j[1].channel_offset = 0;
    check(j, t, Vec::new(), "no channels");
}

// ---------------------------------------------------------------------------------------
// read()

#[test]
fn read_names_the_path_of_a_missing_file() {
    let path = Path::new("/nonexistent/monocap/walk.bvh");
    let e = Bvh::read(path).unwrap_err();
    assert!(matches!(e, BvhError::Io { .. }));
    assert!(
        e.to_string().contains("/nonexistent/monocap/walk.bvh"),
        "{e}"
    );
}

#[test]
fn read_refuses_a_file_over_the_size_cap_before_reading() {
    let path = std::env::temp_dir().join(format!("monocap-bvh-huge-{}.bvh", std::process::id()));
    let file = fs::File::create(&path).unwrap();
    // Sparse: takes no disk space, and reading it would take a while.
    file.set_len(MAX_FILE_BYTES + 1).unwrap();
    drop(file);
    let start = Instant::now();
    let result = Bvh::read(&path);
    fs::remove_file(&path).unwrap();
    let e = result.unwrap_err();
    assert!(matches!(e, BvhError::FileTooLarge { .. }), "{e}");
    assert!(e.to_string().contains("more than the limit"), "{e}");
    assert!(start.elapsed() < Duration::from_secs(1));
}

// ---------------------------------------------------------------------------------------
// Malformed input

#[test]
fn empty_input() {
    parse_err("", "file is empty");
    parse_err(" \r\n\t\n", "file is empty");
    parse_err("\u{feff}", "file is empty");
}

#[test]
fn binary_garbage() {
    let bytes: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    let text = String::from_utf8_lossy(&bytes);
    let e = Bvh::parse(&text).unwrap_err();
    assert_one_line(&e.to_string());
    parse_err(&"\0".repeat(100_000), "expected HIERARCHY");
    // Echoed tokens are escaped and shortened.
    let e = parse_err(
        &format!("\u{1b}[31m{}", "A".repeat(100_000)),
        "expected HIERARCHY",
    );
    assert!(!e.to_string().contains('\u{1b}'));
}

#[test]
fn truncated_hierarchy() {
    let motion = TINY_ZYX.find("MOTION").unwrap();
    for cut in 1..motion {
        let Some(prefix) = TINY_ZYX.get(..cut) else {
            continue;
        };
        let e = Bvh::parse(prefix).expect_err(prefix);
        assert_one_line(&e.to_string());
    }
    let cut = TINY_ZYX.find("    End Site").unwrap();
    parse_err(
        &TINY_ZYX[..cut],
        "line 10: file ends inside joint Chest: missing '}'",
    );
    let cut = TINY_ZYX.find("0 2 0").unwrap();
    parse_err(
        &TINY_ZYX[..cut],
        "file ends in the OFFSET of the End Site of joint Chest",
    );
    parse_err(&TINY_ZYX[..motion], "missing MOTION");
}

#[test]
fn truncated_motion() {
    let (text, _) = read_fixture(BANDAI_FIXTURE);
    // At a line end after 10 frames.
    let line_start = |n: usize| text.match_indices('\n').nth(n - 2).unwrap().0 + 1;
    let tenth = line_start(145);
    parse_err(
        &text[..tenth],
        "expected 20 frames of 132 numbers, file ends after 10 frames",
    );
    // In the middle of a line, and in the middle of a number.
    parse_err(&text[..tenth + 300], "file ends after 10 frames");
    parse_err(&text[..tenth + 301], "file ends after 10 frames");
    // In the MOTION header.
    let header = text.find("Frame Time").unwrap();
    parse_err(&text[..header], "file ends before 'Frame Time:'");
    parse_err(&text[..header + 11], "file ends after 'Frame Time:'");
    // Wrapped rows cut short.
    let wrapped = TINY_ZYX
        .replace("1 2 3 90 0 90 0 0 0\n", "1 2 3 90\n0 90 0 0 0\n")
        .replace("0 0 0 0 0 0 0 0 90\n", "0 0 0 0\n0 0\n");
    parse_err(
        &wrapped,
        "expected 2 frames of 9 numbers, file ends after 1 frames",
    );
}

#[test]
fn bad_frame_counts() {
    parse_err(
        &TINY_ZYX.replace("Frames: 2", "Frames: -5"),
        "line 17: frame count -5 is negative",
    );
    parse_err(
        &TINY_ZYX.replace("Frames: 2", "Frames: 2.5"),
        "frame count '2.5' is not a whole number",
    );
    parse_err(
        &TINY_ZYX.replace("Frames: 2", "Frames: two"),
        "is not a whole number",
    );
    parse_err(
        &TINY_ZYX.replace("Frames: 2", "Frames: 99999999999999999999999999"),
        "declared 99999999999999999999999999 frames, more than the limit of 10000000",
    );
    parse_err(
        &TINY_ZYX.replace("Frames: 2", "Frame: 2"),
        "expected 'Frames:', found 'Frame:'",
    );
}

#[test]
fn huge_declared_frame_counts_fail_fast_without_allocating() {
    let start = Instant::now();
    LARGEST_REQUEST.store(0, Ordering::Relaxed);
    parse_err(
        &TINY_ZYX.replace("Frames: 2", "Frames: 1000000000"),
        "declared 1000000000 frames, more than the limit of 10000000",
    );
    // Within the frame limit but 9,000,000 × 9 numbers (648 MB) declared, two frames given.
    parse_err(
        &TINY_ZYX.replace("Frames: 2", "Frames: 9000000"),
        "expected 9000000 frames of 9 numbers, file ends after 2 frames",
    );
    // 10,000,000 frames of 132 numbers is over the total limit.
    let (text, _) = read_fixture(BANDAI_FIXTURE);
    parse_err(
        &text.replace("Frames:\t20", "Frames:\t10000000"),
        "more than the limit of 200000000 numbers",
    );
    assert!(LARGEST_REQUEST.load(Ordering::Relaxed) < HUGE_REQUEST);
    assert!(start.elapsed() < Duration::from_secs(2));
}

#[test]
fn bad_frame_time() {
    parse_err(
        &TINY_ZYX.replace("Frame Time: 0.5", "Frame Time: 0"),
        "line 18: Frame Time 0 must be positive",
    );
    parse_err(
        &TINY_ZYX.replace("Frame Time: 0.5", "Frame Time: -0.1"),
        "Frame Time -0.1 must be positive",
    );
    parse_err(
        &TINY_ZYX.replace("Frame Time: 0.5", "Frame Time: NaN"),
        "Frame Time NaN must be positive",
    );
    parse_err(
        &TINY_ZYX.replace("Frame Time: 0.5", "Frame Time: inf"),
        "Frame Time inf must be positive",
    );
    parse_err(
        &TINY_ZYX.replace("Frame Time: 0.5", "Frame Time: fast"),
        "'fast' is not a number",
    );
    parse_err(
        &TINY_ZYX.replace("Frame Time: 0.5", "FPS: 2"),
        "expected 'Frame Time:', found 'FPS:'",
    );
}

#[test]
fn bad_numbers() {
    parse_err(
        &TINY_ZYX.replace("0 0 0 0 0 0 0 0 90", "0 0 0 0 abc 0 0 0 90"),
        "line 20: 'abc' is not a number",
    );
    parse_err(
        &TINY_ZYX.replace("0 0 0 0 0 0 0 0 90", "0 0 0 0 nan 0 0 0 90"),
        "line 20: 'nan' is not a finite number",
    );
    parse_err(
        &TINY_ZYX.replace("1 2 3 90", "1 2 1e999 90"),
        "line 19: '1e999' is not a finite number",
    );
    parse_err(
        &TINY_ZYX.replace("OFFSET 0 1 0", "OFFSET 0 x1 0"),
        "line 8: 'x1' is not a number",
    );
    parse_err(
        &TINY_ZYX.replace("OFFSET 0 1 0", "OFFSET 0 inf 0"),
        "'inf' is not a finite number",
    );
    parse_err(
        &TINY_ZYX.replace("OFFSET 0 1 0", "OFFSET 0 1"),
        "line 8: OFFSET of Chest has 2 numbers, expected 3",
    );
}

#[test]
fn bad_rows() {
    parse_err(
        &TINY_ZYX.replace("1 2 3 90 0 90 0 0 0", "1 2 3 90 0 90 0 0"),
        "line 19: frame 0 has 8 numbers, expected 9",
    );
    parse_err(
        &TINY_ZYX.replace("0 0 0 0 0 0 0 0 90", "0 0 0 0 0 0 0 0 90 1"),
        "line 20: frame 1 has 10 numbers, expected 9",
    );
    parse_err(
        &format!("{TINY_ZYX}0 0 0 0 0 0 0 0 0\n"),
        "line 21: data continues after the declared 2 frames of 9 numbers",
    );
    parse_err(
        &format!("{TINY_ZYX}\n\nMOTION\n"),
        "line 23: data continues",
    );
}

#[test]
fn bad_channels() {
    parse_err(
        &TINY_ZYX.replace(
            "CHANNELS 3 Zrotation Yrotation",
            "CHANNELS 3 Wrotation Yrotation",
        ),
        "line 9: unknown channel 'Wrotation' on joint Chest",
    );
    parse_err(
        &TINY_ZYX.replace("CHANNELS 3", "CHANNELS 4"),
        "line 9: joint Chest declares 4 channels but lists 3",
    );
    parse_err(
        &TINY_ZYX.replace("CHANNELS 3", "CHANNELS 2"),
        "line 9: joint Chest declares 2 channels but lists more",
    );
    parse_err(
        &TINY_ZYX.replace("CHANNELS 3", "CHANNELS 7"),
        "line 9: joint Chest declares 7 channels, more than the limit of 6",
    );
    parse_err(
        &TINY_ZYX.replace("CHANNELS 3", "CHANNELS 4000000000000000000000"),
        "more than the limit of 6",
    );
    parse_err(
        &TINY_ZYX.replace("CHANNELS 3", "CHANNELS -1"),
        "channel count '-1' of joint Chest is not a whole number",
    );
    parse_err(
        &TINY_ZYX.replace(
            "Zrotation Yrotation Xrotation\n    End",
            "Zrotation Yrotation Zrotation\n    End",
        ),
        "line 9: channel Zrotation is listed twice on joint Chest",
    );
}

#[test]
fn channels_after_children_are_rejected() {
    let text = TINY_ZYX
        .replace("    CHANNELS 3 Zrotation Yrotation Xrotation\n", "")
        .replace(
            "    End Site",
            "    JOINT Arm\n    {\n    OFFSET 0 1 0\n    }\n    CHANNELS 3 Zrotation Yrotation Xrotation\n    End Site",
        );
    parse_err(
        &text,
        "line 13: CHANNELS of joint Chest must come before its child joints",
    );
}

#[test]
fn bad_structure() {
    parse_err(
        &TINY_ZYX.replace("ROOT Hips\n{\n", "ROOT Hips\n"),
        "line 3: expected '{' after ROOT Hips, found 'OFFSET'",
    );
    parse_err(&TINY_ZYX.replace("ROOT Hips", "ROOT {"), "ROOT has no name");
    parse_err(
        &TINY_ZYX.replace("}\nMOTION", "MOTION"),
        "line 15: MOTION inside joint Hips: missing '}'",
    );
    parse_err(
        &TINY_ZYX.replace("}\nMOTION", "}\n}\nMOTION"),
        "line 16: unbalanced braces",
    );
    parse_err(
        &TINY_ZYX.replace("HIERARCHY", "HEIRARCHY"),
        "line 1: expected HIERARCHY, found 'HEIRARCHY'",
    );
    parse_err(
        &TINY_ZYX.replace("ROOT", "JOINT"),
        "line 2: expected ROOT after HIERARCHY, found 'JOINT'",
    );
    parse_err(
        &TINY_ZYX.replace("MOTION", "MOTON"),
        "line 16: expected MOTION after the hierarchy, found 'MOTON'",
    );
    parse_err(
        &TINY_ZYX.replace("MOTION", ""),
        "expected MOTION after the hierarchy, found 'Frames:'",
    );
    parse_err(
        &TINY_ZYX.replace("  OFFSET 0 0 0\n", ""),
        "line 14: joint Hips has no OFFSET",
    );
    parse_err(
        &TINY_ZYX.replace("OFFSET 0 1 0", "OFFSET 0 1 0 OFFSET 0 1 0"),
        "joint Chest has a second OFFSET",
    );
    parse_err(
        &TINY_ZYX.replace("OFFSET 0 1 0", "OFFSET 0 1 0 ROTATION 0 0 0"),
        "line 8: unknown keyword 'ROTATION' in joint Chest",
    );
    parse_err(
        &TINY_ZYX.replace("JOINT Chest", "JOINT Hips"),
        "line 6: duplicate joint name Hips (first declared on line 2)",
    );
    parse_err(
        &TINY_ZYX.replace("End Site", "End Effector"),
        "expected 'Site' after 'End', found 'Effector'",
    );
    parse_err(
        &TINY_ZYX.replace("OFFSET 0 2 0", ""),
        "End Site of joint Chest has no OFFSET",
    );
    parse_err(
        &TINY_ZYX.replace("OFFSET 0 2 0", "OFFSET 0 2 0 OFFSET 0 2 0"),
        "expected '}' to close the End Site of joint Chest (opened on line 10), found 'OFFSET'",
    );
    parse_err(
        &TINY_ZYX.replace("MOTION", "ROOT Other\n{\nOFFSET 0 0 0\n}\nMOTION"),
        "line 16: a second ROOT is not supported",
    );
    let no_channels = TINY_ZYX
        .replace(
            "CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation",
            "CHANNELS 0",
        )
        .replace("CHANNELS 3 Zrotation Yrotation Xrotation", "");
    parse_err(&no_channels, "the skeleton has no channels");
}

#[test]
fn limits_on_joints_depth_and_names() {
    let skeleton = |body: &str| {
        format!("HIERARCHY\nROOT R\n{{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\n{body}}}\nMOTION\nFrames: 0\nFrame Time: 1\n")
    };
    let siblings: String = (0..1100)
        .map(|i| format!("JOINT J{i}\n{{\nOFFSET 0 1 0\n}}\n"))
        .collect();
    parse_err(&skeleton(&siblings), "more than the limit of 1024 joints");
    let deep: String = (0..300)
        .map(|i| format!("JOINT J{i} {{ OFFSET 0 1 0\n"))
        .chain((0..300).map(|_| "}\n".to_owned()))
        .collect();
    parse_err(&skeleton(&deep), "nested deeper than the limit of 256");
    let long = format!("JOINT {}\n{{\nOFFSET 0 1 0\n}}\n", "n".repeat(1000));
    parse_err(
        &skeleton(&long),
        "1000 bytes long, more than the limit of 256",
    );
    // 1000 joints and nesting 200 are fine.
    let ok: String = (0..1000)
        .map(|i| format!("JOINT J{i}\n{{\nOFFSET 0 1 0\n}}\n"))
        .collect();
    assert_eq!(Bvh::parse(&skeleton(&ok)).unwrap().joints.len(), 1001);
}

#[test]
fn channel_names() {
    for c in Channel::ALL {
        assert_eq!(Channel::from_name(c.name()), Some(c));
        assert_eq!(Channel::from_name(&c.name().to_uppercase()), Some(c));
        assert_eq!(c.to_string(), c.name());
    }
    assert_eq!(Channel::Zrotation.name(), "Zrotation");
    assert_eq!(Channel::from_name("Wrotation"), None);
}

// ---------------------------------------------------------------------------------------
// Fuzzing: never panic; anything accepted can be used and written back.

/// Runs everything a caller might do with a parsed file.
fn exercise(bvh: &Bvh) {
    let mut world = Vec::new();
    for f in 0..bvh.frame_count() {
        bvh.world_transforms(f, &mut world);
        assert_eq!(world.len(), bvh.joints.len());
        assert_eq!(bvh.joint_positions(f).len(), bvh.joints.len());
        assert_eq!(bvh.end_site_positions(f).len(), bvh.joints.len());
    }
    let back = Bvh::parse(&bvh.to_bvh_string()).expect("written text reads back");
    assert_eq!(back.frame_count(), bvh.frame_count());
    assert_eq!(back.channel_count(), bvh.channel_count());
    assert_eq!(back.joints.len(), bvh.joints.len());
}

fn parse_and_exercise(text: &str) {
    match Bvh::parse(text) {
        Ok(bvh) => exercise(&bvh),
        Err(e) => assert_one_line(&e.to_string()),
    }
}

#[derive(Clone, Debug)]
enum Mutation {
    Flip(usize, u8),
    Truncate(usize),
    DeleteLine(usize),
    DuplicateLine(usize),
    SwapLines(usize, usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        4 => (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Mutation::Flip(i, b)),
        1 => any::<usize>().prop_map(Mutation::Truncate),
        2 => any::<usize>().prop_map(Mutation::DeleteLine),
        1 => any::<usize>().prop_map(Mutation::DuplicateLine),
        1 => (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Mutation::SwapLines(a, b)),
    ]
}

fn apply(bytes: &mut Vec<u8>, m: &Mutation) {
    if bytes.is_empty() {
        return;
    }
    let line_starts: Vec<usize> = std::iter::once(0)
        .chain(
            bytes
                .iter()
                .enumerate()
                .filter(|(_, &b)| b == b'\n')
                .map(|(i, _)| i + 1),
        )
        .filter(|&i| i < bytes.len())
        .collect();
    let line = |n: usize| {
        let k = n % line_starts.len();
        let end = line_starts.get(k + 1).copied().unwrap_or(bytes.len());
        line_starts[k]..end
    };
    match *m {
        Mutation::Flip(i, b) => {
            let i = i % bytes.len();
            bytes[i] = b;
        }
        Mutation::Truncate(i) => bytes.truncate(i % bytes.len()),
        Mutation::DeleteLine(n) => {
            bytes.drain(line(n));
        }
        Mutation::DuplicateLine(n) => {
            let r = line(n);
            let copy = bytes[r.clone()].to_vec();
            bytes.splice(r.start..r.start, copy);
        }
        Mutation::SwapLines(a, b) => {
            let (ra, rb) = (line(a), line(b));
            if ra.start < rb.start {
                let (la, lb) = (bytes[ra.clone()].to_vec(), bytes[rb.clone()].to_vec());
                bytes.splice(rb, la);
                bytes.splice(ra, lb);
            }
        }
    }
}

fn token() -> impl Strategy<Value = String> {
    prop_oneof![
        prop::sample::select(vec![
            "HIERARCHY",
            "ROOT",
            "JOINT",
            "End",
            "Site",
            "{",
            "}",
            "OFFSET",
            "CHANNELS",
            "Xposition",
            "Yposition",
            "Zposition",
            "Xrotation",
            "Yrotation",
            "Zrotation",
            "MOTION",
            "Frames:",
            "Frame",
            "Time:",
            "0",
            "1",
            "2",
            "3",
            "6",
            "-1",
            "0.5",
            "1e308",
            "nan",
            "inf",
            "Hips",
            "\n",
            "\r\n",
            " ",
            "\t",
        ])
        .prop_map(str::to_owned),
        "[ -~]{0,6}",
        any::<f64>().prop_map(|v| v.to_string()),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..4096)) {
        parse_and_exercise(&String::from_utf8_lossy(&bytes));
    }

    #[test]
    fn random_tokens_never_panic(tokens in prop::collection::vec(token(), 0..200)) {
        parse_and_exercise(&tokens.join(" "));
    }

    #[test]
    fn mutated_tiny_file_never_panics(mutations in prop::collection::vec(mutation(), 1..6)) {
        let mut bytes = TINY_POSITIONS.as_bytes().to_vec();
        for m in &mutations {
            apply(&mut bytes, m);
        }
        parse_and_exercise(&String::from_utf8_lossy(&bytes));
    }

    #[test]
    fn mutated_fixture_never_panics(mutations in prop::collection::vec(mutation(), 1..6)) {
        let mut bytes = fs::read(fixture(BANDAI_FIXTURE)).unwrap();
        for m in &mutations {
            apply(&mut bytes, m);
        }
        parse_and_exercise(&String::from_utf8_lossy(&bytes));
    }
}
