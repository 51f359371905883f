//! Shading: which of two poses with the same silhouette the picture's brightness
//! explains. A limb tilted towards the camera and the same limb tilted away look
//! alike in outline, but under light from above one faces up and the other down.
//! Within one material, brightness is modelled as a first-order function of the
//! surface normal, I ≈ a + b · n (the first spherical harmonics of any distant
//! lighting on a matte surface), fitted by least squares to the pixels the pose
//! puts that material on; the misfit left says how well the pose's normals explain
//! the picture.

use nalgebra::{Matrix4, Vector4};

use crate::body::parts::Material;
use crate::body::raster::{render_fragments, Fragments};
use crate::body::{Body, Camera, Mask, Pose};

/// The materials, each fitted on its own.
const MATERIALS: usize = 4;

fn material_index(m: Material) -> usize {
    match m {
        Material::Skin => 0,
        Material::Shirt => 1,
        Material::Trousers => 2,
        Material::Shoes => 3,
    }
}

/// Buffers for [`Shading::misfit`].
pub struct Shading {
    fragments: Fragments,
}

impl Shading {
    pub fn new(cam: &Camera) -> Shading {
        Shading {
            fragments: Fragments::new(cam.width, cam.height),
        }
    }

    /// The mean squared brightness misfit (8-bit levels²) over the pixels inside
    /// `person` where `pose` shows one material with the same material all around,
    /// and the number of those pixels. `luma` is the frame's brightness, row-major;
    /// with a `luma` or `person` of another size than the camera's image there is
    /// nothing to compare: (0, 0).
    pub fn misfit(
        &mut self,
        body: &Body,
        cam: &Camera,
        luma: &[u8],
        person: &Mask,
        pose: &Pose,
    ) -> (f64, u64) {
        let (w, h) = (cam.width as usize, cam.height as usize);
        if luma.len() != w * h || person.width() != cam.width || person.height() != cam.height {
            return (0.0, 0);
        }
        if self.fragments.width != cam.width || self.fragments.height != cam.height {
            self.fragments = Fragments::new(cam.width, cam.height);
        }
        let fr = &mut self.fragments;
        render_fragments(body, &body.posed(pose), cam, fr);
        let mut xtx = [Matrix4::<f64>::zeros(); MATERIALS];
        let mut xty = [Vector4::<f64>::zeros(); MATERIALS];
        let mut yty = [0.0f64; MATERIALS];
        let mut count = [0u64; MATERIALS];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if !person.get(x as u32, y as u32) {
                    continue;
                }
                let Some(m) = fr.inner_label(i, |p| material_index(body.parts[p].material)) else {
                    continue;
                };
                let n = fr.normal[i];
                let v = Vector4::new(1.0, f64::from(n[0]), f64::from(n[1]), f64::from(n[2]));
                let lum = f64::from(luma[i]);
                xtx[m] += v * v.transpose();
                xty[m] += v * lum;
                yty[m] += lum * lum;
                count[m] += 1;
            }
        }
        let mut sse = 0.0;
        let mut total = 0;
        for m in 0..MATERIALS {
            if count[m] < 8 {
                continue;
            }
            let a = xtx[m] + Matrix4::identity() * (1e-3 * count[m] as f64);
            let Some(beta) = a.try_inverse().map(|inv| inv * xty[m]) else {
                continue;
            };
            let e = yty[m] - 2.0 * beta.dot(&xty[m]) + (beta.transpose() * xtx[m] * beta)[0];
            sse += e.max(0.0);
            total += count[m];
        }
        if total == 0 {
            return (0.0, 0);
        }
        (sse / total as f64, total)
    }
}

/// The brightness of `pose` lit from above and in front (each material its own
/// albedo, a quarter of the light ambient), and its silhouette.
#[cfg(test)]
pub(crate) fn picture(body: &Body, cam: &Camera, pose: &Pose) -> (Vec<u8>, Mask) {
    let mut fr = Fragments::new(cam.width, cam.height);
    render_fragments(body, &body.posed(pose), cam, &mut fr);
    let light = nalgebra::Vector3::new(-0.3, 0.8, 0.5).normalize();
    let luma = (0..fr.depth.len())
        .map(|i| {
            if !fr.depth[i].is_finite() {
                return 128;
            }
            let n = fr.normal[i];
            let lambert =
                (f64::from(n[0]) * light.x + f64::from(n[1]) * light.y + f64::from(n[2]) * light.z)
                    .max(0.0);
            let albedo = [230.0, 120.0, 90.0, 50.0]
                [material_index(body.parts[fr.part[i] as usize].material)];
            (albedo * (0.25 + 0.75 * lambert)).round() as u8
        })
        .collect();
    let mut m = Mask::new(cam.width, cam.height);
    crate::body::raster::render_mask(body, &body.posed(pose), cam, &mut m);
    (luma, m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::params::{ix, rest_pose, STANDARD_SHAPE};
    use crate::body::skeleton::standard_rest;

    #[test]
    fn shading_tells_an_arm_raised_towards_the_camera_from_one_raised_away() {
        let cam = Camera::new(320, 240, 55.0);
        let body = Body::new(&STANDARD_SHAPE);
        let (_, rest) = standard_rest();
        let mut pose = rest_pose();
        pose[ix::ROOT_TY] = rest[ix::ROOT_TY];
        pose[ix::ROOT_TZ] = -300.0;
        // Facing the camera, the right arm raised forwards (towards the camera) and a
        // little sideways …
        pose[ix::R_SHOULDER] = 40.0;
        pose[ix::R_SHOULDER + 1] = 30.0;
        // … against the same outline from the arm raised as far backwards: its
        // depth flip.
        let flip = crate::track::flips::FLIPS
            .iter()
            .find(|f| f.name == "right arm")
            .expect("the arm's flip");
        let flipped = flip.apply(&body, &pose).expect("the arm is raised");
        let (luma, person) = picture(&body, &cam, &pose);
        let mut s = Shading::new(&cam);
        let (right, n) = s.misfit(&body, &cam, &luma, &person, &pose);
        let (wrong, _) = s.misfit(&body, &cam, &luma, &person, &flipped);
        assert!(n > 1000, "{n} pixels");
        // Rounding to levels and the light's clamp (no light from below) leave
        // a little misfit.
        assert!(right < 16.0, "the pose itself misfits by {right}");
        assert!(wrong > 2.0 * right, "{right} vs {wrong}");
        // A picture of another size has nothing to compare.
        assert_eq!(
            s.misfit(&body, &cam, &luma[..100], &person, &pose),
            (0.0, 0)
        );
    }
}
