//! Real-file tests of the built-in MP4/AVI demuxers and the H.264 / MJPEG decoders.
//! The files live in `../shared/data/video` (see its README); each test skips with a
//! printed reason when that folder is absent.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use monocap::clip::{avi, mp4, DecodeError, FrameSource, Limits};

fn video_dir() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/video");
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!(
            "skipped: {} is absent (real video files not available)",
            dir.display()
        );
        None
    }
}

type Opener = fn(&Path, &Limits) -> Result<Box<dyn FrameSource>, DecodeError>;
type Prober = fn(&Path, &Limits) -> Result<monocap::clip::ClipInfo, DecodeError>;

fn formats(name: &str) -> (Opener, Prober) {
    if name.ends_with(".avi") {
        (avi::open, avi::probe)
    } else {
        (mp4::open, mp4::probe)
    }
}

fn psnr(a: &image::RgbImage, b: &image::RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions());
    let se: f64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(&x, &y)| {
            let d = f64::from(x) - f64::from(y);
            d * d
        })
        .sum();
    let mse = se / a.as_raw().len() as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0f64 * 255.0 / mse).log10()
    }
}

/// Reference PNGs for `file`: `(frame index, path)`.
fn references(dir: &Path, file: &str) -> Vec<(usize, PathBuf)> {
    let stem = file.rsplit_once('.').map_or(file, |(s, _)| s);
    let ext = file.rsplit_once('.').map_or("", |(_, e)| e);
    let mut out = Vec::new();
    let Ok(entries) = std::fs::read_dir(dir.join("ref")) else {
        return out;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        for prefix in [format!("{stem}_frame"), format!("{stem}_{ext}_frame")] {
            if let Some(rest) = name
                .strip_prefix(&prefix)
                .and_then(|r| r.strip_suffix(".png"))
            {
                if let Ok(i) = rest.parse::<usize>() {
                    out.push((i, e.path()));
                }
            }
        }
    }
    out.sort();
    out
}

const FILES: [&str; 5] = [
    "vtest.mp4",
    "vtest.avi",
    "lucia_h264_high_bframes.mp4",
    "dance-twirl_h264_baseline.mp4",
    "tennis_mjpeg.avi",
];

/// Decodes every frame of every file: the count and size match the probe, and the
/// frames with an FFmpeg reference are within 35 dB PSNR of it.
#[test]
fn counts_sizes_and_pixels_match() {
    let Some(dir) = video_dir() else { return };
    let limits = Limits::default();
    for file in FILES {
        let path = dir.join(file);
        let (open, probe) = formats(file);
        let info = probe(&path, &limits).unwrap_or_else(|e| panic!("probe {file}: {e}"));
        println!("{file}: {info:?}");
        let refs = references(&dir, file);
        let mut src = open(&path, &limits).unwrap_or_else(|e| panic!("open {file}: {e}"));
        assert_eq!(src.info(), &info);
        let t0 = Instant::now();
        let mut n = 0usize;
        while let Some(frame) = src
            .next_frame()
            .unwrap_or_else(|e| panic!("{file} frame {n}: {e}"))
        {
            assert_eq!(
                frame.dimensions(),
                (info.width, info.height),
                "{file} frame {n}"
            );
            for (_, rp) in refs.iter().filter(|(i, _)| *i == n) {
                let reference = image::open(rp).unwrap().to_rgb8();
                let p = psnr(&frame, &reference);
                println!(
                    "  {} PSNR {p:.2} dB",
                    rp.file_name().unwrap().to_string_lossy()
                );
                assert!(p >= 35.0, "{file} frame {n}: PSNR {p:.2} dB");
            }
            n += 1;
        }
        assert_eq!(
            n as u64, info.frame_count,
            "{file}: decoded frames vs probe"
        );
        let secs = t0.elapsed().as_secs_f64();
        println!(
            "  {n} frames decoded in {secs:.2} s ({:.0} frames/s, this profile)",
            n as f64 / secs
        );
    }
}

fn expect_info(dir: &Path, file: &str, w: u32, h: u32, fps: f64, frames: Option<u64>) {
    let (_, probe) = formats(file);
    let info = probe(&dir.join(file), &Limits::default()).unwrap();
    assert_eq!((info.width, info.height), (w, h), "{file}");
    assert!((info.fps - fps).abs() < 1e-6, "{file}: fps {}", info.fps);
    if let Some(n) = frames {
        assert_eq!(info.frame_count, n, "{file}");
    }
    assert!(
        (info.duration_s - info.frame_count as f64 / fps).abs() < 0.2,
        "{file}: {info:?}"
    );
}

