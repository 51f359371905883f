//! Round-trip tests for `monocap::clip::write`: every format is written to a
//! temporary directory and read back with an independent decoder.

mod common;

use common::TempDir;
use std::fs;
use std::io::{BufReader, Cursor, Read};
use std::path::Path;
use std::time::Instant;

use image::codecs::gif::GifDecoder;
use image::metadata::LoopCount;
use image::{AnimationDecoder, DynamicImage, GrayImage, Luma, Rgb, RgbImage};
use monocap::clip::write::{
    create, rational_frame_rate, ClipFormat, ClipWriteError, ClipWriter, Frame,
};

fn flat(width: u32, height: u32, colour: [u8; 3]) -> RgbImage {
    RgbImage::from_pixel(width, height, Rgb(colour))
}

/// Horizontal gray ramp from 0 to 255.
fn gray_ramp(width: u32, height: u32) -> RgbImage {
    RgbImage::from_fn(width, height, |x, _| {
        let v = (x * 255 / (width - 1).max(1)) as u8;
        Rgb([v, v, v])
    })
}

/// Every pixel different: colour varies in x, y and across channels.
fn colour_mix(width: u32, height: u32) -> RgbImage {
    RgbImage::from_fn(width, height, |x, y| {
        Rgb([
            (x * 37 + y * 11) as u8,
            (y * 53 + 7) as u8,
            (255 - (x * 29 + y * 3) % 256) as u8,
        ])
    })
}

/// A 0/255 mask: a filled rectangle.
fn mask(width: u32, height: u32) -> GrayImage {
    GrayImage::from_fn(width, height, |x, y| {
        let inside = x >= width / 4 && x < 3 * width / 4 && y >= height / 3;
        Luma([if inside { 255 } else { 0 }])
    })
}

