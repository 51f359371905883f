//! `monocap synth`: clips of the body model driven by real motion capture, filmed by
//! a virtual camera, with their ground truth. These clips are the project's own
//! benchmark material: the tracker's accuracy is measured on them.
//!
//! 1. The capture's frames are picked at the clip's frame rate (nearest source frame,
//!    so every truth pose is the capture's own forward kinematics, not a blend).
//! 2. A level camera is placed at the chosen azimuth around the performer (0° = in
//!    front of the performer's first-frame facing, positive = towards their left),
//!    at the height of the motion's vertical middle and at the smallest distance that
//!    keeps every joint, with a body-thickness margin, inside the image.
//! 3. The capture is retargeted onto the model in the camera's frame, so the truth
//!    parameters are the ones a tracker working in camera coordinates should find.
//! 4. Frames are rendered as 0/255 silhouettes, or in colour over a textured still
//!    background with per-frame sensor noise, so background subtraction has real work
//!    to do. `empty_frames` person-free frames lead.

pub mod composite;

use std::path::Path;

use anyhow::{bail, Context, Result};
use image::{Rgb, RgbImage};
use nalgebra::{IsometryMatrix3, Matrix3, Point3, Rotation3, Translation3, Vector3};
use rand::{RngExt, SeedableRng};
use serde::Serialize;

use crate::body::params::{Pose, MOTION, SHAPE};
use crate::body::parts::Material;
use crate::body::raster::{render_fragments, render_mask, Fragments};
use crate::body::skeleton::{Joint, JOINT_NAMES};
use crate::body::{Body, Camera, Mask};
use crate::clip::write::{self, Frame};
use crate::motion::bvh::Bvh;
use crate::motion::retarget::{detect_unit_scale, fit_shape, target_joints, JointMap, Retargeter};

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Style {
    /// 0/255 masks of the body.
    Silhouette,
    /// A shaded body over a textured background, with sensor noise.
    Color,
}

#[derive(Clone, Debug)]
pub struct SynthOptions {
    pub width: u32,
    pub height: u32,
    pub fov_deg: f64,
    pub fps: f64,
    pub style: Style,
    pub empty_frames: usize,
    pub azimuth_deg: f64,
    /// First source frame used.
    pub first_frame: usize,
    /// Length of the clip's person part in seconds (None: to the end of the capture).
    pub duration_s: Option<f64>,
    /// Seed of the background and the noise.
    pub seed: u64,
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            width: 320,
            height: 240,
            fov_deg: 55.0,
            fps: 30.0,
            style: Style::Color,
            empty_frames: 0,
            azimuth_deg: 0.0,
            first_frame: 0,
            duration_s: None,
            seed: 1,
        }
    }
}

/// Most frames one clip may have (about 9 minutes at 30 fps).
pub const MAX_FRAMES: usize = 16_384;

impl SynthOptions {
    fn validate(&self) -> Result<()> {
        Camera::validate(self.width, self.height, self.fov_deg).map_err(anyhow::Error::msg)?;
        if !(self.fps.is_finite() && self.fps > 0.0 && self.fps <= 240.0) {
            bail!("frame rate {} must be above 0 and at most 240", self.fps);
        }
        if !self.azimuth_deg.is_finite() {
            bail!("azimuth {} is not a number", self.azimuth_deg);
        }
        if self.empty_frames > MAX_FRAMES {
            bail!(
                "{} empty frames is more than the limit of {MAX_FRAMES}",
                self.empty_frames
            );
        }
        if let Some(d) = self.duration_s {
            if !(d.is_finite() && d > 0.0) {
                bail!("duration {d} s must be positive");
            }
        }
        Ok(())
    }
}

/// The ground truth written next to a clip (`format: "monocap.truth/1"`).
#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub struct Truth {
    pub format: String,
    pub fps: f64,
    pub frame_count: usize,
    pub image: ImageSize,
    pub camera: TruthCamera,
    pub source: Source,
    /// The BVH's own joint names (End Sites excluded).
    pub source_joints: Vec<String>,
    pub empty_frames: usize,
    /// The retargeted model: its shape, parameter and joint names.
    pub shape: NamedValues,
    pub parameters: Vec<String>,
    pub joints: Vec<String>,
    /// How closely the model follows the capture (cm, over the model's 18 joints).
    pub retarget: RetargetFit,
    pub frames: Vec<TruthFrame>,
}

#[derive(Clone, Copy, Debug, Serialize, serde::Deserialize)]
pub struct ImageSize {
    pub width: u32,
    pub height: u32,
}

