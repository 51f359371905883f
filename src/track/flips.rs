//! Depth flips (kinematic jumps): one camera cannot tell whether a bone points
//! towards it or away from it. Moving a bone's far end along its line of sight to
//! the other point at the bone's length from its near end gives a pose seen almost
//! exactly as before but with a very different 3D configuration, out of the local
//! search's reach from the first. A tracker that took the wrong branch when a limb
//! or the trunk started to bend (both look alike while the bend is small) stays on
//! it; the tracker therefore also tries each flip of its result, refines it, and
//! keeps it when it explains the frame better.
//!
//! A flip is turned into joint angles by inverse kinematics: the angles of the
//! flipped bone and of the bones it carries (which keep their own lines of sight)
//! are fitted, by the downhill simplex on positions alone (no rendering), to the
//! moved landmarks, the rest of the body held where it is. Joint limits may keep a
//! flip from being reached exactly (a trunk bends back less far than forwards); the
//! search on the frame then decides.
//!
//! One more jump of the same kind is not a flip: a small bow and a nod of the head
//! look alike from the front, and a tracker that put the bend into the neck stays
//! there. [`nod_into_trunk`] straightens the neck and refits the trunk and arms so
//! that the head and hands stay where they are. Nor is [`crouch`]: the hips
//! lowered or raised with the feet kept where they are, a move the search's groups
//! cannot make one at a time.

use nalgebra::Point3;

use super::simplex::{minimize, SimplexOptions};
use crate::body::params::{clamp_to_limits, ix, Group, Pose, MOTION};
use crate::body::skeleton::{
    joints_moved_by, landmark_joint, Joint, Posed, Tip, JOINT_COUNT, LANDMARK_COUNT,
};
use crate::body::Body;

/// What a flip does with the far end of one bone.
#[derive(Clone, Copy, PartialEq, Eq)]
enum End {
    /// It keeps its side of its parent in depth.
    Kept,
    /// It goes to the other side: the flip has no point unless it moves.
    Flipped,
    /// It goes to the other side too, as part of the flipped bone above it (the
    /// whole arm turned with the trunk); it may barely move.
    Follows,
}

/// [`End::Flipped`] when `flip`, [`End::Kept`] otherwise.
const fn end(flip: bool) -> End {
    if flip {
        End::Flipped
    } else {
        End::Kept
    }
}

/// One flip: the bones it moves, each (end, its parent, what happens to the end),
/// parents first; the groups whose angles are refitted; the angle mirrored in the
/// inverse kinematics' second start.
pub struct Flip {
    pub name: &'static str,
    bones: &'static [(usize, usize, End)],
    pub groups: &'static [Group],
    mirror: usize,
}

const fn j(joint: Joint) -> usize {
    joint as usize
}

const fn t(tip: Tip) -> usize {
    JOINT_COUNT + tip as usize
}

use Joint as J;

const NECK: usize = j(J::Neck);
const HEAD: usize = j(J::Head);
const HEAD_TOP: usize = t(Tip::HeadTop);

/// An arm's flip: its bones below the shoulder, the upper arm and the forearm
/// each flipped or not, refitting the arm's group.
macro_rules! arm {
    (Left, $name:expr, $up:expr, $low:expr) => {
        arm!(@ $name, LeftArm, LeftForeArm, LeftHand, LeftHandTip, LeftArm, ix::L_SHOULDER, $up, $low)
    };
    (Right, $name:expr, $up:expr, $low:expr) => {
        arm!(@ $name, RightArm, RightForeArm, RightHand, RightHandTip, RightArm, ix::R_SHOULDER, $up, $low)
    };
    (@ $name:expr, $s:ident, $e:ident, $h:ident, $tip:ident, $group:ident, $mirror:expr, $up:expr, $low:expr) => {
        Flip {
            name: $name,
            bones: &[
                (j(J::$e), j(J::$s), end($up)),
                (j(J::$h), j(J::$e), end($low)),
                (t(Tip::$tip), j(J::$h), End::Kept),
            ],
            groups: &[Group::$group],
            mirror: $mirror,
        }
    };
}

