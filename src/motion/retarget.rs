//! Retargeting real motion capture onto the body model: map a BVH skeleton's joints
//! to the 18 named joints, choose shape values from its bone lengths, and solve the
//! 30 motion parameters of each frame so that the model's joints follow the capture's.
//!
//! The per-frame solve is a damped Gauss–Newton (Levenberg–Marquardt) on joint
//! positions with numeric derivatives, projected onto the joint limits, warm-started
//! from the previous frame. A weak prior towards the previous frame settles the
//! degrees of freedom joint positions cannot see (an upper arm's twist while the elbow
//! is straight, the head's turn).

use nalgebra::{DMatrix, DVector, Point3};

use crate::body::params::{self, ix, sx, Pose, ShapeValues, MOTION, MOTION_COUNT, SHAPE};
use crate::body::skeleton::{standard, Joint, Posed, JOINT_COUNT};
use crate::body::Body;
use crate::motion::bvh::Bvh;

#[derive(Debug, thiserror::Error)]
pub enum RetargetError {
    #[error("cannot retarget: no joint of the BVH matches {0} (looked for {1})")]
    Missing(&'static str, String),
    #[error("cannot retarget: the neck joint {0} does not descend from the hips joint {1}")]
    NotAChain(String, String),
}

/// Names each of our joints may carry in other skeletons, most specific first,
/// after [`normalize`]: CMU, Bandai Namco, Mixamo, Unreal Mannequin, Biped-style.
/// Order matters where conventions clash: Mixamo's `LeftShoulder` is the collar bone
/// and its `LeftArm` the shoulder joint, while CMU's `LeftShoulder` is the shoulder
/// joint, so `leftarm` is tried first.
#[rustfmt::skip]
fn aliases(j: Joint) -> &'static [&'static str] {
    use Joint::*;
    match j {
        Hips => &["hips", "pelvis", "hip"],
        // Derived from the spine chain (see `JointMap`).
        Spine => &[],
        // CMU's `lowerneck` is at chest height; its `Neck` is the neck's base, as ours.
        Neck => &["neck", "neck01", "neck1", "lowerneck"],
        Head => &["head"],
        LeftArm => &["leftarm", "upperarml", "leftupperarm", "lupperarm", "leftshoulder", "lshoulder"],
        LeftForeArm => &["leftforearm", "lowerarml", "leftlowerarm", "lforearm", "leftelbow", "lelbow"],
        LeftHand => &["lefthand", "handl", "leftwrist", "lwrist", "lhand"],
        RightArm => &["rightarm", "upperarmr", "rightupperarm", "rupperarm", "rightshoulder", "rshoulder"],
        RightForeArm => &["rightforearm", "lowerarmr", "rightlowerarm", "rforearm", "rightelbow", "relbow"],
        RightHand => &["righthand", "handr", "rightwrist", "rwrist", "rhand"],
        LeftUpLeg => &["leftupleg", "upperlegl", "thighl", "leftthigh", "leftupperleg", "lefthip", "lthigh", "lhip"],
        LeftLeg => &["leftleg", "lowerlegl", "calfl", "leftshin", "leftlowerleg", "leftknee", "lknee", "lshin"],
        LeftFoot => &["leftfoot", "footl", "leftankle", "lankle", "lfoot"],
        LeftToeBase => &["lefttoebase", "toesl", "balll", "lefttoe", "lefttoes", "ltoe", "toel"],
        RightUpLeg => &["rightupleg", "upperlegr", "thighr", "rightthigh", "rightupperleg", "righthip", "rthigh", "rhip"],
        RightLeg => &["rightleg", "lowerlegr", "calfr", "rightshin", "rightlowerleg", "rightknee", "rknee", "rshin"],
        RightFoot => &["rightfoot", "footr", "rightankle", "rankle", "rfoot"],
        RightToeBase => &["righttoebase", "toesr", "ballr", "righttoe", "righttoes", "rtoe", "toer"],
    }
}

/// Lower case, namespace prefixes (`mixamorig:`) dropped, only letters and digits.
fn normalize(name: &str) -> String {
    let base = name.rsplit(':').next().unwrap_or(name);
    let base = base.strip_prefix("mixamorig").unwrap_or(base);
    base.chars()
        .filter(|c| c.is_ascii_alphanumeric())
        .map(|c| c.to_ascii_lowercase())
        .collect()
}

