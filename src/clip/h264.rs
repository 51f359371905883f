//! H.264 decoding over OpenH264 (the crate `openh264`, built from its bundled C source):
//! Constrained Baseline, Main and High (CABAC, B-frames), 8-bit 4:2:0.
//!
//! Containers hand over one access unit at a time, either in Annex B (start codes, as AVI
//! usually stores it) or length-prefixed as MP4 stores it; [`avcc_to_annex_b`] converts the
//! latter, and [`H264Decoder::with_parameter_sets`] feeds the SPS/PPS of an MP4 `avcC`
//! record before the first sample.
//!
//! Display order: OpenH264 keeps its own reorder buffer for B-frames (pictures are held
//! until their picture order count says they are next, as the SPS's reorder depth
//! allows), so frames leave [`H264Decoder::decode_annex_b`] already in display order; the last
//! few are released by [`H264Decoder::flush`] at the end of the stream. This was checked
//! against FFmpeg's frames of a High-profile file with B-frames
//! (`tests/decode_video.rs`). What this wrapper keeps between calls: the OpenH264 state
//! (reference pictures and that reorder buffer, a handful of frames at most) and one
//! scratch buffer for the Annex B conversion.
//!
//! Colour: the matrix and range the SPS's VUI declares (`matrix_coefficients`,
//! `video_full_range_flag`), read by [`sps_colour`]; when it declares none, BT.601 limited
//! range ("TV range"), FFmpeg's default. Chroma is taken from the co-sited 2×2 block, as
//! FFmpeg's default `yuv420p → rgb24` conversion does.

use image::RgbImage;
use openh264::decoder::{DecodedYUV, Decoder, DecoderConfig, Flush};
use openh264::formats::YUVSource;
use openh264::OpenH264API;

/// Why an access unit could not be decoded (the caller adds the path).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum H264Error {
    /// The bitstream is damaged (a NAL length past the end of the sample, or OpenH264
    /// refused it).
    Corrupt(String),
    /// A decoded picture is larger than the caller allowed.
    TooLarge { width: u32, height: u32 },
}

impl std::fmt::Display for H264Error {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            H264Error::Corrupt(what) => write!(f, "H.264 stream: {what}"),
            H264Error::TooLarge { width, height } => {
                write!(f, "H.264 picture of {width}×{height}")
            }
        }
    }
}

const START_CODE: [u8; 4] = [0, 0, 0, 1];

/// Converts one MP4 sample (NAL units each preceded by a big-endian length of
/// `length_size` bytes, 1 to 4) to Annex B, appending to `out`.
pub fn avcc_to_annex_b(
    sample: &[u8],
    length_size: usize,
    out: &mut Vec<u8>,
) -> Result<(), H264Error> {
    if !(1..=4).contains(&length_size) {
        return Err(H264Error::Corrupt(format!("NAL length size {length_size}")));
    }
    let mut pos = 0usize;
    while pos < sample.len() {
        let Some(len_bytes) = sample.get(pos..pos + length_size) else {
            return Err(H264Error::Corrupt(
                "NAL length cut off at the end of a sample".into(),
            ));
        };
        let len = len_bytes
            .iter()
            .fold(0usize, |acc, &b| (acc << 8) | usize::from(b));
        pos += length_size;
        let Some(nal) = sample.get(pos..pos.saturating_add(len)) else {
            return Err(H264Error::Corrupt(format!(
                "NAL unit of {len} bytes runs past the end of its {}-byte sample",
                sample.len()
            )));
        };
        if !nal.is_empty() {
            out.extend_from_slice(&START_CODE);
            out.extend_from_slice(nal);
        }
        pos += len;
    }
    Ok(())
}

/// True when `data` starts with an Annex B start code (`00 00 01` or `00 00 00 01`).
pub fn is_annex_b(data: &[u8]) -> bool {
    data.starts_with(&[0, 0, 1]) || data.starts_with(&[0, 0, 0, 1])
}

/// A streaming H.264 decoder: access units in (decode order), RGB frames out (display
/// order).
pub struct H264Decoder {
    decoder: Decoder,
    scratch: Vec<u8>,
    max_width: u32,
    max_height: u32,
    colour: Colour,
}

impl H264Decoder {
    /// A decoder that refuses pictures larger than `max_width`×`max_height`.
    pub fn new(max_width: u32, max_height: u32) -> Result<Self, H264Error> {
        // NoFlush: let OpenH264's reorder buffer hold pictures until their display turn
        // (flushing after every call would hand B-frame streams out in decode order).
        let config = DecoderConfig::new().flush_after_decode(Flush::NoFlush);
        let decoder = Decoder::with_api_config(OpenH264API::from_source(), config)
            .map_err(|e| H264Error::Corrupt(format!("cannot start the decoder: {e}")))?;
        Ok(H264Decoder {
            decoder,
            scratch: Vec::new(),
            max_width,
            max_height,
            colour: Colour::default(),
        })
    }

