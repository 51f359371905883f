//! The monocap skeleton: 18 named joints, the standard body's bone offsets scaled
//! by the shape α, and forward kinematics of a motion vector β.
//!
//! World frame: right-handed, Y up, centimetres. The rest pose (β = 0 but for the
//! hip height) stands on y = 0, faces +Z, arms hanging at its sides.

use nalgebra::{IsometryMatrix3, Matrix3, Point3, Rotation3, Translation3, Vector3};

use super::params::{self, ix, sx, Axis, Pose, ShapeValues, MOTION};

/// The 18 joints reported to users (method.md §2), in the order of the motion JSON.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(usize)]
pub enum Joint {
    Hips,
    Spine,
    Neck,
    Head,
    LeftArm,
    LeftForeArm,
    LeftHand,
    RightArm,
    RightForeArm,
    RightHand,
    LeftUpLeg,
    LeftLeg,
    LeftFoot,
    LeftToeBase,
    RightUpLeg,
    RightLeg,
    RightFoot,
    RightToeBase,
}

pub const JOINT_COUNT: usize = 18;

impl Joint {
    pub const ALL: [Joint; JOINT_COUNT] = [
        Joint::Hips,
        Joint::Spine,
        Joint::Neck,
        Joint::Head,
        Joint::LeftArm,
        Joint::LeftForeArm,
        Joint::LeftHand,
        Joint::RightArm,
        Joint::RightForeArm,
        Joint::RightHand,
        Joint::LeftUpLeg,
        Joint::LeftLeg,
        Joint::LeftFoot,
        Joint::LeftToeBase,
        Joint::RightUpLeg,
        Joint::RightLeg,
        Joint::RightFoot,
        Joint::RightToeBase,
    ];

    pub fn index(self) -> usize {
        self as usize
    }

    pub fn name(self) -> &'static str {
        JOINT_NAMES[self as usize]
    }

    pub fn parent(self) -> Option<Joint> {
        use Joint::*;
        Some(match self {
            Hips => return None,
            Spine | LeftUpLeg | RightUpLeg => Hips,
            Neck | LeftArm | RightArm => Spine,
            Head => Neck,
            LeftForeArm => LeftArm,
            LeftHand => LeftForeArm,
            RightForeArm => RightArm,
            RightHand => RightForeArm,
            LeftLeg => LeftUpLeg,
            LeftFoot => LeftLeg,
            LeftToeBase => LeftFoot,
            RightLeg => RightUpLeg,
            RightFoot => RightLeg,
            RightToeBase => RightFoot,
        })
    }

    /// The degrees of freedom this joint's rotation takes from β.
    pub const fn dof(self) -> Dof {
        use Joint::*;
        match self {
            Hips => Dof::Root,
            Spine => Dof::Three(ix::SPINE),
            Neck => Dof::Three(ix::NECK),
            LeftArm => Dof::Three(ix::L_SHOULDER),
            RightArm => Dof::Three(ix::R_SHOULDER),
            LeftUpLeg => Dof::Three(ix::L_HIP),
            RightUpLeg => Dof::Three(ix::R_HIP),
            LeftForeArm => Dof::One(ix::L_ELBOW),
            RightForeArm => Dof::One(ix::R_ELBOW),
            LeftLeg => Dof::One(ix::L_KNEE),
            RightLeg => Dof::One(ix::R_KNEE),
            LeftFoot => Dof::One(ix::L_ANKLE),
            RightFoot => Dof::One(ix::R_ANKLE),
            Head | LeftHand | RightHand | LeftToeBase | RightToeBase => Dof::Fixed,
        }
    }
}

pub const JOINT_NAMES: [&str; JOINT_COUNT] = [
    "Hips",
    "Spine",
    "Neck",
    "Head",
    "LeftArm",
    "LeftForeArm",
    "LeftHand",
    "RightArm",
    "RightForeArm",
    "RightHand",
    "LeftUpLeg",
    "LeftLeg",
    "LeftFoot",
    "LeftToeBase",
    "RightUpLeg",
    "RightLeg",
    "RightFoot",
    "RightToeBase",
];

