//! Motion files of the monocap skeleton.
//!
//! BVH: the 18 joints of method.md §2 with their End Sites (head top, hand and toe
//! tips), centimetres, Y up, the fitted shape as bone offsets, the standing rest pose
//! with arms at the sides. The root declares `Xposition Yposition Zposition Yrotation
//! Xrotation Zrotation` (heading outermost); every other joint `Zrotation Xrotation
//! Yrotation` — the order the model itself rotates in — so a channel value is a motion
//! parameter with its table sign applied, and zero for the axes a joint does not use.

use crate::body::params::{Pose, MOTION};
use crate::body::skeleton::{Dof, Joint, Skeleton, Tip};
use crate::motion::bvh::{Bvh, BvhError, BvhJoint, Channel};

/// The monocap skeleton moving through `poses`, as a BVH.
pub fn monocap_bvh(skeleton: &Skeleton, poses: &[Pose], fps: f64) -> Result<Bvh, BvhError> {
    use Channel::*;
    let mut joints = Vec::with_capacity(Joint::ALL.len());
    let mut channel_offset = 0;
    for j in Joint::ALL {
        let channels = match j.dof() {
            Dof::Root => vec![
                Xposition, Yposition, Zposition, Yrotation, Xrotation, Zrotation,
            ],
            _ => vec![Zrotation, Xrotation, Yrotation],
        };
        let offset = match j.parent() {
            None => [0.0; 3],
            Some(_) => skeleton.offsets[j.index()].into(),
        };
        let end_site = Tip::ALL
            .iter()
            .position(|t| t.joint() == j)
            .map(|i| skeleton.tip_offsets[i].into());
        joints.push(BvhJoint {
            name: j.name().to_string(),
            parent: j.parent().map(Joint::index),
            offset,
            channel_offset,
            channels,
            end_site,
        });
        channel_offset += joints.last().map_or(0, |b: &BvhJoint| b.channels.len());
    }
    let mut data = Vec::with_capacity(poses.len() * channel_offset);
    for pose in poses {
        for j in Joint::ALL {
            let signed = |i: usize| MOTION[i].sign * pose[i];
            match j.dof() {
                // Root: translation, then Y, X, Z rotations.
                Dof::Root => {
                    data.extend_from_slice(&[pose[0], pose[1], pose[2], pose[4], pose[3], pose[5]])
                }
                // The table orders three angles x, z, y; the channels are Z, X, Y.
                Dof::Three(i) => data.extend_from_slice(&[signed(i + 1), signed(i), signed(i + 2)]),
                Dof::One(i) => {
                    let mut zxy = [0.0; 3];
                    let slot = match MOTION[i].axis {
                        crate::body::params::Axis::Z => 0,
                        crate::body::params::Axis::X => 1,
                        crate::body::params::Axis::Y => 2,
                    };
                    zxy[slot] = signed(i);
                    data.extend_from_slice(&zxy);
                }
                Dof::Fixed => data.extend_from_slice(&[0.0; 3]),
            }
        }
    }
    let fps = if fps.is_finite() && fps > 0.0 {
        fps
    } else {
        30.0
    };
    Bvh::from_parts(joints, 1.0 / fps, data)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::params::{self, MOTION};
    use rand::{RngExt, SeedableRng};

    #[test]
    fn written_bvh_reads_back_to_the_model_joints() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let mut shape = params::STANDARD_SHAPE;
        for v in &mut shape {
            *v = rng.random_range(0.8..1.2);
        }
        let sk = Skeleton::new(&shape);
        let poses: Vec<Pose> = (0..20)
            .map(|_| {
                let mut p = params::rest_pose();
                for (i, m) in MOTION.iter().enumerate() {
                    p[i] += rng.random_range(m.lo.max(-150.0)..m.hi.min(150.0));
                }
                p
            })
            .collect();
        let bvh = monocap_bvh(&sk, &poses, 30.0).unwrap();
        let text = bvh.to_bvh_string();
        let back = Bvh::parse(&text).unwrap();
        assert_eq!(back.frame_count(), poses.len());
        assert!((back.fps() - 30.0).abs() < 1e-3);
        let names: Vec<&str> = back.joints.iter().map(|j| j.name.as_str()).collect();
        assert_eq!(names, crate::body::skeleton::JOINT_NAMES);
        let mut worst: f64 = 0.0;
        for (f, pose) in poses.iter().enumerate() {
            let model = sk.posed(pose);
            let read = back.joint_positions(f);
            for j in Joint::ALL {
                worst = worst.max((read[j.index()] - model.joint(j)).norm());
            }
            let ends = back.end_site_positions(f);
            for (i, t) in Tip::ALL.iter().enumerate() {
                let e = ends[t.joint().index()].expect("end site");
                worst = worst.max((e - model.tips[i]).norm());
            }
        }
        assert!(worst < 0.01, "round trip error {worst} cm");
    }
}