/// Writes `frames` to `path` and finishes the clip.
fn write_clip(path: &Path, width: u32, height: u32, fps: f64, frames: &[Frame<'_>]) {
    let mut writer = create(path, width, height, fps).expect("create writer");
    for (i, &frame) in frames.iter().enumerate() {
        writer.push(frame).expect("push frame");
        assert_eq!(writer.frames_written(), i + 1);
    }
    writer.finish().expect("finish clip");
}

// ---------------------------------------------------------------- Y4M

/// Full-range BT.601 (JFIF) RGB → YCbCr, unrounded.
fn ycbcr(rgb: [f64; 3]) -> [f64; 3] {
    let [r, g, b] = rgb;
    [
        0.299 * r + 0.587 * g + 0.114 * b,
        128.0 - 0.168736 * r - 0.331264 * g + 0.5 * b,
        128.0 + 0.5 * r - 0.418688 * g - 0.081312 * b,
    ]
}

fn assert_close(actual: u8, expected: f64, what: &str) {
    let expected = expected.clamp(0.0, 255.0);
    assert!(
        (f64::from(actual) - expected).abs() <= 1.0,
        "{what}: got {actual}, expected {expected:.2}"
    );
}

/// Checks a decoded 4:2:0 frame against `img`: Y per pixel, chroma from the
/// average RGB of each (possibly partial) 2×2 block.
fn check_y4m_frame(frame: &y4m::Frame<'_>, img: &RgbImage, label: &str) {
    let (w, h) = img.dimensions();
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    assert_eq!(frame.get_y_plane().len(), (w * h) as usize);
    assert_eq!(frame.get_u_plane().len(), (cw * ch) as usize);
    assert_eq!(frame.get_v_plane().len(), (cw * ch) as usize);
    for (x, y, p) in img.enumerate_pixels() {
        let expected = ycbcr(p.0.map(f64::from))[0];
        let actual = frame.get_y_plane()[(y * w + x) as usize];
        assert_close(actual, expected, &format!("{label} Y at ({x},{y})"));
    }
    for cy in 0..ch {
        for cx in 0..cw {
            let mut sum = [0.0; 3];
            let mut count = 0.0;
            for y in 2 * cy..(2 * cy + 2).min(h) {
                for x in 2 * cx..(2 * cx + 2).min(w) {
                    for (s, v) in sum.iter_mut().zip(img.get_pixel(x, y).0) {
                        *s += f64::from(v);
                    }
                    count += 1.0;
                }
            }
            let [_, cb, cr] = ycbcr(sum.map(|s| s / count));
            let i = (cy * cw + cx) as usize;
            assert_close(
                frame.get_u_plane()[i],
                cb,
                &format!("{label} Cb at ({cx},{cy})"),
            );
            assert_close(
                frame.get_v_plane()[i],
                cr,
                &format!("{label} Cr at ({cx},{cy})"),
            );
        }
    }
}

fn open_y4m(path: &Path) -> y4m::Decoder<BufReader<fs::File>> {
    y4m::Decoder::new(BufReader::new(fs::File::open(path).expect("open y4m")))
        .expect("parse y4m header")
}

#[test]
fn y4m_rgb_frames_match_bt601_full_range() {
    let dir = TempDir::new("y4m-rgb");
    let path = dir.path("clip.y4m");
    let (w, h) = (8, 6);
    let images = [
        flat(w, h, [255, 0, 0]),
        flat(w, h, [0, 255, 0]),
        flat(w, h, [0, 0, 255]),
        gray_ramp(w, h),
        colour_mix(w, h),
    ];
    let frames: Vec<Frame<'_>> = images.iter().map(Frame::Rgb).collect();
    write_clip(&path, w, h, 30.0, &frames);
    assert_eq!(dir.files(), ["clip.y4m"], "temporary file renamed away");

    let mut decoder = open_y4m(&path);
    assert_eq!((decoder.get_width(), decoder.get_height()), (8, 6));
    let rate = decoder.get_framerate();
    assert_eq!((rate.num, rate.den), (30, 1));
    assert!(matches!(
        decoder.get_colorspace(),
        y4m::Colorspace::C420jpeg
    ));
    assert!(decoder.get_raw_params().ends_with(b" C420jpeg"));
    for (i, img) in images.iter().enumerate() {
        let frame = decoder.read_frame().expect("read frame");
        check_y4m_frame(&frame, img, &format!("frame {i}"));
    }
    assert!(matches!(decoder.read_frame(), Err(y4m::Error::EOF)));
}

#[test]
fn y4m_primaries_have_the_textbook_values() {
    let dir = TempDir::new("y4m-primaries");
    let path = dir.path("clip.y4m");
    let images = [
        flat(2, 2, [255, 0, 0]),
        flat(2, 2, [0, 255, 0]),
        flat(2, 2, [0, 0, 255]),
    ];
    let frames: Vec<Frame<'_>> = images.iter().map(Frame::Rgb).collect();
    write_clip(&path, 2, 2, 30.0, &frames);
    let mut decoder = open_y4m(&path);
    // JFIF: red (76, 85, 255), green (150, 44, 21), blue (29, 255, 107).
    for expected in [[76, 85, 255], [150, 44, 21], [29, 255, 107]] {
        let frame = decoder.read_frame().expect("read frame");
        let got = [
            frame.get_y_plane()[0],
            frame.get_u_plane()[0],
            frame.get_v_plane()[0],
        ];
        for (g, e) in got.iter().zip(expected) {
            assert!(g.abs_diff(e) <= 1, "got {got:?}, expected {expected:?}");
        }
    }
}

#[test]
fn y4m_gray_mask_has_exact_luma_and_neutral_chroma() {
    let dir = TempDir::new("y4m-gray");
    let path = dir.path("mask.y4m");
    let (w, h) = (10, 6);
    let colour = colour_mix(w, h);
    let mask = mask(w, h);
    // A gray frame after an RGB one is converted, not rejected.
    write_clip(
        &path,
        w,
        h,
        25.0,
        &[Frame::Rgb(&colour), Frame::Gray(&mask)],
    );

    let mut decoder = open_y4m(&path);
    decoder.read_frame().expect("rgb frame");
    let frame = decoder.read_frame().expect("mask frame");
    assert_eq!(frame.get_y_plane(), mask.as_raw().as_slice());
    assert!(frame.get_y_plane().contains(&0));
    assert!(frame.get_y_plane().contains(&255));
    assert!(frame.get_u_plane().iter().all(|&v| v == 128));
    assert!(frame.get_v_plane().iter().all(|&v| v == 128));
}

#[test]
fn y4m_odd_size_rounds_chroma_up() {
    let dir = TempDir::new("y4m-odd");
    let path = dir.path("odd.y4m");
    let (w, h) = (5, 3);
    let images = [colour_mix(w, h), gray_ramp(w, h), flat(w, h, [10, 200, 30])];
    let frames: Vec<Frame<'_>> = images.iter().map(Frame::Rgb).collect();
    write_clip(&path, w, h, 12.5, &frames);

    let mut decoder = open_y4m(&path);
    assert_eq!((decoder.get_width(), decoder.get_height()), (5, 3));
    let rate = decoder.get_framerate();
    assert_eq!((rate.num, rate.den), (25, 2));
    for (i, img) in images.iter().enumerate() {
        let frame = decoder.read_frame().expect("read frame");
        check_y4m_frame(&frame, img, &format!("odd frame {i}"));
    }
}

#[test]
fn y4m_header_carries_ntsc_rate() {
    let dir = TempDir::new("y4m-ntsc");
    let path = dir.path("ntsc.Y4M");
    let img = flat(4, 4, [1, 2, 3]);
    write_clip(&path, 4, 4, 29.97, &[Frame::Rgb(&img)]);
    let rate = open_y4m(&path).get_framerate();
    assert_eq!((rate.num, rate.den), (30000, 1001));
}

#[test]
fn frame_rates_become_good_rationals() {
    let cases = [
        (30.0, (30, 1)),
        (25.0, (25, 1)),
        (60.0, (60, 1)),
        (1000.0, (1000, 1)),
        (12.5, (25, 2)),
        (7.5, (15, 2)),
        (0.5, (1, 2)),
        (1.0 / 3.0, (1, 3)),
        (29.97, (30000, 1001)),
        (30000.0 / 1001.0, (30000, 1001)),
        (23.976, (24000, 1001)),
        (59.94, (60000, 1001)),
        (119.88, (120000, 1001)),
        (14.3, (143, 10)),
        (7000.0 / 1001.0, (1000, 143)),
        (std::f64::consts::PI, (103_993, 33_102)),
    ];
    for (fps, expected) in cases {
        let got = rational_frame_rate(fps);
        assert_eq!(got, Some(expected), "fps {fps}");
        let (n, d) = expected;
        assert!((f64::from(n) / f64::from(d) - fps).abs() / fps < 1e-4);
    }
    for bad in [0.0, -30.0, f64::NAN, f64::INFINITY, 1e-300, 1e300] {
        assert_eq!(rational_frame_rate(bad), None, "fps {bad}");
    }
}

// ---------------------------------------------------------------- PNG archives

/// Checks decoded PNG bytes against the frame they came from, exactly.
fn check_png(bytes: &[u8], expected: Frame<'_>, name: &str) {
    let decoded = image::load_from_memory_with_format(bytes, image::ImageFormat::Png)
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    match (decoded, expected) {
        (DynamicImage::ImageRgb8(got), Frame::Rgb(want)) => assert!(got == *want, "{name}"),
        (DynamicImage::ImageLuma8(got), Frame::Gray(want)) => assert!(got == *want, "{name}"),
        (got, _) => panic!("{name}: unexpected PNG colour type {:?}", got.color()),
    }
}

fn mixed_frames() -> (RgbImage, GrayImage, RgbImage) {
    (colour_mix(9, 7), mask(9, 7), gray_ramp(9, 7))
}

#[test]
fn zip_holds_one_exact_png_per_frame_in_order() {
    let dir = TempDir::new("zip");
    let path = dir.path("frames.zip");
    let (a, m, b) = mixed_frames();
    let frames = [
        Frame::Rgb(&a),
        Frame::Gray(&m),
        Frame::Rgb(&b),
        Frame::Gray(&m),
    ];
    write_clip(&path, 9, 7, 30.0, &frames);
    assert_eq!(dir.files(), ["frames.zip"]);

    let file = fs::File::open(&path).expect("open zip");
    let mut archive = zip::ZipArchive::new(BufReader::new(file)).expect("read zip");
    assert_eq!(archive.len(), frames.len());
    for (i, &frame) in frames.iter().enumerate() {
        let mut entry = archive.by_index(i).expect("zip entry");
        let name = format!("{i:06}.png");
        assert_eq!(entry.name().expect("entry name"), name);
        assert_eq!(entry.compression(), zip::CompressionMethod::Deflated);
        let mut bytes = Vec::new();
        entry.read_to_end(&mut bytes).expect("read entry");
        check_png(&bytes, frame, &name);
    }
}

/// A ustar entry parsed by hand: name and data.
struct TarEntry {
    name: String,
    data: Vec<u8>,
}

fn parse_octal(field: &[u8]) -> u64 {
    let text = std::str::from_utf8(field).expect("ascii octal");
    let digits = text.trim_matches(|c: char| c == '\0' || c == ' ');
    u64::from_str_radix(digits, 8).expect("octal number")
}

/// Parses a ustar archive strictly: checksums, magic, padding, end marker.
fn parse_tar(bytes: &[u8]) -> Vec<TarEntry> {
    assert_eq!(bytes.len() % 512, 0, "whole 512-byte blocks");
    let mut entries = Vec::new();
    let mut pos = 0;
    loop {
        let header = &bytes[pos..pos + 512];
        if header.iter().all(|&b| b == 0) {
            assert_eq!(bytes.len(), pos + 1024, "two zero blocks end the archive");
            assert!(bytes[pos..].iter().all(|&b| b == 0));
            return entries;
        }
        let mut for_sum = header.to_vec();
        for_sum[148..156].fill(b' ');
        let sum: u64 = for_sum.iter().map(|&b| u64::from(b)).sum();
        assert_eq!(parse_octal(&header[148..156]), sum, "header checksum");
        assert_eq!(&header[257..265], b"ustar\x0000", "ustar magic and version");
        assert_eq!(header[156], b'0', "regular file");
        let name_end = header[..100].iter().position(|&b| b == 0).unwrap_or(100);
        let name = String::from_utf8(header[..name_end].to_vec()).expect("utf-8 name");
        let size = parse_octal(&header[124..136]) as usize;
        let data = bytes[pos + 512..pos + 512 + size].to_vec();
        let padded = size.div_ceil(512) * 512;
        assert!(bytes[pos + 512 + size..pos + 512 + padded]
            .iter()
            .all(|&b| b == 0));
        entries.push(TarEntry { name, data });
        pos += 512 + padded;
    }
}

#[test]
fn tar_holds_one_exact_png_per_frame_in_order() {
    let dir = TempDir::new("tar");
    let path = dir.path("frames.TAR");
    let (a, m, b) = mixed_frames();
    let frames = [Frame::Gray(&m), Frame::Rgb(&a), Frame::Rgb(&b)];
    write_clip(&path, 9, 7, 30.0, &frames);
    assert_eq!(dir.files(), ["frames.TAR"]);

    let entries = parse_tar(&fs::read(&path).expect("read tar"));
    assert_eq!(entries.len(), frames.len());
    for (i, (entry, &frame)) in entries.iter().zip(&frames).enumerate() {
        assert_eq!(entry.name, format!("{i:06}.png"));
        check_png(&entry.data, frame, &entry.name);
    }
}

// ---------------------------------------------------------------- GIF

fn decode_gif(path: &Path) -> (LoopCount, Vec<image::Frame>) {
    let reader = BufReader::new(fs::File::open(path).expect("open gif"));
    let decoder = GifDecoder::new(reader).expect("gif header");
    let loops = decoder.loop_count();
    let frames = decoder.into_frames().collect_frames().expect("gif frames");
    (loops, frames)
}

fn delay_ms(frame: &image::Frame) -> f64 {
    let (num, den) = frame.delay().numer_denom_ms();
    f64::from(num) / f64::from(den)
}

#[test]
fn gif_delays_keep_the_average_rate_exact() {
    for (fps, expected_cs) in [
        (30.0, &[3, 4, 3, 3, 4, 3, 3, 4, 3, 3][..]),
        (12.5, &[8, 8, 8, 8][..]),
        (29.97, &[3, 4, 3, 3, 4, 3, 3, 4, 3, 3, 4][..]),
        (7.0, &[14, 15, 14, 14, 14, 15, 14][..]),
    ] {
        let dir = TempDir::new("gif-delays");
        let path = dir.path("timing.gif");
        let img = flat(4, 3, [200, 100, 50]);
        let frames = vec![Frame::Rgb(&img); expected_cs.len()];
        write_clip(&path, 4, 3, fps, &frames);

        let (loops, decoded) = decode_gif(&path);
        assert!(matches!(loops, LoopCount::Infinite));
        assert_eq!(decoded.len(), expected_cs.len(), "fps {fps}");
        let mut total_ms = 0.0;
        for (i, (frame, &cs)) in decoded.iter().zip(expected_cs).enumerate() {
            assert_eq!(delay_ms(frame), f64::from(cs) * 10.0, "fps {fps} frame {i}");
            total_ms += delay_ms(frame);
            let exact_ms = (i + 1) as f64 * 1000.0 / fps;
            assert!((total_ms - exact_ms).abs() <= 10.0, "fps {fps} after {i}");
        }
    }
}

#[test]
fn gif_loops_forever_via_netscape_extension() {
    let dir = TempDir::new("gif-loop");
    let path = dir.path("loop.gif");
    let m = mask(6, 4);
    write_clip(&path, 6, 4, 10.0, &[Frame::Gray(&m), Frame::Gray(&m)]);
    let bytes = fs::read(&path).expect("read gif");
    // Application extension NETSCAPE2.0, sub-block 1, loop count 0 = forever.
    let looping = b"NETSCAPE2.0\x03\x01\x00\x00";
    assert!(bytes.windows(looping.len()).any(|w| w == looping));
    assert_eq!(bytes.last(), Some(&0x3B), "GIF trailer");
}

#[test]
fn gif_masks_exact_and_rgb_close() {
    let dir = TempDir::new("gif-content");
    let path = dir.path("content.GIF");
    let (w, h) = (128, 96);
    let m = mask(w, h);
    let ramp = GrayImage::from_fn(w, h, |x, y| Luma([((x * 2 + y) % 256) as u8]));
    let flats = RgbImage::from_fn(w, h, |x, y| match (x * 3 / w, y * 2 / h) {
        (0, 0) => Rgb([255, 0, 0]),
        (1, 0) => Rgb([0, 160, 80]),
        (2, 0) => Rgb([20, 40, 250]),
        (0, _) => Rgb([255, 255, 255]),
        (1, _) => Rgb([0, 0, 0]),
        _ => Rgb([128, 128, 128]),
    });
    // Smooth shading, like a render: many colours, but on a 2D ramp.
    let rich = RgbImage::from_fn(w, h, |x, y| {
        Rgb([(x * 255 / (w - 1)) as u8, (y * 255 / (h - 1)) as u8, 96])
    });
    let distinct: std::collections::HashSet<_> = rich.pixels().collect();
    assert!(distinct.len() > 256, "the rich frame needs quantising");
    let frames = [
        Frame::Rgb(&flats),
        Frame::Gray(&m),
        Frame::Rgb(&rich),
        Frame::Gray(&ramp),
    ];
    write_clip(&path, w, h, 30.0, &frames);
    assert_eq!(dir.files(), ["content.GIF"]);

    let (_, decoded) = decode_gif(&path);
    assert_eq!(decoded.len(), 4);
    let rgb: Vec<RgbImage> = decoded
        .into_iter()
        .map(|f| DynamicImage::ImageRgba8(f.into_buffer()).into_rgb8())
        .collect();

    for (got, want) in rgb[0].pixels().zip(flats.pixels()) {
        for (g, w) in got.0.iter().zip(want.0) {
            assert!(g.abs_diff(w) <= 2, "flat colour {got:?} vs {want:?}");
        }
    }
    for (gray_frame, want) in [(&rgb[1], &m), (&rgb[3], &ramp)] {
        for (got, want) in gray_frame.pixels().zip(want.pixels()) {
            assert_eq!(got.0, [want[0]; 3], "gray frames decode exactly");
        }
    }
    let total_error: u64 = rgb[2]
        .as_raw()
        .iter()
        .zip(rich.as_raw())
        .map(|(&g, &w)| u64::from(g.abs_diff(w)))
        .sum();
    let mean_error = total_error as f64 / rich.as_raw().len() as f64;
    // NeuQuant at the writer's speed gives about 5.6 here; a broken palette
    // or index mapping gives tens.
    assert!(mean_error < 8.0, "quantised frame mean error {mean_error}");
}

/// Times the GIF writer on a 320×240, 120-frame clip with many colours per
/// frame. Run with
/// `cargo test --release --test clip_write -- --ignored --nocapture gif_speed`.
#[test]
#[ignore = "timing; run in release mode"]
fn gif_speed_320x240_120_frames() {
    let dir = TempDir::new("gif-speed");
    let path = dir.path("speed.gif");
    let (w, h) = (320, 240);
    let frames: Vec<RgbImage> = (0..120u32)
        .map(|t| {
            RgbImage::from_fn(w, h, |x, y| {
                // Shaded gradients moving over time, plus pixel noise.
                let noise = (x.wrapping_mul(73_856_093) ^ y.wrapping_mul(19_349_663) ^ t)
                    .wrapping_mul(83_492_791)
                    >> 28;
                Rgb([
                    ((x + 2 * t) % 256) as u8,
                    ((y * 255 / h + t) % 256) as u8,
                    ((x + y + noise) % 256) as u8,
                ])
            })
        })
        .collect();
    let start = Instant::now();
    let mut writer = create(&path, w, h, 30.0).expect("create");
    for frame in &frames {
        writer.push(Frame::Rgb(frame)).expect("push");
    }
    writer.finish().expect("finish");
    let elapsed = start.elapsed();
    let size = fs::metadata(&path).expect("gif written").len();
    let (_, decoded) = decode_gif(&path);
    assert_eq!(decoded.len(), frames.len());
    let mut total_error = 0_u64;
    for (got, want) in decoded.into_iter().zip(&frames) {
        let got = DynamicImage::ImageRgba8(got.into_buffer()).into_rgb8();
        total_error += got
            .as_raw()
            .iter()
            .zip(want.as_raw())
            .map(|(&g, &w)| u64::from(g.abs_diff(w)))
            .sum::<u64>();
    }
    let mean_error = total_error as f64 / (frames.len() * frames[0].as_raw().len()) as f64;
    println!("GIF 320x240x120: {elapsed:.2?}, {size} bytes, mean abs error {mean_error:.2}");
}

// ---------------------------------------------------------------- errors

#[test]
fn errors_can_cross_threads() {
    fn assert_send_sync<T: Send + Sync + 'static>() {}
    assert_send_sync::<ClipWriteError>();
}

#[test]
fn unknown_or_missing_extension_is_rejected() {
    let dir = TempDir::new("ext");
    for name in ["clip.avi", "clip"] {
        let path = dir.path(name);
        let err = create(&path, 4, 4, 30.0).err().expect("unsupported format");
        let message = err.to_string();
        assert!(
            matches!(err, ClipWriteError::UnsupportedExtension { .. }),
            "{message}"
        );
        assert!(message.contains(name), "{message}");
        assert!(message.contains(".y4m, .zip, .tar, .gif"), "{message}");
        assert!(!message.contains('\n'));
    }
    let message = create(&dir.path("clip.avi"), 4, 4, 30.0)
        .err()
        .unwrap()
        .to_string();
    assert!(
        message.contains("unsupported extension \".avi\""),
        "{message}"
    );
    assert!(dir.files().is_empty(), "nothing created");

    assert_eq!(
        ClipFormat::from_path(Path::new("a/b.ZiP")).ok(),
        Some(ClipFormat::ZipPng)
    );
    assert_eq!(
        ClipFormat::from_path(Path::new("x.Gif")).ok(),
        Some(ClipFormat::Gif)
    );
}

#[test]
fn wrong_frame_size_is_rejected_and_writer_continues() {
    let dir = TempDir::new("size");
    let path = dir.path("clip.zip");
    let good = flat(8, 6, [1, 2, 3]);
    let bad = flat(6, 8, [1, 2, 3]);
    let bad_mask = mask(8, 5);
    let mut writer = create(&path, 8, 6, 30.0).expect("create");
    writer.push(Frame::Rgb(&good)).expect("good frame");
    let err = writer.push(Frame::Rgb(&bad)).expect_err("wrong size");
    let message = err.to_string();
    assert!(
        matches!(
            err,
            ClipWriteError::FrameSize {
                index: 1,
                expected: (8, 6),
                actual: (6, 8),
                ..
            }
        ),
        "{message}"
    );
    assert!(message.contains("is 6x8, but the clip is 8x6"), "{message}");
    assert!(message.contains("clip.zip"), "{message}");
    assert!(writer.push(Frame::Gray(&bad_mask)).is_err());
    assert_eq!(writer.frames_written(), 1);
    writer.push(Frame::Rgb(&good)).expect("still usable");
    writer.finish().expect("finish");
    let archive = zip::ZipArchive::new(Cursor::new(fs::read(&path).unwrap())).unwrap();
    assert_eq!(archive.len(), 2);
}

#[test]
fn unwritable_directory_fails_cleanly() {
    let dir = TempDir::new("unwritable");
    // A directory that does not exist cannot be written to, even by root.
    let path = dir.path("missing/sub/clip.gif");
    let err = create(&path, 4, 4, 30.0).err().expect("cannot create");
    let message = err.to_string();
    assert!(
        matches!(
            err,
            ClipWriteError::Io {
                action: "create",
                ..
            }
        ),
        "{message}"
    );
    assert!(message.starts_with("cannot create "), "{message}");
    assert!(message.contains("clip.gif.tmp"), "{message}");

    // A path whose parent is a file fails the same way.
    fs::write(dir.path("file"), b"x").unwrap();
    let message = create(&dir.path("file/clip.y4m"), 4, 4, 30.0)
        .err()
        .expect("parent is a file")
        .to_string();
    assert!(message.contains("cannot create"), "{message}");
}

#[test]
fn invalid_parameters_are_rejected() {
    let dir = TempDir::new("params");
    let path = dir.path("clip.gif");
    for fps in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let err = create(&path, 4, 4, fps).err().expect("bad fps");
        assert!(
            matches!(err, ClipWriteError::InvalidFrameRate { .. }),
            "{err}"
        );
        assert!(err.to_string().contains("invalid frame rate"), "{err}");
    }
    // GIF delays stop at 655.35 s; other formats take slow rates.
    let err = create(&path, 4, 4, 0.001).err().expect("too slow for GIF");
    assert!(err.to_string().contains("655.35 s"), "{err}");
    assert!(create(&dir.path("slow.y4m"), 4, 4, 0.001).is_ok());

    for (w, h) in [(0, 4), (4, 0)] {
        let err = create(&path, w, h, 30.0).err().expect("empty size");
        assert!(matches!(err, ClipWriteError::InvalidSize { .. }), "{err}");
    }
    let err = create(&path, 70_000, 4, 30.0)
        .err()
        .expect("too wide for GIF");
    assert!(err.to_string().contains("65535"), "{err}");
    assert!(dir.files().is_empty(), "{:?}", dir.files());
}