/// How β rotates a joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dof {
    /// Root: translation β[0..3], rotation `Ry(β4) · Rx(β3) · Rz(β5)`.
    Root,
    /// Three angles starting at this index, in the table's order x, z, y; the
    /// rotation is `Rz · Rx · Ry` with each parameter's sign applied.
    Three(usize),
    /// One angle about the parameter's axis.
    One(usize),
    Fixed,
}

/// Extremity points (End Sites): the tips the tracker's extremity term pulls on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tip {
    HeadTop,
    LeftHandTip,
    RightHandTip,
    LeftToeTip,
    RightToeTip,
}

pub const TIP_COUNT: usize = 5;

impl Tip {
    pub const ALL: [Tip; TIP_COUNT] = [
        Tip::HeadTop,
        Tip::LeftHandTip,
        Tip::RightHandTip,
        Tip::LeftToeTip,
        Tip::RightToeTip,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Tip::HeadTop => "HeadTop",
            Tip::LeftHandTip => "LeftHandTip",
            Tip::RightHandTip => "RightHandTip",
            Tip::LeftToeTip => "LeftToeTip",
            Tip::RightToeTip => "RightToeTip",
        }
    }

    /// The joint whose End Site this tip is.
    pub fn joint(self) -> Joint {
        match self {
            Tip::HeadTop => Joint::Head,
            Tip::LeftHandTip => Joint::LeftHand,
            Tip::RightHandTip => Joint::RightHand,
            Tip::LeftToeTip => Joint::LeftToeBase,
            Tip::RightToeTip => Joint::RightToeBase,
        }
    }
}

/// Landmarks: the 18 joints followed by the 5 tips.
pub const LANDMARK_COUNT: usize = JOINT_COUNT + TIP_COUNT;

/// Standard body dimensions in cm (about 175 cm tall standing).
pub mod standard {
    /// Hip joints below the Hips root.
    pub const HIP_DROP: f64 = 6.0;
    /// Half the distance between the hip joints.
    pub const HIP_HALF_WIDTH: f64 = 9.0;
    pub const THIGH: f64 = 42.0;
    pub const SHIN: f64 = 41.0;
    /// Ankle joint above the sole.
    pub const ANKLE_HEIGHT: f64 = 8.0;
    /// Ankle to the ball of the foot (forwards) and its drop.
    pub const TOE_FORWARD: f64 = 13.0;
    pub const TOE_DROP: f64 = 6.0;
    /// Ball of the foot to the toe tip.
    pub const TOE_TIP: f64 = 7.0;
    /// Hips root to the Spine joint (lower back).
    pub const LOWER_BACK: f64 = 10.0;
    /// Spine joint to the base of the neck.
    pub const TORSO: f64 = 39.0;
    /// Spine joint to the shoulder joints (height) and their half spacing.
    pub const SHOULDER_HEIGHT: f64 = 35.0;
    pub const SHOULDER_HALF_WIDTH: f64 = 17.5;
    /// Neck base to the Head joint (skull base).
    pub const NECK: f64 = 9.0;
    /// Head joint to the top of the head.
    pub const HEAD: f64 = 21.0;
    pub const UPPER_ARM: f64 = 29.0;
    pub const FOREARM: f64 = 25.0;
    pub const HAND: f64 = 18.0;
}

/// Height of the Hips root above the ground in the standard rest pose.
pub const STANDARD_HIP_HEIGHT: f64 =
    standard::HIP_DROP + standard::THIGH + standard::SHIN + standard::ANKLE_HEIGHT;

/// A body of a given shape: bone offsets fixed, ready to pose.
#[derive(Clone, Debug)]
pub struct Skeleton {
    pub shape: ShapeValues,
    /// Offset of each joint from its parent, in the parent's frame (cm).
    pub offsets: [Vector3<f64>; JOINT_COUNT],
    /// Offset of each tip from its joint, in the joint's frame (cm).
    pub tip_offsets: [Vector3<f64>; TIP_COUNT],
}

