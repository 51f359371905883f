//! Real people over a still scene: the frames of a DAVIS sequence pasted under their
//! hand-drawn masks onto a still background, with the sensor noise and JPEG
//! compression a camera adds. The masks are then the silhouettes' ground truth.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use image::codecs::jpeg::{JpegDecoder, JpegEncoder};
use image::{DynamicImage, GrayImage, ImageDecoder, RgbImage};
use rand::{RngExt, SeedableRng};

use crate::body::Mask;

/// Camera effects added to every composite frame.
#[derive(Clone, Copy, Debug)]
pub struct CameraEffects {
    /// Standard deviation of the per-channel sensor noise (8-bit levels).
    pub noise_sigma: f64,
    /// JPEG quality of the round trip (0: none).
    pub jpeg_quality: u8,
}

impl Default for CameraEffects {
    fn default() -> Self {
        CameraEffects {
            noise_sigma: 3.0,
            jpeg_quality: 85,
        }
    }
}

/// A composite clip: frames and, for each, the true silhouette (None before the
/// person appears).
pub struct Composite {
    pub frames: Vec<RgbImage>,
    pub truth: Vec<Option<Mask>>,
}

/// The frame and mask files of a DAVIS sequence folder, in order.
pub fn davis_files(seq: &Path) -> Result<Vec<(PathBuf, PathBuf)>> {
    let mut frames: Vec<PathBuf> = std::fs::read_dir(seq.join("frames"))
        .with_context(|| format!("cannot list {}", seq.join("frames").display()))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "jpg"))
        .collect();
    frames.sort();
    let pairs: Vec<_> = frames
        .into_iter()
        .map(|f| {
            let stem = f.file_stem().unwrap_or_default().to_owned();
            let mask = seq.join("masks").join(stem).with_extension("png");
            (f, mask)
        })
        .collect();
    if pairs.is_empty() {
        bail!("no frames in {}", seq.display());
    }
    Ok(pairs)
}

/// Pastes the person of each DAVIS frame onto `background` (scaled to the frames'
/// size), after `empty_frames` frames of the background alone.
pub fn davis_composite(
    seq: &Path,
    background: &RgbImage,
    empty_frames: usize,
    effects: CameraEffects,
    seed: u64,
) -> Result<Composite> {
    let files = davis_files(seq)?;
    let first = image::open(&files[0].0)?.to_rgb8();
    let (w, h) = first.dimensions();
    let bg = image::imageops::resize(background, w, h, image::imageops::FilterType::Triangle);
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut out = Composite {
        frames: Vec::new(),
        truth: Vec::new(),
    };
    for _ in 0..empty_frames {
        out.frames.push(camera(&bg, effects, &mut rng)?);
        out.truth.push(None);
    }
    for (frame, mask) in files {
        let img = image::open(&frame)?.to_rgb8();
        let m: GrayImage = image::open(&mask)
            .with_context(|| format!("cannot read {}", mask.display()))?
            .to_luma8();
        if img.dimensions() != (w, h) || m.dimensions() != (w, h) {
            bail!(
                "{} and its mask differ in size from the first frame",
                frame.display()
            );
        }
        let mut comp = bg.clone();
        for (x, y, p) in m.enumerate_pixels() {
            if p.0[0] >= 128 {
                comp.put_pixel(x, y, *img.get_pixel(x, y));
            }
        }
        out.frames.push(camera(&comp, effects, &mut rng)?);
        out.truth.push(Some(Mask::from_gray(&m, 128)));
    }
    Ok(out)
}

/// Sensor noise, then a JPEG round trip.
pub fn camera(img: &RgbImage, effects: CameraEffects, rng: &mut impl RngExt) -> Result<RgbImage> {
    let mut noisy = img.clone();
    if effects.noise_sigma > 0.0 {
        for px in noisy.pixels_mut() {
            for c in px.0.iter_mut() {
                let u1: f64 = rng.random_range(f64::EPSILON..1.0);
                let u2: f64 = rng.random_range(0.0..1.0);
                let n = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
                *c = (*c as f64 + n * effects.noise_sigma)
                    .round()
                    .clamp(0.0, 255.0) as u8;
            }
        }
    }
    if effects.jpeg_quality == 0 {
        return Ok(noisy);
    }
    let mut bytes = Vec::new();
    JpegEncoder::new_with_quality(&mut bytes, effects.jpeg_quality).encode_image(&noisy)?;
    let dec = JpegDecoder::new(std::io::Cursor::new(bytes))?;
    let (w, h) = dec.dimensions();
    let mut buf = vec![0u8; dec.total_bytes() as usize];
    let color = dec.color_type();
    dec.read_image(&mut buf)?;
    let img = match color {
        image::ColorType::Rgb8 => RgbImage::from_raw(w, h, buf).context("jpeg size")?,
        _ => DynamicImage::from(GrayImage::from_raw(w, h, buf).context("jpeg size")?).to_rgb8(),
    };
    Ok(img)
}