/// A leg's flip: its bones below the hip, the thigh and the shin each flipped or
/// not, refitting the leg's group.
macro_rules! leg {
    (Left, $name:expr, $up:expr, $low:expr) => {
        leg!(@ $name, LeftUpLeg, LeftLeg, LeftFoot, LeftToeBase, LeftToeTip, LeftLeg, ix::L_HIP, $up, $low)
    };
    (Right, $name:expr, $up:expr, $low:expr) => {
        leg!(@ $name, RightUpLeg, RightLeg, RightFoot, RightToeBase, RightToeTip, RightLeg, ix::R_HIP, $up, $low)
    };
    (@ $name:expr, $hip:ident, $k:ident, $a:ident, $toe:ident, $tip:ident, $group:ident, $mirror:expr, $up:expr, $low:expr) => {
        Flip {
            name: $name,
            bones: &[
                (j(J::$k), j(J::$hip), end($up)),
                (j(J::$a), j(J::$k), end($low)),
                (j(J::$toe), j(J::$a), End::Kept),
                (t(Tip::$tip), j(J::$toe), End::Kept),
            ],
            groups: &[Group::$group],
            mirror: $mirror,
        }
    };
}

/// The trunk's flip: the neck and shoulders to the other side of the spine's
/// joint in depth, the head carried; the arms below the shoulders `arms`: kept on
/// their side (the hands still seen where they were, as arms hanging under gravity
/// stay) or following the trunk (the whole upper body mirrored, as arms held to
/// the trunk are).
macro_rules! trunk {
    ($name:expr, $arms:expr) => {
        Flip {
            name: $name,
            bones: &[
                (NECK, j(J::Spine), End::Flipped),
                (j(J::LeftArm), j(J::Spine), End::Flipped),
                (j(J::RightArm), j(J::Spine), End::Flipped),
                (HEAD, NECK, End::Kept),
                (HEAD_TOP, HEAD, End::Kept),
                (j(J::LeftForeArm), j(J::LeftArm), $arms),
                (j(J::LeftHand), j(J::LeftForeArm), $arms),
                (t(Tip::LeftHandTip), j(J::LeftHand), $arms),
                (j(J::RightForeArm), j(J::RightArm), $arms),
                (j(J::RightHand), j(J::RightForeArm), $arms),
                (t(Tip::RightHandTip), j(J::RightHand), $arms),
            ],
            groups: &[Group::Torso, Group::LeftArm, Group::RightArm],
            mirror: ix::SPINE,
        }
    };
}

/// The flips tried: the trunk (with the arms kept or following), the head, and
/// each limb's upper bone, lower bone and both.
pub const FLIPS: [Flip; 15] = [
    trunk!("spine", End::Kept),
    trunk!("spine with the arms", End::Follows),
    Flip {
        name: "neck",
        bones: &[(HEAD, NECK, End::Flipped), (HEAD_TOP, HEAD, End::Flipped)],
        groups: &[Group::Torso],
        mirror: ix::NECK,
    },
    arm!(Left, "left upper arm", true, false),
    arm!(Left, "left forearm", false, true),
    arm!(Left, "left arm", true, true),
    arm!(Right, "right upper arm", true, false),
    arm!(Right, "right forearm", false, true),
    arm!(Right, "right arm", true, true),
    leg!(Left, "left thigh", true, false),
    leg!(Left, "left shin", false, true),
    leg!(Left, "left leg", true, true),
    leg!(Right, "right thigh", true, false),
    leg!(Right, "right shin", false, true),
    leg!(Right, "right leg", true, true),
];

/// A bone whose end a flip moves less than this (cm) lies across its line of
/// sight: it has no flip.
const MIN_MOVE_CM: f64 = 4.0;

/// Inverse kinematics closer than this (sum of squared landmark misses, cm²) to
/// the flipped landmarks needs no second pass.
const CLOSE_CM2: f64 = 4.0;

/// The point on the camera's ray through `q` (the camera at the origin) at `r` from
/// `p`: of the two, the one on the other side of `p`'s depth from `side` when
/// `flip`, on the same side otherwise. The nearest point of the ray when it misses
/// that sphere.
fn along_ray(q: Point3<f64>, p: Point3<f64>, r: f64, side: f64, flip: bool) -> Point3<f64> {
    let Some(dir) = q.coords.try_normalize(1e-9) else {
        return q;
    };
    let mid = dir.dot(&p.coords);
    let disc = mid * mid - (p.coords.norm_squared() - r * r);
    let half = disc.max(0.0).sqrt();
    let [a, b] = [mid - half, mid + half].map(|t| Point3::from(dir * t));
    // Depth along the line of sight through p: nearer the camera is negative.
    let sight = p.coords.normalize();
    let depth = |x: Point3<f64>| (x - p).dot(&sight);
    let want = if flip { -side } else { side };
    if (depth(a) - want).abs() <= (depth(b) - want).abs() {
        a
    } else {
        b
    }
}

impl Flip {
    /// The parameters refitted.
    pub fn params(&self) -> Vec<usize> {
        self.groups.iter().flat_map(|g| g.range()).collect()
    }

