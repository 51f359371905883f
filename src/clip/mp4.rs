//! MP4 / QuickTime (ISO BMFF) with H.264 video, demuxed with `re_mp4`.
//!
//! The file is never read whole: the top-level boxes are walked by their headers, the
//! `moov` box is parsed (its size is capped), and each sample's bytes are read by offset
//! and size from the file when its turn comes. What a source keeps between calls: the
//! open file, one `(offset, size)` pair per video sample (16 bytes a frame), and the
//! H.264 decoder with its reorder buffer (see [`crate::clip::h264`]).
//!
//! `re_mp4` indexes its sample tables without checking them, so they are checked here
//! first (chunk offsets cover every chunk, `stts`/`ctts` runs cover every sample, `stss`
//! numbers from 1), and any panic left inside it is caught and reported as
//! [`DecodeError::Corrupt`].

use std::collections::VecDeque;
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

use image::RgbImage;
use re_mp4::{BoxHeader, BoxType, MoovBox, ReadBox, StblBox, StsdBoxContent, TrackKind};

use super::h264::{H264Decoder, H264Error};
use super::{ClipInfo, DecodeError, FrameSource, Limits};

/// Largest `moov` box read into memory.
const MAX_MOOV_BYTES: u64 = 64 << 20;
/// Most samples any one track may have (audio tracks included), so the tables stay small.
const MAX_TRACK_SAMPLES: u64 = 4 << 20;
/// Largest single video sample (one compressed frame).
const MAX_SAMPLE_BYTES: u64 = 64 << 20;

/// The container's description of a clip; `open` refuses it unless it is H.264.
pub fn probe(path: &Path, limits: &Limits) -> Result<ClipInfo, DecodeError> {
    Ok(demux(path, limits)?.info)
}

/// Opens an MP4 for streaming decode (H.264 only).
pub fn open(path: &Path, limits: &Limits) -> Result<Box<dyn FrameSource>, DecodeError> {
    let d = demux(path, limits)?;
    let Some(avc) = d.avc else {
        return Err(DecodeError::UnsupportedCodec {
            path: path.to_path_buf(),
            container: "mp4".into(),
            codec: d.info.codec,
        });
    };
    let sps: Vec<&[u8]> = avc.sps.iter().map(Vec::as_slice).collect();
    let pps: Vec<&[u8]> = avc.pps.iter().map(Vec::as_slice).collect();
    let decoder = H264Decoder::with_parameter_sets(limits.max_width, limits.max_height, &sps, &pps)
        .map_err(|e| h264_error(path, e))?;
    Ok(Box::new(Mp4Source {
        path: path.to_path_buf(),
        info: d.info,
        file: d.file,
        samples: d.samples,
        next: 0,
        length_size: avc.length_size,
        decoder,
        buf: Vec::new(),
        flushed: VecDeque::new(),
        finished: false,
    }))
}

pub(crate) fn h264_error(path: &Path, e: H264Error) -> DecodeError {
    match e {
        H264Error::TooLarge { width, height } => DecodeError::TooLarge {
            path: path.to_path_buf(),
            what: format!("decoded frame size {width}×{height} is over the limit"),
        },
        H264Error::Corrupt(what) => DecodeError::Corrupt {
            path: path.to_path_buf(),
            what,
        },
    }
}

struct Avc {
    sps: Vec<Vec<u8>>,
    pps: Vec<Vec<u8>>,
    length_size: usize,
}

struct Demuxed {
    info: ClipInfo,
    avc: Option<Avc>,
    file: File,
    /// `(offset, size)` of each video sample, in decode order.
    samples: Vec<(u64, u64)>,
}

fn mp4_err(path: &Path, e: re_mp4::Error) -> DecodeError {
    match e {
        re_mp4::Error::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            DecodeError::truncated(path, "a box is cut off")
        }
        other => DecodeError::corrupt(path, format!("MP4 structure: {other}")),
    }
}

/// Runs `f`, turning a panic inside `re_mp4` into `Corrupt`.
fn guarded<T>(path: &Path, f: impl FnOnce() -> Result<T, re_mp4::Error>) -> Result<T, DecodeError> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r.map_err(|e| mp4_err(path, e)),
        Err(_) => Err(DecodeError::corrupt(path, "inconsistent MP4 sample tables")),
    }
}