/// Which BVH joint drives each of the 18 joints.
///
/// Skeletons place their root and lower-back joints at different heights (CMU's root
/// is 10 cm above its hip joints, Bandai's 2 cm, ours 6; Bandai's `Spine` is 38% of
/// the way up the back, ours 20%), so our Hips and Spine targets are not joints of
/// the capture but points of its spine chain — from the midpoint of its hip joints
/// through its spine joints to its Neck — at our joints' fractions of that length.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct JointMap {
    pub source: [usize; JOINT_COUNT],
    /// The capture's joints from its Hips to its Neck, both included.
    pub spine_chain: Vec<usize>,
}

impl JointMap {
    /// Every one of the 18 joints must be found.
    pub fn detect(bvh: &Bvh) -> Result<JointMap, RetargetError> {
        let names: Vec<String> = bvh.joints.iter().map(|j| normalize(&j.name)).collect();
        let mut source = [0; JOINT_COUNT];
        for j in Joint::ALL.into_iter().filter(|j| *j != Joint::Spine) {
            let found = aliases(j)
                .iter()
                .find_map(|a| names.iter().position(|n| n == a));
            source[j.index()] =
                found.ok_or_else(|| RetargetError::Missing(j.name(), aliases(j).join(", ")))?;
        }
        let (hips, neck) = (source[Joint::Hips.index()], source[Joint::Neck.index()]);
        let mut spine_chain = vec![neck];
        while let Some(&last) = spine_chain.last() {
            if last == hips {
                break;
            }
            match bvh.joints[last].parent {
                Some(p) if spine_chain.len() <= bvh.joints.len() => spine_chain.push(p),
                _ => {
                    return Err(RetargetError::NotAChain(
                        bvh.joints[neck].name.clone(),
                        bvh.joints[hips].name.clone(),
                    ))
                }
            }
        }
        spine_chain.reverse();
        // A nominal source for Spine: the chain's first joint above the Hips.
        source[Joint::Spine.index()] = *spine_chain.get(1).unwrap_or(&hips);
        Ok(JointMap {
            source,
            spine_chain,
        })
    }
}

/// Centimetres per unit of a BVH file, judged from its leg length (about 80 cm for
/// an adult): centimetres, metres, millimetres, inches, or the CMU database's
/// unit (1/0.45 inch), whichever puts the legs nearest a human length.
pub fn detect_unit_scale(bvh: &Bvh, map: &JointMap) -> f64 {
    const CANDIDATES: [f64; 5] = [1.0, 100.0, 0.1, 2.54, 2.54 / 0.45];
    let p = bvh.joint_positions(0);
    let at = |j: Joint| p[map.source[j.index()]];
    let leg = |a: Joint, b: Joint, c: Joint| (at(a) - at(b)).norm() + (at(b) - at(c)).norm();
    let units = 0.5
        * (leg(Joint::LeftUpLeg, Joint::LeftLeg, Joint::LeftFoot)
            + leg(Joint::RightUpLeg, Joint::RightLeg, Joint::RightFoot));
    let standard_leg = standard::THIGH + standard::SHIN;
    CANDIDATES
        .into_iter()
        .min_by(|a, b| {
            let da = (units * a / standard_leg).ln().abs();
            let db = (units * b / standard_leg).ln().abs();
            da.total_cmp(&db)
        })
        .unwrap_or(1.0)
}