    /// The flipped pose of `pose` (the camera at the origin, as the body's frame is
    /// the camera's), or `None` when a bone it flips barely moves. Each bone's end
    /// moves along its line of sight (so it is seen where it was) to where the bone
    /// keeps its length from its parent's new place.
    pub fn apply(&self, body: &Body, pose: &Pose) -> Option<Pose> {
        let now = body.posed(pose).landmarks();
        let mut target = now;
        for &(end, parent, how) in self.bones {
            let p0 = now[parent];
            let sight = p0.coords.try_normalize(1e-9)?;
            let side = (now[end] - p0).dot(&sight);
            let r = (now[end] - p0).norm();
            target[end] = along_ray(now[end], target[parent], r, side, how != End::Kept);
        }
        // Every flipped bone must move: a composite flip one of whose bones lies
        // across its line of sight is the other bone's flip, tried on its own.
        let still = self.bones.iter().any(|&(end, _, how)| {
            how == End::Flipped && (target[end] - now[end]).norm() < MIN_MOVE_CM
        });
        if still {
            return None;
        }
        let params = self.params();
        let x0: Vec<f64> = params.iter().map(|&k| pose[k]).collect();
        // The misfit is far from convex in the angles: start from the pose and from
        // it with the first bone's flexion mirrored.
        let mut mirrored = x0.clone();
        if let Some(m) = params.iter().position(|&k| k == self.mirror) {
            mirrored[m] = -mirrored[m];
        }
        Some(fit_landmarks(body, pose, &params, &target, [x0, mirrored]))
    }
}

/// A nod of the head larger than this (degrees) is also tried as a bend of the
/// trunk.
const MIN_NOD_DEG: f64 = 5.0;

/// The head's nod moved into the trunk: the neck straightened (its forward angle
/// to zero) and the trunk and arms refitted so that the head, hands and the rest
/// stay where they are. From the front, a bow and a nod of the head look alike
/// while they are small; a tracker that put the bend into the neck stays there.
/// `None` when the head barely nods.
pub fn nod_into_trunk(body: &Body, pose: &Pose) -> Option<Pose> {
    if pose[ix::NECK].abs() < MIN_NOD_DEG {
        return None;
    }
    let target = body.posed(pose).landmarks();
    let mut base = *pose;
    base[ix::NECK] = 0.0;
    // The neck's other angles (tilt, turn) stay as they are.
    let params: Vec<usize> = Jump::NodIntoTrunk
        .params()
        .into_iter()
        .filter(|k| !(ix::NECK..ix::NECK + 3).contains(k))
        .collect();
    let x0: Vec<f64> = params.iter().map(|&k| base[k]).collect();
    // Seeds: the trunk bent by the nod, and as it is.
    let mut bent = x0.clone();
    if let Some(i) = params.iter().position(|&k| k == ix::SPINE) {
        bent[i] = (bent[i] + pose[ix::NECK]).clamp(MOTION[ix::SPINE].lo, MOTION[ix::SPINE].hi);
    }
    Some(fit_landmarks(body, &base, &params, &target, [bent, x0]))
}

/// The groups a swap refits.
const LEG_GROUPS: [Group; 2] = [Group::LeftLeg, Group::RightLeg];
const ARM_GROUPS: [Group; 2] = [Group::LeftArm, Group::RightArm];

/// The groups a [`Jump::Crouch`] refits: the hips' place and turn, the trunk
/// (a crouch bends it forwards) and the legs.
const CROUCH_GROUPS: [Group; 4] = [Group::Global, Group::Torso, Group::LeftLeg, Group::RightLeg];

/// The groups [`nod_into_trunk`] refits.
const NOD_GROUPS: [Group; 3] = [Group::Torso, Group::LeftArm, Group::RightArm];

