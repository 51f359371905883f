//! The one table of the model's parameters (method.md §2).
//!
//! Everything that names, bounds or steps a parameter reads this file: the
//! kinematics, the tracker's simplex (length scales), the exports (BVH channel
//! values) and the API (names in the motion JSON and keyframes).
//!
//! Units are the user's: translations in centimetres, angles in degrees. A
//! motion vector is therefore exactly what the motion JSON prints.

/// Number of motion parameters β.
pub const MOTION_COUNT: usize = 30;
/// Number of shape parameters α.
pub const SHAPE_COUNT: usize = 12;

/// A motion vector β: 30 values in the order of [`MOTION`].
pub type Pose = [f64; MOTION_COUNT];
/// A shape vector α: 12 scale factors in the order of [`SHAPE`] (1.0 = standard body).
pub type ShapeValues = [f64; SHAPE_COUNT];

/// The six groups optimised together (method.md §5, "Hierarchical").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Group {
    Global,
    Torso,
    LeftArm,
    RightArm,
    LeftLeg,
    RightLeg,
}

impl Group {
    /// All groups in the order the hierarchical search visits them.
    pub const ALL: [Group; 6] = [
        Group::Global,
        Group::Torso,
        Group::LeftArm,
        Group::RightArm,
        Group::LeftLeg,
        Group::RightLeg,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Group::Global => "global",
            Group::Torso => "torso",
            Group::LeftArm => "left_arm",
            Group::RightArm => "right_arm",
            Group::LeftLeg => "left_leg",
            Group::RightLeg => "right_leg",
        }
    }

    /// Indices into a [`Pose`] of this group's parameters (contiguous by construction).
    pub fn range(self) -> std::ops::Range<usize> {
        match self {
            Group::Global => 0..6,
            Group::Torso => 6..12,
            Group::LeftArm => 12..16,
            Group::RightArm => 16..20,
            Group::LeftLeg => 20..25,
            Group::RightLeg => 25..30,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unit {
    Cm,
    Deg,
}

impl Unit {
    pub fn name(self) -> &'static str {
        match self {
            Unit::Cm => "cm",
            Unit::Deg => "deg",
        }
    }
}

/// A coordinate axis of a joint's local frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    X,
    Y,
    Z,
}

/// One motion parameter.
#[derive(Clone, Copy, Debug)]
pub struct MotionParam {
    /// Stable name used in the motion JSON, keyframes and the API.
    pub name: &'static str,
    pub group: Group,
    pub unit: Unit,
    /// Anatomical (or practical) lower and upper limit, inclusive (Eq. 7).
    pub lo: f64,
    pub hi: f64,
    /// Characteristic length scale λ: the simplex's initial step (method.md §5).
    pub scale: f64,
    /// Local axis the value rotates about (angles) or translates along (root).
    pub axis: Axis,
    /// The rotation applied is `sign * value` about `axis`, so that a positive value
    /// means the same movement on the left and right side (flexion, abduction, …).
    pub sign: f64,
    /// What a positive value does.
    pub doc: &'static str,
}

/// One row of the table, in column order.
#[allow(clippy::too_many_arguments)]
const fn p(
    name: &'static str,
    group: Group,
    unit: Unit,
    lo: f64,
    hi: f64,
    scale: f64,
    axis: Axis,
    sign: f64,
    doc: &'static str,
) -> MotionParam {
    MotionParam {
        name,
        group,
        unit,
        lo,
        hi,
        scale,
        axis,
        sign,
        doc,
    }
}

use Axis::{X, Y, Z};
use Group::*;
use Unit::{Cm, Deg};

/// Translations are bounded only to keep arithmetic sane (1 km).
const FAR: f64 = 100_000.0;