/// Walks all the top-level boxes (headers only); returns the offset and size of `moov`.
fn find_moov(path: &Path, file: &mut File, len: u64) -> Result<(u64, u64), DecodeError> {
    let mut pos = 0u64;
    let mut first = true;
    let mut moov = None;
    while pos < len {
        let mut head = [0u8; 8];
        if len - pos < 8 {
            return Err(DecodeError::truncated(
                path,
                format!("box header cut off at byte {pos}"),
            ));
        }
        file.seek(SeekFrom::Start(pos))
            .map_err(|e| DecodeError::io(path, e))?;
        file.read_exact(&mut head)
            .map_err(|e| DecodeError::io(path, e))?;
        let kind = [head[4], head[5], head[6], head[7]];
        if first {
            const KNOWN: [&[u8; 4]; 7] = [
                b"ftyp", b"moov", b"mdat", b"free", b"skip", b"wide", b"styp",
            ];
            if !KNOWN.iter().any(|k| **k == kind) {
                return Err(DecodeError::UnknownFormat {
                    path: path.to_path_buf(),
                    what: "no MP4 box at the start of the file".into(),
                });
            }
            first = false;
        }
        let mut size = u64::from(u32::from_be_bytes([head[0], head[1], head[2], head[3]]));
        if size == 1 {
            let mut large = [0u8; 8];
            if len - pos < 16 {
                return Err(DecodeError::truncated(
                    path,
                    format!("box header cut off at byte {pos}"),
                ));
            }
            file.read_exact(&mut large)
                .map_err(|e| DecodeError::io(path, e))?;
            size = u64::from_be_bytes(large);
            if size < 16 {
                return Err(DecodeError::corrupt(
                    path,
                    format!("box at byte {pos} has size {size}"),
                ));
            }
        } else if size == 0 {
            size = len - pos;
        } else if size < 8 {
            return Err(DecodeError::corrupt(
                path,
                format!("box at byte {pos} has size {size}"),
            ));
        }
        let end = pos
            .checked_add(size)
            .ok_or_else(|| DecodeError::corrupt(path, "box size overflows"))?;
        let name = String::from_utf8_lossy(&kind).into_owned();
        if end > len {
            let what = format!(
                "{name} box at byte {pos} declares {size} bytes, only {} are in the file",
                len - pos
            );
            return Err(DecodeError::truncated(path, what));
        }
        if &kind == b"moov" {
            if size > MAX_MOOV_BYTES {
                return Err(DecodeError::TooLarge {
                    path: path.to_path_buf(),
                    what: format!("moov box of {size} bytes"),
                });
            }
            if moov.is_some() {
                return Err(DecodeError::corrupt(path, "two moov boxes"));
            }
            moov = Some((pos, size));
        }
        pos = end;
    }
    // Every top-level box is whole (a box cut off by the end of the file is `Truncated`).
    if let Some(m) = moov {
        return Ok(m);
    }
    Err(DecodeError::truncated(
        path,
        "no moov box (the index) in the file",
    ))
}

/// Checks what `re_mp4` indexes without checking, for one track's sample tables.
fn check_stbl(path: &Path, stbl: &StblBox) -> Result<(), DecodeError> {
    let stsz = &stbl.stsz;
    let n = u64::from(stsz.sample_count);
    if stsz.sample_size == 0 && stsz.sample_sizes.len() as u64 != n {
        return Err(DecodeError::corrupt(
            path,
            "stsz lists fewer sizes than samples",
        ));
    }
    if n > MAX_TRACK_SAMPLES {
        return Err(DecodeError::TooLarge {
            path: path.to_path_buf(),
            what: format!("a track of {n} samples"),
        });
    }
    if n == 0 {
        return Ok(());
    }
    let chunks = match (&stbl.stco, &stbl.co64) {
        (Some(stco), _) => stco.entries.len() as u64,
        (None, Some(co64)) => co64.entries.len() as u64,
        (None, None) => {
            return Err(DecodeError::corrupt(
                path,
                "no chunk offset table (stco/co64)",
            ))
        }
    };
    let stsc = &stbl.stsc.entries;
    if stsc.is_empty() {
        return Err(DecodeError::corrupt(
            path,
            "empty sample-to-chunk table (stsc)",
        ));
    }
    let mut prev = 0u32;
    for e in stsc {
        if e.first_chunk <= prev {
            return Err(DecodeError::corrupt(
                path,
                "stsc chunk numbers do not increase from 1",
            ));
        }
        prev = e.first_chunk;
    }
    // The chunk each sample lands in, as re_mp4 walks it.
    let mut chunk = 1u64;
    let mut run = 0usize;
    let mut last_in_chunk = u64::from(stsc[0].samples_per_chunk);
    let mut last_chunk_in_run = stsc
        .get(1)
        .map_or(u64::MAX, |e| u64::from(e.first_chunk) - 1);
    for s in 1..n {
        if s >= last_in_chunk {
            chunk += 1;
            if chunk > last_chunk_in_run {
                run += 1;
                last_chunk_in_run = stsc
                    .get(run + 1)
                    .map_or(u64::MAX, |e| u64::from(e.first_chunk) - 1);
            }
            last_in_chunk += u64::from(stsc[run].samples_per_chunk);
        }
        if chunk > chunks {
            return Err(DecodeError::corrupt(
                path,
                format!("sample {s} is in chunk {chunk}, but only {chunks} chunk offsets"),
            ));
        }
    }
    // stts: a run index per sample, advancing when the sample passes the run's end.
    let runs_needed = |counts: &mut dyn Iterator<Item = u64>, strict: bool| -> bool {
        let counts: Vec<u64> = counts.collect();
        let mut idx: i64 = -1;
        let mut last: i64 = -1;
        for s in 0..n as i64 {
            let passes = if strict { s > last } else { s >= last };
            if passes {
                idx += 1;
                if last < 0 {
                    last = 0;
                }
                match counts.get(idx as usize) {
                    Some(&c) => last += c as i64,
                    None => return false,
                }
            }
        }
        true
    };
    if !runs_needed(
        &mut stbl.stts.entries.iter().map(|e| u64::from(e.sample_count)),
        true,
    ) {
        return Err(DecodeError::corrupt(
            path,
            "time-to-sample table (stts) covers fewer samples than the track",
        ));
    }
    if let Some(ctts) = &stbl.ctts {
        if !runs_needed(
            &mut ctts.entries.iter().map(|e| u64::from(e.sample_count)),
            false,
        ) {
            return Err(DecodeError::corrupt(
                path,
                "composition offsets (ctts) cover fewer samples than the track",
            ));
        }
    }
    if let Some(stss) = &stbl.stss {
        if stss.entries.contains(&0) {
            return Err(DecodeError::corrupt(
                path,
                "sync sample table (stss) has sample number 0",
            ));
        }
    }
    Ok(())
}