/// A jump the tracker tries from each frame's result: a depth flip, the head's nod
/// moved into the trunk, a swap of the legs or the arms, a crouch, or the whole
/// body's depth mirror.
#[derive(Clone, Copy)]
pub enum Jump {
    Flip(&'static Flip),
    NodIntoTrunk,
    /// The legs' angles exchanged: seen from the side, or from the back for the
    /// mirror image, the other leg in front looks alike. Only the colour frame's
    /// inner outlines tell them apart ([`super::outlines`]).
    SwapLegs,
    /// The arms' angles exchanged (likewise).
    SwapArms,
    /// The hips lowered by [`CROUCH_CM`], the legs bent so that the feet stay
    /// where they are ([`crouch`]).
    Crouch,
    /// The whole body mirrored in depth ([`depth_mirror`]): seen from an oblique
    /// view, a track can settle on the mirror image of the person, turned away
    /// from the true heading with left and right exchanged, and no single group's
    /// search reaches the true pose from it. Refined over every group.
    Mirror,
}

/// The landmarks a [`crouch`] keeps in place: the ankles, toe bases and toe tips.
const FEET: [usize; 6] = [
    j(J::LeftFoot),
    j(J::LeftToeBase),
    t(Tip::LeftToeTip),
    j(J::RightFoot),
    j(J::RightToeBase),
    t(Tip::RightToeTip),
];

/// How far (cm) the [`Jump::Crouch`] jump moves the hips down.
pub const CROUCH_CM: f64 = 5.0;

/// The hips moved up by `d` cm (down when `d` is negative) and the legs refitted by
/// inverse kinematics so that the feet (ankles, toe bases and toe tips) stay where
/// they are, the rest of the body carried along with the hips.
///
/// A person who squats or kneels lowers the hips and bends the knees together. The
/// hierarchical search can do neither on its own: the global group cannot lower
/// the hips while the legs are straight (the feet would sink below the ground,
/// which costs +∞), and the legs' groups, bending with the hips held, lift the feet
/// off the ground. It takes another way down instead, the whole body pitched
/// forwards and turned: in CMU 131_01's crouch seen from −120° the tracked answers
/// pitched it 27–36° with the heading over 70° off, while the bottom of the truth's
/// basin cost about half as much (README "The crouch as a jump").
pub fn crouch(body: &Body, pose: &Pose, d: f64) -> Pose {
    let target = body.posed(pose).landmarks();
    let mut base = *pose;
    base[ix::ROOT_TY] += d;
    let params: Vec<usize> = LEG_GROUPS.iter().flat_map(|g| g.range()).collect();
    let mut weight = [0.0; LANDMARK_COUNT];
    for i in FEET {
        weight[i] = 1.0;
    }
    // Seeds: the legs as they are, and with the thighs raised (or lowered) a
    // degree per centimetre, so that the knees bend forwards.
    let x0: Vec<f64> = params.iter().map(|&k| base[k]).collect();
    let mut thighs = x0.clone();
    for (v, &k) in thighs.iter_mut().zip(&params) {
        if k == ix::L_HIP || k == ix::R_HIP {
            *v = (*v - d).clamp(MOTION[k].lo, MOTION[k].hi);
        }
    }
    fit_landmarks_weighted(body, &base, &params, &target, &weight, [x0, thighs])
}

/// `pose` with the `n` angles from `left` and from `right` exchanged; None when
/// they differ by under a degree (the swap would move nothing).
fn swapped(pose: &Pose, left: usize, right: usize, n: usize) -> Option<Pose> {
    let apart = (0..n).any(|k| (pose[left + k] - pose[right + k]).abs() >= 1.0);
    apart.then(|| {
        let mut p = *pose;
        exchange(&mut p, left, right, n);
        p
    })
}

/// Exchanges the `n` values from `left` with the `n` from `right`.
fn exchange(pose: &mut Pose, left: usize, right: usize, n: usize) {
    for k in 0..n {
        pose.swap(left + k, right + k);
    }
}

impl Jump {
    /// Every jump: the flips, the nod, the swaps, then the crouch down. Not up:
    /// rising is within the search's own reach (the global group lifts the hips, the
    /// feet leave the ground at a finite cost, and the legs' groups straighten them
    /// back onto it), where crouching is not ([`crouch`]). The jump up cost about a
    /// sixth of the jumps' evaluations; leaving it out saved 10% of the time for
    /// 0.002 of PCK and 0.4 mm of PA-MPJPE on the benchmark (README "The crouch
    /// down alone").
    pub fn all() -> impl Iterator<Item = Jump> {
        FLIPS.iter().map(Jump::Flip).chain([
            Jump::NodIntoTrunk,
            Jump::SwapLegs,
            Jump::SwapArms,
            Jump::Crouch,
            Jump::Mirror,
        ])
    }

    /// The parameters the jump changes (and the search then refines).
    pub fn params(self) -> Vec<usize> {
        match self {
            Jump::Flip(f) => f.params(),
            Jump::NodIntoTrunk => NOD_GROUPS.iter().flat_map(|g| g.range()).collect(),
            Jump::SwapLegs => LEG_GROUPS.iter().flat_map(|g| g.range()).collect(),
            Jump::SwapArms => ARM_GROUPS.iter().flat_map(|g| g.range()).collect(),
            Jump::Crouch => CROUCH_GROUPS.iter().flat_map(|g| g.range()).collect(),
            Jump::Mirror => Group::ALL.iter().flat_map(|g| g.range()).collect(),
        }
    }

