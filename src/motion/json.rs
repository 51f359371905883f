//! The motion JSON of contracts.md (`format: "monocap.motion/1"`).
//!
//! Fields beyond the contract's (allowed: "add fields freely"): per frame `person`
//! (false on frames without a person, whose pose is held from the nearest tracked
//! frame and whose `cost` and `iou` are null), and `init_frame` at the top.

use serde::{Deserialize, Serialize};

use crate::body::params::{Pose, MOTION, SHAPE};
use crate::body::skeleton::{Joint, JOINT_NAMES};
use crate::body::{Body, Camera};
use crate::track::tracker::Track;

pub const FORMAT: &str = "monocap.motion/1";

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct MotionJson {
    pub format: String,
    pub fps: f64,
    pub frame_count: usize,
    pub image: Image,
    pub camera: CameraJson,
    pub units: String,
    pub shape: Shape,
    pub parameters: Vec<String>,
    pub joints: Vec<String>,
    pub init_frame: usize,
    pub frames: Vec<MotionFrame>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct CameraJson {
    pub fov_deg: f64,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Shape {
    pub names: Vec<String>,
    pub values: Vec<f64>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct MotionFrame {
    pub index: usize,
    pub person: bool,
    pub params: Vec<f64>,
    pub cost: Option<f64>,
    pub iou: Option<f64>,
    pub keyframe: bool,
    /// Camera frame (x right, y up, z from the camera into the scene), cm.
    pub joints3d: Vec<[f64; 3]>,
    /// Pixels of the clip (origin top-left, v down); null for a joint behind the
    /// camera.
    pub joints2d: Vec<Option<[f64; 2]>>,
}

impl MotionJson {
    /// The motion of `track`, reported with `camera` (the clip's own resolution).
    pub fn new(track: &Track, camera: &Camera, fps: f64) -> MotionJson {
        let body = Body::new(&track.shape);
        let frames = track
            .frames
            .iter()
            .map(|f| {
                let (joints3d, joints2d) = joints(&body, camera, &f.pose);
                MotionFrame {
                    index: f.index,
                    person: f.person,
                    params: f.pose.to_vec(),
                    cost: f.cost.filter(|c| c.is_finite()),
                    iou: f.iou.filter(|c| c.is_finite()),
                    keyframe: f.keyframe,
                    joints3d,
                    joints2d,
                }
            })
            .collect();
        MotionJson {
            format: FORMAT.into(),
            fps,
            frame_count: track.frames.len(),
            image: Image {
                width: camera.width,
                height: camera.height,
            },
            camera: CameraJson {
                fov_deg: camera.fov_deg,
                fx: camera.fx,
                fy: camera.fy,
                cx: camera.cx,
                cy: camera.cy,
            },
            units: "cm".into(),
            shape: Shape {
                names: SHAPE.iter().map(|s| s.name.to_string()).collect(),
                values: track.shape.to_vec(),
            },
            parameters: MOTION.iter().map(|m| m.name.to_string()).collect(),
            joints: JOINT_NAMES.iter().map(|s| s.to_string()).collect(),
            init_frame: track.init_frame,
            frames,
        }
    }
}

/// The 18 joints of `pose` in the contract's camera frame and in pixels.
pub fn joints(body: &Body, camera: &Camera, pose: &Pose) -> (Vec<[f64; 3]>, Vec<Option<[f64; 2]>>) {
    let posed = body.posed(pose);
    Joint::ALL
        .iter()
        .map(|&j| {
            let p = posed.joint(j);
            (camera.to_contract(&p), camera.project(&p))
        })
        .unzip()
}