#[test]
fn unfinished_or_empty_clips_leave_no_file() {
    let dir = TempDir::new("cleanup");
    for format in ClipFormat::ALL {
        let path = dir.path(&format!("dropped.{}", format.extension()));
        let img = flat(4, 4, [9, 9, 9]);
        let mut writer = create(&path, 4, 4, 30.0).expect("create");
        writer.push(Frame::Rgb(&img)).expect("push");
        assert_eq!(dir.files().len(), 1, "only the temporary file exists");
        drop(writer);
        assert!(dir.files().is_empty(), "{format:?}: {:?}", dir.files());

        let path = dir.path(&format!("empty.{}", format.extension()));
        let err = create(&path, 4, 4, 30.0)
            .unwrap()
            .finish()
            .expect_err("no frames");
        assert!(matches!(err, ClipWriteError::NoFrames { .. }), "{err}");
        assert!(err.to_string().contains("no frames"), "{err}");
        assert!(dir.files().is_empty(), "{format:?}: {:?}", dir.files());
    }
}

#[test]
fn finishing_replaces_an_existing_file() {
    let dir = TempDir::new("replace");
    let path = dir.path("clip.tar");
    fs::write(&path, b"old contents").unwrap();
    let img = flat(3, 3, [5, 6, 7]);
    write_clip(&path, 3, 3, 30.0, &[Frame::Rgb(&img)]);
    assert_eq!(parse_tar(&fs::read(&path).unwrap()).len(), 1);
    assert_eq!(dir.files(), ["clip.tar"]);
}