    /// The pose after the jump, `None` when it would barely move anything.
    pub fn apply(self, body: &Body, pose: &Pose) -> Option<Pose> {
        match self {
            Jump::Flip(f) => f.apply(body, pose),
            Jump::NodIntoTrunk => nod_into_trunk(body, pose),
            Jump::SwapLegs => swapped(pose, ix::L_HIP, ix::R_HIP, ix::R_HIP - ix::L_HIP),
            Jump::SwapArms => swapped(
                pose,
                ix::L_SHOULDER,
                ix::R_SHOULDER,
                ix::R_SHOULDER - ix::L_SHOULDER,
            ),
            Jump::Crouch => Some(crouch(body, pose, -CROUCH_CM)),
            Jump::Mirror => Some(depth_mirror(pose)),
        }
    }
}

/// The whole body mirrored in depth: reflected in the vertical plane through its
/// root square to the line of sight from the camera (at the world's origin), left
/// and right exchanged so that it is a body again. Seen by an orthographic camera
/// it is the same silhouette; a pinhole camera sees it nearly so. The heading h
/// becomes 2φ − h + 180° (φ: the heading that faces the camera), the rest is
/// [`exchange_sides`]; the root's position and the forward bends are kept.
pub fn depth_mirror(pose: &Pose) -> Pose {
    let facing = (-pose[ix::ROOT_TX]).atan2(-pose[ix::ROOT_TZ]).to_degrees();
    let mut m = exchange_sides(pose);
    let h = 2.0 * facing - pose[ix::ROOT_RY] + 180.0;
    // The same heading within a turn of the original's, so that nothing unwinds.
    m[ix::ROOT_RY] = h - 360.0 * ((h - pose[ix::ROOT_RY]) / 360.0).round();
    clamp_to_limits(&mut m);
    m
}

/// `pose` with left and right exchanged, as in a mirror: the limbs' angles
/// swapped (the right side's parameters are signed so that equal values are
/// mirror images), the roll and the trunk's and neck's sideways bends and twists
/// negated. The root's position and heading and the forward bends are kept.
pub fn exchange_sides(pose: &Pose) -> Pose {
    let mut m = *pose;
    for k in [
        ix::ROOT_RZ,
        ix::SPINE + 1,
        ix::SPINE + 2,
        ix::NECK + 1,
        ix::NECK + 2,
    ] {
        m[k] = -pose[k];
    }
    exchange(
        &mut m,
        ix::L_SHOULDER,
        ix::R_SHOULDER,
        ix::R_SHOULDER - ix::L_SHOULDER,
    );
    exchange(&mut m, ix::L_HIP, ix::R_HIP, ix::R_HIP - ix::L_HIP);
    m
}

/// `pose` with `params` fitted by inverse kinematics to the landmarks `target`,
/// from each of `seeds` (values of `params`); the best fit.
fn fit_landmarks<const N: usize>(
    body: &Body,
    pose: &Pose,
    params: &[usize],
    target: &[Point3<f64>; LANDMARK_COUNT],
    seeds: [Vec<f64>; N],
) -> Pose {
    fit_landmarks_weighted(body, pose, params, target, &[1.0; LANDMARK_COUNT], seeds)
}

/// [`fit_landmarks`] with each landmark's squared miss weighed by `weight` (0: the
/// landmark goes where it will).
fn fit_landmarks_weighted<const N: usize>(
    body: &Body,
    pose: &Pose,
    params: &[usize],
    target: &[Point3<f64>; LANDMARK_COUNT],
    weight: &[f64; LANDMARK_COUNT],
    seeds: [Vec<f64>; N],
) -> Pose {
    let steps: Vec<f64> = params.iter().map(|&k| 4.0 * MOTION[k].scale).collect();
    let lo: Vec<f64> = params.iter().map(|&k| MOTION[k].lo).collect();
    let hi: Vec<f64> = params.iter().map(|&k| MOTION[k].hi).collect();
    let base = *pose;
    let fit = |x: &[f64]| -> Pose {
        let mut p = base;
        for (&k, v) in params.iter().zip(x) {
            p[k] = *v;
        }
        p
    };
    // Only the joints the parameters move are posed again for each trial, in
    // place, and only the landmarks whose share can be other than 0 summed (in
    // order: the sum is the same as over all of them).
    let moved = joints_moved_by(params);
    let mut posed = body.posed(&base);
    let share =
        |posed: &Posed, i: usize| weight[i] * (posed.landmark(i) - target[i]).norm_squared();
    let counted: Vec<usize> = (0..LANDMARK_COUNT)
        .filter(|&i| landmark_joint(i).is_some_and(|j| moved[j]) || share(&posed, i) != 0.0)
        .collect();
    let mut misfit = |x: &[f64]| -> f64 {
        body.skeleton.repose_moved(&fit(x), &moved, &mut posed);
        counted.iter().map(|&i| share(&posed, i)).sum()
    };
    // Landmarks within a centimetre or so are enough: the search refines the
    // result on the frame itself.
    let opts = SimplexOptions {
        max_evals: 100 * (params.len() + 1),
        ftol: 0.0,
        abs_tol: 0.1,
        xtol: 0.01,
    };
    // A second pass (fresh steps) only when the first stopped far from the targets.
    let mut best: Option<(f64, Vec<f64>)> = None;
    for seed in seeds {
        let mut r = minimize(&mut misfit, &seed, &steps, &lo, &hi, &opts);
        if r.f > CLOSE_CM2 {
            let again = minimize(&mut misfit, &r.x, &steps, &lo, &hi, &opts);
            if again.f < r.f {
                r = again;
            }
        }
        if best.as_ref().is_none_or(|(f, _)| r.f < *f) {
            best = Some((r.f, r.x));
        }
    }
    best.map_or(base, |(_, x)| fit(&x))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::params::{ix, rest_pose, STANDARD_SHAPE};
    use crate::body::skeleton::Posed;
    use crate::body::Camera;

    #[test]
    fn the_depth_mirror_is_the_reflected_body_with_left_and_right_exchanged() {
        use crate::body::params::MOTION_COUNT;
        use rand::{RngExt, SeedableRng};
        let body = Body::new(&STANDARD_SHAPE);
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let pair = |j: Joint| -> Joint {
            let n = format!("{j:?}");
            let other = if let Some(r) = n.strip_prefix("Left") {
                format!("Right{r}")
            } else if let Some(r) = n.strip_prefix("Right") {
                format!("Left{r}")
            } else {
                n
            };
            Joint::ALL
                .into_iter()
                .find(|k| format!("{k:?}") == other)
                .unwrap()
        };
        for _ in 0..50 {
            let mut pose = [0.0; MOTION_COUNT];
            for (k, v) in pose.iter_mut().enumerate() {
                let (lo, hi) = (MOTION[k].lo.max(-170.0), MOTION[k].hi.min(170.0));
                *v = rng.random_range(lo..hi);
            }
            pose[ix::ROOT_TX] = rng.random_range(-150.0..150.0);
            pose[ix::ROOT_TY] = rng.random_range(-50.0..50.0);
            pose[ix::ROOT_TZ] = rng.random_range(-600.0..-200.0);
            let mirrored = depth_mirror(&pose);
            let (a, b) = (body.posed(&pose), body.posed(&mirrored));
            let root = a.joint(Joint::Hips).coords;
            let n = nalgebra::Vector3::new(root.x, 0.0, root.z).normalize();
            for j in Joint::ALL {
                let p = a.joint(j).coords - root;
                let reflected = p - 2.0 * p.dot(&n) * n;
                let got = b.joint(pair(j)).coords - root;
                assert!(
                    (got - reflected).norm() < 1e-6,
                    "{j:?}: {got} vs {reflected}"
                );
            }
        }
    }

    fn flip(name: &str) -> &'static Flip {
        FLIPS.iter().find(|f| f.name == name).unwrap()
    }