/// The 30 motion parameters, grouped as in method.md §2.
///
/// Three-angle joints rotate as `Rz · Rx · Ry` in their parent's frame (the twist
/// about the bone, Y, innermost); the root rotates as `Ry · Rx · Rz` (heading
/// outermost). The standing rest pose (all zeros) faces +Z with Y up and the
/// arms hanging at the sides, palms facing the thighs.
#[rustfmt::skip]
pub const MOTION: [MotionParam; MOTION_COUNT] = [
    //  name            group     unit  lo      hi     λ     axis sign  positive means
    p("root_tx",      Global,   Cm,  -FAR,   FAR,    4.0,  X,  1.0, "hips move right (+X)"),
    p("root_ty",      Global,   Cm,  -FAR,   FAR,    4.0,  Y,  1.0, "hips move up"),
    p("root_tz",      Global,   Cm,  -FAR,   FAR,    8.0,  Z,  1.0, "hips move towards +Z"),
    p("root_rx",      Global,   Deg, -100.0, 100.0,  6.0,  X,  1.0, "body pitches forwards"),
    p("root_ry",      Global,   Deg, -720.0, 720.0,  10.0, Y,  1.0, "body turns to its left (heading)"),
    p("root_rz",      Global,   Deg, -100.0, 100.0,  6.0,  Z,  1.0, "body rolls towards its right"),
    p("spine_x",      Torso,    Deg, -30.0,  90.0,   8.0,  X,  1.0, "spine bends forwards"),
    p("spine_z",      Torso,    Deg, -40.0,  40.0,   6.0,  Z,  1.0, "spine bends to its right"),
    p("spine_y",      Torso,    Deg, -50.0,  50.0,   8.0,  Y,  1.0, "spine twists to its left"),
    p("neck_x",       Torso,    Deg, -50.0,  70.0,   8.0,  X,  1.0, "head nods forwards"),
    p("neck_z",       Torso,    Deg, -45.0,  45.0,   8.0,  Z,  1.0, "head tilts to its right"),
    p("neck_y",       Torso,    Deg, -80.0,  80.0,   10.0, Y,  1.0, "head turns to its left"),
    p("l_shoulder_x", LeftArm,  Deg, -70.0,  180.0,  12.0, X, -1.0, "left arm raises forwards"),
    p("l_shoulder_z", LeftArm,  Deg, -40.0,  180.0,  12.0, Z,  1.0, "left arm raises sideways"),
    p("l_shoulder_y", LeftArm,  Deg, -100.0, 100.0,  15.0, Y,  1.0, "left arm twists outwards"),
    p("l_elbow",      LeftArm,  Deg, -5.0,   160.0,  12.0, X, -1.0, "left elbow bends"),
    p("r_shoulder_x", RightArm, Deg, -70.0,  180.0,  12.0, X, -1.0, "right arm raises forwards"),
    p("r_shoulder_z", RightArm, Deg, -40.0,  180.0,  12.0, Z, -1.0, "right arm raises sideways"),
    p("r_shoulder_y", RightArm, Deg, -100.0, 100.0,  15.0, Y, -1.0, "right arm twists outwards"),
    p("r_elbow",      RightArm, Deg, -5.0,   160.0,  12.0, X, -1.0, "right elbow bends"),
    p("l_hip_x",      LeftLeg,  Deg, -50.0,  140.0,  10.0, X, -1.0, "left thigh raises forwards"),
    p("l_hip_z",      LeftLeg,  Deg, -35.0,  90.0,   8.0,  Z,  1.0, "left thigh raises sideways"),
    p("l_hip_y",      LeftLeg,  Deg, -70.0,  70.0,   10.0, Y,  1.0, "left thigh twists outwards"),
    p("l_knee",       LeftLeg,  Deg, -5.0,   160.0,  12.0, X,  1.0, "left knee bends"),
    p("l_ankle",      LeftLeg,  Deg, -45.0,  70.0,   8.0,  X,  1.0, "left toes point down"),
    p("r_hip_x",      RightLeg, Deg, -50.0,  140.0,  10.0, X, -1.0, "right thigh raises forwards"),
    p("r_hip_z",      RightLeg, Deg, -35.0,  90.0,   8.0,  Z, -1.0, "right thigh raises sideways"),
    p("r_hip_y",      RightLeg, Deg, -70.0,  70.0,   10.0, Y, -1.0, "right thigh twists outwards"),
    p("r_knee",       RightLeg, Deg, -5.0,   160.0,  12.0, X,  1.0, "right knee bends"),
    p("r_ankle",      RightLeg, Deg, -45.0,  70.0,   8.0,  X,  1.0, "right toes point down"),
];

/// Indices of named parameters, for code that addresses one directly.
pub mod ix {
    pub const ROOT_TX: usize = 0;
    pub const ROOT_TY: usize = 1;
    pub const ROOT_TZ: usize = 2;
    pub const ROOT_RX: usize = 3;
    pub const ROOT_RY: usize = 4;
    pub const ROOT_RZ: usize = 5;
    pub const SPINE: usize = 6;
    pub const NECK: usize = 9;
    pub const L_SHOULDER: usize = 12;
    pub const L_ELBOW: usize = 15;
    pub const R_SHOULDER: usize = 16;
    pub const R_ELBOW: usize = 19;
    pub const L_HIP: usize = 20;
    pub const L_KNEE: usize = 23;
    pub const L_ANKLE: usize = 24;
    pub const R_HIP: usize = 25;
    pub const R_KNEE: usize = 28;
    pub const R_ANKLE: usize = 29;
}

/// One shape parameter: a scale factor on the standard body (about 175 cm tall).
#[derive(Clone, Copy, Debug)]
pub struct ShapeParam {
    pub name: &'static str,
    /// Plausible range of the factor for an adult.
    pub lo: f64,
    pub hi: f64,
    /// Simplex step for shape fitting.
    pub scale: f64,
    pub doc: &'static str,
}

const fn s(name: &'static str, lo: f64, hi: f64, doc: &'static str) -> ShapeParam {
    ShapeParam {
        name,
        lo,
        hi,
        scale: 0.05,
        doc,
    }
}

