//! Connected regions of a mask, and the choice of the person's regions among them.
//! (imageproc 0.25's `connected_components` panics on an image whose every pixel is
//! its own region, such as a checkerboard of noise, so labelling is done here.)

use crate::body::Mask;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Connectivity {
    Four,
    Eight,
}

/// One region: its area and inclusive bounding box `[x0, y0, x1, y1]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Blob {
    pub area: u64,
    pub bbox: [u32; 4],
}

/// Regions of the pixels of a mask equal to `value`.
#[derive(Clone, Debug)]
pub struct Blobs {
    pub width: u32,
    pub height: u32,
    /// Per pixel, row-major: 0 outside every region, else the region's index + 1.
    pub labels: Vec<u32>,
    pub blobs: Vec<Blob>,
}

impl Blobs {
    /// Labels the regions of pixels equal to `value`: the rows' runs of such pixels,
    /// joined (union–find) with the runs they touch in the row above; regions are
    /// numbered in the raster order of their first pixel. In a refining pass over
    /// vtest.mp4, the clean-up and the person's regions (mostly labelling) took
    /// 1.4–1.8 s instead of 11–13 s with a pixel-by-pixel flood fill, which the
    /// tests keep as the reference.
    pub fn label(mask: &Mask, value: bool, connectivity: Connectivity) -> Blobs {
        let (w, h) = (mask.width(), mask.height());
        // Runs as (y, x0, x1) inclusive, row by row; `rows[y]` is where row y's start.
        let mut runs: Vec<(u32, u32, u32)> = Vec::new();
        let mut rows = Vec::with_capacity(h as usize + 1);
        for y in 0..h {
            rows.push(runs.len());
            let mut x = 0;
            while x < w {
                if mask.get(x, y) != value {
                    x += 1;
                    continue;
                }
                let x0 = x;
                while x < w && mask.get(x, y) == value {
                    x += 1;
                }
                runs.push((y, x0, x - 1));
            }
        }
        rows.push(runs.len());
        let mut parent: Vec<usize> = (0..runs.len()).collect();
        fn root(parent: &mut [usize], mut i: usize) -> usize {
            while parent[i] != i {
                parent[i] = parent[parent[i]];
                i = parent[i];
            }
            i
        }
        // Runs touch when their spans overlap, or meet at a corner under 8-connectivity.
        let reach = u32::from(connectivity == Connectivity::Eight);
        for y in 1..h as usize {
            let (above, here) = (rows[y - 1]..rows[y], rows[y]..rows[y + 1]);
            let mut a = above.start;
            for r in here {
                let (_, x0, x1) = runs[r];
                while a < above.end && runs[a].2 + reach < x0 {
                    a += 1;
                }
                let mut b = a;
                while b < above.end && runs[b].1 <= x1 + reach {
                    let (ra, rb) = (root(&mut parent, r), root(&mut parent, b));
                    // The smaller index (earlier in raster order) stays the root.
                    let (lo, hi) = (ra.min(rb), ra.max(rb));
                    parent[hi] = lo;
                    b += 1;
                }
            }
        }
        let mut labels = vec![0u32; w as usize * h as usize];
        let mut blobs: Vec<Blob> = Vec::new();
        let mut label_of = vec![0u32; runs.len()];
        for r in 0..runs.len() {
            let top = root(&mut parent, r);
            let (y, x0, x1) = runs[r];
            let label = if top == r {
                blobs.push(Blob {
                    area: 0,
                    bbox: [x0, y, x1, y],
                });
                blobs.len() as u32
            } else {
                label_of[top]
            };
            label_of[r] = label;
            let blob = &mut blobs[label as usize - 1];
            blob.area += u64::from(x1 - x0 + 1);
            let b = &mut blob.bbox;
            *b = [b[0].min(x0), b[1].min(y), b[2].max(x1), b[3].max(y)];
            let row = (y * w) as usize;
            labels[row + x0 as usize..=row + x1 as usize].fill(label);
        }
        Blobs {
            width: w,
            height: h,
            labels,
            blobs,
        }
    }

    /// The region of pixel (x, y), if any.
    pub fn at(&self, x: u32, y: u32) -> Option<usize> {
        let l = self.labels[(y * self.width + x) as usize];
        (l > 0).then(|| l as usize - 1)
    }

    /// Whether a region touches the image border.
    pub fn touches_border(&self, i: usize) -> bool {
        let b = self.blobs[i].bbox;
        b[0] == 0 || b[1] == 0 || b[2] + 1 == self.width || b[3] + 1 == self.height
    }