    /// A body 3 m in front of the camera and facing it, its hips `hips` cm above
    /// the camera, with `set` applied.
    fn flipped(name: &str, hips: f64, set: &[(usize, f64)]) -> (Posed, Posed) {
        let body = Body::new(&STANDARD_SHAPE);
        let mut pose = rest_pose();
        pose[ix::ROOT_TY] = hips;
        pose[ix::ROOT_TZ] = -300.0;
        for &(k, v) in set {
            pose[k] = v;
        }
        let out = flip(name).apply(&body, &pose).expect("a flip");
        (body.posed(&pose), body.posed(&out))
    }

    fn pixels_apart(a: &Point3<f64>, b: &Point3<f64>) -> f64 {
        let cam = Camera::new(320, 240, 55.0);
        let (pa, pb) = (cam.project(a).unwrap(), cam.project(b).unwrap());
        ((pa[0] - pb[0]).powi(2) + (pa[1] - pb[1]).powi(2)).sqrt()
    }

    #[test]
    fn an_arm_raised_forwards_flips_to_one_raised_backwards_seen_alike() {
        let (a, b) = flipped("left arm", -45.0, &[(ix::L_SHOULDER, 50.0)]);
        let hand = |p: &Posed| p.joint(Joint::LeftHand);
        let px = pixels_apart(&hand(&a), &hand(&b));
        assert!(px < 3.0, "the hand moved {px:.1} px in the image");
        // In front of the shoulder (towards the camera, +z) before, behind it after.
        let shoulder = a.joint(Joint::LeftArm).z;
        let (before, after) = (hand(&a).z - shoulder, hand(&b).z - shoulder);
        assert!(
            before > 20.0 && after < -20.0,
            "depth {before:.1} -> {after:.1}"
        );
        // The rest of the body has not moved.
        assert!((a.joint(Joint::RightHand) - b.joint(Joint::RightHand)).norm() < 1e-9);
        assert!((a.joint(Joint::LeftFoot) - b.joint(Joint::LeftFoot)).norm() < 1e-9);
    }

