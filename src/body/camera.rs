//! The pinhole camera (method.md §2): principal point at the image centre, focal
//! length from the horizontal field of view.
//!
//! Internally the camera frame is right-handed with x right, y up and the camera
//! looking down −z (so the world's rotations stay proper). The motion JSON's camera
//! frame has z pointing from the camera into the scene: [`Camera::to_contract`]
//! flips z. Pixel coordinates have their origin at the top-left corner of the image
//! with u right and v down; pixel (i, j) covers [i, i+1) × [j, j+1), so its centre is
//! (i + 0.5, j + 0.5).

use nalgebra::{IsometryMatrix3, Point3, Vector3};

/// Nearest depth (cm) at which geometry is projected.
pub const NEAR: f64 = 1.0;

#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub width: u32,
    pub height: u32,
    pub fov_deg: f64,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// World → camera (the internal, −z looking frame).
    pub world_to_camera: IsometryMatrix3<f64>,
}

impl Camera {
    /// A camera at the world origin looking down −z (world = camera frame).
    pub fn new(width: u32, height: u32, fov_deg: f64) -> Camera {
        let fx = width as f64 / 2.0 / (fov_deg.to_radians() / 2.0).tan();
        Camera {
            width,
            height,
            fov_deg,
            fx,
            fy: fx,
            cx: width as f64 / 2.0,
            cy: height as f64 / 2.0,
            world_to_camera: IsometryMatrix3::identity(),
        }
    }

    pub fn with_pose(mut self, world_to_camera: IsometryMatrix3<f64>) -> Camera {
        self.world_to_camera = world_to_camera;
        self
    }

    /// Checks a requested field of view and image size, for user input.
    pub fn validate(width: u32, height: u32, fov_deg: f64) -> Result<(), String> {
        if !(fov_deg.is_finite() && fov_deg > 1.0 && fov_deg < 170.0) {
            return Err(format!(
                "field of view {fov_deg}° must lie between 1° and 170°"
            ));
        }
        if width == 0 || height == 0 || width > 8192 || height > 8192 {
            return Err(format!(
                "image size {width}×{height} must be between 1 and 8192 pixels a side"
            ));
        }
        Ok(())
    }

    /// A world point in the internal camera frame.
    pub fn to_camera(&self, p: &Point3<f64>) -> Point3<f64> {
        self.world_to_camera * p
    }

    /// A world point in the contract's camera frame (x right, y up, z into the scene).
    pub fn to_contract(&self, p: &Point3<f64>) -> [f64; 3] {
        let c = self.to_camera(p);
        [c.x, c.y, -c.z]
    }

    /// Pixel coordinates of a point in the internal camera frame, or `None` behind
    /// the near plane.
    pub fn project_camera(&self, c: &Point3<f64>) -> Option<[f64; 2]> {
        let depth = -c.z;
        if depth < NEAR {
            return None;
        }
        Some([
            self.cx + self.fx * c.x / depth,
            self.cy - self.fy * c.y / depth,
        ])
    }

    /// Pixel coordinates of a world point, or `None` behind the near plane.
    pub fn project(&self, p: &Point3<f64>) -> Option<[f64; 2]> {
        self.project_camera(&self.to_camera(p))
    }

    /// The camera's centre in the world.
    pub fn eye(&self) -> Point3<f64> {
        self.world_to_camera.inverse() * Point3::origin()
    }

    /// The world direction, from [`Camera::eye`], of the line of sight through the
    /// pixel position (u, v): the points [`Camera::project`] sends there (scaled
    /// to depth 1 in front of the camera).
    pub fn ray(&self, u: f64, v: f64) -> Vector3<f64> {
        let c = Vector3::new((u - self.cx) / self.fx, (self.cy - v) / self.fy, -1.0);
        self.world_to_camera.inverse() * c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn focal_length_matches_the_contract_example() {
        let cam = Camera::new(320, 240, 55.0);
        assert!((cam.fx - 307.3).abs() < 0.1, "fx {}", cam.fx);
        assert_eq!((cam.cx, cam.cy), (160.0, 120.0));
    }

    #[test]
    fn projection_axes() {
        let cam = Camera::new(320, 240, 55.0);
        let c = cam.project(&Point3::new(0.0, 0.0, -300.0)).unwrap();
        assert_eq!(c, [160.0, 120.0]);
        let r = cam.project(&Point3::new(10.0, 10.0, -300.0)).unwrap();
        assert!(r[0] > 160.0 && r[1] < 120.0, "right and up: {r:?}");
        assert!(cam.project(&Point3::new(0.0, 0.0, 10.0)).is_none());
        assert_eq!(
            cam.to_contract(&Point3::new(1.0, 2.0, -3.0)),
            [1.0, 2.0, 3.0]
        );
    }

    #[test]
    fn a_pixels_ray_from_the_eye_meets_the_points_seen_there() {
        let cam = Camera::new(320, 240, 55.0).with_pose(IsometryMatrix3::from_parts(
            nalgebra::Translation3::new(30.0, -80.0, -500.0),
            nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), 2.0),
        ));
        let eye = cam.eye();
        assert!(cam.to_camera(&eye).coords.norm() < 1e-9, "{eye:?}");
        let p = Point3::new(-40.0, 25.0, 130.0);
        let [u, v] = cam.project(&p).expect("in front");
        let ray = cam.ray(u, v);
        let depth = -cam.to_camera(&p).z;
        assert!((eye + depth * ray - p).norm() < 1e-9, "{ray:?}");
    }
}