fn demux(path: &Path, limits: &Limits) -> Result<Demuxed, DecodeError> {
    let mut file = File::open(path).map_err(|e| DecodeError::io(path, e))?;
    let len = file.metadata().map_err(|e| DecodeError::io(path, e))?.len();
    let (moov_pos, moov_size) = find_moov(path, &mut file, len)?;

    // Parse the moov alone first and check its tables, so re_mp4 never indexes past them.
    file.seek(SeekFrom::Start(moov_pos))
        .map_err(|e| DecodeError::io(path, e))?;
    let moov_bytes = {
        let mut b = vec![0u8; moov_size as usize];
        file.read_exact(&mut b)
            .map_err(|e| DecodeError::io(path, e))?;
        b
    };
    let moov = guarded(path, || {
        let mut cur = std::io::Cursor::new(&moov_bytes[..]);
        let header = BoxHeader::read(&mut cur)?;
        if header.name != BoxType::MoovBox {
            return Err(re_mp4::Error::InvalidData("moov box expected"));
        }
        MoovBox::read_box(&mut cur, header.size)
    })?;
    drop(moov_bytes);
    for trak in &moov.traks {
        check_stbl(path, &trak.mdia.minf.stbl)?;
    }
    drop(moov);

    file.seek(SeekFrom::Start(0))
        .map_err(|e| DecodeError::io(path, e))?;
    let mp4 = guarded(path, || re_mp4::Mp4::read(BufReader::new(&mut file), len))?;

    let Some(track) = mp4
        .tracks()
        .values()
        .find(|t| t.kind == Some(TrackKind::Video))
    else {
        return Err(DecodeError::corrupt(path, "no video track"));
    };
    let trak = track.trak(&mp4);
    let stbl = &trak.mdia.minf.stbl;
    let (codec, avc, entry_w, entry_h) = match &stbl.stsd.contents {
        StsdBoxContent::Avc1(b) => {
            let c = &b.avcc.contents;
            let avc = Avc {
                sps: c
                    .sequence_parameter_sets
                    .iter()
                    .map(|n| n.bytes.clone())
                    .collect(),
                pps: c
                    .picture_parameter_sets
                    .iter()
                    .map(|n| n.bytes.clone())
                    .collect(),
                length_size: usize::from(c.length_size_minus_one & 3) + 1,
            };
            ("h264".to_string(), Some(avc), b.width, b.height)
        }
        StsdBoxContent::Hvc1(b) | StsdBoxContent::Hev1(b) => {
            ("hevc".to_string(), None, b.width, b.height)
        }
        StsdBoxContent::Av01(b) => ("av1".to_string(), None, b.width, b.height),
        StsdBoxContent::Vp09(b) => ("vp9".to_string(), None, b.width, b.height),
        StsdBoxContent::Vp08(b) => ("vp8".to_string(), None, b.width, b.height),
        StsdBoxContent::Unknown(fourcc) => (fourcc.to_string(), None, 0, 0),
        _ => ("unknown".to_string(), None, 0, 0),
    };
    let (mut width, mut height) = (u32::from(entry_w), u32::from(entry_h));
    if width == 0 || height == 0 {
        (width, height) = (u32::from(track.width), u32::from(track.height));
    }
    limits.check_size(path, width, height)?;

    let frame_count = track.samples.len() as u64;
    if frame_count > limits.max_frames {
        return Err(DecodeError::TooLarge {
            path: path.to_path_buf(),
            what: format!("{frame_count} frames (the limit is {})", limits.max_frames),
        });
    }
    if frame_count == 0 {
        return Err(DecodeError::corrupt(path, "the video track has no samples"));
    }
    let mut samples = Vec::with_capacity(track.samples.len());
    for (i, s) in track.samples.iter().enumerate() {
        if s.size > MAX_SAMPLE_BYTES {
            return Err(DecodeError::corrupt(
                path,
                format!("sample {i} claims {} bytes", s.size),
            ));
        }
        let end = s
            .offset
            .checked_add(s.size)
            .ok_or_else(|| DecodeError::corrupt(path, "sample offset overflows"))?;
        if end > len {
            let what = format!(
                "sample {i} (bytes {}..{end}) lies past the end of the {len}-byte file",
                s.offset
            );
            return Err(if s.offset < len && moov_pos < s.offset {
                DecodeError::truncated(path, what)
            } else {
                DecodeError::corrupt(path, what)
            });
        }
        samples.push((s.offset, s.size));
    }

    // Frame rate from the commonest sample duration (stts), as players report it.
    let timescale = u64::from(trak.mdia.mdhd.timescale);
    let commonest = stbl
        .stts
        .entries
        .iter()
        .filter(|e| e.sample_delta > 0)
        .max_by_key(|e| e.sample_count)
        .map(|e| e.sample_delta);
    let fps = match commonest {
        Some(delta) if timescale > 0 => timescale as f64 / f64::from(delta),
        _ => 0.0,
    };
    let duration_s = if timescale > 0 && trak.mdia.mdhd.duration > 0 {
        trak.mdia.mdhd.duration as f64 / timescale as f64
    } else if fps > 0.0 {
        frame_count as f64 / fps
    } else {
        0.0
    };
    let info = ClipInfo {
        container: "mp4".into(),
        codec,
        width,
        height,
        fps,
        frame_count,
        duration_s,
        is_mask: false,
    };
    drop(mp4);
    Ok(Demuxed {
        info,
        avc,
        file,
        samples,
    })
}