    /// A trunk flip's neck, before (`a`) and after (`b`): checks that it is seen
    /// where it was; its depths from the spine's joint (towards the camera, +z).
    fn neck_depths(a: &Posed, b: &Posed) -> (f64, f64) {
        let neck = |p: &Posed| p.joint(Joint::Neck);
        let px = pixels_apart(&neck(a), &neck(b));
        assert!(px < 3.0, "the neck moved {px:.1} px in the image");
        let spine = a.joint(Joint::Spine).z;
        (neck(a).z - spine, neck(b).z - spine)
    }

    #[test]
    fn a_trunk_bent_forwards_flips_to_one_bent_backwards_with_the_arms_carried() {
        let (a, b) = flipped("spine", -10.0, &[(ix::SPINE, 25.0)]);
        let (before, after) = neck_depths(&a, &b);
        assert!(
            before > 10.0 && after < -5.0,
            "depth {before:.1} -> {after:.1}"
        );
        // The arms are carried: the hands are still seen about where they were.
        let px = pixels_apart(&a.joint(Joint::LeftHand), &b.joint(Joint::LeftHand));
        assert!(px < 4.0, "the left hand moved {px:.1} px in the image");
    }

    #[test]
    fn a_trunk_bent_backwards_flips_to_one_bent_forwards_with_the_arms_following() {
        // The arms held slightly apart, straight along the trunk.
        let set = [
            (ix::SPINE, -25.0),
            (ix::L_SHOULDER + 1, 10.0),
            (ix::R_SHOULDER + 1, 10.0),
        ];
        let (a, b) = flipped("spine with the arms", -10.0, &set);
        let (before, after) = neck_depths(&a, &b);
        assert!(
            before < -10.0 && after > 10.0,
            "depth {before:.1} -> {after:.1}"
        );
        // The hands turn with the trunk, away from the camera as the shoulders come
        // nearer (the "spine" flip keeps them on their side of the shoulders, and so
        // brings them nearer with them).
        let (_, kept) = flipped("spine", -10.0, &set);
        let spine = a.joint(Joint::Spine).z;
        for hand in [Joint::LeftHand, Joint::RightHand] {
            let depth = |p: &Posed| p.joint(hand).z - spine;
            let (before, after, kept) = (depth(&a), depth(&b), depth(&kept));
            println!("{hand:?}: depth {before:.1} -> {after:.1} cm (kept: {kept:.1})");
            assert!(
                after < before - 5.0 && after < kept - 5.0,
                "{hand:?}: depth {before:.1} -> {after:.1} (kept: {kept:.1})"
            );
        }
    }

    #[test]
    fn flips_of_any_pose_stay_within_the_joint_limits() {
        let body = Body::new(&STANDARD_SHAPE);
        // A fixed pseudo-random sequence (no dependency needed for 50 poses).
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..50 {
            let mut pose = rest_pose();
            pose[ix::ROOT_TZ] = -300.0;
            for (k, m) in MOTION.iter().enumerate().skip(3) {
                let (lo, hi) = (m.lo.max(-180.0), m.hi.min(180.0));
                pose[k] = lo + (hi - lo) * next();
            }
            for flip in &FLIPS {
                let Some(out) = flip.apply(&body, &pose) else {
                    continue;
                };
                for (k, m) in MOTION.iter().enumerate() {
                    assert!(out[k].is_finite(), "{}: {} not finite", flip.name, m.name);
                    assert!(
                        (m.lo..=m.hi).contains(&out[k]),
                        "{}: {} = {} outside its limits",
                        flip.name,
                        m.name,
                        out[k]
                    );
                    if !flip.params().contains(&k) {
                        assert_eq!(out[k], pose[k], "{} changed {}", flip.name, m.name);
                    }
                }
            }
        }
    }