/// The 12 shape parameters (method.md §2); left and right share each value.
#[rustfmt::skip]
pub const SHAPE: [ShapeParam; SHAPE_COUNT] = [
    s("head",          0.7, 1.4, "head size"),
    s("torso_height",  0.7, 1.4, "hips to neck"),
    s("torso_width",   0.6, 1.6, "chest and shoulder width"),
    s("torso_depth",   0.6, 1.8, "chest and belly depth"),
    s("pelvis_width",  0.6, 1.6, "pelvis width and hip joint spacing"),
    s("upper_arm",     0.7, 1.4, "shoulder to elbow"),
    s("forearm",       0.7, 1.4, "elbow to fingertips"),
    s("arm_thickness", 0.5, 2.0, "arm radii"),
    s("thigh",         0.7, 1.4, "hip to knee"),
    s("shin",          0.7, 1.4, "knee to ankle"),
    s("leg_thickness", 0.5, 2.0, "leg radii"),
    s("foot",          0.7, 1.4, "foot length"),
];

/// Indices into a [`ShapeValues`].
pub mod sx {
    pub const HEAD: usize = 0;
    pub const TORSO_HEIGHT: usize = 1;
    pub const TORSO_WIDTH: usize = 2;
    pub const TORSO_DEPTH: usize = 3;
    pub const PELVIS_WIDTH: usize = 4;
    pub const UPPER_ARM: usize = 5;
    pub const FOREARM: usize = 6;
    pub const ARM_THICKNESS: usize = 7;
    pub const THIGH: usize = 8;
    pub const SHIN: usize = 9;
    pub const LEG_THICKNESS: usize = 10;
    pub const FOOT: usize = 11;
}

/// The standard body: every factor 1.
pub const STANDARD_SHAPE: ShapeValues = [1.0; SHAPE_COUNT];

/// The typical performer of the motion captures in `../shared/data/mocap` (Bandai
/// Namco and CMU), as `monocap synth` retargets them: for each source, the median
/// of each value over its captures, then the mean of the two sources
/// ([`crate::track::prior::typical_shape`]). The standard body, drawn from
/// anthropometric tables, has a longer trunk between the joint centres (hips to
/// neck 49 cm, the performers about 38), a wider pelvis and chest and longer upper
/// arms. The initialisation starts from this shape
/// ([`crate::track::TrackOptions::start_shape`]).
#[rustfmt::skip]
pub const TYPICAL_SHAPE: ShapeValues = [
    1.0, 0.767, 0.775, 1.0, 0.741, 0.843, 0.825, 1.0, 0.952, 0.978, 1.0, 0.839,
];

/// The rest pose standing at the origin with its feet on the ground (y = 0).
pub fn rest_pose() -> Pose {
    let mut pose = [0.0; MOTION_COUNT];
    pose[ix::ROOT_TY] = crate::body::skeleton::STANDARD_HIP_HEIGHT;
    pose
}

/// Index of a motion parameter by name.
pub fn motion_index(name: &str) -> Option<usize> {
    MOTION.iter().position(|m| m.name == name)
}

/// Index of a shape parameter by name.
pub fn shape_index(name: &str) -> Option<usize> {
    SHAPE.iter().position(|m| m.name == name)
}

/// Whether every parameter lies within its limits (the joint half of Eq. 7).
pub fn within_limits(pose: &Pose) -> bool {
    pose.iter()
        .zip(MOTION.iter())
        .all(|(v, m)| *v >= m.lo && *v <= m.hi)
}

/// Clamp every parameter into its limits.
pub fn clamp_to_limits(pose: &mut Pose) {
    for (v, m) in pose.iter_mut().zip(MOTION.iter()) {
        *v = v.clamp(m.lo, m.hi);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn groups_cover_every_parameter_once_in_order() {
        let mut next = 0;
        for g in Group::ALL {
            let r = g.range();
            assert_eq!(r.start, next, "group {} starts at {}", g.name(), r.start);
            for i in r.clone() {
                assert_eq!(
                    MOTION[i].group, g,
                    "{} is in the wrong group",
                    MOTION[i].name
                );
            }
            next = r.end;
        }
        assert_eq!(next, MOTION_COUNT);
        let sizes: Vec<usize> = Group::ALL.iter().map(|g| g.range().len()).collect();
        assert_eq!(sizes, [6, 6, 4, 4, 5, 5]);
    }

    #[test]
    fn names_are_unique_and_limits_sane() {
        for (i, a) in MOTION.iter().enumerate() {
            assert!(a.lo < a.hi && a.lo <= 0.0 && a.hi >= 0.0, "{}", a.name);
            assert!(a.scale > 0.0);
            assert_eq!(motion_index(a.name), Some(i));
        }
        for (i, a) in SHAPE.iter().enumerate() {
            assert!(a.lo < 1.0 && a.hi > 1.0, "{}", a.name);
            assert_eq!(shape_index(a.name), Some(i));
        }
        assert_eq!(MOTION[ix::L_ELBOW].name, "l_elbow");
        assert_eq!(MOTION[ix::R_ANKLE].name, "r_ankle");
        assert_eq!(MOTION[ix::NECK].name, "neck_x");
        assert_eq!(SHAPE[sx::FOOT].name, "foot");
        assert!(within_limits(&rest_pose()));
    }
}
