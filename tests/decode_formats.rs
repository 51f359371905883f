//! Decoders for Y4M, animated images and frame archives, the format sniffing
//! of `clip::open`, and their behaviour on hostile or damaged input.
//!
//! Tests that need `../shared/data` skip with a printed reason when it is absent.

mod common;

use common::TempDir;
use std::fs;
use std::io::{Cursor, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::OnceLock;
use std::time::Instant;

use image::{GrayImage, ImageEncoder, Luma, Rgb, RgbImage};
use monocap::clip::open::{open, open_masks, probe};
use monocap::clip::write::{create, Frame};
use monocap::clip::{ffmpeg, ClipInfo, DecodeError, FrameSource, Limits};
use proptest::prelude::*;

fn data_dir(sub: &str) -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(sub);
    if dir.is_dir() {
        Some(dir)
    } else {
        println!("skipped: {} is absent", dir.display());
        None
    }
}

fn psnr(a: &RgbImage, b: &RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions());
    let se: f64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(&x, &y)| (f64::from(x) - f64::from(y)).powi(2))
        .sum();
    let mse = se / a.as_raw().len() as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0 * 255.0 / mse).log10()
    }
}

fn all_frames(source: &mut dyn FrameSource) -> Vec<RgbImage> {
    let mut frames = Vec::new();
    while let Some(f) = source.next_frame().expect("frame decodes") {
        frames.push(f);
    }
    frames
}

/// Reference frames `<file>_frameNNNN.png` in `ref/`, by index.
fn references(dir: &Path, file: &str) -> Vec<(usize, PathBuf)> {
    let prefix = format!("{file}_frame");
    let mut out: Vec<(usize, PathBuf)> = fs::read_dir(dir.join("ref"))
        .map(|rd| {
            rd.filter_map(|e| {
                let e = e.ok()?;
                let name = e.file_name().to_string_lossy().into_owned();
                let idx = name
                    .strip_prefix(&prefix)?
                    .strip_suffix(".png")?
                    .parse()
                    .ok()?;
                Some((idx, e.path()))
            })
            .collect()
        })
        .unwrap_or_default();
    out.sort();
    out
}

fn check_refs(dir: &Path, file: &str, frames: &[RgbImage]) {
    let refs = references(dir, file);
    if refs.is_empty() {
        println!("{file}: no reference frames in ref/ (nothing to compare)");
    }
    for (idx, p) in refs {
        let reference = image::open(&p).expect("reference decodes").into_rgb8();
        let value = psnr(&frames[idx], &reference);
        println!("{file} frame {idx}: PSNR {value:.2} dB");
        assert!(value >= 35.0, "{file} frame {idx}: PSNR {value:.2} dB < 35");
    }
}

/// Box-downscales `img` to `w`×`h` (area average).
fn downscale(img: &RgbImage, w: u32, h: u32) -> RgbImage {
    let (sw, sh) = img.dimensions();
    RgbImage::from_fn(w, h, |x, y| {
        let (x0, x1) = (x * sw / w, ((x + 1) * sw / w).max(x * sw / w + 1));
        let (y0, y1) = (y * sh / h, ((y + 1) * sh / h).max(y * sh / h + 1));
        let mut sum = [0u32; 3];
        for yy in y0..y1 {
            for xx in x0..x1 {
                for (s, v) in sum.iter_mut().zip(img.get_pixel(xx, yy).0) {
                    *s += u32::from(v);
                }
            }
        }
        let n = (x1 - x0) * (y1 - y0);
        Rgb(sum.map(|s| ((s + n / 2) / n) as u8))
    })
}

#[test]
fn y4m_lucia_decodes_20_frames() {
    let Some(dir) = data_dir("video") else { return };
    let path = dir.join("lucia_20frames.y4m");
    let limits = Limits::default();
    let info = probe(&path, &limits).unwrap();
    assert_eq!(
        (info.container.as_str(), info.width, info.height),
        ("y4m", 214, 120)
    );
    assert_eq!(info.frame_count, 20);
    assert_eq!(info.fps, 30.0);
    let mut source = open(&path, &limits).unwrap();
    let frames = all_frames(source.as_mut());
    assert_eq!(frames.len(), 20);
    assert!(frames.iter().all(|f| f.dimensions() == (214, 120)));
    check_refs(&dir, "lucia_20frames.y4m", &frames);

    // No FFmpeg reference of this file exists: check the colour range against
    // the DAVIS source frame instead (box-downscaled). The header says
    // XCOLORRANGE=LIMITED; reading it as full range must match worse.
    let Some(davis) = data_dir("davis/lucia/frames") else {
        return;
    };
    let tmp = TempDir::new("y4m-range");
    let bytes = fs::read(&path).unwrap();
    let text = String::from_utf8_lossy(&bytes[..200]).into_owned();
    let full = text.replacen("XCOLORRANGE=LIMITED", "XCOLORRANGE=FULL", 1);
    let mut patched = full.as_bytes().to_vec();
    patched.extend_from_slice(&bytes[200..]);
    let full_path = tmp.write("full.y4m", &patched);
    let full_frame = open(&full_path, &limits)
        .unwrap()
        .next_frame()
        .unwrap()
        .unwrap();
    let source_frame = image::open(davis.join("00000.jpg")).unwrap().into_rgb8();
    let small = downscale(&source_frame, 214, 120);
    let (as_limited, as_full) = (psnr(&frames[0], &small), psnr(&full_frame, &small));
    println!(
        "lucia frame 0 vs downscaled DAVIS JPEG: limited {as_limited:.2} dB, full {as_full:.2} dB"
    );
    assert!(as_limited > as_full);
}