    #[test]
    fn a_swap_exchanges_the_limbs_and_nothing_else() {
        let body = Body::new(&STANDARD_SHAPE);
        let mut pose = rest_pose();
        pose[ix::ROOT_TZ] = -300.0;
        // Symmetric limbs: nothing to swap.
        assert!(Jump::SwapLegs.apply(&body, &pose).is_none());
        assert!(Jump::SwapArms.apply(&body, &pose).is_none());
        pose[ix::L_HIP] = 40.0;
        pose[ix::R_KNEE] = 70.0;
        pose[ix::L_SHOULDER + 1] = 60.0;
        let legs = Jump::SwapLegs.apply(&body, &pose).unwrap();
        assert_eq!((legs[ix::R_HIP], legs[ix::L_KNEE]), (40.0, 70.0));
        assert_eq!((legs[ix::L_HIP], legs[ix::R_KNEE]), (0.0, 0.0));
        let arms = Jump::SwapArms.apply(&body, &pose).unwrap();
        assert_eq!(
            (arms[ix::R_SHOULDER + 1], arms[ix::L_SHOULDER + 1]),
            (60.0, 0.0)
        );
        for (k, (a, b)) in legs.iter().zip(&pose).enumerate() {
            if !Jump::SwapLegs.params().contains(&k) {
                assert_eq!(a, b);
            }
        }
        // The swapped knee bends the same way, on the other side: the right foot
        // now hangs where the left one did, mirrored across the body.
        let (p, q) = (body.posed(&pose), body.posed(&legs));
        let (lf, rf) = (Joint::LeftFoot.index(), Joint::RightFoot.index());
        assert!(
            (p.joints[lf].translation.vector.y - q.joints[rf].translation.vector.y).abs() < 1e-6
        );
        assert_eq!(Jump::SwapLegs.apply(&body, &legs), Some(pose));
    }

    #[test]
    fn a_nod_moved_into_the_trunk_bends_it_and_keeps_the_head_nearer() {
        let body = Body::new(&STANDARD_SHAPE);
        let mut pose = rest_pose();
        pose[ix::ROOT_TZ] = -300.0;
        pose[ix::NECK] = 30.0;
        let out = nod_into_trunk(&body, &pose).expect("a nod");
        assert_eq!(out[ix::NECK], 0.0);
        assert!(out[ix::SPINE] > 3.0, "spine_x {:.0}°", out[ix::SPINE]);
        // The head top stays nearer its place than with the neck merely straightened
        // (the fit also keeps the shoulders and hands, so the trunk takes part of
        // the nod only).
        let top = |p: &Pose| body.posed(p).tips[Tip::HeadTop as usize];
        let mut straight = pose;
        straight[ix::NECK] = 0.0;
        let (moved, naive) = (
            (top(&out) - top(&pose)).norm(),
            (top(&straight) - top(&pose)).norm(),
        );
        assert!(
            moved < 0.8 * naive,
            "head top moved {moved:.1} cm, {naive:.1} cm straightened"
        );
        println!(
            "spine {:.1}°, head top moved {moved:.1} cm ({naive:.1} cm straightened)",
            out[ix::SPINE]
        );
        pose[ix::NECK] = 2.0;
        assert!(nod_into_trunk(&body, &pose).is_none());
    }

    #[test]
    fn a_crouch_lowers_the_hips_and_bends_the_knees_with_the_feet_kept() {
        let body = Body::new(&STANDARD_SHAPE);
        let mut pose = rest_pose();
        pose[ix::ROOT_TZ] = -300.0;
        let moved = |a: &Pose, b: &Pose| {
            let (la, lb) = (body.posed(a).landmarks(), body.posed(b).landmarks());
            FEET.iter()
                .map(|&i| (la[i] - lb[i]).norm())
                .fold(0.0, f64::max)
        };
        let down = crouch(&body, &pose, -CROUCH_CM);
        assert!((down[ix::ROOT_TY] - (pose[ix::ROOT_TY] - CROUCH_CM)).abs() < 1e-9);
        let m = moved(&pose, &down);
        assert!(m < 1.0, "the feet moved {m:.2} cm");
        for knee in [ix::L_KNEE, ix::R_KNEE] {
            let bent = down[knee] - pose[knee];
            assert!(bent > 10.0, "a knee bent by {bent:.1}°");
        }
        // The arms and the trunk are carried along, untouched.
        for k in ix::SPINE..ix::L_HIP {
            assert_eq!(down[k], pose[k]);
        }
        // And up again: the knees straighten, the feet still kept. (Near straight,
        // a knee barely changes the leg's length, so not to the very degree.)
        let up = crouch(&body, &down, CROUCH_CM);
        let m = moved(&pose, &up);
        assert!(m < 1.0, "the feet moved {m:.2} cm");
        for knee in [ix::L_KNEE, ix::R_KNEE] {
            assert!(
                up[knee] < pose[knee] + 0.5 * (down[knee] - pose[knee]),
                "a knee at {:.1}° after rising, {:.1}° crouched, {:.1}° before",
                up[knee],
                down[knee],
                pose[knee]
            );
        }
    }
}