impl Skeleton {
    pub fn new(shape: &ShapeValues) -> Skeleton {
        use standard as s;
        let a = |i: usize| shape[i];
        let th = a(sx::TORSO_HEIGHT);
        let mut offsets = [Vector3::zeros(); JOINT_COUNT];
        let mut set = |j: Joint, x: f64, y: f64, z: f64| offsets[j.index()] = Vector3::new(x, y, z);
        let hip_x = s::HIP_HALF_WIDTH * a(sx::PELVIS_WIDTH);
        let sh_x = s::SHOULDER_HALF_WIDTH * a(sx::TORSO_WIDTH);
        set(Joint::Spine, 0.0, s::LOWER_BACK * th, 0.0);
        set(Joint::Neck, 0.0, s::TORSO * th, 0.0);
        set(Joint::Head, 0.0, s::NECK * th, 0.0);
        for (side, arm, fore, hand) in [
            (1.0, Joint::LeftArm, Joint::LeftForeArm, Joint::LeftHand),
            (-1.0, Joint::RightArm, Joint::RightForeArm, Joint::RightHand),
        ] {
            set(arm, side * sh_x, s::SHOULDER_HEIGHT * th, 0.0);
            set(fore, 0.0, -s::UPPER_ARM * a(sx::UPPER_ARM), 0.0);
            set(hand, 0.0, -s::FOREARM * a(sx::FOREARM), 0.0);
        }
        for (side, up, leg, foot, toe) in [
            (
                1.0,
                Joint::LeftUpLeg,
                Joint::LeftLeg,
                Joint::LeftFoot,
                Joint::LeftToeBase,
            ),
            (
                -1.0,
                Joint::RightUpLeg,
                Joint::RightLeg,
                Joint::RightFoot,
                Joint::RightToeBase,
            ),
        ] {
            set(up, side * hip_x, -s::HIP_DROP, 0.0);
            set(leg, 0.0, -s::THIGH * a(sx::THIGH), 0.0);
            set(foot, 0.0, -s::SHIN * a(sx::SHIN), 0.0);
            set(toe, 0.0, -s::TOE_DROP, s::TOE_FORWARD * a(sx::FOOT));
        }
        let fa = a(sx::FOREARM);
        let tip_offsets = [
            Vector3::new(0.0, s::HEAD * a(sx::HEAD), 0.0),
            Vector3::new(0.0, -s::HAND * fa, 0.0),
            Vector3::new(0.0, -s::HAND * fa, 0.0),
            Vector3::new(0.0, 0.0, s::TOE_TIP * a(sx::FOOT)),
            Vector3::new(0.0, 0.0, s::TOE_TIP * a(sx::FOOT)),
        ];
        Skeleton {
            shape: *shape,
            offsets,
            tip_offsets,
        }
    }

    /// Forward kinematics: the world frame of every joint for pose β.
    pub fn pose(&self, pose: &Pose, out: &mut Posed) {
        self.pose_keeping(pose, None, out);
    }

    /// [`Skeleton::pose`] for the joints `moved` marks (parents before children: a
    /// joint moves when its parent does) and the tips on them; every other joint and
    /// tip is copied from `base`, a pose posed in full that differs from `pose` only
    /// in parameters of moved joints. The same result as posing in full, for fewer
    /// joints' rotations.
    pub fn pose_moved(
        &self,
        pose: &Pose,
        base: &Posed,
        moved: &[bool; JOINT_COUNT],
        out: &mut Posed,
    ) {
        self.pose_keeping(pose, Some((base, moved)), out);
    }

    /// Poses every joint, or only the moved ones of `keep` (the rest copied).
    fn pose_keeping(
        &self,
        pose: &Pose,
        keep: Option<(&Posed, &[bool; JOINT_COUNT])>,
        out: &mut Posed,
    ) {
        let kept = |i: usize| keep.filter(|(_, moved)| !moved[i]).map(|(base, _)| base);
        for j in Joint::ALL {
            let i = j.index();
            match kept(i) {
                Some(base) => out.joints[i] = base.joints[i],
                None => self.pose_joint(j, pose, out),
            }
        }
        for (i, t) in Tip::ALL.iter().enumerate() {
            match kept(t.joint().index()) {
                Some(base) => out.tips[i] = base.tips[i],
                None => self.pose_tip(i, *t, out),
            }
        }
    }