#[test]
fn gif_dance_twirl() {
    let Some(dir) = data_dir("video") else { return };
    let path = dir.join("dance-twirl.gif");
    let limits = Limits::default();
    let info = probe(&path, &limits).unwrap();
    println!("{info:?}");
    assert_eq!(
        (info.container.as_str(), info.width, info.height),
        ("gif", 214, 120)
    );
    assert_eq!(info.fps, 15.0, "the GIF's 7/7/6 cs delays make 15 fps");
    let start = Instant::now();
    let mut source = open(&path, &limits).unwrap();
    let frames = all_frames(source.as_mut());
    println!("{} frames in {:?}", frames.len(), start.elapsed());
    assert_eq!(frames.len() as u64, info.frame_count);
    assert_eq!(frames.len(), 90, "DAVIS dance-twirl has 90 frames");
    check_refs(&dir, "dance-twirl.gif", &frames);
}

/// Synthetic frames: a gradient with a moving square.
fn synthetic(n: usize, w: u32, h: u32) -> Vec<RgbImage> {
    (0..n)
        .map(|i| {
            RgbImage::from_fn(w, h, |x, y| {
                let inside = (x as usize).abs_diff(4 + 3 * i) < 4 && y.abs_diff(h / 2) < 4;
                if inside {
                    Rgb([220, 40, 40])
                } else {
                    Rgb([(x * 255 / w) as u8, (y * 255 / h) as u8, 128])
                }
            })
        })
        .collect()
}

fn write_clip(path: &Path, frames: &[RgbImage]) {
    let (w, h) = frames[0].dimensions();
    let mut writer = create(path, w, h, 10.0).unwrap();
    for f in frames {
        writer.push(Frame::Rgb(f)).unwrap();
    }
    writer.finish().unwrap();
}

#[test]
fn round_trips_through_the_writers() {
    let tmp = TempDir::new("roundtrip");
    let frames = synthetic(4, 38, 24);
    let limits = Limits::default();
    for ext in ["zip", "tar", "gif", "y4m"] {
        let path = tmp.path(&format!("clip.{ext}"));
        write_clip(&path, &frames);
        let info = probe(&path, &limits).unwrap();
        assert_eq!(
            (info.width, info.height, info.frame_count),
            (38, 24, 4),
            "{ext}"
        );
        assert_eq!(info.container, ext);
        assert!(!info.is_mask);
        let mut source = open(&path, &limits).unwrap();
        let back = all_frames(source.as_mut());
        assert_eq!(back.len(), 4, "{ext}");
        let worst = frames
            .iter()
            .zip(&back)
            .map(|(a, b)| psnr(a, b))
            .fold(f64::INFINITY, f64::min);
        println!("{ext}: worst PSNR {worst:.2} dB");
        match ext {
            "zip" | "tar" => assert_eq!(back, frames, "{ext} is lossless"),
            "gif" => {
                // The writer quantises many-colour frames; the decoder must
                // give exactly what the `image` crate's own decoder gives.
                use image::AnimationDecoder;
                let file = fs::File::open(&path).unwrap();
                let direct: Vec<RgbImage> =
                    image::codecs::gif::GifDecoder::new(std::io::BufReader::new(file))
                        .unwrap()
                        .into_frames()
                        .map(|f| {
                            image::DynamicImage::ImageRgba8(f.unwrap().into_buffer()).into_rgb8()
                        })
                        .collect();
                assert_eq!(back, direct);
                assert!(worst >= 20.0, "gif PSNR {worst:.2}");
                assert!((info.fps - 10.0).abs() < 1e-9);
                // Frames of at most 256 colours are stored exactly.
                let few: Vec<RgbImage> = (0..3u8)
                    .map(|i| {
                        RgbImage::from_fn(9, 7, |x, y| {
                            Rgb([40 * i, (x * 20) as u8, (y * 30) as u8])
                        })
                    })
                    .collect();
                let exact = tmp.path("few.gif");
                write_clip(&exact, &few);
                assert_eq!(all_frames(open(&exact, &limits).unwrap().as_mut()), few);
            }
            _ => {
                assert_eq!(info.fps, 10.0);
                // The writer states XCOLORRANGE=FULL; the reader honours it.
                let full = path.clone();
                let back = all_frames(open(&full, &limits).unwrap().as_mut());
                let worst = frames
                    .iter()
                    .zip(&back)
                    .map(|(a, b)| psnr(a, b))
                    .fold(f64::INFINITY, f64::min);
                // 4:2:0 chroma smears the sharp red square's edges.
                println!("y4m round trip: worst PSNR {worst:.2} dB");
                assert!(worst >= 25.0, "y4m PSNR {worst:.2}");
                // Smooth content survives 4:2:0 well; gray is exact.
                let smooth: Vec<RgbImage> = (0..3u32)
                    .map(|i| {
                        RgbImage::from_fn(38, 24, |x, y| {
                            Rgb([(x * 6 + i) as u8, (y * 9) as u8, (100 + x + y) as u8])
                        })
                    })
                    .collect();
                let gray = GrayImage::from_fn(38, 24, |x, y| Luma([(x * 5 + y * 3) as u8]));
                let p = tmp.path("smooth.y4m");
                let mut writer = create(&p, 38, 24, 25.0).unwrap();
                for f in &smooth {
                    writer.push(Frame::Rgb(f)).unwrap();
                }
                writer.push(Frame::Gray(&gray)).unwrap();
                writer.finish().unwrap();
                let mut bytes = fs::read(&p).unwrap();
                let nl = bytes.iter().position(|&b| b == b'\n').unwrap();
                bytes.splice(nl..nl, b" XCOLORRANGE=FULL".iter().copied());
                let full = tmp.write("smooth_full.y4m", &bytes);
                let back = all_frames(open(&full, &limits).unwrap().as_mut());
                assert_eq!(back.len(), 4);
                for (a, b) in smooth.iter().zip(&back) {
                    let v = psnr(a, b);
                    println!("y4m smooth frame: PSNR {v:.2} dB");
                    assert!(v >= 35.0, "smooth y4m PSNR {v:.2}");
                }
                let gray_rgb = image::DynamicImage::ImageLuma8(gray).into_rgb8();
                assert_eq!(back[3], gray_rgb, "gray is exact in full range");
            }
        }
    }
}