/// What the data README states about each file.
#[test]
fn probe_matches_the_stated_formats() {
    let Some(dir) = video_dir() else { return };
    expect_info(&dir, "vtest.mp4", 480, 360, 10.0, Some(795));
    expect_info(&dir, "vtest.avi", 480, 360, 10.0, Some(795));
    expect_info(
        &dir,
        "lucia_h264_high_bframes.mp4",
        428,
        240,
        30.0,
        Some(70),
    );
    expect_info(
        &dir,
        "dance-twirl_h264_baseline.mp4",
        428,
        240,
        30.0,
        Some(90),
    );
    expect_info(&dir, "tennis_mjpeg.avi", 428, 240, 24.0, Some(70));
    for (file, codec, container) in [
        ("vtest.mp4", "h264", "mp4"),
        ("vtest.avi", "h264", "avi"),
        ("tennis_mjpeg.avi", "mjpeg", "avi"),
    ] {
        let info = formats(file).1(&dir.join(file), &Limits::default()).unwrap();
        assert_eq!(
            (info.codec.as_str(), info.container.as_str()),
            (codec, container)
        );
    }
}

/// `vtest.avi` is the same footage as `vtest.mp4`, encoded separately: its frames are
/// close to FFmpeg's frames of the MP4.
#[test]
fn vtest_avi_is_the_same_footage() {
    let Some(dir) = video_dir() else { return };
    let refs = references(&dir, "vtest.mp4");
    assert!(!refs.is_empty());
    let mut src = avi::open(&dir.join("vtest.avi"), &Limits::default()).unwrap();
    let mut n = 0;
    while let Some(frame) = src.next_frame().unwrap() {
        for (_, rp) in refs.iter().filter(|(i, _)| *i == n) {
            let p = psnr(&frame, &image::open(rp).unwrap().to_rgb8());
            println!(
                "vtest.avi frame {n} vs {}: PSNR {p:.2} dB",
                rp.file_name().unwrap().to_string_lossy()
            );
            assert!(p >= 30.0, "vtest.avi frame {n}: {p:.2} dB");
        }
        n += 1;
    }
    assert_eq!(n, 795);
}

/// B-frames come out in display order: the reference frame matches frame 10 far better
/// than its neighbours in display order.
#[test]
fn bframes_in_display_order() {
    let Some(dir) = video_dir() else { return };
    let reference = image::open(dir.join("ref/lucia_h264_high_bframes_frame0010.png"))
        .unwrap()
        .to_rgb8();
    let mut src = mp4::open(&dir.join("lucia_h264_high_bframes.mp4"), &Limits::default()).unwrap();
    let frames: Vec<_> = (0..12)
        .map(|_| src.next_frame().unwrap().unwrap())
        .collect();
    let p: Vec<f64> = frames.iter().map(|f| psnr(f, &reference)).collect();
    println!("PSNR against frame 10 of frames 8..12: {:?}", &p[8..12]);
    assert!(p[10] > p[9] + 3.0 && p[10] > p[11] + 3.0, "{p:?}");
}

#[test]
fn hevc_is_probed_but_not_decoded() {
    let Some(dir) = video_dir() else { return };
    let path = dir.join("lucia_hevc.mp4");
    let info = mp4::probe(&path, &Limits::default()).unwrap();
    assert_eq!(info.codec, "hevc");
    assert_eq!(info.container, "mp4");
    assert!(
        info.frame_count > 0 && info.width > 0 && info.fps > 0.0,
        "{info:?}"
    );
    match mp4::open(&path, &Limits::default()) {
        Err(e @ DecodeError::UnsupportedCodec { .. }) => {
            let msg = e.to_string();
            println!("{msg}");
            assert!(
                msg.contains("hevc") && msg.contains("mp4") && msg.contains("lucia_hevc.mp4"),
                "{msg}"
            );
        }
        Err(e) => panic!("wrong error: {e}"),
        Ok(_) => panic!("HEVC opened"),
    }
}

static TEMP_COUNTER: AtomicUsize = AtomicUsize::new(0);

/// A temporary file holding `bytes`, removed on drop.
struct TempFile(PathBuf);

