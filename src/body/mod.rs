//! The 3D body: shape and pose parameters, kinematics, camera and the silhouette
//! rasterizer (method.md §2).

pub mod camera;
pub mod params;
pub mod parts;
pub mod raster;
pub mod skeleton;

pub use camera::Camera;
pub use params::{Pose, ShapeValues};
pub use parts::{Part, PART_COUNT};
pub use raster::Mask;
pub use skeleton::{Joint, Posed, Skeleton};

/// A body of a given shape: its skeleton and its parts, fixed until the shape changes.
#[derive(Clone, Debug)]
pub struct Body {
    pub skeleton: Skeleton,
    pub parts: [Part; PART_COUNT],
}

impl Body {
    pub fn new(shape: &ShapeValues) -> Body {
        Body {
            skeleton: Skeleton::new(shape),
            parts: parts::body_parts(shape),
        }
    }

    pub fn shape(&self) -> &ShapeValues {
        &self.skeleton.shape
    }

    /// Forward kinematics (see [`Skeleton::pose`]).
    pub fn posed(&self, pose: &Pose) -> Posed {
        self.skeleton.posed(pose)
    }
}