fn png_bytes(img: &RgbImage) -> Vec<u8> {
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(
            img.as_raw(),
            img.width(),
            img.height(),
            image::ExtendedColorType::Rgb8,
        )
        .unwrap();
    out
}

fn gray_png(img: &GrayImage) -> Vec<u8> {
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(
            img.as_raw(),
            img.width(),
            img.height(),
            image::ExtendedColorType::L8,
        )
        .unwrap();
    out
}

fn zip_of(entries: &[(&str, Vec<u8>)]) -> Vec<u8> {
    let mut zip = zip::ZipWriter::new(Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    for (name, bytes) in entries {
        if name.ends_with('/') {
            zip.add_directory(*name, options).unwrap();
        } else {
            zip.start_file(*name, options).unwrap();
            zip.write_all(bytes).unwrap();
        }
    }
    zip.finish().unwrap().into_inner()
}

/// A minimal ustar archive (our own writer, names up to 100 bytes).
fn tar_of(entries: &[(&str, Vec<u8>)]) -> Vec<u8> {
    let mut out = Vec::new();
    for (name, bytes) in entries {
        let mut h = [0u8; 512];
        h[..name.len()].copy_from_slice(name.as_bytes());
        h[100..108].copy_from_slice(b"0000644\0");
        h[108..116].copy_from_slice(b"0000000\0");
        h[116..124].copy_from_slice(b"0000000\0");
        h[124..136].copy_from_slice(format!("{:011o}\0", bytes.len()).as_bytes());
        h[136..148].copy_from_slice(b"00000000000\0");
        h[156] = if name.ends_with('/') { b'5' } else { b'0' };
        h[257..263].copy_from_slice(b"ustar\0");
        h[263..265].copy_from_slice(b"00");
        h[148..156].copy_from_slice(b"        ");
        let sum: u32 = h.iter().map(|&b| u32::from(b)).sum();
        h[148..156].copy_from_slice(format!("{sum:06o}\0 ").as_bytes());
        out.extend_from_slice(&h);
        out.extend_from_slice(bytes);
        out.resize(out.len().div_ceil(512) * 512, 0);
    }
    out.resize(out.len() + 1024, 0);
    out
}

fn solid(v: u8) -> RgbImage {
    RgbImage::from_pixel(8, 6, Rgb([v, 255 - v, 7]))
}

#[test]
fn archives_sort_naturally_and_skip_litter() {
    let tmp = TempDir::new("natural");
    let entries = vec![
        ("clip/", Vec::new()),
        ("clip/frame10.png", png_bytes(&solid(10))),
        ("clip/frame2.png", png_bytes(&solid(2))),
        ("clip/frame1.png", png_bytes(&solid(1))),
        ("__MACOSX/clip/._frame1.png", b"\0\x05\x16\x07junk".to_vec()),
        ("clip/.DS_Store", b"\0\0\0\x01Bud1".to_vec()),
        ("clip/Thumbs.db", b"junk".to_vec()),
        ("clip/notes.txt", b"frames of a clip".to_vec()),
    ];
    let limits = Limits::default();
    for (name, bytes) in [("a.zip", zip_of(&entries)), ("a.tar", tar_of(&entries))] {
        let path = tmp.write(name, &bytes);
        let mut source = open(&path, &limits).unwrap();
        assert_eq!(source.info().frame_count, 3, "{name}");
        assert!(!source.info().is_mask);
        let order: Vec<u8> = all_frames(source.as_mut())
            .iter()
            .map(|f| f.get_pixel(0, 0).0[0])
            .collect();
        assert_eq!(order, [1, 2, 10], "{name}");
    }
}

fn binary_mask(i: u32) -> GrayImage {
    GrayImage::from_fn(16, 12, |x, _| Luma([if x < 4 + i { 255 } else { 0 }]))
}

#[test]
fn archives_detect_masks() {
    let tmp = TempDir::new("masks");
    let limits = Limits::default();
    let masks: Vec<(String, Vec<u8>)> = (0..3)
        .map(|i| (format!("m{i}.png"), gray_png(&binary_mask(i))))
        .collect();
    let borrowed: Vec<(&str, Vec<u8>)> =
        masks.iter().map(|(n, b)| (n.as_str(), b.clone())).collect();
    for (name, bytes) in [("m.zip", zip_of(&borrowed)), ("m.tar", tar_of(&borrowed))] {
        let path = tmp.write(name, &bytes);
        let info = probe(&path, &limits).unwrap();
        assert!(info.is_mask, "{name}");
        let mut source = open(&path, &limits).unwrap();
        assert!(source.info().is_mask);
        let frames = all_frames(source.as_mut());
        assert_eq!(frames[1].get_pixel(4, 0).0, [255, 255, 255]);
        assert_eq!(frames[1].get_pixel(5, 0).0, [0, 0, 0]);
    }
    // One gray level that is not 0/255 in the last frame: not a mask clip.
    let mut last = binary_mask(2);
    last.put_pixel(15, 11, Luma([128]));
    let mut mixed = borrowed.clone();
    mixed[2].1 = gray_png(&last);
    let path = tmp.write("notmask.zip", &zip_of(&mixed));
    assert!(!probe(&path, &limits).unwrap().is_mask);
    // A colour clip thresholded on request.
    let colour = tmp.write("colour.zip", &zip_of(&[("0.png", png_bytes(&solid(200)))]));
    let mut forced = open_masks(&colour, &limits).unwrap();
    assert!(forced.info().is_mask);
    let f = forced.next_frame().unwrap().unwrap();
    assert!(f.as_raw().iter().all(|&v| v == 0 || v == 255));
}

#[test]
fn davis_masks_zip_is_a_mask_clip() {
    let Some(dir) = data_dir("davis/lucia/masks") else {
        return;
    };
    let tmp = TempDir::new("davis");
    let mut names: Vec<PathBuf> = fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    names.sort();
    let path = tmp.path("lucia_masks.zip");
    let mut zip = zip::ZipWriter::new(fs::File::create(&path).unwrap());
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    for p in &names {
        zip.start_file(
            format!("masks/{}", p.file_name().unwrap().to_string_lossy()),
            options,
        )
        .unwrap();
        zip.write_all(&fs::read(p).unwrap()).unwrap();
    }
    zip.finish().unwrap();
    let limits = Limits::default();
    let start = Instant::now();
    let mut source = open(&path, &limits).unwrap();
    let info = source.info().clone();
    println!("{info:?} opened in {:?}", start.elapsed());
    assert!(info.is_mask);
    assert_eq!((info.width, info.height, info.frame_count), (854, 480, 70));
    let frames = all_frames(source.as_mut());
    assert_eq!(frames.len(), 70);
    let first = image::open(&names[0]).unwrap().into_rgb8();
    assert_eq!(frames[0], first);
}

fn expect_err(result: Result<(), DecodeError>, what: &str) -> DecodeError {
    match result {
        Ok(()) => panic!("{what}: expected an error"),
        Err(e) => {
            println!("{what}: {e}");
            e
        }
    }
}

/// Probes, opens and drains a clip; the first error.
fn read_all(path: &Path, limits: &Limits) -> Result<(), DecodeError> {
    probe(path, limits)?;
    let mut source = open(path, limits)?;
    let mut n = 0;
    while source.next_frame()?.is_some() {
        n += 1;
        assert!(n <= limits.max_frames, "more frames than the limit");
    }
    Ok(())
}

/// Small valid files of every format read here, by name.
fn samples() -> &'static Vec<(&'static str, Vec<u8>)> {
    static SAMPLES: OnceLock<Vec<(&'static str, Vec<u8>)>> = OnceLock::new();
    SAMPLES.get_or_init(|| {
        let tmp = TempDir::new("samples");
        let frames = synthetic(3, 12, 8);
        let mut out = Vec::new();
        for (name, ext) in [
            ("y4m", "y4m"),
            ("gif", "gif"),
            ("zip", "zip"),
            ("tar", "tar"),
        ] {
            let p = tmp.path(&format!("s.{ext}"));
            write_clip(&p, &frames);
            out.push((name, fs::read(&p).unwrap()));
        }
        out.push(("png", png_bytes(&frames[0])));
        let mut webp = Vec::new();
        image::codecs::webp::WebPEncoder::new_lossless(&mut webp)
            .write_image(frames[0].as_raw(), 12, 8, image::ExtendedColorType::Rgb8)
            .unwrap();
        out.push(("webp", webp));
        let mut jpeg = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 90)
            .write_image(frames[0].as_raw(), 12, 8, image::ExtendedColorType::Rgb8)
            .unwrap();
        out.push(("jpeg", jpeg));
        out.push(("apng", apng(&frames)));
        out.push(("awebp", animated_webp(&frames)));
        out
    })
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let mut body = kind.to_vec();
    body.extend_from_slice(data);
    out.extend_from_slice(&body);
    out.extend_from_slice(&crc32(&body).to_be_bytes());
}