    /// [`Skeleton::pose_moved`] in place: `out` already holds, for every joint
    /// `moved` leaves out, the frame a base pose gives it (it was posed in full
    /// from that base, and since only from poses that differ from it in
    /// parameters of moved joints), so only the moved joints and the tips on them
    /// are posed again. The same result as posing in full, with nothing copied.
    pub fn repose_moved(&self, pose: &Pose, moved: &[bool; JOINT_COUNT], out: &mut Posed) {
        for j in Joint::ALL {
            if moved[j.index()] {
                self.pose_joint(j, pose, out);
            }
        }
        for (i, t) in Tip::ALL.iter().enumerate() {
            if moved[t.joint().index()] {
                self.pose_tip(i, *t, out);
            }
        }
    }

    /// Poses joint `j` in `out`, whose frame of its parent is already posed. The
    /// joint's rotation in its parent's frame is taken from `out`'s store when its
    /// angles are the ones it was made from (`Rotations`): a search over a group
    /// moves the joints below it without turning them.
    #[inline]
    fn pose_joint(&self, j: Joint, pose: &Pose, out: &mut Posed) {
        let i = j.index();
        let rotation = *out.rotations.get(j, pose);
        let local = IsometryMatrix3::from_parts(
            match j.dof() {
                Dof::Root => {
                    Translation3::new(pose[ix::ROOT_TX], pose[ix::ROOT_TY], pose[ix::ROOT_TZ])
                }
                _ => Translation3::from(self.offsets[i]),
            },
            rotation,
        );
        out.joints[i] = match j.parent() {
            Some(p) => out.joints[p.index()] * local,
            None => local,
        };
    }

    /// Places tip `t` (the `i`-th) in `out`, whose frame of its joint is posed.
    #[inline]
    fn pose_tip(&self, i: usize, t: Tip, out: &mut Posed) {
        out.tips[i] = out.joints[t.joint().index()] * Point3::from(self.tip_offsets[i]);
    }

    /// Convenience: a freshly allocated [`Posed`].
    pub fn posed(&self, pose: &Pose) -> Posed {
        let mut out = Posed::default();
        self.pose(pose, &mut out);
        out
    }
}

/// The root's rotation: heading (Y) outermost, then pitch (X), then roll (Z).
pub fn root_rotation(pose: &Pose) -> Rotation3<f64> {
    axis_rotation(Axis::Y, pose[ix::ROOT_RY])
        * axis_rotation(Axis::X, pose[ix::ROOT_RX])
        * axis_rotation(Axis::Z, pose[ix::ROOT_RZ])
}

/// A non-root joint's rotation in its parent's frame.
pub fn joint_rotation(dof: Dof, pose: &Pose) -> Rotation3<f64> {
    let signed = |i: usize| MOTION[i].sign * pose[i];
    match dof {
        Dof::Three(i) => {
            axis_rotation(Axis::Z, signed(i + 1))
                * axis_rotation(Axis::X, signed(i))
                * axis_rotation(Axis::Y, signed(i + 2))
        }
        Dof::One(i) => axis_rotation(MOTION[i].axis, signed(i)),
        Dof::Fixed | Dof::Root => Rotation3::identity(),
    }
}

/// Right-handed rotation by `deg` degrees about a coordinate axis.
pub fn axis_rotation(axis: Axis, deg: f64) -> Rotation3<f64> {
    let (s, c) = deg.to_radians().sin_cos();
    let m = match axis {
        Axis::X => Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c),
        Axis::Y => Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c),
        Axis::Z => Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0),
    };
    Rotation3::from_matrix_unchecked(m)
}

/// A posed body: world frames of the joints and world positions of the tips.
#[derive(Clone, Debug)]
pub struct Posed {
    pub joints: [IsometryMatrix3<f64>; JOINT_COUNT],
    pub tips: [Point3<f64>; TIP_COUNT],
    /// The joints' rotations in their parents' frames as last made, for posing
    /// again.
    rotations: Rotations,
}

