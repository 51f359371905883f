//! Inner outlines: which of two poses with the same silhouette the picture shows.
//!
//! A silhouette cannot tell a body from its mirror image in depth, a leg in front
//! from the same leg behind, or the left arm from the right one seen from the
//! back. The colour frame can: where one part passes in front of another, or the
//! clothes change colour, the picture has an edge, and a pose puts its own inner
//! outlines there or elsewhere. The disagreement of a pose with the frame counts
//! the pixels of the model's outlines (its outer outline, the outline of a part in
//! front of another more than [`DEPTH_STEP`] cm behind it, and the borders between
//! materials) with no edge of the frame within a pixel, plus the edge pixels
//! inside the person with no outline of the model within a pixel.
//!
//! It is not part of F: the search's hot loop renders coverage only, and F already
//! prices the silhouette. The tracker weighs it in where the silhouette is silent:
//! when it chooses between a frame's result and a jump that looks alike
//! ([`super::flips`]: the depth flips, the nod, the left/right swaps). Not between
//! the initial candidates: weighed in there, it turned frontal clips into their
//! mirror images (README, "The colour frame's inner outlines").

use super::objective::Target;
use crate::body::raster::{render_fragments, Fragments};
use crate::body::{Body, Camera, Mask, Pose};

/// A part whose surface lies this much (cm) behind its neighbour's is occluded
/// there: the neighbour's outline shows.
const DEPTH_STEP: f32 = 4.0;

/// The edges of one colour frame, ready for [`Outlines::disagreement`].
#[derive(Clone, Debug)]
pub struct FrameEdges {
    /// The frame's edges grown by a pixel (a model outline there is explained).
    near: Mask,
    /// The frame's edges inside the person (each wants a model outline near it).
    inner: Mask,
}

impl FrameEdges {
    /// From the edge map T of a colour frame and the person's silhouette.
    pub fn new(edges: &Mask, person: &Mask) -> FrameEdges {
        let mut inner = edges.clone();
        inner.and_with(person);
        FrameEdges {
            near: edges.dilated_square(1),
            inner,
        }
    }
}

/// Buffers for [`Outlines::disagreement`] (one per search, reused).
pub struct Outlines {
    fragments: Fragments,
    outline: Mask,
}

impl Outlines {
    pub fn new(cam: &Camera) -> Outlines {
        Outlines {
            fragments: Fragments::new(cam.width, cam.height),
            outline: Mask::new(cam.width, cam.height),
        }
    }

    /// Pixels where `pose`'s outlines and the frame's edges disagree (see the module
    /// docs); None when the frame had no colour picture.
    pub fn disagreement(
        &mut self,
        body: &Body,
        cam: &Camera,
        target: &Target,
        pose: &Pose,
    ) -> Option<f64> {
        let edges = target.edges.as_ref()?;
        let fr = &mut self.fragments;
        render_fragments(body, &body.posed(pose), cam, fr);
        let (w, h) = (cam.width as usize, cam.height as usize);
        let out = &mut self.outline;
        out.clear();
        let material = |k: usize| body.parts[fr.part[k] as usize].material;
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let d = fr.depth[i];
                if !d.is_finite() {
                    continue;
                }
                let neighbours = [
                    (x > 0).then(|| i - 1),
                    (x + 1 < w).then_some(i + 1),
                    (y > 0).then(|| i - w),
                    (y + 1 < h).then_some(i + w),
                ];
                // The image border cuts the body: no outline of its own there.
                let shows = neighbours.iter().flatten().any(|&j| {
                    let e = fr.depth[j];
                    !e.is_finite() || e - d > DEPTH_STEP || (e >= d && material(j) != material(i))
                });
                if shows {
                    out.set(x as u32, y as u32, true);
                }
            }
        }
        let near_outline = out.dilated_square(1);
        let mut missing = 0u64;
        for ((o, n), (e, m)) in out
            .words()
            .iter()
            .zip(edges.near.words())
            .zip(edges.inner.words().iter().zip(near_outline.words()))
        {
            missing += u64::from((o & !n).count_ones()) + u64::from((e & !m).count_ones());
        }
        Some(missing as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::params::{ix, rest_pose};
    use crate::body::raster::render_mask;
    use crate::body::skeleton::standard_rest;
    use crate::track::objective::Weights;
    use crate::vision::features::{compute, FeatureOptions};
    use image::{Rgb, RgbImage};

    /// A colour frame of `pose` (each material its own flat colour over grey).
    fn picture(body: &Body, cam: &Camera, pose: &Pose) -> (RgbImage, Mask) {
        let mut fr = Fragments::new(cam.width, cam.height);
        render_fragments(body, &body.posed(pose), cam, &mut fr);
        let mut img = RgbImage::from_pixel(cam.width, cam.height, Rgb([128, 128, 128]));
        for (i, px) in img.pixels_mut().enumerate() {
            if fr.depth[i].is_finite() {
                let n = fr.normal[i];
                let shade = 0.5 + 0.5 * f64::from(n[2].abs());
                let base = match body.parts[fr.part[i] as usize].material as u8 {
                    0 => [220.0, 170.0, 140.0],
                    1 => [50.0, 100.0, 180.0],
                    2 => [90.0, 70.0, 60.0],
                    _ => [40.0, 40.0, 40.0],
                };
                *px = Rgb(base.map(|c: f64| (c * shade) as u8));
            }
        }
        let mut m = Mask::new(cam.width, cam.height);
        render_mask(body, &body.posed(pose), cam, &mut m);
        (img, m)
    }

    #[test]
    fn the_picture_tells_a_leg_in_front_from_the_same_leg_behind() {
        let cam = Camera::new(320, 240, 55.0);
        let body = Body::new(&crate::body::params::STANDARD_SHAPE);
        let (_, rest) = standard_rest();
        let mut pose = rest_pose();
        pose[ix::ROOT_TY] = rest[ix::ROOT_TY];
        pose[ix::ROOT_TZ] = -350.0;
        // Seen from the side, mid-stride: the right leg forwards, the left back.
        pose[ix::ROOT_RY] = 90.0;
        pose[ix::R_HIP] = -30.0;
        pose[ix::L_HIP] = 25.0;
        pose[ix::L_KNEE] = 40.0;
        let swapped = crate::track::flips::Jump::SwapLegs
            .apply(&body, &pose)
            .expect("legs apart");
        let (img, sil) = picture(&body, &cam, &pose);
        let f = compute(&sil, Some(&img), None, &FeatureOptions::default());
        let target = Target::new(&f, &Weights::default());
        let mut o = Outlines::new(&cam);
        let right = o.disagreement(&body, &cam, &target, &pose).unwrap();
        let wrong = o.disagreement(&body, &cam, &target, &swapped).unwrap();
        assert!(right + 20.0 < wrong, "{right} vs {wrong}");

        // Without a colour picture there is nothing to tell them apart by.
        let f = compute(&sil, None, None, &FeatureOptions::default());
        let target = Target::new(&f, &Weights::default());
        assert_eq!(o.disagreement(&body, &cam, &target, &pose), None);
    }
}