/// The IDAT payload of a PNG made by the image crate.
fn idat_of(png: &[u8]) -> Vec<u8> {
    let mut data = Vec::new();
    let mut at = 8;
    while at + 8 <= png.len() {
        let len = u32::from_be_bytes(png[at..at + 4].try_into().unwrap()) as usize;
        if &png[at + 4..at + 8] == b"IDAT" {
            data.extend_from_slice(&png[at + 8..at + 8 + len]);
        }
        at += 12 + len;
    }
    data
}

/// An APNG assembled by hand (the image crate has no APNG encoder).
fn apng(frames: &[RgbImage]) -> Vec<u8> {
    let (w, h) = frames[0].dimensions();
    let first = png_bytes(&frames[0]);
    let mut out = first[..8 + 25].to_vec(); // signature and IHDR
    let mut actl = (frames.len() as u32).to_be_bytes().to_vec();
    actl.extend_from_slice(&0u32.to_be_bytes());
    chunk(&mut out, b"acTL", &actl);
    let mut seq = 0u32;
    for (i, f) in frames.iter().enumerate() {
        let mut fctl = seq.to_be_bytes().to_vec();
        seq += 1;
        for v in [w, h, 0, 0] {
            fctl.extend_from_slice(&v.to_be_bytes());
        }
        fctl.extend_from_slice(&1u16.to_be_bytes());
        fctl.extend_from_slice(&8u16.to_be_bytes()); // 1/8 s
        fctl.extend_from_slice(&[0, 0]);
        chunk(&mut out, b"fcTL", &fctl);
        let data = idat_of(&png_bytes(f));
        if i == 0 {
            chunk(&mut out, b"IDAT", &data);
        } else {
            let mut fdat = seq.to_be_bytes().to_vec();
            seq += 1;
            fdat.extend_from_slice(&data);
            chunk(&mut out, b"fdAT", &fdat);
        }
    }
    chunk(&mut out, b"IEND", &[]);
    out
}