struct Mp4Source {
    path: PathBuf,
    info: ClipInfo,
    file: File,
    samples: Vec<(u64, u64)>,
    next: usize,
    length_size: usize,
    decoder: H264Decoder,
    buf: Vec<u8>,
    /// Frames released by the final flush, in display order.
    flushed: VecDeque<RgbImage>,
    finished: bool,
}

impl Mp4Source {
    /// Every frame has the size `info` promises.
    fn checked(&self, frame: RgbImage) -> Result<Option<RgbImage>, DecodeError> {
        if frame.dimensions() != (self.info.width, self.info.height) {
            let (w, h) = frame.dimensions();
            return Err(DecodeError::corrupt(
                &self.path,
                format!(
                    "a decoded frame is {w}×{h}, the container says {}×{}",
                    self.info.width, self.info.height
                ),
            ));
        }
        Ok(Some(frame))
    }
}

impl FrameSource for Mp4Source {
    fn info(&self) -> &ClipInfo {
        &self.info
    }

    fn next_frame(&mut self) -> Result<Option<RgbImage>, DecodeError> {
        loop {
            if let Some(f) = self.flushed.pop_front() {
                return self.checked(f);
            }
            if let Some(&(offset, size)) = self.samples.get(self.next) {
                self.next += 1;
                self.buf.resize(size as usize, 0);
                self.file
                    .seek(SeekFrom::Start(offset))
                    .map_err(|e| DecodeError::io(&self.path, e))?;
                self.file.read_exact(&mut self.buf).map_err(|e| {
                    if e.kind() == std::io::ErrorKind::UnexpectedEof {
                        DecodeError::truncated(
                            &self.path,
                            format!("sample {} is cut off", self.next - 1),
                        )
                    } else {
                        DecodeError::io(&self.path, e)
                    }
                })?;
                let frame = self
                    .decoder
                    .decode_length_prefixed(&self.buf, self.length_size)
                    .map_err(|e| h264_error(&self.path, e))?;
                if let Some(f) = frame {
                    return self.checked(f);
                }
                continue;
            }
            if self.finished {
                return Ok(None);
            }
            self.finished = true;
            self.flushed = self
                .decoder
                .flush()
                .map_err(|e| h264_error(&self.path, e))?
                .into();
        }
    }
}