    /// A decoder primed with the parameter sets of an MP4 `avcC` record.
    pub fn with_parameter_sets(
        max_width: u32,
        max_height: u32,
        sps: &[&[u8]],
        pps: &[&[u8]],
    ) -> Result<Self, H264Error> {
        let mut dec = Self::new(max_width, max_height)?;
        let mut headers = Vec::new();
        for nal in sps.iter().chain(pps.iter()).filter(|n| !n.is_empty()) {
            headers.extend_from_slice(&START_CODE);
            headers.extend_from_slice(nal);
        }
        if !headers.is_empty() {
            // Parameter sets alone produce no picture.
            let _ = dec.decode_annex_b(&headers)?;
        }
        Ok(dec)
    }

    /// Decodes one length-prefixed (MP4) access unit; returns the frame that is next in
    /// display order, if one is ready.
    pub fn decode_length_prefixed(
        &mut self,
        sample: &[u8],
        length_size: usize,
    ) -> Result<Option<RgbImage>, H264Error> {
        let mut buf = std::mem::take(&mut self.scratch);
        buf.clear();
        let result =
            avcc_to_annex_b(sample, length_size, &mut buf).and_then(|()| self.decode_annex_b(&buf));
        self.scratch = buf;
        result
    }

    /// Decodes one Annex B access unit (or any run of whole NAL units).
    pub fn decode_annex_b(&mut self, data: &[u8]) -> Result<Option<RgbImage>, H264Error> {
        if data.is_empty() {
            return Ok(None);
        }
        for nal in annex_b_nals(data) {
            if nal.first().map(|b| b & 0x1f) == Some(7) {
                if let Some(c) = sps_colour(nal) {
                    self.colour = c;
                }
            }
        }
        let (max_w, max_h, colour) = (self.max_width, self.max_height, self.colour);
        match self.decoder.decode(data) {
            Ok(Some(yuv)) => yuv_to_rgb(&yuv, max_w, max_h, colour).map(Some),
            Ok(None) => Ok(None),
            Err(e) => Err(H264Error::Corrupt(format!(
                "the decoder refused an access unit: {e}"
            ))),
        }
    }

    /// The frames still held in the reorder buffer, in display order (call once at the
    /// end of the stream).
    pub fn flush(&mut self) -> Result<Vec<RgbImage>, H264Error> {
        let (max_w, max_h, colour) = (self.max_width, self.max_height, self.colour);
        let frames = self
            .decoder
            .flush_remaining()
            .map_err(|e| H264Error::Corrupt(format!("flushing the decoder failed: {e}")))?;
        frames
            .iter()
            .map(|yuv| yuv_to_rgb(yuv, max_w, max_h, colour))
            .collect()
    }
}

/// BT.601 limited-range YUV 4:2:0 → RGB, refusing pictures over the size limit before
/// allocating the RGB buffer.
fn yuv_to_rgb(
    yuv: &DecodedYUV<'_>,
    max_w: u32,
    max_h: u32,
    colour: Colour,
) -> Result<RgbImage, H264Error> {
    let (w, h) = yuv.dimensions();
    let (wu, hu) = (
        u32::try_from(w).unwrap_or(u32::MAX),
        u32::try_from(h).unwrap_or(u32::MAX),
    );
    if w == 0 || h == 0 || wu > max_w || hu > max_h {
        return Err(H264Error::TooLarge {
            width: wu,
            height: hu,
        });
    }
    let (sy, su, sv) = yuv.strides();
    let (yp, up, vp) = (yuv.y(), yuv.u(), yuv.v());
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    let plane_ok = |plane: &[u8], stride: usize, pw: usize, ph: usize| {
        stride >= pw && plane.len() >= (ph - 1) * stride + pw
    };
    if !plane_ok(yp, sy, w, h) || !plane_ok(up, su, cw, ch) || !plane_ok(vp, sv, cw, ch) {
        return Err(H264Error::Corrupt(
            "decoder returned planes smaller than the picture".into(),
        ));
    }
    let mut out = vec![0u8; w * h * 3];
    for (row, line) in out.chunks_exact_mut(w * 3).enumerate() {
        let yrow = &yp[row * sy..row * sy + w];
        let urow = &up[(row / 2) * su..(row / 2) * su + cw];
        let vrow = &vp[(row / 2) * sv..(row / 2) * sv + cw];
        for (x, px) in line.chunks_exact_mut(3).enumerate() {
            let rgb = colour.to_rgb(yrow[x], urow[x / 2], vrow[x / 2]);
            px.copy_from_slice(&rgb);
        }
    }
    RgbImage::from_raw(wu, hu, out)
        .ok_or_else(|| H264Error::Corrupt("picture buffer has the wrong size".into()))
}