#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub struct TruthCamera {
    pub fov_deg: f64,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub azimuth_deg: f64,
    /// Camera position in the capture's world (cm, Y up) and its distance to the
    /// point it looks at.
    pub position_world: [f64; 3],
    pub distance_cm: f64,
    /// The ground plane's height in the camera frame (cm): y = this, level camera.
    pub ground_y: f64,
}

#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub struct Source {
    pub file: String,
    pub first_frame: usize,
    /// Source frames per clip frame (the capture's rate over the clip's).
    pub frame_step: f64,
    pub fps: f64,
    pub cm_per_unit: f64,
}

#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub struct NamedValues {
    pub names: Vec<String>,
    pub values: Vec<f64>,
}

#[derive(Clone, Copy, Debug, Serialize, serde::Deserialize)]
pub struct RetargetFit {
    pub mean_cm: f64,
    pub max_cm: f64,
}

#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub struct TruthFrame {
    pub index: usize,
    pub source_frame: usize,
    /// Per source joint: camera frame (x right, y up, z into the scene), cm.
    pub joints3d: Vec<[f64; 3]>,
    /// Per source joint: pixels, origin top-left, v down.
    pub joints2d: Vec<[f64; 2]>,
    /// The retargeted model's 30 parameters (cm, degrees).
    pub params: Vec<f64>,
    /// The model's 18 joints for those parameters, camera frame and pixels.
    pub model_joints3d: Vec<[f64; 3]>,
    pub model_joints2d: Vec<[f64; 2]>,
}

/// Renders the clip to `out` (format by extension) and returns its truth.
pub fn synthesize(bvh: &Bvh, source_name: &str, opts: &SynthOptions, out: &Path) -> Result<Truth> {
    opts.validate()?;
    let mut writer = write::create(out, opts.width, opts.height, opts.fps)?;
    let truth = synthesize_with(bvh, source_name, opts, |f| Ok(writer.push(f.image)?))?;
    writer.finish()?;
    Ok(truth)
}

/// One rendered frame, handed to the sink of [`synthesize_with`].
pub struct SynthFrame<'a> {
    pub index: usize,
    pub image: Frame<'a>,
    /// The model's true silhouette (empty on person-free frames).
    pub mask: &'a Mask,
}