impl TempFile {
    fn new(bytes: &[u8], ext: &str) -> Self {
        let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
        let path = std::env::temp_dir().join(format!(
            "monocap_decode_video_{}_{n}.{ext}",
            std::process::id()
        ));
        std::fs::write(&path, bytes).unwrap();
        TempFile(path)
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Probes, opens and decodes up to `max_frames`; the first error, if any.
fn exercise(path: &Path, avi_format: bool, max_frames: usize) -> Option<DecodeError> {
    let (open, probe): (Opener, Prober) = if avi_format {
        (avi::open, avi::probe)
    } else {
        (mp4::open, mp4::probe)
    };
    let limits = Limits::default();
    let _ = probe(path, &limits);
    let mut src = match open(path, &limits) {
        Ok(s) => s,
        Err(e) => return Some(e),
    };
    for _ in 0..max_frames {
        match src.next_frame() {
            Ok(Some(_)) => {}
            Ok(None) => return None,
            Err(e) => return Some(e),
        }
    }
    None
}

/// Every real file cut at several points gives `Truncated` (or `Corrupt` where the cut
/// leaves something inconsistent) from probe and open, never a panic.
#[test]
fn truncated_files_are_errors() {
    let Some(dir) = video_dir() else { return };
    for file in FILES.iter().copied().chain(["lucia_hevc.mp4"]) {
        let bytes = std::fs::read(dir.join(file)).unwrap();
        let ext = file.rsplit_once('.').unwrap().1;
        let len = bytes.len();
        for cut in [0, 7, 12, 100, 5000, len / 3, len / 2, len - 1000, len - 1] {
            let tmp = TempFile::new(&bytes[..cut], ext);
            let (_, probe) = formats(file);
            let err = probe(&tmp.0, &Limits::default()).err();
            println!(
                "{file} cut at {cut}: {}",
                err.as_ref().map_or("ok".into(), |e| e.to_string())
            );
            assert!(
                matches!(
                    err,
                    Some(
                        DecodeError::Truncated { .. }
                            | DecodeError::Corrupt { .. }
                            | DecodeError::UnknownFormat { .. }
                    )
                ),
                "{file} cut at {cut}: {err:?}"
            );
            if cut >= 100 {
                assert!(
                    matches!(err, Some(DecodeError::Truncated { .. })),
                    "{file} cut at {cut}: {err:?}"
                );
            }
            assert!(
                exercise(&tmp.0, ext == "avi", 3).is_some(),
                "{file} cut at {cut} opened"
            );
        }
    }
}

fn find(bytes: &[u8], tag: &[u8; 4]) -> usize {
    bytes
        .windows(4)
        .position(|w| w == tag)
        .unwrap_or_else(|| panic!("no {}", String::from_utf8_lossy(tag)))
}

/// Sample tables that point past the end of the file are refused before decoding.
#[test]
fn sample_tables_past_the_end_are_errors() {
    let Some(dir) = video_dir() else { return };
    for file in [
        "dance-twirl_h264_baseline.mp4",
        "vtest.mp4",
        "lucia_h264_high_bframes.mp4",
    ] {
        let bytes = std::fs::read(dir.join(file)).unwrap();
        // stco: version/flags, count, then offsets; push the last chunk far out.
        let mut patched = bytes.clone();
        let at = find(&bytes, b"stco") + 8;
        let count = u32::from_be_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
        let last = at + 4 + 4 * (count - 1);
        patched[last..last + 4].copy_from_slice(&0xFFFF_0000u32.to_be_bytes());
        let tmp = TempFile::new(&patched, "mp4");
        let err = mp4::probe(&tmp.0, &Limits::default()).unwrap_err();
        println!("{file}, stco past the end: {err}");
        assert!(matches!(
            err,
            DecodeError::Corrupt { .. } | DecodeError::Truncated { .. }
        ));
        assert!(exercise(&tmp.0, false, 3).is_some());

        // stsz: version/flags, sample_size, count, then sizes; make one enormous.
        let mut patched = bytes.clone();
        let at = find(&bytes, b"stsz") + 16;
        patched[at..at + 4].copy_from_slice(&0x7FFF_FFF0u32.to_be_bytes());
        let tmp = TempFile::new(&patched, "mp4");
        let err = mp4::probe(&tmp.0, &Limits::default()).unwrap_err();
        println!("{file}, huge stsz entry: {err}");
        assert!(matches!(
            err,
            DecodeError::Corrupt { .. } | DecodeError::Truncated { .. }
        ));

        // stsz: the count larger than the table.
        let mut patched = bytes.clone();
        let at = find(&bytes, b"stsz") + 12;
        patched[at..at + 4].copy_from_slice(&0x00FF_FFFFu32.to_be_bytes());
        let tmp = TempFile::new(&patched, "mp4");
        let err = mp4::probe(&tmp.0, &Limits::default()).unwrap_err();
        println!("{file}, stsz count past its box: {err}");
        assert!(matches!(err, DecodeError::Corrupt { .. }));
    }
}

/// A frame size over the limits is refused before anything of that size is allocated.
#[test]
fn huge_frame_sizes_are_refused() {
    let Some(dir) = video_dir() else { return };
    // MP4: the avc1 sample entry's width and height (32 bytes into the box).
    let bytes = std::fs::read(dir.join("dance-twirl_h264_baseline.mp4")).unwrap();
    let mut patched = bytes.clone();
    let stsd = find(&bytes, b"stsd");
    let at = stsd + find(&bytes[stsd..], b"avc1") - 4 + 32;
    patched[at..at + 4].copy_from_slice(&[0xFF, 0xF0, 0xFF, 0xF0]);
    let tmp = TempFile::new(&patched, "mp4");
    for err in [
        mp4::probe(&tmp.0, &Limits::default()).err(),
        mp4::open(&tmp.0, &Limits::default()).err(),
    ] {
        println!("mp4 65520×65520: {err:?}");
        assert!(matches!(err, Some(DecodeError::TooLarge { .. })));
    }
    // AVI: the strf BITMAPINFOHEADER's width and height.
    for file in ["tennis_mjpeg.avi", "vtest.avi"] {
        let bytes = std::fs::read(dir.join(file)).unwrap();
        let mut patched = bytes.clone();
        let at = find(&bytes, b"strf") + 8 + 4;
        patched[at..at + 8].copy_from_slice(&[0, 0, 0, 0x40, 0, 0, 0, 0x40]);
        let tmp = TempFile::new(&patched, "avi");
        for err in [
            avi::probe(&tmp.0, &Limits::default()).err(),
            avi::open(&tmp.0, &Limits::default()).err(),
        ] {
            println!("{file} huge: {err:?}");
            assert!(matches!(err, Some(DecodeError::TooLarge { .. })));
        }
    }
    // Tight limits on a real file.
    let small = Limits {
        max_width: 100,
        max_height: 100,
        ..Limits::default()
    };
    for file in FILES {
        let err = formats(file).1(&dir.join(file), &small).unwrap_err();
        assert!(matches!(err, DecodeError::TooLarge { .. }), "{file}: {err}");
    }
    let few = Limits {
        max_frames: 10,
        ..Limits::default()
    };
    for file in FILES {
        let err = formats(file).1(&dir.join(file), &few).unwrap_err();
        assert!(matches!(err, DecodeError::TooLarge { .. }), "{file}: {err}");
    }
}

/// Garbage is `UnknownFormat`; garbage behind a valid magic is `Corrupt` or `Truncated`.
#[test]
fn garbage_is_an_error() {
    let garbage: Vec<u8> = (0..20_000u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    let tmp = TempFile::new(&garbage, "bin");
    assert!(matches!(
        mp4::probe(&tmp.0, &Limits::default()),
        Err(DecodeError::UnknownFormat { .. })
    ));
    assert!(matches!(
        avi::probe(&tmp.0, &Limits::default()),
        Err(DecodeError::UnknownFormat { .. })
    ));
    assert!(matches!(
        mp4::open(&tmp.0, &Limits::default()),
        Err(DecodeError::UnknownFormat { .. })
    ));
    assert!(matches!(
        avi::open(&tmp.0, &Limits::default()),
        Err(DecodeError::UnknownFormat { .. })
    ));

    let mut riff = b"RIFF\xff\xff\xff\xffAVI ".to_vec();
    riff.extend_from_slice(&garbage);
    let tmp = TempFile::new(&riff, "avi");
    let err = avi::probe(&tmp.0, &Limits::default()).unwrap_err();
    println!("RIFF + garbage: {err}");
    assert!(matches!(
        err,
        DecodeError::Corrupt { .. } | DecodeError::Truncated { .. }
    ));

    let mut mp4_bytes = b"\x00\x00\x00\x10ftypisom\x00\x00\x00\x00".to_vec();
    mp4_bytes.extend_from_slice(b"\x00\x00\x01\x00moov");
    mp4_bytes.extend_from_slice(&garbage[..248]);
    let tmp = TempFile::new(&mp4_bytes, "mp4");
    let err = mp4::probe(&tmp.0, &Limits::default()).unwrap_err();
    println!("ftyp + moov of garbage: {err}");
    assert!(matches!(
        err,
        DecodeError::Corrupt { .. } | DecodeError::Truncated { .. }
    ));
}

/// Decoding speed of `vtest.mp4`; run with
/// `cargo test --release --test decode_video throughput -- --ignored --nocapture`.
#[test]
#[ignore = "a measurement: run in release with --ignored --nocapture"]
fn throughput_vtest_mp4() {
    let Some(dir) = video_dir() else { return };
    for file in ["vtest.mp4", "vtest.avi"] {
        let t0 = Instant::now();
        let mut src = formats(file).0(&dir.join(file), &Limits::default()).unwrap();
        let mut n = 0u32;
        while src.next_frame().unwrap().is_some() {
            n += 1;
        }
        let secs = t0.elapsed().as_secs_f64();
        println!(
            "{file}: {n} frames 480×360 in {secs:.3} s = {:.0} frames/s",
            f64::from(n) / secs
        );
    }
}

mod fuzz {
    use super::*;
    use proptest::prelude::*;

    fn real(file: &str) -> Option<Vec<u8>> {
        let dir = video_dir()?;
        std::fs::read(dir.join(file)).ok()
    }

    /// A mutation of a real file: byte flips (mostly in its first 100 KB: the headers and
    /// first frames) and a cut.
    fn mutate(bytes: &[u8], flips: &[(usize, u8)], cut: Option<usize>) -> Vec<u8> {
        let mut out = bytes.to_vec();
        let head = out.len().min(100_000);
        for &(at, x) in flips {
            let i = at % head;
            out[i] ^= x.max(1);
        }
        if let Some(c) = cut {
            out.truncate(c % (out.len() + 1));
        }
        out
    }

    proptest! {
        // 40 cases each by default (the whole file stays well under 30 s in the dev
        // profile); MONOCAP_FUZZ_CASES=2000 for a longer run.
        #![proptest_config(ProptestConfig {
            cases: std::env::var("MONOCAP_FUZZ_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(40),
            failure_persistence: None,
            ..ProptestConfig::default()
        })]

        #[test]
        fn random_bytes_never_panic(
            prefix in 0usize..3,
            body in proptest::collection::vec(any::<u8>(), 0..4096),
        ) {
            let mut bytes = match prefix {
                0 => Vec::new(),
                1 => b"RIFF\x00\x10\x00\x00AVI LIST".to_vec(),
                _ => b"\x00\x00\x00\x10ftypisom\x00\x00\x00\x00\x00\x00\x08\x00moov".to_vec(),
            };
            bytes.extend_from_slice(&body);
            let tmp = TempFile::new(&bytes, "bin");
            let _ = exercise(&tmp.0, true, 3);
            let _ = exercise(&tmp.0, false, 3);
        }

        #[test]
        fn mutated_mp4_never_panics(
            which in 0usize..2,
            flips in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..12),
            cut in proptest::option::of(any::<usize>()),
        ) {
            // moov last (flips hit the frames) and moov first (flips hit the tables too).
            let file = ["lucia_h264_high_bframes.mp4", "dance-twirl_h264_baseline.mp4"][which];
            let Some(bytes) = real(file) else { return Ok(()) };
            let tmp = TempFile::new(&mutate(&bytes, &flips, cut), "mp4");
            let _ = exercise(&tmp.0, false, 4);
        }

        #[test]
        fn mutated_avi_never_panics(
            which in 0usize..2,
            flips in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..12),
            cut in proptest::option::of(any::<usize>()),
        ) {
            let file = ["tennis_mjpeg.avi", "vtest.avi"][which];
            let Some(bytes) = real(file) else { return Ok(()) };
            let tmp = TempFile::new(&mutate(&bytes, &flips, cut), "avi");
            let _ = exercise(&tmp.0, true, 4);
        }
    }
}