/// How to turn Y'CbCr into RGB: 16.16 fixed-point coefficients.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Colour {
    y_offset: i32,
    y_gain: i32,
    r_v: i32,
    g_u: i32,
    g_v: i32,
    b_u: i32,
}

impl Default for Colour {
    /// BT.601, limited range.
    fn default() -> Self {
        Colour::new(0.299, 0.114, false)
    }
}

impl Colour {
    /// From the luma weights of red and blue (`kr`, `kb`) and the range.
    pub fn new(kr: f64, kb: f64, full_range: bool) -> Self {
        let kg = 1.0 - kr - kb;
        let (y_offset, y_gain, c_gain) = if full_range {
            (0, 1.0, 1.0)
        } else {
            (16, 255.0 / 219.0, 255.0 / 224.0)
        };
        let fx = |v: f64| (v * 65536.0).round() as i32;
        Colour {
            y_offset,
            y_gain: fx(y_gain),
            r_v: fx(2.0 * (1.0 - kr) * c_gain),
            g_u: fx(2.0 * kb * (1.0 - kb) / kg * c_gain),
            g_v: fx(2.0 * kr * (1.0 - kr) / kg * c_gain),
            b_u: fx(2.0 * (1.0 - kb) * c_gain),
        }
    }

    /// From the VUI's `matrix_coefficients` (ITU-T H.273) and full-range flag; matrices
    /// this does not know, and "unspecified", fall back to BT.601 as FFmpeg does.
    pub fn from_vui(matrix: u8, full_range: bool) -> Self {
        match matrix {
            1 => Colour::new(0.2126, 0.0722, full_range),
            4 => Colour::new(0.30, 0.11, full_range),
            7 => Colour::new(0.212, 0.087, full_range),
            9 | 10 => Colour::new(0.2627, 0.0593, full_range),
            _ => Colour::new(0.299, 0.114, full_range),
        }
    }

    #[inline]
    fn to_rgb(self, y: u8, u: u8, v: u8) -> [u8; 3] {
        let c = (i32::from(y) - self.y_offset) * self.y_gain;
        let d = i32::from(u) - 128;
        let e = i32::from(v) - 128;
        let clamp = |x: i32| ((x + 32768) >> 16).clamp(0, 255) as u8;
        [
            clamp(c + self.r_v * e),
            clamp(c - self.g_u * d - self.g_v * e),
            clamp(c + self.b_u * d),
        ]
    }
}

/// The NAL units of an Annex B buffer (start codes removed; trailing zero bytes of the
/// next start code may remain, which does not matter to the parsers here).
pub fn annex_b_nals(data: &[u8]) -> impl Iterator<Item = &[u8]> {
    let mut starts = Vec::new();
    let mut i = 0;
    while i + 3 <= data.len() {
        if data[i] == 0 && data[i + 1] == 0 && data[i + 2] == 1 {
            starts.push(i + 3);
            i += 3;
        } else {
            i += 1;
        }
    }
    let ends: Vec<usize> = starts
        .iter()
        .skip(1)
        .map(|&s| s - 3)
        .chain(std::iter::once(data.len()))
        .collect();
    starts
        .into_iter()
        .zip(ends)
        .map(move |(s, e)| &data[s..e.max(s)])
}

/// Bit reader over an RBSP (emulation-prevention bytes removed), for the SPS.
struct Bits {
    bytes: Vec<u8>,
    pos: usize,
}

impl Bits {
    fn new(nal: &[u8]) -> Self {
        let mut bytes = Vec::with_capacity(nal.len());
        let mut zeros = 0;
        for &b in nal {
            if zeros >= 2 && b == 3 {
                zeros = 0;
                continue;
            }
            zeros = if b == 0 { zeros + 1 } else { 0 };
            bytes.push(b);
        }
        Bits { bytes, pos: 0 }
    }

    fn bit(&mut self) -> Option<u32> {
        let byte = *self.bytes.get(self.pos / 8)?;
        let b = (byte >> (7 - self.pos % 8)) & 1;
        self.pos += 1;
        Some(u32::from(b))
    }

    fn bits(&mut self, n: u32) -> Option<u32> {
        (0..n).try_fold(0u32, |acc, _| Some((acc << 1) | self.bit()?))
    }

    fn ue(&mut self) -> Option<u32> {
        let mut zeros = 0;
        while self.bit()? == 0 {
            zeros += 1;
            if zeros > 31 {
                return None;
            }
        }
        Some(((1u64 << zeros) - 1 + u64::from(self.bits(zeros)?)).min(u64::from(u32::MAX)) as u32)
    }

    fn se(&mut self) -> Option<i32> {
        let k = self.ue()?;
        let mag = (k / 2 + k % 2) as i32;
        Some(if k % 2 == 1 { mag } else { -mag })
    }
}

