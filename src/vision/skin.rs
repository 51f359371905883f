//! Which of the person's pixels show skin, by colour: a per-clip model learned from a
//! fitted frame, where the model's own parts say which pixels are skin (forearms,
//! hands, neck, head) and which are clothes.
//!
//! The silhouette cannot tell where a forearm lies in front of the torso: both are
//! inside it. Bare forearms differ from a shirt in colour, so pixels of skin colour
//! inside the torso's image say where the forearm is. The model is a histogram of
//! colours (5 bits a channel) of skin and of everything else on the person, each
//! spread over its neighbouring bins, so a colour seen near a learned one counts too.

use super::super::body::raster::Mask;
use image::RgbImage;

/// Bits kept of each colour channel.
const BITS: u32 = 5;
const SIDE: usize = 1 << BITS;
/// Bins of the colour histogram.
pub const BINS: usize = SIDE * SIDE * SIDE;
/// A pixel that is not the person's (no colour kept).
pub const NO_COLOUR: u16 = u16::MAX;

/// The colour bin of an RGB pixel.
pub fn bin(px: [u8; 3]) -> u16 {
    let q = |c: u8| (c >> (8 - BITS)) as usize;
    ((q(px[0]) * SIDE + q(px[1])) * SIDE + q(px[2])) as u16
}

/// Each pixel's colour bin inside `person`, [`NO_COLOUR`] outside it (row-major).
/// None when the frame is not the mask's size.
pub fn colour_bins(frame: &RgbImage, person: &Mask) -> Option<Vec<u16>> {
    let (w, h) = (person.width(), person.height());
    if frame.width() != w || frame.height() != h {
        return None;
    }
    let mut out = vec![NO_COLOUR; w as usize * h as usize];
    for y in 0..h {
        for x in 0..w {
            if person.get(x, y) {
                out[(y * w + x) as usize] = bin(frame.get_pixel(x, y).0);
            }
        }
    }
    Some(out)
}

/// The probability that a colour bin of the person is skin.
#[derive(Clone, Debug)]
pub struct SkinModel {
    p: Vec<f32>,
    /// Pixels it was learned from: skin, other.
    pub learned: (u64, u64),
}

impl SkinModel {
    /// Learns from one frame's colour bins: `skin` and `other` are the pixels known to
    /// be skin and not skin. None when either class has fewer than `min` pixels.
    pub fn learn(bins: &[u16], skin: &Mask, other: &Mask, min: u64) -> Option<SkinModel> {
        let w = skin.width();
        let mut counts = [vec![0f32; BINS], vec![0f32; BINS]];
        let mut learned = (0u64, 0u64);
        for y in 0..skin.height() {
            for x in 0..w {
                let b = bins[(y * w + x) as usize];
                if b == NO_COLOUR {
                    continue;
                }
                let (s, o) = (skin.get(x, y), other.get(x, y));
                if s && !o {
                    counts[0][b as usize] += 1.0;
                    learned.0 += 1;
                } else if o && !s {
                    counts[1][b as usize] += 1.0;
                    learned.1 += 1;
                }
            }
        }
        if learned.0 < min || learned.1 < min {
            return None;
        }
        let [skin_c, other_c] = counts.map(|c| spread(&c));
        let p = skin_c
            .iter()
            .zip(&other_c)
            .map(|(&s, &o)| if s + o > 0.0 { s / (s + o) } else { 0.0 })
            .collect();
        Some(SkinModel { p, learned })
    }

    /// The probability that colour bin `b` is skin (0 for [`NO_COLOUR`]).
    pub fn p(&self, b: u16) -> f32 {
        self.p.get(b as usize).copied().unwrap_or(0.0)
    }
}

/// Each bin's count summed with its 26 neighbours' (a 3×3×3 box).
fn spread(c: &[f32]) -> Vec<f32> {
    let idx = |r: usize, g: usize, b: usize| (r * SIDE + g) * SIDE + b;
    let mut out = vec![0f32; BINS];
    let mut tmp = vec![0f32; BINS];
    // Separable: along b, then g, then r.
    let pass = |src: &[f32], dst: &mut [f32], axis: usize| {
        for r in 0..SIDE {
            for g in 0..SIDE {
                for b in 0..SIDE {
                    let at = [r, g, b];
                    let mut s = 0.0;
                    for d in [-1i32, 0, 1] {
                        let v = at[axis] as i32 + d;
                        if (0..SIDE as i32).contains(&v) {
                            let mut q = at;
                            q[axis] = v as usize;
                            s += src[idx(q[0], q[1], q[2])];
                        }
                    }
                    dst[idx(r, g, b)] = s;
                }
            }
        }
    };
    pass(c, &mut tmp, 2);
    pass(&tmp, &mut out, 1);
    pass(&out.clone(), &mut tmp, 0);
    tmp
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Rgb;

    #[test]
    fn learns_skin_from_labelled_pixels_and_generalises_to_near_colours() {
        let (w, h) = (20, 10);
        // Left half skin-coloured, right half blue; the labels say so.
        let frame = RgbImage::from_fn(w, h, |x, _| {
            if x < 10 {
                Rgb([200, 160, 130])
            } else {
                Rgb([50, 90, 170])
            }
        });
        let mut person = Mask::new(w, h);
        let (mut skin, mut other) = (Mask::new(w, h), Mask::new(w, h));
        for y in 0..h {
            for x in 0..w {
                person.set(x, y, true);
                skin.set(x, y, x < 10);
                other.set(x, y, x >= 10);
            }
        }
        let bins = colour_bins(&frame, &person).unwrap();
        let m = SkinModel::learn(&bins, &skin, &other, 10).unwrap();
        assert_eq!(m.learned, (100, 100));
        assert!(m.p(bin([200, 160, 130])) > 0.99);
        // A slightly different shade of each counts as its class.
        assert!(m.p(bin([207, 152, 124])) > 0.99);
        assert!(m.p(bin([50, 90, 170])) < 0.01);
        assert!(m.p(bin([58, 98, 178])) < 0.01);
        // A colour never seen is not skin.
        assert_eq!(m.p(bin([0, 255, 0])), 0.0);
        assert_eq!(m.p(NO_COLOUR), 0.0);
        // Too few of a class: no model.
        assert!(SkinModel::learn(&bins, &skin, &other, 101).is_none());
        // A frame of another size has no bins.
        assert!(colour_bins(&RgbImage::new(3, 3), &person).is_none());
    }
}