/// Shape values from the capture's bone lengths (median over the given frames of
/// joint positions in cm). Thicknesses and head size cannot be seen in a skeleton
/// and stay standard.
pub fn fit_shape(frames: &[[Point3<f64>; JOINT_COUNT]]) -> ShapeValues {
    use Joint::*;
    let median_len = |pairs: &[(Joint, Joint)]| -> f64 {
        let mut v: Vec<f64> = frames
            .iter()
            .map(|f| {
                pairs
                    .iter()
                    .map(|(a, b)| (f[a.index()] - f[b.index()]).norm())
                    .sum::<f64>()
                    / pairs.len() as f64
            })
            .collect();
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    let s = standard::TOE_FORWARD.hypot(standard::TOE_DROP);
    let mut shape = params::STANDARD_SHAPE;
    let mut set = |i: usize, len: f64, std_len: f64| shape[i] = len / std_len;
    set(
        sx::UPPER_ARM,
        median_len(&[(LeftArm, LeftForeArm), (RightArm, RightForeArm)]),
        standard::UPPER_ARM,
    );
    set(
        sx::FOREARM,
        median_len(&[(LeftForeArm, LeftHand), (RightForeArm, RightHand)]),
        standard::FOREARM,
    );
    set(
        sx::THIGH,
        median_len(&[(LeftUpLeg, LeftLeg), (RightUpLeg, RightLeg)]),
        standard::THIGH,
    );
    set(
        sx::SHIN,
        median_len(&[(LeftLeg, LeftFoot), (RightLeg, RightFoot)]),
        standard::SHIN,
    );
    set(
        sx::FOOT,
        median_len(&[(LeftFoot, LeftToeBase), (RightFoot, RightToeBase)]),
        s,
    );
    set(
        sx::PELVIS_WIDTH,
        median_len(&[(LeftUpLeg, RightUpLeg)]),
        2.0 * standard::HIP_HALF_WIDTH,
    );
    set(
        sx::TORSO_WIDTH,
        median_len(&[(LeftArm, RightArm)]),
        2.0 * standard::SHOULDER_HALF_WIDTH,
    );
    set(
        sx::TORSO_HEIGHT,
        median_len(&[(Hips, Neck)]),
        standard::LOWER_BACK + standard::TORSO,
    );
    for (v, p) in shape.iter_mut().zip(SHAPE.iter()) {
        *v = if v.is_finite() {
            v.clamp(p.lo, p.hi)
        } else {
            1.0
        };
    }
    shape
}

/// How well one frame was fitted.
#[derive(Clone, Copy, Debug, Default)]
pub struct Residual {
    /// Mean and largest distance (cm) between model joints and capture joints.
    pub mean_cm: f64,
    pub max_cm: f64,
    /// The joint with the largest distance.
    pub worst: Option<Joint>,
}

/// Weight of each joint's position residual: the Hips and Spine targets are derived
/// points of the capture's trunk (see [`JointMap`]), so they count less.
fn joint_weight(j: Joint) -> f64 {
    match j {
        Joint::Hips | Joint::Spine => 0.5,
        _ => 1.0,
    }
}

/// Joints placed by the global and torso parameters alone.
fn is_trunk(j: Joint) -> bool {
    use Joint::*;
    matches!(
        j,
        Hips | Spine | Neck | Head | LeftArm | RightArm | LeftUpLeg | RightUpLeg
    )
}

/// Prior weight (per length scale of a parameter) towards the previous solution.
const PRIOR: f64 = 0.15;
/// The global and torso parameters, fitted before the limbs.
const TRUNK_PARAMS: std::ops::Range<usize> = 0..12;
/// Gauss–Newton iterations per frame at most.
const MAX_ITERS: usize = 60;

/// Solves frames one after another, each starting from the previous solution.
pub struct Retargeter {
    pub body: Body,
    prev: Option<Pose>,
    posed: Posed,
}

impl Retargeter {
    pub fn new(shape: &ShapeValues) -> Retargeter {
        Retargeter {
            body: Body::new(shape),
            prev: None,
            posed: Posed::default(),
        }
    }

    /// Fits one frame to target joint positions (cm, in the frame the result should
    /// live in: world Y up).
    ///
    /// Two candidates are polished by the least-squares solve and the better kept:
    /// the previous frame's pose, and a pose whose trunk is fitted first and whose
    /// limbs are then solved in closed form (immune to the local minima a bent elbow
    /// or knee creates when the search starts from a straight one).
    pub fn solve(&mut self, target: &[Point3<f64>; JOINT_COUNT]) -> (Pose, Residual) {
        let prior = match self.prev {
            Some(p) => p,
            None => self.initial_guess(target),
        };
        let trunk = self.gauss_newton(prior, &prior, target, TRUNK_PARAMS);
        let mut analytic = trunk;
        self.limbs_in_closed_form(&mut analytic, target);
        let a = self.gauss_newton(analytic, &prior, target, 0..MOTION_COUNT);
        let b = self.gauss_newton(prior, &prior, target, 0..MOTION_COUNT);
        let mut pose = if self.cost(&a, &prior, target) <= self.cost(&b, &prior, target) {
            a
        } else {
            b
        };
        // Keep the heading within one turn of zero so long turning motions stay in
        // range; the wrapped pose is the same pose.
        if pose[ix::ROOT_RY] > 360.0 {
            pose[ix::ROOT_RY] -= 360.0;
        } else if pose[ix::ROOT_RY] < -360.0 {
            pose[ix::ROOT_RY] += 360.0;
        }
        self.prev = Some(pose);
        (pose, self.residual(&pose, target))
    }

    /// Sets the arm and leg angles from the targets in the frames of the already
    /// posed trunk: swing from the upper bone's direction, flexion from the angle
    /// between the bones, twist from the lower bone's direction, ankle from the foot.
    fn limbs_in_closed_form(&mut self, pose: &mut Pose, target: &[Point3<f64>; JOINT_COUNT]) {
        use Joint::*;
        let limbs = [
            (
                LeftArm,
                LeftForeArm,
                LeftHand,
                None,
                ix::L_SHOULDER,
                ix::L_ELBOW,
            ),
            (
                RightArm,
                RightForeArm,
                RightHand,
                None,
                ix::R_SHOULDER,
                ix::R_ELBOW,
            ),
            (
                LeftUpLeg,
                LeftLeg,
                LeftFoot,
                Some(LeftToeBase),
                ix::L_HIP,
                ix::L_KNEE,
            ),
            (
                RightUpLeg,
                RightLeg,
                RightFoot,
                Some(RightToeBase),
                ix::R_HIP,
                ix::R_KNEE,
            ),
        ];
        for (root, mid, end, toe, first, flex) in limbs {
            self.body.skeleton.pose(pose, &mut self.posed);
            let parent = self.posed.joints[root.parent().map_or(0, |p| p.index())].rotation;
            let t = |j: Joint| target[j.index()];
            let (Some(u), Some(w)) = (
                (parent.inverse() * (t(mid) - t(root))).try_normalize(1e-9),
                (parent.inverse() * (t(end) - t(mid))).try_normalize(1e-9),
            ) else {
                continue;
            };
            let sign = |k: usize| MOTION[k].sign;
            // Swing: Rz(a)·Rx(c)·(0, −1, 0) = (cos c·sin a, −cos c·cos a, −sin c).
            let c = (-u.z).clamp(-1.0, 1.0).asin();
            let a = u.x.atan2(-u.y);
            // Flexion: the angle between the bones; its sign is the parameter's.
            let phi = u.dot(&w).clamp(-1.0, 1.0).acos();
            pose[first] = c.to_degrees() / sign(first);
            pose[first + 1] = a.to_degrees() / sign(first + 1);
            pose[flex] = phi.to_degrees();
            // Twist: in the swung frame the lower bone is
            // Ry(t)·Rx(f)·(0, −1, 0) = (−sin f·sin t, −cos f, −sin f·cos t), f = sign·φ.
            let swing =
                crate::body::skeleton::axis_rotation(crate::body::params::Axis::Z, a.to_degrees())
                    * crate::body::skeleton::axis_rotation(
                        crate::body::params::Axis::X,
                        c.to_degrees(),
                    );
            let wl = swing.inverse() * w;
            let f = sign(flex) * phi;
            if f.sin().abs() > 0.15 {
                let tw = (-wl.x / f.sin()).atan2(-wl.z / f.sin());
                pose[first + 2] = tw.to_degrees() / sign(first + 2);
            }
            params::clamp_to_limits(pose);
            // Ankle: the foot's pitch in the shin's frame against its rest direction.
            if let Some(toe) = toe {
                self.body.skeleton.pose(pose, &mut self.posed);
                let shin = self.posed.joints[mid.index()].rotation;
                let ankle = flex + 1;
                let rest = self.body.skeleton.offsets[toe.index()];
                if let Some(fl) = (shin.inverse() * (t(toe) - t(end))).try_normalize(1e-9) {
                    // Rx(θ) turns the rest direction (0, ry, rz) within the YZ plane.
                    let angle = |v: &nalgebra::Vector3<f64>| v.z.atan2(v.y);
                    let theta = angle(&rest) - angle(&fl);
                    pose[ankle] = theta.to_degrees() / sign(ankle);
                }
                params::clamp_to_limits(pose);
            }
        }
    }

    /// Root at the capture's hips, heading from the hip joints.
    fn initial_guess(&self, target: &[Point3<f64>; JOINT_COUNT]) -> Pose {
        let mut pose = params::rest_pose();
        let hips = target[Joint::Hips.index()];
        pose[ix::ROOT_TX] = hips.x;
        pose[ix::ROOT_TY] = hips.y;
        pose[ix::ROOT_TZ] = hips.z;
        // Left hip minus right hip points along the body's +X; the body faces +Z
        // of its own frame, i.e. along (left − right) × up rotated.
        let lr = target[Joint::LeftUpLeg.index()] - target[Joint::RightUpLeg.index()];
        pose[ix::ROOT_RY] = (-lr.z).atan2(lr.x).to_degrees();
        pose
    }

    /// Weighted joint residuals (only the trunk's joints when `trunk_only`) and the
    /// prior's.
    fn residuals(
        &mut self,
        pose: &Pose,
        prior: &Pose,
        target: &[Point3<f64>; JOINT_COUNT],
        trunk_only: bool,
        out: &mut DVector<f64>,
    ) {
        self.body.skeleton.pose(pose, &mut self.posed);
        for j in Joint::ALL {
            let w = if trunk_only && !is_trunk(j) {
                0.0
            } else {
                joint_weight(j)
            };
            let d = (self.posed.joint(j) - target[j.index()]) * w;
            out.fixed_rows_mut::<3>(3 * j.index()).copy_from(&d);
        }
        for k in 0..MOTION_COUNT {
            out[3 * JOINT_COUNT + k] = PRIOR * (pose[k] - prior[k]) / MOTION[k].scale;
        }
    }

    /// The least-squares objective: joint residuals plus the prior.
    fn cost(&mut self, pose: &Pose, prior: &Pose, target: &[Point3<f64>; JOINT_COUNT]) -> f64 {
        let mut r = DVector::zeros(3 * JOINT_COUNT + MOTION_COUNT);
        self.residuals(pose, prior, target, false, &mut r);
        r.norm_squared()
    }

    /// Levenberg–Marquardt over the parameters in `active` (the others stay put).
    fn gauss_newton(
        &mut self,
        start: Pose,
        prior: &Pose,
        target: &[Point3<f64>; JOINT_COUNT],
        active: std::ops::Range<usize>,
    ) -> Pose {
        let m = 3 * JOINT_COUNT + MOTION_COUNT;
        let mut pose = start;
        params::clamp_to_limits(&mut pose);
        let mut r = DVector::zeros(m);
        let mut r2 = DVector::zeros(m);
        let n = active.len();
        let trunk_only = active.end <= TRUNK_PARAMS.end;
        let mut jac = DMatrix::zeros(m, n);
        self.residuals(&pose, prior, target, trunk_only, &mut r);
        let mut cost = r.norm_squared();
        let mut lambda = 1e-3;
        for _ in 0..MAX_ITERS {
            for (col, k) in active.clone().enumerate() {
                let h = 1e-4 * MOTION[k].scale;
                let mut p = pose;
                p[k] += h;
                self.residuals(&p, prior, target, trunk_only, &mut r2);
                jac.set_column(col, &((&r2 - &r) / h));
            }
            let jtj = jac.transpose() * &jac;
            let jtr = jac.transpose() * &r;
            let mut improved = false;
            while lambda < 1e8 {
                let mut a = jtj.clone();
                for k in 0..n {
                    a[(k, k)] += lambda * (jtj[(k, k)] + 1e-6);
                }
                let Some(step) = a.cholesky().map(|c| c.solve(&(-&jtr))) else {
                    lambda *= 10.0;
                    continue;
                };
                let mut cand = pose;
                for (col, k) in active.clone().enumerate() {
                    cand[k] += step[col];
                }
                params::clamp_to_limits(&mut cand);
                self.residuals(&cand, prior, target, trunk_only, &mut r2);
                let c2 = r2.norm_squared();
                if c2 < cost {
                    let gain = cost - c2;
                    pose = cand;
                    std::mem::swap(&mut r, &mut r2);
                    cost = c2;
                    lambda = (lambda * 0.3).max(1e-7);
                    improved = gain > 1e-10 * (1.0 + cost);
                    break;
                }
                lambda *= 10.0;
            }
            if !improved {
                break;
            }
        }
        pose
    }

    fn residual(&mut self, pose: &Pose, target: &[Point3<f64>; JOINT_COUNT]) -> Residual {
        self.body.skeleton.pose(pose, &mut self.posed);
        let mut res = Residual::default();
        for j in Joint::ALL {
            let d = (self.posed.joint(j) - target[j.index()]).norm();
            res.mean_cm += d / JOINT_COUNT as f64;
            if d >= res.max_cm {
                res.max_cm = d;
                res.worst = Some(j);
            }
        }
        res
    }
}

/// The point at `fraction` of a polyline's length.
fn point_along(chain: &[Point3<f64>], fraction: f64) -> Point3<f64> {
    let total: f64 = chain.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
    let mut left = total * fraction;
    for w in chain.windows(2) {
        let len = (w[1] - w[0]).norm();
        if len >= left && len > 0.0 {
            return w[0] + (w[1] - w[0]) * (left / len);
        }
        left -= len;
    }
    chain.last().copied().unwrap_or_else(Point3::origin)
}

/// The capture's mapped joint positions for one frame, in cm, after `transform`.
pub fn target_joints(
    bvh: &Bvh,
    map: &JointMap,
    frame: usize,
    cm_per_unit: f64,
    transform: &nalgebra::IsometryMatrix3<f64>,
) -> [Point3<f64>; JOINT_COUNT] {
    let p = bvh.joint_positions(frame);
    let mut out = [Point3::origin(); JOINT_COUNT];
    for (o, &s) in out.iter_mut().zip(map.source.iter()) {
        *o = transform * Point3::from(p[s].coords * cm_per_unit);
    }
    // Our Hips and Spine: points at the standard fractions of the capture's trunk.
    let mid_hips = Point3::from(
        (p[map.source[Joint::LeftUpLeg.index()]].coords
            + p[map.source[Joint::RightUpLeg.index()]].coords)
            / 2.0,
    );
    let chain: Vec<Point3<f64>> = std::iter::once(mid_hips)
        .chain(map.spine_chain.iter().skip(1).map(|&i| p[i]))
        .collect();
    let total = standard::HIP_DROP + standard::LOWER_BACK + standard::TORSO;
    for (joint, along) in [
        (Joint::Hips, standard::HIP_DROP),
        (Joint::Spine, standard::HIP_DROP + standard::LOWER_BACK),
    ] {
        let at = point_along(&chain, along / total);
        out[joint.index()] = transform * Point3::from(at.coords * cm_per_unit);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalize_names() {
        assert_eq!(normalize("mixamorig:LeftArm"), "leftarm");
        assert_eq!(normalize("UpperArm_L"), "upperarml");
        assert_eq!(normalize("spine_01"), "spine01");
    }

    #[test]
    fn recovers_a_pose_of_the_model_itself() {
        // Targets made by the model: the solve must find joints within a millimetre.
        let shape = params::STANDARD_SHAPE;
        let body = Body::new(&shape);
        let mut truth = params::rest_pose();
        truth[ix::ROOT_RY] = 30.0;
        truth[ix::L_SHOULDER] = 40.0;
        truth[ix::L_ELBOW] = 70.0;
        truth[ix::R_HIP] = 30.0;
        truth[ix::R_KNEE] = 45.0;
        truth[ix::SPINE] = 15.0;
        let posed = body.posed(&truth);
        let mut target = [Point3::origin(); JOINT_COUNT];
        for j in Joint::ALL {
            target[j.index()] = posed.joint(j);
        }
        let mut rt = Retargeter::new(&shape);
        let (_, res) = rt.solve(&target);
        assert!(res.max_cm < 0.1, "{res:?}");
    }
}