    /// The person's regions: the largest, and those of at least `min_fraction` of its
    /// area lying within `gap_fraction` of its height from its bounding box (a limb
    /// detached by a thin gap stays; a passer-by or noise farther away goes). Returns
    /// the largest region's index and a keep flag per region (None without regions).
    pub fn person(&self, min_fraction: f64, gap_fraction: f64) -> Option<(usize, Vec<bool>)> {
        let main =
            (0..self.blobs.len()).max_by_key(|&i| (self.blobs[i].area, std::cmp::Reverse(i)))?;
        let Blob {
            area: marea,
            bbox: mb,
        } = self.blobs[main];
        let gap = gap_fraction * (mb[3] - mb[1] + 1) as f64;
        let keep = self
            .blobs
            .iter()
            .enumerate()
            .map(|(i, b)| {
                let bb = b.bbox;
                let dx = (bb[0] as f64 - mb[2] as f64)
                    .max(mb[0] as f64 - bb[2] as f64)
                    .max(0.0);
                let dy = (bb[1] as f64 - mb[3] as f64)
                    .max(mb[1] as f64 - bb[3] as f64)
                    .max(0.0);
                i == main || (b.area as f64 >= min_fraction * marea as f64 && dx.hypot(dy) <= gap)
            })
            .collect();
        Some((main, keep))
    }

    /// A mask of the regions flagged in `keep`.
    pub fn mask_of(&self, keep: &[bool]) -> Mask {
        let mut m = Mask::new(self.width, self.height);
        for (i, &l) in self.labels.iter().enumerate() {
            if l > 0 && keep[l as usize - 1] {
                m.set(i as u32 % self.width, i as u32 / self.width, true);
            }
        }
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The labelling by a pixel-by-pixel flood fill (what [`Blobs::label`] replaced).
    fn reference_label(mask: &Mask, value: bool, connectivity: Connectivity) -> Blobs {
        let (w, h) = (mask.width(), mask.height());
        let mut labels = vec![0u32; w as usize * h as usize];
        let mut blobs = Vec::new();
        let mut stack = Vec::new();
        for y0 in 0..h {
            for x0 in 0..w {
                let i0 = (y0 * w + x0) as usize;
                if labels[i0] != 0 || mask.get(x0, y0) != value {
                    continue;
                }
                let label = blobs.len() as u32 + 1;
                let mut blob = Blob {
                    area: 0,
                    bbox: [x0, y0, x0, y0],
                };
                labels[i0] = label;
                stack.push((x0, y0));
                while let Some((x, y)) = stack.pop() {
                    blob.area += 1;
                    let b = &mut blob.bbox;
                    *b = [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)];
                    for ny in y.saturating_sub(1)..=(y + 1).min(h - 1) {
                        for nx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                            let diagonal = nx != x && ny != y;
                            if diagonal && connectivity == Connectivity::Four {
                                continue;
                            }
                            let i = (ny * w + nx) as usize;
                            if labels[i] == 0 && mask.get(nx, ny) == value {
                                labels[i] = label;
                                stack.push((nx, ny));
                            }
                        }
                    }
                }
                blobs.push(blob);
            }
        }
        Blobs {
            width: w,
            height: h,
            labels,
            blobs,
        }
    }

    proptest::proptest! {
        #[test]
        fn run_labelling_matches_a_flood_fill(
            w in 1u32..90,
            h in 1u32..40,
            bits in proptest::collection::vec(proptest::bool::weighted(0.45), 3600),
            value in proptest::bool::ANY,
            eight in proptest::bool::ANY,
        ) {
            let mut m = Mask::new(w, h);
            for y in 0..h {
                for x in 0..w {
                    m.set(x, y, bits[(y * w + x) as usize]);
                }
            }
            let c = if eight { Connectivity::Eight } else { Connectivity::Four };
            let (a, b) = (Blobs::label(&m, value, c), reference_label(&m, value, c));
            proptest::prop_assert_eq!(a.labels, b.labels);
            proptest::prop_assert_eq!(a.blobs, b.blobs);
        }
    }

    #[test]
    fn connectivity_and_degenerate_masks() {
        // A checkerboard: one 8-connected region, every pixel its own 4-region.
        let mut m = Mask::new(6, 4);
        for y in 0..4 {
            for x in 0..6 {
                m.set(x, y, (x + y) % 2 == 0);
            }
        }
        assert_eq!(Blobs::label(&m, true, Connectivity::Eight).blobs.len(), 1);
        assert_eq!(Blobs::label(&m, true, Connectivity::Four).blobs.len(), 12);
        assert_eq!(Blobs::label(&m, false, Connectivity::Four).blobs.len(), 12);
        let one = Mask::new(1, 1);
        let b = Blobs::label(&one, false, Connectivity::Four);
        assert_eq!(
            b.blobs,
            vec![Blob {
                area: 1,
                bbox: [0, 0, 0, 0]
            }]
        );
        assert!(b.touches_border(0));
        assert!(Blobs::label(&one, true, Connectivity::Eight)
            .person(0.1, 0.1)
            .is_none());
        let empty = Mask::new(0, 0);
        assert!(Blobs::label(&empty, true, Connectivity::Eight)
            .blobs
            .is_empty());
    }
}
