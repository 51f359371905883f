//! The body's volume: spheres and cylinders with anisotropic scale (quadrics),
//! each rigidly attached to a joint frame (method.md §2).
//!
//! Every part is an affine image of a canonical solid: the unit ball for an
//! ellipsoid, or the unit cylinder x² + z² ≤ 1, 0 ≤ y ≤ 1 for a cylinder. In its
//! joint's frame a canonical point q sits at `center + radii ⊙ q` (all parts here are
//! aligned with their joint's axes, so the scale is diagonal).

use nalgebra::Vector3;

use super::params::{sx, ShapeValues, SHAPE};
use super::skeleton::{standard, Joint};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Ellipsoid,
    Cylinder,
}

/// What a part looks like in colour renders.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Material {
    Skin,
    Shirt,
    Trousers,
    Shoes,
}

#[derive(Clone, Copy, Debug)]
pub struct Part {
    pub name: &'static str,
    pub joint: Joint,
    pub kind: Kind,
    /// Canonical origin in the joint's frame (cm).
    pub center: Vector3<f64>,
    /// Scale of the canonical solid along x, y, z (for a cylinder y is its length).
    pub radii: Vector3<f64>,
    pub material: Material,
}

/// Number of parts of the body.
pub const PART_COUNT: usize = 26;

/// The first parts are the trunk's (pelvis, abdomen, chest, shoulders, neck, head);
/// the arms' and then the legs' follow.
pub const TRUNK_PARTS: usize = 6;

/// The chest's half-width and half-depth (cm) in the standard body, scaled by
/// the torso's width and depth.
const CHEST_RADII: (f64, f64) = (15.5, 10.5);
/// The pelvis's half-width and half-depth (cm) in the standard body, scaled by the
/// pelvis's width and the torso's depth.
const PELVIS_RADII: (f64, f64) = (15.5, 10.5);

/// `shape` with its torso and pelvis narrowed or widened to be as wide as they are
/// deep (within the values' ranges): a trunk whose outline hardly changes with the
/// way it faces. The initialisation judges the heading with such a trunk too
/// ([`crate::track::tracker::TrackOptions::round_start`]): with the trunk's real
/// width unknown, a wide trunk turned towards the side explains a narrow one seen
/// from the front.
pub fn round_trunk(shape: &ShapeValues) -> ShapeValues {
    let mut out = *shape;
    let depth = shape[sx::TORSO_DEPTH];
    for (i, (half_width, half_depth)) in [
        (sx::TORSO_WIDTH, CHEST_RADII),
        (sx::PELVIS_WIDTH, PELVIS_RADII),
    ] {
        out[i] = (depth * half_depth / half_width).clamp(SHAPE[i].lo, SHAPE[i].hi);
    }
    out
}