/// Renders the clip frame by frame into `sink` and returns its truth.
pub fn synthesize_with(
    bvh: &Bvh,
    source_name: &str,
    opts: &SynthOptions,
    mut sink: impl FnMut(SynthFrame<'_>) -> Result<()>,
) -> Result<Truth> {
    opts.validate()?;
    let map = JointMap::detect(bvh)?;
    let cm = detect_unit_scale(bvh, &map);
    let frames = pick_frames(bvh, opts)?;

    // World positions (cm) of every source joint in the frames used.
    let world: Vec<Vec<Point3<f64>>> = frames
        .iter()
        .map(|&f| {
            bvh.joint_positions(f)
                .into_iter()
                .map(|p| Point3::from(p.coords * cm))
                .collect()
        })
        .collect();
    let cam = place_camera(bvh, &map, &world, frames[0], opts)?;

    // Retarget in the camera frame.
    let targets: Vec<_> = frames
        .iter()
        .map(|&f| target_joints(bvh, &map, f, cm, &cam.camera.world_to_camera))
        .collect();
    let shape = fit_shape(&targets);
    let mut rt = Retargeter::new(&shape);
    let mut poses: Vec<Pose> = Vec::with_capacity(frames.len());
    let mut fit = RetargetFit {
        mean_cm: 0.0,
        max_cm: 0.0,
    };
    for t in &targets {
        let (pose, r) = rt.solve(t);
        fit.mean_cm += r.mean_cm / targets.len() as f64;
        fit.max_cm = fit.max_cm.max(r.max_cm);
        poses.push(pose);
    }
    let body = Body::new(&shape);
    let camera = &cam.camera;

    // Render.
    let mut scene = Scene::new(opts, camera);
    for index in 0..opts.empty_frames {
        scene.draw(index, None, &body, camera, &mut sink)?;
    }
    for (k, pose) in poses.iter().enumerate() {
        let posed = body.posed(pose);
        scene.draw(
            opts.empty_frames + k,
            Some(&posed),
            &body,
            camera,
            &mut sink,
        )?;
    }

    // Truth.
    let proj = |p: &Point3<f64>| -> Result<[f64; 2]> {
        camera.project(p).context("a joint is behind the camera")
    };
    let mut truth_frames = Vec::with_capacity(frames.len());
    for (k, (&f, pose)) in frames.iter().zip(&poses).enumerate() {
        let posed = body.posed(pose);
        let mut joints3d = Vec::new();
        let mut joints2d = Vec::new();
        for p in &world[k] {
            joints3d.push(camera.to_contract(p));
            joints2d.push(proj(p)?);
        }
        // The model lives in the camera frame already (world_to_camera applied to
        // the targets), so its "world" is the internal camera frame.
        let model_cam = Camera {
            world_to_camera: IsometryMatrix3::identity(),
            ..camera.clone()
        };
        let mut model_joints3d = Vec::new();
        let mut model_joints2d = Vec::new();
        for j in Joint::ALL {
            let p = posed.joint(j);
            model_joints3d.push(model_cam.to_contract(&p));
            model_joints2d.push(
                model_cam
                    .project(&p)
                    .context("a model joint is behind the camera")?,
            );
        }
        truth_frames.push(TruthFrame {
            index: opts.empty_frames + k,
            source_frame: f,
            joints3d,
            joints2d,
            params: pose.to_vec(),
            model_joints3d,
            model_joints2d,
        });
    }
    Ok(Truth {
        format: "monocap.truth/1".into(),
        fps: opts.fps,
        frame_count: opts.empty_frames + frames.len(),
        image: ImageSize {
            width: opts.width,
            height: opts.height,
        },
        camera: TruthCamera {
            fov_deg: camera.fov_deg,
            fx: camera.fx,
            fy: camera.fy,
            cx: camera.cx,
            cy: camera.cy,
            azimuth_deg: opts.azimuth_deg,
            position_world: cam.position.into(),
            distance_cm: cam.distance,
            ground_y: cam.ground_y,
        },
        source: Source {
            file: source_name.to_string(),
            first_frame: frames[0],
            frame_step: frame_step(bvh, opts),
            fps: bvh.fps(),
            cm_per_unit: cm,
        },
        source_joints: bvh.joints.iter().map(|j| j.name.clone()).collect(),
        empty_frames: opts.empty_frames,
        shape: NamedValues {
            names: SHAPE.iter().map(|s| s.name.to_string()).collect(),
            values: shape.to_vec(),
        },
        parameters: MOTION.iter().map(|m| m.name.to_string()).collect(),
        joints: JOINT_NAMES.iter().map(|s| s.to_string()).collect(),
        retarget: fit,
        frames: truth_frames,
    })
}

/// Source frames per clip frame. Frame times are written with few digits (CMU's
/// `.0083333` for 120 fps), so a ratio within 0.1% of a whole number is that number.
fn frame_step(bvh: &Bvh, opts: &SynthOptions) -> f64 {
    let step = bvh.fps() / opts.fps;
    let whole = step.round();
    if whole >= 1.0 && (step - whole).abs() < 1e-3 * whole {
        whole
    } else {
        step
    }
}

/// Source frames nearest to each clip frame's time.
fn pick_frames(bvh: &Bvh, opts: &SynthOptions) -> Result<Vec<usize>> {
    let n = bvh.frame_count();
    if n == 0 {
        bail!("the BVH has no frames");
    }
    if opts.first_frame >= n {
        bail!(
            "first frame {} is past the capture's last frame {}",
            opts.first_frame,
            n - 1
        );
    }
    let step = frame_step(bvh, opts);
    let limit = match opts.duration_s {
        Some(d) => ((d * opts.fps).round() as usize).max(1),
        None => usize::MAX,
    };
    // In floating point until the frame is known to exist: a tiny Frame Time makes
    // the step huge.
    let frames: Vec<usize> = (0..)
        .map(|k| (opts.first_frame as f64 + k as f64 * step).round())
        .take_while(|&f| f < n as f64)
        .take(limit.min(MAX_FRAMES))
        .map(|f| f as usize)
        .collect();
    Ok(frames)
}

struct Placed {
    camera: Camera,
    position: Vector3<f64>,
    distance: f64,
    ground_y: f64,
}

/// Body-thickness margin (cm) around each joint when fitting the motion in frame.
const BODY_MARGIN: f64 = 18.0;
/// Fraction of the image kept free at each border.
const BORDER: f64 = 0.04;

fn place_camera(
    bvh: &Bvh,
    map: &JointMap,
    world: &[Vec<Point3<f64>>],
    first: usize,
    opts: &SynthOptions,
) -> Result<Placed> {
    // The performer's facing in the first frame: (left hip − right hip) × up.
    let p0 = bvh.joint_positions(first);
    let lr = p0[map.source[Joint::LeftUpLeg.index()]] - p0[map.source[Joint::RightUpLeg.index()]];
    let facing = Vector3::new(-lr.z, 0.0, lr.x)
        .try_normalize(1e-9)
        .context("the capture's hip joints coincide: cannot tell which way the performer faces")?;
    let dir =
        Rotation3::from_axis_angle(&Vector3::y_axis(), opts.azimuth_deg.to_radians()) * facing;

    let (mut lo, mut hi) = (Vector3::repeat(f64::MAX), Vector3::repeat(f64::MIN));
    for p in world.iter().flatten() {
        lo = lo.inf(&p.coords);
        hi = hi.sup(&p.coords);
    }
    // Head tops and soles reach beyond the joints.
    lo.y -= 12.0;
    hi.y += 25.0;
    let centre = (lo + hi) / 2.0;
    // Camera axes (rows of world → camera): z = dir (towards the camera), y = up.
    let z = dir;
    let y = Vector3::y();
    let x = y.cross(&z);
    let rot = Rotation3::from_matrix_unchecked(Matrix3::from_rows(&[
        x.transpose(),
        y.transpose(),
        z.transpose(),
    ]));
    let camera_at = |d: f64| -> (Vector3<f64>, Camera) {
        let pos = centre + dir * d;
        let t = -(rot * pos);
        let cam = Camera::new(opts.width, opts.height, opts.fov_deg)
            .with_pose(IsometryMatrix3::from_parts(Translation3::from(t), rot));
        (pos, cam)
    };
    let fits = |cam: &Camera| {
        let (w, h) = (cam.width as f64, cam.height as f64);
        world.iter().flatten().all(|p| {
            let c = cam.to_camera(p);
            let depth = -c.z - BODY_MARGIN;
            if depth < 10.0 {
                return false;
            }
            // The margin box's corners nearest to the image border, seen at the
            // margin's front depth.
            let [u0, u1] =
                [c.x - BODY_MARGIN, c.x + BODY_MARGIN].map(|x| cam.cx + cam.fx * x / depth);
            let [v0, v1] =
                [c.y + BODY_MARGIN, c.y - BODY_MARGIN].map(|y| cam.cy - cam.fy * y / depth);
            u0 >= BORDER * w
                && u1 <= (1.0 - BORDER) * w
                && v0 >= BORDER * h
                && v1 <= (1.0 - BORDER) * h
        })
    };
    let (mut near, mut far) = (50.0, 50_000.0);
    if !fits(&camera_at(far).1) {
        bail!("the motion cannot be framed: it spans more than the camera can see from 500 m");
    }
    for _ in 0..60 {
        let mid = 0.5 * (near + far);
        if fits(&camera_at(mid).1) {
            far = mid;
        } else {
            near = mid;
        }
    }
    let (position, camera) = camera_at(far);
    // The capture's floor is its world's y = 0; the camera is level.
    Ok(Placed {
        camera,
        position,
        distance: far,
        ground_y: -position.y,
    })
}

/// The still background and the per-frame noise of colour clips.
struct Scene {
    style: Style,
    background: RgbImage,
    frame: RgbImage,
    mask: Mask,
    fragments: Fragments,
    rng: rand::rngs::StdRng,
    light: Vector3<f64>,
}

/// Standard deviation of the sensor noise per channel (8-bit levels).
const NOISE_SIGMA: f64 = 3.0;

impl Scene {
    fn new(opts: &SynthOptions, camera: &Camera) -> Scene {
        let mut rng = rand::rngs::StdRng::seed_from_u64(opts.seed);
        let background = make_background(opts.width, opts.height, camera, &mut rng);
        Scene {
            style: opts.style,
            frame: background.clone(),
            background,
            mask: Mask::new(opts.width, opts.height),
            fragments: Fragments::new(opts.width, opts.height),
            rng,
            // From above, in front and to the camera's left, in the camera frame.
            light: Vector3::new(-0.4, 0.7, 0.6).normalize(),
        }
    }

    fn draw(
        &mut self,
        index: usize,
        posed: Option<&crate::body::Posed>,
        body: &Body,
        camera: &Camera,
        sink: &mut impl FnMut(SynthFrame<'_>) -> Result<()>,
    ) -> Result<()> {
        // The model was retargeted in the camera frame: render it with an identity
        // extrinsic.
        let model_cam = Camera {
            world_to_camera: IsometryMatrix3::identity(),
            ..camera.clone()
        };
        self.mask.clear();
        if let Some(posed) = posed {
            render_mask(body, posed, &model_cam, &mut self.mask);
        }
        match self.style {
            Style::Silhouette => {
                let gray = self.mask.to_gray();
                sink(SynthFrame {
                    index,
                    image: Frame::Gray(&gray),
                    mask: &self.mask,
                })?;
            }
            Style::Color => {
                self.frame.copy_from_slice(&self.background);
                if let Some(posed) = posed {
                    render_fragments(body, posed, &model_cam, &mut self.fragments);
                    self.shade(body);
                }
                for px in self.frame.pixels_mut() {
                    for c in px.0.iter_mut() {
                        let n: f64 = gaussian(&mut self.rng) * NOISE_SIGMA;
                        *c = (*c as f64 + n).round().clamp(0.0, 255.0) as u8;
                    }
                }
                sink(SynthFrame {
                    index,
                    image: Frame::Rgb(&self.frame),
                    mask: &self.mask,
                })?;
            }
        }
        Ok(())
    }

    fn shade(&mut self, body: &Body) {
        let f = &self.fragments;
        for (i, px) in self.frame.pixels_mut().enumerate() {
            if !f.depth[i].is_finite() {
                continue;
            }
            let n = f.normal[i];
            let lambert = (n[0] as f64 * self.light.x
                + n[1] as f64 * self.light.y
                + n[2] as f64 * self.light.z)
                .max(0.0);
            let base = material_colour(body.parts[f.part[i] as usize].material);
            let k = 0.45 + 0.55 * lambert;
            *px = Rgb(base.map(|c| (c * k).round().clamp(0.0, 255.0) as u8));
        }
    }
}

fn material_colour(m: Material) -> [f64; 3] {
    match m {
        Material::Skin => [214.0, 168.0, 138.0],
        Material::Shirt => [52.0, 96.0, 170.0],
        Material::Trousers => [92.0, 74.0, 60.0],
        Material::Shoes => [40.0, 40.0, 44.0],
    }
}

/// A still room: a textured wall with a few framed panels above the horizon, a
/// floor below it (the camera is level, so the horizon is the middle row).
fn make_background(
    width: u32,
    height: u32,
    camera: &Camera,
    rng: &mut rand::rngs::StdRng,
) -> RgbImage {
    let wall: [f64; 3] = [
        rng.random_range(150.0..200.0),
        rng.random_range(150.0..195.0),
        rng.random_range(140.0..185.0),
    ];
    let floor: [f64; 3] = [
        rng.random_range(110.0..150.0),
        rng.random_range(115.0..150.0),
        rng.random_range(120.0..160.0),
    ];
    let horizon = camera.cy;
    let mut img = RgbImage::from_fn(width, height, |x, y| {
        let fy = y as f64 + 0.5;
        let (base, shade) = if fy < horizon {
            (wall, 0.92 + 0.08 * (fy / horizon))
        } else {
            // Floor boards: stripes that converge like a real floor would.
            let depth = (fy - horizon).max(1.0);
            let stripe = ((x as f64 - camera.cx) / depth * 3.0).floor() as i64;
            (floor, if stripe.rem_euclid(2) == 0 { 1.0 } else { 0.93 })
        };
        Rgb(base.map(|c| (c * shade).clamp(0.0, 255.0) as u8))
    });
    // Panels on the wall.
    for _ in 0..4 {
        // Panels a tenth to a quarter of the image (at least a pixel, however small).
        let w = rng.random_range((width / 10).max(1)..(width / 4).max(2));
        let h = rng.random_range((height / 10).max(1)..(height / 4).max(2));
        let x0 = rng.random_range(0..width.saturating_sub(w).max(1));
        let y0 = rng.random_range(0..(horizon as u32).saturating_sub(h).max(1));
        let colour: [f64; 3] = [
            rng.random_range(60.0..230.0),
            rng.random_range(60.0..230.0),
            rng.random_range(60.0..230.0),
        ];
        for y in y0..(y0 + h).min(height) {
            for x in x0..(x0 + w).min(width) {
                img.put_pixel(x, y, Rgb(colour.map(|c| c as u8)));
            }
        }
    }
    // Fixed fine texture, so the background is not flat.
    for px in img.pixels_mut() {
        let t: f64 = rng.random_range(-6.0..6.0);
        for c in px.0.iter_mut() {
            *c = (*c as f64 + t).clamp(0.0, 255.0) as u8;
        }
    }
    img
}

/// A standard normal sample (Box–Muller).
fn gaussian(rng: &mut impl RngExt) -> f64 {
    let u1: f64 = rng.random_range(f64::EPSILON..1.0);
    let u2: f64 = rng.random_range(0.0..1.0);
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}