fn u24(v: u32) -> [u8; 3] {
    let b = v.to_le_bytes();
    [b[0], b[1], b[2]]
}

fn riff_chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(kind);
    out.extend_from_slice(&(data.len() as u32).to_le_bytes());
    out.extend_from_slice(data);
    if data.len() % 2 == 1 {
        out.push(0);
    }
}

/// An animated WebP assembled by hand from lossless frames of the image
/// crate (which has no animation encoder); 100 ms per frame.
fn animated_webp(frames: &[RgbImage]) -> Vec<u8> {
    let (w, h) = frames[0].dimensions();
    let mut body = b"WEBP".to_vec();
    let mut vp8x = vec![0x02, 0, 0, 0];
    vp8x.extend_from_slice(&u24(w - 1));
    vp8x.extend_from_slice(&u24(h - 1));
    riff_chunk(&mut body, b"VP8X", &vp8x);
    riff_chunk(&mut body, b"ANIM", &[0, 0, 0, 255, 0, 0]);
    for f in frames {
        let mut still = Vec::new();
        image::codecs::webp::WebPEncoder::new_lossless(&mut still)
            .write_image(f.as_raw(), w, h, image::ExtendedColorType::Rgb8)
            .unwrap();
        assert_eq!(&still[12..16], b"VP8L");
        let mut anmf = [u24(0), u24(0), u24(w - 1), u24(h - 1), u24(100)].concat();
        anmf.push(0x02); // no blending, no disposal
        anmf.extend_from_slice(&still[12..]);
        riff_chunk(&mut body, b"ANMF", &anmf);
    }
    let mut out = b"RIFF".to_vec();
    out.extend_from_slice(&(body.len() as u32).to_le_bytes());
    out.extend_from_slice(&body);
    out
}