impl Default for Posed {
    fn default() -> Self {
        Posed {
            joints: [IsometryMatrix3::identity(); JOINT_COUNT],
            tips: [Point3::origin(); TIP_COUNT],
            rotations: Rotations::default(),
        }
    }
}

/// Each joint's rotation in its parent's frame with the bits of the angles it was
/// made from: posing again at the same angles takes the stored rotation instead of
/// three sines and cosines and two matrix products. The rotation depends on the
/// angles alone (not on the shape), so the store holds whichever skeleton poses it.
#[derive(Clone, Debug)]
struct Rotations {
    /// Per joint, its angles' bits (unused ones 0); [`NOT_MADE`] before the first.
    made: [[u64; 3]; JOINT_COUNT],
    rotations: [Rotation3<f64>; JOINT_COUNT],
}

/// Bits no angle has (a NaN no arithmetic makes): a rotation not made yet.
const NOT_MADE: [u64; 3] = [u64::MAX; 3];

/// Per joint, the first of its angles in β and how many it takes (0: none).
const ANGLES: [(usize, usize); JOINT_COUNT] = {
    let mut out = [(0, 0); JOINT_COUNT];
    let mut i = 0;
    while i < JOINT_COUNT {
        out[i] = match Joint::ALL[i].dof() {
            Dof::Root => (ix::ROOT_RX, 3),
            Dof::Three(first) => (first, 3),
            Dof::One(first) => (first, 1),
            Dof::Fixed => (0, 0),
        };
        i += 1;
    }
    out
};

impl Default for Rotations {
    fn default() -> Self {
        Rotations {
            made: [NOT_MADE; JOINT_COUNT],
            rotations: [Rotation3::identity(); JOINT_COUNT],
        }
    }
}

impl Rotations {
    /// Joint `j`'s rotation at `pose`, made unless stored for the same angles.
    #[inline]
    fn get(&mut self, j: Joint, pose: &Pose) -> &Rotation3<f64> {
        let i = j.index();
        let (first, n) = ANGLES[i];
        if n == 0 {
            // Never made: the identity the store starts with.
            return &self.rotations[i];
        }
        let key = if n == 3 {
            [
                pose[first].to_bits(),
                pose[first + 1].to_bits(),
                pose[first + 2].to_bits(),
            ]
        } else {
            [pose[first].to_bits(), 0, 0]
        };
        if self.made[i] != key {
            self.rotations[i] = match j.dof() {
                Dof::Root => root_rotation(pose),
                dof => joint_rotation(dof, pose),
            };
            self.made[i] = key;
        }
        &self.rotations[i]
    }
}

impl Posed {
    pub fn joint(&self, j: Joint) -> Point3<f64> {
        Point3::from(self.joints[j.index()].translation.vector)
    }

    /// Landmark `i` of [`Posed::landmarks`]: joint `i`, or tip `i − JOINT_COUNT`.
    #[inline]
    pub fn landmark(&self, i: usize) -> Point3<f64> {
        if i < JOINT_COUNT {
            Point3::from(self.joints[i].translation.vector)
        } else {
            self.tips[i - JOINT_COUNT]
        }
    }

    /// The 18 joint positions followed by the 5 tips.
    pub fn landmarks(&self) -> [Point3<f64>; LANDMARK_COUNT] {
        std::array::from_fn(|i| self.landmark(i))
    }
}

/// The index of the joint whose frame carries landmark `i` ([`Posed::landmarks`]):
/// the joint itself, or the tip's; None past the last landmark.
pub fn landmark_joint(i: usize) -> Option<usize> {
    if i < JOINT_COUNT {
        Some(i)
    } else {
        Tip::ALL.get(i - JOINT_COUNT).map(|t| t.joint().index())
    }
}

/// Which joints move when the parameters `params` change: a joint moves when it or
/// one of its ancestors takes one of them.
pub fn joints_moved_by(params: &[usize]) -> [bool; JOINT_COUNT] {
    let takes = |j: Joint| -> bool {
        let r = match j.dof() {
            Dof::Root => 0..6,
            Dof::Three(i) => i..i + 3,
            Dof::One(i) => i..i + 1,
            Dof::Fixed => 0..0,
        };
        params.iter().any(|p| r.contains(p))
    };
    let mut out = [false; JOINT_COUNT];
    for j in Joint::ALL {
        // Parents come before children in Joint::ALL.
        out[j.index()] = takes(j) || j.parent().is_some_and(|p| out[p.index()]);
    }
    out
}