/// The parts of a body of shape α.
pub fn body_parts(shape: &ShapeValues) -> [Part; PART_COUNT] {
    use Kind::{Cylinder as C, Ellipsoid as E};
    use Material::*;
    let a = |i: usize| shape[i];
    let (th, tw, td, pw) = (
        a(sx::TORSO_HEIGHT),
        a(sx::TORSO_WIDTH),
        a(sx::TORSO_DEPTH),
        a(sx::PELVIS_WIDTH),
    );
    let hd = a(sx::HEAD);
    let (ua, fa, at) = (a(sx::UPPER_ARM), a(sx::FOREARM), a(sx::ARM_THICKNESS));
    let (tl, sl, lt, ft) = (a(sx::THIGH), a(sx::SHIN), a(sx::LEG_THICKNESS), a(sx::FOOT));
    let v = Vector3::new;
    let part = |name, joint, kind, center, radii, material| Part {
        name,
        joint,
        kind,
        center,
        radii,
        material,
    };
    let upper_arm = standard::UPPER_ARM * ua;
    let forearm = standard::FOREARM * fa;
    let hand = standard::HAND * fa;
    let thigh = standard::THIGH * tl;
    let shin = standard::SHIN * sl;
    let torso = standard::TORSO * th;
    let arm = |side: bool| {
        let (s, f, h) = if side {
            (Joint::LeftArm, Joint::LeftForeArm, Joint::LeftHand)
        } else {
            (Joint::RightArm, Joint::RightForeArm, Joint::RightHand)
        };
        #[rustfmt::skip]
        let parts = [
            part("shoulder",  s, E, v(0.0, 0.0, 0.0),        v(6.0, 6.0, 6.0) * at,             Shirt),
            part("upper_arm", s, C, v(0.0, -upper_arm, 0.0), v(5.0 * at, upper_arm, 5.3 * at), Shirt),
            part("elbow",     f, E, v(0.0, 0.0, 0.0),        v(4.3, 4.3, 4.3) * at,             Shirt),
            part("forearm",   f, C, v(0.0, -forearm, 0.0),   v(4.0 * at, forearm, 4.2 * at),   Skin),
            part("hand",      h, E, v(0.0, -hand / 2.0, 0.0), v(2.4 * at, hand / 2.0, 4.6 * at), Skin),
        ];
        parts
    };
    let leg = |side: bool| {
        let (u, l, f) = if side {
            (Joint::LeftUpLeg, Joint::LeftLeg, Joint::LeftFoot)
        } else {
            (Joint::RightUpLeg, Joint::RightLeg, Joint::RightFoot)
        };
        #[rustfmt::skip]
        let parts = [
            part("thigh", u, C, v(0.0, -thigh, 0.0),   v(7.8 * lt, thigh, 8.3 * lt), Trousers),
            part("knee",  l, E, v(0.0, 0.0, 0.0),      v(5.8, 5.8, 5.8) * lt,        Trousers),
            part("shin",  l, C, v(0.0, -shin, 0.0),    v(5.3 * lt, shin, 5.6 * lt),  Trousers),
            part("ankle", f, E, v(0.0, 0.0, 0.0),      v(4.0, 4.0, 4.0) * lt,        Shoes),
            part("foot",  f, E, v(0.0, -4.5, 7.5 * ft), v(4.6, 3.5, 13.0 * ft),      Shoes),
        ];
        parts
    };
    #[rustfmt::skip]
    let trunk = [
        part("pelvis",    Joint::Hips,  E, v(0.0, -1.0, 0.0),         v(PELVIS_RADII.0 * pw, 11.0, PELVIS_RADII.1 * td), Trousers),
        part("abdomen",   Joint::Spine, C, v(0.0, -8.0 * th, 0.0),    v(13.5 * tw, 0.55 * torso, 9.5 * td),      Shirt),
        part("chest",     Joint::Spine, C, v(0.0, 0.35 * torso, 0.0), v(CHEST_RADII.0 * tw, 0.55 * torso, CHEST_RADII.1 * td), Shirt),
        part("shoulders", Joint::Spine, E, v(0.0, 0.88 * torso, 0.0), v(18.5 * tw, 6.5, 9.0 * td),               Shirt),
        part("neck",      Joint::Neck,  C, v(0.0, -3.0, 0.0),         v(5.5, standard::NECK * th + 4.0, 6.0),    Skin),
        part("head",      Joint::Head,  E, v(0.0, 10.0 * hd, 1.5 * hd), v(8.0, 11.0, 10.0) * hd,                Skin),
    ];
    let (la, ra, ll, rl) = (arm(true), arm(false), leg(true), leg(false));
    let mut out = [trunk[0]; PART_COUNT];
    for (o, p) in out
        .iter_mut()
        .zip(trunk.iter().chain(&la).chain(&ra).chain(&ll).chain(&rl))
    {
        *o = *p;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::params::STANDARD_SHAPE;
    use crate::body::skeleton::standard_rest;

    #[test]
    fn the_trunk_parts_come_first() {
        let parts = body_parts(&STANDARD_SHAPE);
        for (i, p) in parts.iter().enumerate() {
            let trunk = matches!(
                p.joint,
                Joint::Hips | Joint::Spine | Joint::Neck | Joint::Head
            );
            assert_eq!(trunk, i < TRUNK_PARTS, "part {i} ({})", p.name);
        }
    }

    #[test]
    fn a_round_trunk_is_as_wide_as_it_is_deep_and_keeps_the_rest() {
        use crate::body::params::TYPICAL_SHAPE;
        let part = |parts: &[Part], name: &str| *parts.iter().find(|p| p.name == name).unwrap();
        for (k, start) in [STANDARD_SHAPE, TYPICAL_SHAPE].into_iter().enumerate() {
            let round = round_trunk(&start);
            let parts = body_parts(&round);
            for name in ["chest", "pelvis"] {
                let r = part(&parts, name).radii;
                assert!((r.x - r.z).abs() < 1e-9, "shape {k}: {name} {r:?}");
            }
            for i in (0..start.len()).filter(|&i| i != sx::TORSO_WIDTH && i != sx::PELVIS_WIDTH) {
                assert_eq!(round[i], start[i], "shape {k}: {} changed", SHAPE[i].name);
            }
            // The start's trunk was wider than deep.
            assert!(round[sx::TORSO_WIDTH] < start[sx::TORSO_WIDTH], "shape {k}");
        }
        // A trunk too shallow to match within the width's range stops at its bound.
        let mut shallow = STANDARD_SHAPE;
        shallow[sx::TORSO_DEPTH] = 0.6;
        let round = round_trunk(&shallow);
        assert_eq!(round[sx::TORSO_WIDTH], SHAPE[sx::TORSO_WIDTH].lo);
        assert_eq!(round[sx::PELVIS_WIDTH], SHAPE[sx::PELVIS_WIDTH].lo);
    }

    #[test]
    fn standard_body_feet_touch_the_ground_and_head_top_is_the_tip() {
        let (sk, pose) = standard_rest();
        let posed = sk.posed(&pose);
        let parts = body_parts(&STANDARD_SHAPE);
        let mut lowest = f64::INFINITY;
        let mut highest = f64::NEG_INFINITY;
        for p in &parts {
            let frame = posed.joints[p.joint.index()];
            // Axis-aligned parts in an unrotated rest pose: y extent is exact.
            let (y0, y1) = match p.kind {
                Kind::Ellipsoid => (p.center.y - p.radii.y, p.center.y + p.radii.y),
                Kind::Cylinder => (p.center.y, p.center.y + p.radii.y),
            };
            lowest = lowest.min(frame.translation.y + y0);
            highest = highest.max(frame.translation.y + y1);
        }
        assert!(lowest.abs() < 1e-9, "lowest point {lowest}");
        let tip = posed.tips[0].y;
        assert!(
            (highest - tip).abs() < 1e-9,
            "top {highest} vs head tip {tip}"
        );
    }
}