#[test]
fn stills_webp_jpeg_and_apng_open() {
    let tmp = TempDir::new("stills");
    let limits = Limits::default();
    let frames = synthetic(3, 12, 8);
    for (name, bytes) in samples() {
        let path = tmp.write(&format!("sample.{name}"), bytes);
        let info = probe(&path, &limits).unwrap();
        let mut source = open(&path, &limits).unwrap();
        let back = all_frames(source.as_mut());
        println!("{name}: {info:?}");
        assert_eq!(back.len() as u64, info.frame_count, "{name}");
        assert_eq!((info.width, info.height), (12, 8));
        match *name {
            "png" | "webp" => assert_eq!(back, frames[..1], "{name} is lossless"),
            "apng" => {
                assert_eq!(info.container, "apng");
                assert_eq!(info.fps, 8.0);
                assert_eq!(back, frames);
            }
            "awebp" => {
                assert_eq!(info.container, "webp");
                assert_eq!(info.fps, 10.0);
                assert_eq!(back, frames);
            }
            "jpeg" => assert!(psnr(&back[0], &frames[0]) > 25.0),
            _ => assert_eq!(back.len(), 3),
        }
    }
}

#[test]
fn truncated_files_fail_cleanly() {
    let tmp = TempDir::new("truncated");
    let limits = Limits::default();
    for (name, bytes) in samples() {
        // A tar file cut inside its two end-of-archive blocks loses nothing.
        let last_data = if *name == "tar" {
            bytes.len() - 1024
        } else {
            bytes.len()
        };
        for cut in [bytes.len() / 2, last_data * 9 / 10, 20] {
            let path = tmp.write(&format!("cut.{name}"), &bytes[..cut]);
            let e = expect_err(
                read_all(&path, &limits),
                &format!("{name} cut to {cut} bytes"),
            );
            assert!(
                matches!(
                    e,
                    DecodeError::Truncated { .. }
                        | DecodeError::Corrupt { .. }
                        | DecodeError::UnknownFormat { .. }
                ),
                "{name}: {e:?}"
            );
        }
    }
    // A GIF missing only its trailer byte still reads whole (a common defect).
    let gif = &samples().iter().find(|(n, _)| *n == "gif").unwrap().1;
    assert_eq!(gif.last(), Some(&0x3B));
    let path = tmp.write("no_trailer.gif", &gif[..gif.len() - 1]);
    let frames = all_frames(open(&path, &limits).unwrap().as_mut());
    assert_eq!(frames.len(), 3);
    let y4m = &samples().iter().find(|(n, _)| *n == "y4m").unwrap().1;
    let path = tmp.write("cut.y4m", &y4m[..y4m.len() - 10]);
    let e = expect_err(read_all(&path, &limits), "y4m missing its last bytes");
    assert!(matches!(e, DecodeError::Truncated { .. }));
}

#[test]
fn sniffing_ignores_the_extension() {
    let tmp = TempDir::new("sniff");
    let limits = Limits::default();
    let gif = &samples().iter().find(|(n, _)| *n == "gif").unwrap().1;
    let path = tmp.write("really_a_gif.mp4", gif);
    let info = probe(&path, &limits).unwrap();
    assert_eq!(info.container, "gif");
    assert_eq!(all_frames(open(&path, &limits).unwrap().as_mut()).len(), 3);
    let text = tmp.write("notes.mp4", b"These are my holiday notes, not a video.\n");
    let e = expect_err(read_all(&text, &limits), "text named .mp4");
    assert!(matches!(e, DecodeError::UnknownFormat { .. }), "{e:?}");
    assert!(e.to_string().contains("text"));
    let empty = tmp.write("empty.gif", b"");
    let e = expect_err(read_all(&empty, &limits), "empty file");
    assert!(matches!(e, DecodeError::UnknownFormat { .. }), "{e:?}");
}

#[test]
fn zip_bomb_fails_on_the_entry_limit() {
    let tmp = TempDir::new("bomb");
    let path = tmp.path("bomb.zip");
    let start = Instant::now();
    let mut zip = zip::ZipWriter::new(fs::File::create(&path).unwrap());
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .large_file(false);
    zip.start_file("frame0.png", options).unwrap();
    std::io::copy(
        &mut std::io::Read::take(std::io::repeat(0), 200 << 20),
        &mut zip,
    )
    .unwrap();
    zip.finish().unwrap();
    let size = fs::metadata(&path).unwrap().len();
    println!(
        "200 MiB of zeros deflated to {size} bytes in {:?}",
        start.elapsed()
    );
    let start = Instant::now();
    let e = expect_err(read_all(&path, &Limits::default()), "zip bomb");
    let took = start.elapsed();
    println!("refused in {took:?}");
    assert!(matches!(e, DecodeError::TooLarge { .. }), "{e:?}");
    assert!(took.as_secs_f64() < 1.0);

    // An entry under the declared limit but over a tighter one: refused
    // while inflating too (the declared size is checked first here).
    let small = Limits {
        max_entry_bytes: 1 << 20,
        ..Limits::default()
    };
    let noise = RgbImage::from_fn(64, 64, |x, y| {
        let v = (x * 7919 + y * 104_729).wrapping_mul(2_654_435_761) >> 13;
        Rgb([v as u8, (v >> 8) as u8, (v >> 16) as u8])
    });
    let noisy = png_bytes(&noise);
    assert!(noisy.len() > 4000);
    let tight = Limits {
        max_entry_bytes: 1000,
        ..small.clone()
    };
    let path = tmp.write("big.zip", &zip_of(&[("0.png", noisy.clone())]));
    let e = expect_err(read_all(&path, &tight), "entry over a 1000-byte limit");
    assert!(matches!(e, DecodeError::TooLarge { .. }), "{e:?}");
    // The same archive lying about the entry's size (100 bytes in both
    // headers): the inflated bytes are bounded all the same.
    let mut lying = zip_of(&[("0.png", noisy)]);
    assert_eq!(&lying[..4], b"PK\x03\x04");
    lying[22..26].copy_from_slice(&100u32.to_le_bytes());
    let cd = lying.windows(4).position(|w| w == b"PK\x01\x02").unwrap();
    lying[cd + 24..cd + 28].copy_from_slice(&100u32.to_le_bytes());
    let path = tmp.write("lying.zip", &lying);
    let e = expect_err(read_all(&path, &tight), "entry lying about its size");
    assert!(
        matches!(
            e,
            DecodeError::TooLarge { .. } | DecodeError::Corrupt { .. }
        ),
        "{e:?}"
    );
    let total = Limits {
        max_total_bytes: 100,
        ..Limits::default()
    };
    let path = tmp.write(
        "total.zip",
        &zip_of(&[
            ("0.png", png_bytes(&solid(1))),
            ("1.png", png_bytes(&solid(2))),
        ]),
    );
    let e = expect_err(read_all(&path, &total), "entries over a total limit");
    assert!(matches!(e, DecodeError::TooLarge { .. }), "{e:?}");
}