/// The standard body standing at rest, for tests and defaults.
pub fn standard_rest() -> (Skeleton, Pose) {
    (Skeleton::new(&params::STANDARD_SHAPE), params::rest_pose())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Point3<f64>, b: [f64; 3], tol: f64) -> bool {
        (a - Point3::from(b)).norm() < tol
    }

    #[test]
    fn moved_joints_follow_the_hierarchy() {
        let m = joints_moved_by(&[ix::L_ELBOW]);
        assert!(m[Joint::LeftForeArm.index()] && m[Joint::LeftHand.index()]);
        assert!(!m[Joint::LeftArm.index()] && !m[Joint::Hips.index()]);
        let all = joints_moved_by(&[ix::ROOT_RY]);
        assert!(all.iter().all(|&b| b));
        let spine = joints_moved_by(&[ix::SPINE]);
        assert!(spine[Joint::RightHand.index()] && !spine[Joint::LeftLeg.index()]);
    }

    #[test]
    fn each_landmark_is_carried_by_its_joint() {
        let (sk, mut pose) = standard_rest();
        let before = sk.posed(&pose);
        assert_eq!(landmark_joint(LANDMARK_COUNT), None);
        // A landmark that moves with the left shoulder's turn is carried by a
        // joint the turn moves.
        pose[crate::body::params::ix::L_SHOULDER] += 30.0;
        let after = sk.posed(&pose);
        let moved = joints_moved_by(&[crate::body::params::ix::L_SHOULDER]);
        for i in 0..LANDMARK_COUNT {
            let j = landmark_joint(i).expect("a landmark");
            let shifted = (after.landmark(i) - before.landmark(i)).norm() > 1e-9;
            assert!(
                !shifted || moved[j],
                "landmark {i} moved with joint {j} still"
            );
        }
        let hand_tip = JOINT_COUNT + Tip::LeftHandTip as usize;
        assert!((after.landmark(hand_tip) - before.landmark(hand_tip)).norm() > 1.0);
        for (k, t) in Tip::ALL.iter().enumerate() {
            assert_eq!(landmark_joint(JOINT_COUNT + k), Some(t.joint().index()));
        }
    }

    #[test]
    fn posing_the_moved_joints_alone_matches_posing_all() {
        let (sk, mut from) = standard_rest();
        for (k, v) in from.iter_mut().enumerate() {
            *v += (k as f64 * 1.7).sin() * 12.0;
        }
        let base = sk.posed(&from);
        for g in crate::body::params::Group::ALL {
            let params: Vec<usize> = g.range().collect();
            let moved = joints_moved_by(&params);
            let mut pose = from;
            for &k in &params {
                pose[k] += 9.0 + k as f64;
            }
            let full = sk.posed(&pose);
            // Filled with the base's frames, so that any joint it failed to pose
            // stays wrong.
            let mut part = base.clone();
            sk.pose_moved(&pose, &base, &moved, &mut part);
            assert_eq!(part.joints, full.joints, "{}", g.name());
            assert_eq!(part.tips, full.tips, "{}", g.name());
            // In place, from the base and then from another pose of the group's.
            let mut here = base.clone();
            sk.repose_moved(&pose, &moved, &mut here);
            assert_eq!(here.joints, full.joints, "{}", g.name());
            assert_eq!(here.tips, full.tips, "{}", g.name());
            let mut again = pose;
            for &k in &params {
                again[k] -= 20.0;
            }
            sk.repose_moved(&again, &moved, &mut here);
            let full = sk.posed(&again);
            assert_eq!(here.joints, full.joints, "{}", g.name());
            assert_eq!(here.tips, full.tips, "{}", g.name());
            let kept = moved.iter().filter(|m| !**m).count();
            assert_eq!(kept == 0, g == crate::body::params::Group::Global);
        }
    }

    #[test]
    fn a_posed_body_reused_across_poses_and_shapes_matches_a_fresh_one() {
        // The stored rotations must follow every angle, and none may carry a
        // shape: one Posed, posed in turn with two skeletons at poses that differ
        // in one angle at a time, against a fresh Posed each time.
        let (sk, rest) = standard_rest();
        let mut shape = params::STANDARD_SHAPE;
        for (k, v) in shape.iter_mut().enumerate() {
            *v *= 1.0 + 0.03 * k as f64;
        }
        let other = Skeleton::new(&shape);
        let mut reused = Posed::default();
        let mut pose = rest;
        for k in 0..pose.len() {
            pose[k] += 7.0 + k as f64;
            for s in [&sk, &other] {
                s.pose(&pose, &mut reused);
                let fresh = s.posed(&pose);
                assert_eq!(reused.joints, fresh.joints, "parameter {k}");
                assert_eq!(reused.tips, fresh.tips, "parameter {k}");
            }
        }
    }

    #[test]
    fn rest_pose_stands_on_the_ground_about_175_cm_tall() {
        let (sk, pose) = standard_rest();
        let p = sk.posed(&pose);
        let top = p.tips[Tip::HeadTop as usize];
        assert!((170.0..180.0).contains(&top.y), "head top at {}", top.y);
        let ankle = p.joint(Joint::LeftFoot);
        assert!((ankle.y - standard::ANKLE_HEIGHT).abs() < 1e-9);
        // Left is +X for a body facing +Z.
        assert!(p.joint(Joint::LeftHand).x > 10.0 && p.joint(Joint::RightHand).x < -10.0);
        assert!(p.tips[Tip::LeftToeTip as usize].z > 15.0);
        for (i, name) in JOINT_NAMES.iter().enumerate() {
            assert_eq!(Joint::ALL[i].name(), *name);
            assert_eq!(Joint::ALL[i].index(), i);
        }
    }

    #[test]
    fn signs_make_positive_values_mean_the_documented_movement() {
        let (sk, rest) = standard_rest();
        let moved = |name: &str, v: f64| {
            let mut pose = rest;
            pose[params::motion_index(name).unwrap()] = v;
            sk.posed(&pose)
        };
        // Elbow flexion brings the wrist forwards (+Z) on both sides.
        assert!(moved("l_elbow", 90.0).joint(Joint::LeftHand).z > 20.0);
        assert!(moved("r_elbow", 90.0).joint(Joint::RightHand).z > 20.0);
        // Shoulder flexion raises the arm forwards; abduction raises it outwards.
        let up = moved("l_shoulder_x", 90.0).joint(Joint::LeftForeArm);
        assert!(
            close(up, [standard::SHOULDER_HALF_WIDTH, 142.0, 29.0], 1e-6),
            "{up}"
        );
        assert!(moved("l_shoulder_z", 90.0).joint(Joint::LeftForeArm).x > 40.0);
        assert!(moved("r_shoulder_z", 90.0).joint(Joint::RightForeArm).x < -40.0);
        // Knee flexion takes the ankle backwards; hip flexion the knee forwards.
        assert!(moved("l_knee", 90.0).joint(Joint::LeftFoot).z < -30.0);
        assert!(moved("r_hip_x", 90.0).joint(Joint::RightLeg).z > 30.0);
        // Heading: +90° about Y turns the body to face +X.
        let turned = moved("root_ry", 90.0);
        assert!(turned.tips[Tip::LeftToeTip as usize].x > 15.0);
        // Spine flexion leans the neck forwards.
        assert!(moved("spine_x", 45.0).joint(Joint::Neck).z > 20.0);
    }

    #[test]
    fn shape_scales_the_bones() {
        let mut shape = params::STANDARD_SHAPE;
        shape[sx::THIGH] = 1.2;
        let sk = Skeleton::new(&shape);
        let p = sk.posed(&params::rest_pose());
        let thigh = (p.joint(Joint::LeftUpLeg) - p.joint(Joint::LeftLeg)).norm();
        assert!((thigh - 1.2 * standard::THIGH).abs() < 1e-9);
    }
}