#[test]
fn writers_can_move_to_another_thread() {
    let dir = TempDir::new("thread");
    let path = dir.path("clip.y4m");
    let writer: Box<dyn ClipWriter> = create(&path, 4, 4, 30.0).unwrap();
    let handle = std::thread::spawn(move || {
        let mut writer = writer;
        let img = flat(4, 4, [1, 1, 1]);
        writer.push(Frame::Rgb(&img)).unwrap();
        writer.finish()
    });
    handle.join().unwrap().unwrap();
    assert_eq!(open_y4m(&path).read_frame().unwrap().get_y_plane(), [1; 16]);
}

/// `<path>.tmp` pointed at `/dev/full` makes every flush fail with ENOSPC.
#[cfg(target_os = "linux")]
#[test]
fn io_errors_stop_the_writer_and_remove_the_temporary_file() {
    if !Path::new("/dev/full").exists() {
        eprintln!("skipped: no /dev/full");
        return;
    }
    let dir = TempDir::new("io-error");
    let big = colour_mix(256, 256);
    for format in ClipFormat::ALL {
        let name = format!("full.{}", format.extension());
        let path = dir.path(&name);
        std::os::unix::fs::symlink("/dev/full", dir.path(&format!("{name}.tmp"))).unwrap();
        let mut writer = create(&path, 256, 256, 30.0).expect("create");
        // Pushes succeed until the writer's buffer has to go to the disk.
        let first = (0..100)
            .find_map(|_| writer.push(Frame::Rgb(&big)).err())
            .expect("disk full within 100 frames");
        let accepted = writer.frames_written();
        let message = first.to_string();
        assert!(matches!(first, ClipWriteError::Stopped { .. }), "{message}");
        assert!(message.contains("cannot write"), "{message}");
        assert!(message.contains(&format!("{name}.tmp")), "{message}");
        assert!(!message.contains('\n'), "{message}");
        assert!(dir.files().is_empty(), "{format:?}: {:?}", dir.files());

        let again = writer.push(Frame::Rgb(&big)).expect_err("stopped");
        assert_eq!(again.to_string(), message, "{format:?}");
        assert_eq!(writer.frames_written(), accepted);
        let at_finish = writer.finish().expect_err("stopped");
        assert_eq!(at_finish.to_string(), message, "{format:?}");
    }

    // A small frame stays in the buffer: the error surfaces at finish.
    let path = dir.path("late.y4m");
    std::os::unix::fs::symlink("/dev/full", dir.path("late.y4m.tmp")).unwrap();
    let small = flat(4, 4, [1, 2, 3]);
    let mut writer = create(&path, 4, 4, 30.0).expect("create");
    writer.push(Frame::Rgb(&small)).expect("buffered");
    let err = writer.finish().expect_err("disk full at flush");
    assert!(err.to_string().starts_with("cannot finish "), "{err}");
    assert!(dir.files().is_empty(), "{:?}", dir.files());
}