#[test]
fn huge_headers_fail_fast() {
    let tmp = TempDir::new("huge");
    let limits = Limits::default();
    // GIF sides are 16-bit: 65535×65535 is the largest a header can claim.
    let mut gif = b"GIF89a".to_vec();
    gif.extend_from_slice(&65535u16.to_le_bytes());
    gif.extend_from_slice(&65535u16.to_le_bytes());
    gif.extend_from_slice(&[
        0, 0, 0, 0x2C, 0, 0, 0, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0, 2, 2, 0x4C, 0x01, 0, 0x3B,
    ]);
    // A PNG claiming 100000×100000.
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = 100_000u32.to_be_bytes().to_vec();
    ihdr.extend_from_slice(&100_000u32.to_be_bytes());
    ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);
    chunk(&mut png, b"IHDR", &ihdr);
    chunk(&mut png, b"IEND", &[]);
    let y4m = b"YUV4MPEG2 W100000 H100000 F30:1 C420jpeg\nFRAME\n".to_vec();
    for (name, bytes) in [("huge.gif", gif), ("huge.png", png), ("huge.y4m", y4m)] {
        let path = tmp.write(name, &bytes);
        let start = Instant::now();
        let e = expect_err(read_all(&path, &limits), name);
        assert!(matches!(e, DecodeError::TooLarge { .. }), "{name}: {e:?}");
        assert!(
            start.elapsed().as_millis() < 200,
            "{name} took {:?}",
            start.elapsed()
        );
    }
}

#[test]
fn hostile_and_inconsistent_archives() {
    let tmp = TempDir::new("hostile");
    let limits = Limits::default();
    let frame = png_bytes(&solid(3));
    let evil = vec![
        ("0.png", frame.clone()),
        ("../../etc/passwd", b"root:x:0:0".to_vec()),
    ];
    for (name, bytes) in [("evil.zip", zip_of(&evil)), ("evil.tar", tar_of(&evil))] {
        let path = tmp.write(name, &bytes);
        let e = expect_err(read_all(&path, &limits), name);
        assert!(matches!(e, DecodeError::Corrupt { .. }), "{e:?}");
        assert!(e.to_string().contains("../../etc/passwd"));
    }
    // (Nothing is ever written to disk by the readers: entries are read into memory.)

    let big = png_bytes(&RgbImage::new(9, 6));
    let mixed = vec![("0.png", frame.clone()), ("1.png", big)];
    for (name, bytes) in [("mixed.zip", zip_of(&mixed)), ("mixed.tar", tar_of(&mixed))] {
        let path = tmp.write(name, &bytes);
        let e = expect_err(read_all(&path, &limits), name);
        assert!(
            matches!(e, DecodeError::Corrupt { .. }) && e.to_string().contains("mixed frame sizes"),
            "{e:?}"
        );
    }
    // Mixed sizes across JPEG frames are found while streaming.
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new(&mut jpeg)
        .write_image(
            RgbImage::new(9, 6).as_raw(),
            9,
            6,
            image::ExtendedColorType::Rgb8,
        )
        .unwrap();
    let path = tmp.write(
        "mixed_jpeg.zip",
        &zip_of(&[("0.png", frame.clone()), ("1.jpg", jpeg)]),
    );
    let e = expect_err(read_all(&path, &limits), "mixed PNG/JPEG sizes");
    assert!(e.to_string().contains("mixed frame sizes"), "{e:?}");

    let none = vec![("readme.txt", b"hello".to_vec()), ("dir/", Vec::new())];
    for (name, bytes) in [
        ("none.zip", zip_of(&none)),
        ("none.tar", tar_of(&none)),
        ("empty.zip", zip_of(&[])),
    ] {
        let path = tmp.write(name, &bytes);
        let e = expect_err(read_all(&path, &limits), name);
        assert!(matches!(e, DecodeError::UnknownFormat { .. }), "{e:?}");
    }
    let fake = tmp.write(
        "fake.zip",
        &zip_of(&[("0.png", b"not a png at all".to_vec())]),
    );
    let e = expect_err(
        read_all(&fake, &limits),
        "a .png entry that is not an image",
    );
    assert!(matches!(e, DecodeError::Corrupt { .. }), "{e:?}");
}