/// The colour conversion an SPS (NAL unit including its one-byte header) asks for, or
/// `None` when it cannot be read.
pub fn sps_colour(nal: &[u8]) -> Option<Colour> {
    let mut b = Bits::new(nal.get(1..)?);
    let profile = b.bits(8)?;
    b.bits(16)?; // constraint flags, level
    b.ue()?; // seq_parameter_set_id
    if matches!(
        profile,
        100 | 110 | 122 | 244 | 44 | 83 | 86 | 118 | 128 | 138 | 139 | 134 | 135
    ) {
        let chroma_format = b.ue()?;
        if chroma_format == 3 {
            b.bit()?;
        }
        b.ue()?;
        b.ue()?;
        b.bit()?;
        if b.bit()? == 1 {
            for i in 0..if chroma_format == 3 { 12 } else { 8 } {
                if b.bit()? == 1 {
                    let size = if i < 6 { 16 } else { 64 };
                    let (mut last, mut next) = (8i32, 8i32);
                    for _ in 0..size {
                        if next != 0 {
                            next = (last + b.se()? + 256).rem_euclid(256);
                        }
                        if next != 0 {
                            last = next;
                        }
                    }
                }
            }
        }
    }
    b.ue()?; // log2_max_frame_num_minus4
    match b.ue()? {
        0 => {
            b.ue()?;
        }
        1 => {
            b.bit()?;
            b.se()?;
            b.se()?;
            for _ in 0..b.ue()?.min(256) {
                b.se()?;
            }
        }
        _ => {}
    }
    b.ue()?; // max_num_ref_frames
    b.bit()?;
    b.ue()?; // width in macroblocks - 1
    b.ue()?; // height in map units - 1
    if b.bit()? == 0 {
        b.bit()?; // mb_adaptive_frame_field_flag
    }
    b.bit()?; // direct_8x8_inference_flag
    if b.bit()? == 1 {
        for _ in 0..4 {
            b.ue()?;
        }
    }
    if b.bit()? == 0 {
        return Some(Colour::default());
    }
    // VUI
    if b.bit()? == 1 && b.bits(8)? == 255 {
        b.bits(32)?;
    }
    if b.bit()? == 1 {
        b.bit()?;
    }
    if b.bit()? == 0 {
        return Some(Colour::default());
    }
    b.bits(3)?; // video_format
    let full_range = b.bit()? == 1;
    let matrix = if b.bit()? == 1 {
        b.bits(16)?; // colour primaries, transfer characteristics
        b.bits(8)? as u8
    } else {
        2
    };
    Some(Colour::from_vui(matrix, full_range))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn length_prefixed_becomes_annex_b() {
        let sample = [0, 0, 0, 2, 0x65, 0xAA, 0, 0, 0, 1, 0x41];
        let mut out = Vec::new();
        avcc_to_annex_b(&sample, 4, &mut out).unwrap();
        assert_eq!(out, [0, 0, 0, 1, 0x65, 0xAA, 0, 0, 0, 1, 0x41]);
    }

    #[test]
    fn nal_past_the_end_is_corrupt() {
        let mut out = Vec::new();
        assert!(avcc_to_annex_b(&[0, 0, 0, 9, 1], 4, &mut out).is_err());
        assert!(avcc_to_annex_b(&[0, 0], 4, &mut out).is_err());
        assert!(avcc_to_annex_b(&[1], 0, &mut out).is_err());
    }

    #[test]
    fn colour_conversion_limits() {
        for c in [Colour::default(), Colour::from_vui(1, false)] {
            assert_eq!(c.to_rgb(16, 128, 128), [0, 0, 0]);
            assert_eq!(c.to_rgb(235, 128, 128), [255, 255, 255]);
        }
        let [r, g, b] = Colour::default().to_rgb(81, 90, 240);
        assert!(r > 240 && g < 10 && b < 10, "{r} {g} {b}");
        assert_eq!(
            Colour::from_vui(2, true).to_rgb(255, 128, 128),
            [255, 255, 255]
        );
    }

    #[test]
    fn nal_splitting() {
        let data = [0, 0, 0, 1, 0x67, 1, 2, 0, 0, 1, 0x68, 3];
        let nals: Vec<&[u8]> = annex_b_nals(&data).collect();
        assert_eq!(nals, vec![&[0x67, 1, 2][..], &[0x68, 3][..]]);
        assert_eq!(annex_b_nals(&[1, 2, 3]).count(), 0);
    }

    #[test]
    fn sps_garbage_does_not_panic() {
        for len in 0..64u8 {
            let nal: Vec<u8> = (0..len).map(|i| i.wrapping_mul(37) ^ 0x5a).collect();
            let _ = sps_colour(&nal);
        }
        let _ = sps_colour(&[0x67, 100, 0, 0, 0xff, 0xff, 0xff, 0xff]);
    }
}