#[test]
fn ffmpeg_fallback_when_installed() {
    if !ffmpeg::available() {
        println!("skipped: no ffmpeg on PATH");
        return;
    }
    let Some(dir) = data_dir("video") else { return };
    let limits = Limits::default();
    let path = dir.join("lucia_hevc.mp4");
    let info: ClipInfo = probe(&path, &limits).unwrap();
    println!("{info:?}");
    let mut source = open(&path, &limits).unwrap();
    let mut n = 0;
    while let Some(f) = source.next_frame().unwrap() {
        assert_eq!(f.dimensions(), (info.width, info.height));
        n += 1;
    }
    assert!(n > 0);
    // Dropping a source mid-stream kills and reaps the child.
    let mut source = ffmpeg::open(&dir.join("vtest.mp4"), &limits).unwrap();
    source.next_frame().unwrap().unwrap();
    drop(source);
}

/// Small limits keep every fuzz case cheap.
fn fuzz_limits() -> Limits {
    Limits {
        max_width: 256,
        max_height: 256,
        max_pixels: 256 * 256,
        max_frames: 64,
        max_entry_bytes: 1 << 20,
        max_total_bytes: 8 << 20,
    }
}

fn fuzz_one(bytes: &[u8]) {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    static DIR: OnceLock<TempDir> = OnceLock::new();
    let dir = DIR.get_or_init(|| TempDir::new("fuzz"));
    let path = dir.write(
        &format!("case{}.mp4", COUNTER.fetch_add(1, Ordering::Relaxed)),
        bytes,
    );
    let _ = read_all(&path, &fuzz_limits());
    let _ = fs::remove_file(&path);
}

proptest! {
    // 256 cases each (well under a second); `PROPTEST_CASES=N` runs more.
    #![proptest_config(ProptestConfig {
        cases: std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(256),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600), magic in 0usize..10) {
        let prefixes: [&[u8]; 10] = [b"", b"YUV4MPEG2 ", b"GIF89a", b"\x89PNG\r\n\x1a\n", b"RIFF\x20\0\0\0WEBP", b"PK\x03\x04", b"PK\x05\x06", b"\xFF\xD8\xFF", b"YUV4MPEG2 W4 H4 ", b"GIF87a\x04\0\x04\0"];
        let mut data = prefixes[magic].to_vec();
        data.extend_from_slice(&bytes);
        fuzz_one(&data);
    }

    #[test]
    fn mutated_samples_never_panic(
        which in 0usize..64,
        flips in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..8),
        cut in proptest::option::of(any::<usize>()),
    ) {
        let (_, sample) = &samples()[which % samples().len()];
        let mut data = sample.clone();
        for (at, x) in flips {
            let i = at % data.len();
            data[i] ^= x.max(1);
        }
        if let Some(c) = cut {
            data.truncate(c % (data.len() + 1));
        }
        fuzz_one(&data);
    }
}

#[test]
fn mutated_tar_headers_never_panic() {
    // Every byte of the first tar header set to a few values, one at a time.
    let tar = &samples().iter().find(|(n, _)| *n == "tar").unwrap().1;
    for i in 0..512 {
        for v in [0u8, b'7', 0xFF] {
            let mut data = tar.clone();
            data[i] = v;
            fuzz_one(&data);
        }
    }
}

#[test]
fn containers_of_the_other_decoders_are_dispatched() {
    let Some(dir) = data_dir("video") else { return };
    let limits = Limits::default();
    for (name, container, w, h) in [
        ("vtest.mp4", "mp4", 480, 360),
        ("vtest.avi", "avi", 480, 360),
        ("tennis_mjpeg.avi", "avi", 428, 240),
    ] {
        let info = probe(&dir.join(name), &limits).unwrap();
        println!("{name}: {info:?}");
        assert_eq!(
            (info.container.as_str(), info.width, info.height),
            (container, w, h)
        );
    }
    // HEVC: read through ffmpeg when installed, else a clear UnsupportedCodec.
    let hevc = dir.join("lucia_hevc.mp4");
    match open(&hevc, &limits) {
        Ok(source) => {
            assert!(ffmpeg::available(), "HEVC opened without ffmpeg");
            println!("lucia_hevc.mp4 through ffmpeg: {:?}", source.info());
        }
        Err(e) => {
            println!("lucia_hevc.mp4: {e}");
            assert!(!ffmpeg::available());
            assert!(matches!(e, DecodeError::UnsupportedCodec { .. }), "{e:?}");
        }
    }
}
