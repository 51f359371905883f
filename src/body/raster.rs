//! The silhouette rasterizer: body + pose + camera → binary mask. It is the
//! tracker's inner loop (thousands of calls per frame), so:
//!
//! - each part is visited only inside its projected bounding box;
//! - a pixel is inside a part when the ray through its centre meets the part. For a
//!   quadric the ray test's discriminant is a quadratic in the pixel's column, so for
//!   every row the exact span of an ellipsoid (and of a cylinder's infinite hull) comes
//!   from one quadratic equation; only a cylinder's two span ends need per-pixel tests
//!   against its caps;
//! - spans are written into a bit-packed [`Mask`] (one bit a pixel, rows of u64
//!   words), so filling, counting and XOR-ing work on 64 pixels at a time;
//! - nothing is allocated per call.
//!
//! Parts that reach behind the camera's near plane are not drawn (a pose that puts
//! the body behind the camera has nothing sensible to show).

use image::GrayImage;
use multiversion::multiversion;
use nalgebra::{IsometryMatrix3, Matrix3, Point3, Vector3};

use super::camera::Camera;
use super::parts::{Kind, Part, PART_COUNT};
use super::skeleton::{Posed, LANDMARK_COUNT};
use super::Body;

/// A binary image, one bit per pixel, each row padded to whole u64 words.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Mask {
    width: u32,
    height: u32,
    stride: usize,
    words: Vec<u64>,
}

impl Mask {
    pub fn new(width: u32, height: u32) -> Mask {
        let stride = (width as usize).div_ceil(64);
        Mask {
            width,
            height,
            stride,
            words: vec![0; stride * height as usize],
        }
    }

    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    /// Words per row.
    pub fn stride(&self) -> usize {
        self.stride
    }

    pub fn words(&self) -> &[u64] {
        &self.words
    }

    pub fn row(&self, y: u32) -> &[u64] {
        let s = y as usize * self.stride;
        &self.words[s..s + self.stride]
    }

    pub fn clear(&mut self) {
        self.words.fill(0);
    }

    /// Clears rows y0..=y1 (clipped to the image).
    pub fn clear_rows(&mut self, y0: u32, y1: u32) {
        if y0 >= self.height || y0 > y1 {
            return;
        }
        let y1 = y1.min(self.height - 1);
        self.words[y0 as usize * self.stride..(y1 as usize + 1) * self.stride].fill(0);
    }

    /// Mutable words of row y.
    pub fn row_mut(&mut self, y: u32) -> &mut [u64] {
        let s = y as usize * self.stride;
        &mut self.words[s..s + self.stride]
    }

    pub fn get(&self, x: u32, y: u32) -> bool {
        let w = self.words[y as usize * self.stride + (x as usize >> 6)];
        (w >> (x & 63)) & 1 == 1
    }

    pub fn set(&mut self, x: u32, y: u32, on: bool) {
        let w = &mut self.words[y as usize * self.stride + (x as usize >> 6)];
        if on {
            *w |= 1 << (x & 63);
        } else {
            *w &= !(1 << (x & 63));
        }
    }

    /// Sets pixels x0..=x1 of row y (both within the image, x0 ≤ x1).
    pub fn fill_span(&mut self, y: u32, x0: u32, x1: u32) {
        debug_assert!(x0 <= x1 && x1 < self.width && y < self.height);
        let base = y as usize * self.stride;
        let (w0, w1) = (x0 as usize >> 6, x1 as usize >> 6);
        let lo = !0u64 << (x0 & 63);
        let hi = !0u64 >> (63 - (x1 & 63));
        if w0 == w1 {
            self.words[base + w0] |= lo & hi;
        } else {
            self.words[base + w0] |= lo;
            for w in &mut self.words[base + w0 + 1..base + w1] {
                *w = !0;
            }
            self.words[base + w1] |= hi;
        }
    }

    /// Number of set pixels.
    pub fn count(&self) -> u64 {
        self.words.iter().map(|w| w.count_ones() as u64).sum()
    }

    /// Number of pixels set in both masks.
    pub fn count_and(&self, other: &Mask) -> u64 {
        self.same_size(other);
        let both = self.words.iter().zip(&other.words);
        both.map(|(a, b)| (a & b).count_ones() as u64).sum()
    }

    fn same_size(&self, other: &Mask) {
        assert!(
            self.width == other.width && self.height == other.height,
            "masks of different sizes"
        );
    }

    /// Sets every pixel set in `other`.
    pub fn or_with(&mut self, other: &Mask) {
        self.same_size(other);
        for (a, b) in self.words.iter_mut().zip(&other.words) {
            *a |= b;
        }
    }

    /// Keeps only the pixels also set in `other`.
    pub fn and_with(&mut self, other: &Mask) {
        self.same_size(other);
        for (a, b) in self.words.iter_mut().zip(&other.words) {
            *a &= b;
        }
    }

    /// Pixels set in both.
    pub fn and_count(&self, other: &Mask) -> u64 {
        self.same_size(other);
        let it = self.words.iter().zip(&other.words);
        it.map(|(a, b)| (a & b).count_ones() as u64).sum()
    }

    /// Pixels set in exactly one (the plain XOR cost, Eq. 2).
    pub fn xor_count(&self, other: &Mask) -> u64 {
        self.same_size(other);
        let it = self.words.iter().zip(&other.words);
        it.map(|(a, b)| (a ^ b).count_ones() as u64).sum()
    }

    /// Intersection over union (1 when both are empty).
    pub fn iou(&self, other: &Mask) -> f64 {
        let inter = self.and_count(other);
        let union = self.count() + other.count() - inter;
        if union == 0 {
            1.0
        } else {
            inter as f64 / union as f64
        }
    }

    /// The mask dilated by a (2r+1)×(2r+1) square (the L∞ ball of radius r), word
    /// by word: each row ORed with its shifts by up to r pixels, then each output
    /// row the OR of the 2r+1 rows around it.
    pub fn dilated_square(&self, r: u32) -> Mask {
        let stride = self.stride;
        let tail = match self.width % 64 {
            0 => !0u64,
            bits => (1u64 << bits) - 1,
        };
        let mut wide = vec![0u64; self.words.len()];
        for (src, dst) in self.words.chunks(stride).zip(wide.chunks_mut(stride)) {
            dst.copy_from_slice(src);
            for k in 1..=r.min(self.width) as usize {
                let (words, bits) = (k / 64, (k % 64) as u32);
                for (i, d) in dst.iter_mut().enumerate() {
                    // Towards higher x: bit j of the source lands on j + k.
                    let from = |j: usize| src.get(j).copied().unwrap_or(0);
                    if i >= words {
                        let lo = from(i - words);
                        let carry = if bits > 0 && i > words {
                            from(i - words - 1) >> (64 - bits)
                        } else {
                            0
                        };
                        *d |= (lo << bits) | carry;
                    }
                    // Towards lower x: bit j lands on j - k.
                    let hi = from(i + words);
                    let carry = if bits > 0 {
                        from(i + words + 1) << (64 - bits)
                    } else {
                        0
                    };
                    *d |= (hi >> bits) | carry;
                }
            }
            if let Some(last) = dst.last_mut() {
                *last &= tail;
            }
        }
        let mut out = Mask::new(self.width, self.height);
        let h = self.height as usize;
        for y in 0..h {
            let (y0, y1) = (y.saturating_sub(r as usize), (y + r as usize).min(h - 1));
            let dst = &mut out.words[y * stride..(y + 1) * stride];
            for row in wide[y0 * stride..(y1 + 1) * stride].chunks(stride) {
                for (d, s) in dst.iter_mut().zip(row) {
                    *d |= s;
                }
            }
        }
        out
    }

    /// An 8-bit image, 255 where set and 0 elsewhere.
    pub fn to_gray(&self) -> GrayImage {
        GrayImage::from_fn(self.width, self.height, |x, y| {
            image::Luma([if self.get(x, y) { 255 } else { 0 }])
        })
    }

    /// Set where the image is at least `threshold`.
    pub fn from_gray(img: &GrayImage, threshold: u8) -> Mask {
        let mut m = Mask::new(img.width(), img.height());
        for (x, y, p) in img.enumerate_pixels() {
            if p.0[0] >= threshold {
                m.set(x, y, true);
            }
        }
        m
    }
}

/// One part, ready to rasterize: the ray through pixel (u, v) in the part's
/// canonical space is `o + t·(g + u·p + v·q)`, where t is the depth in cm.
#[derive(Clone, Copy, Debug)]
struct Prepared {
    kind: Kind,
    o: Vector3<f64>,
    g: Vector3<f64>,
    p: Vector3<f64>,
    q: Vector3<f64>,
    /// The row quadratic's terms that are the same on every row
    /// ([`Prepared::row_quadratic`]): o·p and o·o − 1 (over x and z alone for a
    /// cylinder), and the quadratic's leading coefficient (o·p)² − (o·o − 1) p·p.
    op: f64,
    k: f64,
    a: f64,
    /// 1/(2a): the rows' roots without a division ([`roots_by_centre`]).
    inv_2a: f64,
    /// A cylinder's caps (y = 0 and y = 1) as [`Prepared::cylinder_row`] meets them:
    /// the terms of each cap's row quadratic that are the same on every row.
    caps: [Cap; 2],
    /// Inclusive pixel bounds of the projected bounding box, clipped to the image.
    x0: i64,
    x1: i64,
    y0: i64,
    y1: i64,
}

/// A part's A⁻¹ (the diagonal of its canonical scaling's inverse): 1 / each radius.
fn inverse_radii(part: &Part) -> Vector3<f64> {
    Vector3::new(1.0 / part.radii.x, 1.0 / part.radii.y, 1.0 / part.radii.z)
}

impl Prepared {
    /// None when the part is off-screen or crosses the near plane.
    fn new(part: &Part, joint_to_camera: &IsometryMatrix3<f64>, cam: &Camera) -> Option<Prepared> {
        let rot = joint_to_camera.rotation.matrix();
        let inv_a = inverse_radii(part);
        // Conservative screen bounds from the corners of the canonical bounding box.
        let (ylo, yhi) = match part.kind {
            Kind::Ellipsoid => (-1.0, 1.0),
            Kind::Cylinder => (0.0, 1.0),
        };
        let (mut umin, mut umax, mut vmin, mut vmax) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for corner in 0..8 {
            let qc = Vector3::new(
                if corner & 1 == 0 { -1.0 } else { 1.0 },
                if corner & 2 == 0 { ylo } else { yhi },
                if corner & 4 == 0 { -1.0 } else { 1.0 },
            );
            let local = part.center + part.radii.component_mul(&qc);
            let c = joint_to_camera * Point3::from(local);
            let [u, v] = cam.project_camera(&c)?;
            umin = umin.min(u);
            umax = umax.max(u);
            vmin = vmin.min(v);
            vmax = vmax.max(v);
        }
        let x0 = ceil_i64(umin - 0.5).max(0);
        let x1 = floor_i64(umax - 0.5).min(cam.width as i64 - 1);
        let y0 = ceil_i64(vmin - 0.5).max(0);
        let y1 = floor_i64(vmax - 0.5).min(cam.height as i64 - 1);
        if x0 > x1 || y0 > y1 {
            return None;
        }
        // Camera → canonical: q = A⁻¹ (Rᵀ (x − t) − c).
        let rt = rot.transpose();
        let m = Matrix3::from_diagonal(&inv_a) * rt;
        let o = inv_a.component_mul(&(rt * (-joint_to_camera.translation.vector) - part.center));
        // Camera ray direction through pixel (u, v): ((u − cx)/fx, −(v − cy)/fy, −1).
        let d00 = Vector3::new(-cam.cx / cam.fx, cam.cy / cam.fy, -1.0);
        let p: Vector3<f64> = m.column(0) / cam.fx;
        let (op, pp, k) = match part.kind {
            Kind::Ellipsoid => (o.dot(&p), p.dot(&p), o.dot(&o) - 1.0),
            Kind::Cylinder => (
                o.x * p.x + o.z * p.z,
                p.x * p.x + p.z * p.z,
                o.x * o.x + o.z * o.z - 1.0,
            ),
        };
        let a = op * op - k * pp;
        // Only a cylinder has caps (an ellipsoid's are never read).
        let caps = match part.kind {
            Kind::Cylinder => [Cap::new(&o, &p, 0.0), Cap::new(&o, &p, 1.0)],
            Kind::Ellipsoid => [Cap::default(); 2],
        };
        Some(Prepared {
            kind: part.kind,
            o,
            g: m * d00,
            p,
            q: -m.column(1) / cam.fy,
            op,
            k,
            a,
            inv_2a: 0.5 / a,
            caps,
            x0,
            x1,
            y0,
            y1,
        })
    }

    /// The direction of the row's ray at u = 0; the ray at u is `r + u·p`.
    fn row_base(&self, v: f64) -> Vector3<f64> {
        self.g + v * self.q
    }

    /// Coefficients (A, B, C) of the discriminant A·u² + B·u + C of the ray test along
    /// a row: the whole solid for an ellipsoid, the infinite side surface for a cylinder.
    fn row_quadratic(&self, r: &Vector3<f64>) -> (f64, f64, f64) {
        let (o, p) = (&self.o, &self.p);
        let (or, rr, rp) = match self.kind {
            Kind::Ellipsoid => (o.dot(r), r.dot(r), r.dot(p)),
            Kind::Cylinder => (
                o.x * r.x + o.z * r.z,
                r.x * r.x + r.z * r.z,
                r.x * p.x + r.z * p.z,
            ),
        };
        let (op, k) = (self.op, self.k);
        (self.a, 2.0 * (or * op - k * rp), or * or - k * rr)
    }

    /// Where along the row `r` the quadratic's test passes: None when nowhere,
    /// `Some(None)` when the quadratic is degenerate (every pixel must be tested).
    fn row_roots(&self, r: &Vector3<f64>) -> Option<Option<(f64, f64)>> {
        if !self.proper() {
            return Some(None);
        }
        let (a, b, c) = self.row_quadratic(r);
        // a < 0, so the test passes between the roots.
        roots_by_centre(a, b, c, self.inv_2a).map(Some)
    }

    /// Whether the rows' hull quadratic is a proper one (its leading coefficient
    /// `a` not ≥ −1e-18; a NaN counts, as it always has); else every pixel of the
    /// box must be tested.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    #[inline(always)]
    fn proper(&self) -> bool {
        !(self.a >= -1e-18)
    }

    /// The hull quadratic's terms ([`roots_by_centre`]) on every row of the box,
    /// into `out` (row y0 + k at k); only for a [`Prepared::proper`] quadratic. The
    /// rows are done together in a loop with no branches, which the compiler can
    /// run several rows at a time (with each row's branches in between, each
    /// square root waited on the last).
    #[inline(always)]
    fn hull_rows(&self, out: &mut HullRows) {
        let n = (self.y1 - self.y0 + 1) as usize;
        let (a, inv_2a) = (self.a, self.inv_2a);
        let rows = out.disc[..n]
            .iter_mut()
            .zip(&mut out.centre[..n])
            .zip(&mut out.half[..n]);
        for (k, ((disc, centre), half)) in rows.enumerate() {
            // The same value as row_interval's `y as f64 + 0.5`: rows fit an i32.
            let r = self.row_base((self.y0 as i32 + k as i32) as f64 + 0.5);
            let (_, b, c) = self.row_quadratic(&r);
            *disc = b * b - 4.0 * a * c;
            *centre = -b * inv_2a;
            *half = (disc.sqrt() * inv_2a).abs();
        }
    }

    /// The inclusive pixel span of a row where the quadratic's test passes, clipped
    /// to the bounding box.
    #[inline(always)]
    fn row_span(&self, r: &Vector3<f64>) -> Option<(i64, i64)> {
        // Degenerate (the camera sits inside a cylinder's infinite hull, or the
        // conic is not an ellipse): test every pixel of the box.
        let (lo, hi) = self
            .row_roots(r)?
            .unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
        let x0 = if lo.is_finite() {
            ceil_i64(lo - 0.5).max(self.x0)
        } else {
            self.x0
        };
        let x1 = if hi.is_finite() {
            floor_i64(hi - 0.5).min(self.x1)
        } else {
            self.x1
        };
        (x0 <= x1).then_some((x0, x1))
    }

    /// The part's span on row `y`'s centre line as real columns `[lo, hi]` (pixel x
    /// covers `[x, x + 1)`), clipped to `[0, width]`: the exact roots for an
    /// ellipsoid; for a cylinder the hull's roots where the ray grazing the hull
    /// touches it between the caps, else the ends of the caps' own spans
    /// ([`Prepared::cylinder_row`]). Where those quadratics degenerate, each end is
    /// found to 1/64 of a pixel by bisection ([`Prepared::bisected_row`]).
    ///
    /// Returned as stored in [`PartSpans`], `[0, 0]` when the row misses the part:
    /// a value that fits a register (a wider one went through memory and stalled
    /// the loop that stores it).
    #[inline(always)]
    fn row_interval(&self, y: i64, width: f64) -> [f32; 2] {
        let r = self.row_base(y as f64 + 0.5);
        self.interval_of(&r, self.row_roots(&r), width)
    }

    /// [`Prepared::row_interval`] along the row `r` whose hull roots
    /// ([`Prepared::row_roots`]) are `roots`.
    #[inline(always)]
    fn interval_of(
        &self,
        r: &Vector3<f64>,
        roots: Option<Option<(f64, f64)>>,
        width: f64,
    ) -> [f32; 2] {
        let (lo, hi) = match roots {
            None => return [0.0; 2],
            Some(Some((lo, hi))) if self.kind == Kind::Ellipsoid => (lo, hi),
            Some(Some((lo, hi))) => match self.cylinder_row(r, lo, hi) {
                Some(Some(iv)) => iv,
                Some(None) => return self.bisected_row(r, Some((lo, hi)), width),
                None => return [0.0; 2],
            },
            Some(None) => return self.bisected_row(r, None, width),
        };
        stored_span(lo, hi, width)
    }

    /// A cylinder's span along the row `r` inside its hull's span `[lo, hi]`: None
    /// when the row misses it, `Some(None)` when a quadratic degenerates. The
    /// cylinder is the convex hull of its two caps, so each end of its span is
    /// either the hull's (where the ray grazing the side touches it at a height
    /// between the caps) or a cap's rim (the end of that cap's span).
    #[inline(always)]
    fn cylinder_row(&self, r: &Vector3<f64>, lo: f64, hi: f64) -> Option<Option<(f64, f64)>> {
        let o = &self.o;
        // Whether the ray at u, tangent to the side, touches it between the caps.
        let grazes = |u: f64| {
            let (a, b, _) = side_quadratic(o, &(r + u * self.p));
            if a < 1e-18 {
                return None;
            }
            // The touching point's height y = o.y − b/a·d.y, scaled by a > 0.
            let ay = a * o.y - b * (r.y + u * self.p.y);
            Some((0.0..=a).contains(&ay))
        };
        let (Some(lo_in), Some(hi_in)) = (grazes(lo), grazes(hi)) else {
            return Some(None);
        };
        // Each cap's span is a quadratic's ([`Cap`]). Not an ellipse in the image (a
        // cap seen edge-on): bisect.
        let (p, q) = (&self.p, r);
        if self.caps.iter().any(|c| c.a <= 0.0) {
            return Some(None);
        }
        // Both ends graze the side: the caps' spans are not needed.
        if lo_in && hi_in {
            return Some((lo < hi).then_some((lo, hi)));
        }
        let mut caps: Option<(f64, f64)> = None;
        for &Cap {
            s,
            x1,
            z1,
            a,
            inv_2a,
        } in &self.caps
        {
            let (x0, z0) = (o.x * q.y + s * q.x, o.z * q.y + s * q.z);
            let b = 2.0 * (x0 * x1 + z0 * z1 - q.y * p.y);
            let cc = x0 * x0 + z0 * z0 - q.y * q.y;
            if let Some((l, h)) = roots_by_centre(a, b, cc, inv_2a) {
                caps = Some(caps.map_or((l, h), |(cl, ch)| (cl.min(l), ch.max(h))));
            }
        }
        let (l, h) = match (lo_in, hi_in, caps) {
            // (Both ends graze the side: returned above.)
            (true, true, _) => (lo, hi),
            (true, false, Some((_, ch))) => (lo, ch.min(hi)),
            (false, true, Some((cl, _))) => (cl.max(lo), hi),
            (false, false, Some((cl, ch))) => (cl.max(lo), ch.min(hi)),
            (_, _, None) => return None,
        };
        Some((l < h).then_some((l, h)))
    }

    /// A cylinder's span along the row `r` found by ray tests: inside the hull's
    /// span (None: the whole box), each end bisected to 1/64 of a pixel, clipped
    /// to `[0, width]`. A sliver between two pixel centres is missed.
    #[inline(never)]
    fn bisected_row(&self, r: &Vector3<f64>, hull: Option<(f64, f64)>, width: f64) -> [f32; 2] {
        let (lo, hi, exact) = match hull {
            Some((lo, hi)) => (lo.max(0.0), hi.min(width), true),
            None => (
                (self.x0 as f64 - 0.5).max(0.0),
                (self.x1 as f64 + 1.5).min(width),
                false,
            ),
        };
        if lo >= hi {
            return [0.0; 2];
        }
        let dir = |u: f64| r + u * self.p;
        let (first, last) = (ceil_i64(lo - 0.5), floor_i64(hi - 0.5));
        let (mut x0, mut x1) = (first, last);
        while x0 <= x1 && !self.hits(&dir(x0 as f64 + 0.5)) {
            x0 += 1;
        }
        while x1 >= x0 && !self.hits(&dir(x1 as f64 + 0.5)) {
            x1 -= 1;
        }
        if x0 > x1 {
            return [0.0; 2];
        }
        // From a point off the part (`out`) to one on it (`inside`): where the
        // ray test changes.
        let edge = |mut out: f64, mut inside: f64| {
            for _ in 0..6 {
                let m = 0.5 * (out + inside);
                if self.hits(&dir(m)) {
                    inside = m;
                } else {
                    out = m;
                }
            }
            0.5 * (out + inside)
        };
        // The hull's own end where the ray just inside it meets the part.
        let eps = 1e-4;
        let l = if exact && x0 == first && self.hits(&dir(lo + eps)) {
            lo
        } else {
            edge(lo.max(x0 as f64 - 0.5), x0 as f64 + 0.5)
        };
        let h = if exact && x1 == last && self.hits(&dir(hi - eps)) {
            hi
        } else {
            edge(hi.min(x1 as f64 + 1.5), x1 as f64 + 0.5)
        };
        stored_span(l, h, width)
    }

    /// The exact ray test for the pixel whose ray direction is `d`.
    fn hits(&self, d: &Vector3<f64>) -> bool {
        let o = &self.o;
        match self.kind {
            Kind::Ellipsoid => {
                let od = o.dot(d);
                od < 0.0 && od * od - d.dot(d) * (o.dot(o) - 1.0) >= 0.0
            }
            Kind::Cylinder => cylinder_hit(o, d),
        }
    }

    /// Depth (cm) and canonical normal where the ray `d` enters the part.
    fn entry(&self, d: &Vector3<f64>) -> Option<(f64, Vector3<f64>)> {
        let o = &self.o;
        match self.kind {
            Kind::Ellipsoid => {
                let (od, dd) = (o.dot(d), d.dot(d));
                let disc = od * od - dd * (o.dot(o) - 1.0);
                if od >= 0.0 || disc < 0.0 {
                    return None;
                }
                let t = (-od - disc.sqrt()) / dd;
                Some((t, o + t * d))
            }
            Kind::Cylinder => {
                let (t0, _) = cylinder_interval(o, d)?;
                let side = o + t0 * d;
                if (0.0..=1.0).contains(&side.y) {
                    return Some((t0, Vector3::new(side.x, 0.0, side.z)));
                }
                // Entered through a cap.
                let cap = if side.y < 0.0 { 0.0 } else { 1.0 };
                let t = (cap - o.y) / d.y;
                Some((
                    t,
                    Vector3::new(0.0, if cap == 0.0 { -1.0 } else { 1.0 }, 0.0),
                ))
            }
        }
    }
}

/// For the unit cylinder x² + z² ≤ 1, 0 ≤ y ≤ 1 and the line o + t·d: the range of t
/// inside the infinite cylinder, when the line meets the finite one.
/// `x.ceil() as i64` without the library call the baseline x86-64 target makes for
/// `ceil` (it runs for every row of every part drawn): the same value for every `x`,
/// saturating alike, NaN giving 0.
#[inline]
fn ceil_i64(x: f64) -> i64 {
    let t = x as i64;
    if (t as f64) < x {
        t.saturating_add(1)
    } else {
        t
    }
}

/// `x.floor() as i64`, as [`ceil_i64`].
#[inline]
fn floor_i64(x: f64) -> i64 {
    let t = x as i64;
    if (t as f64) > x {
        t.saturating_sub(1)
    } else {
        t
    }
}

/// The span `[lo, hi]` clipped to `[0, width]` as [`PartSpans`] stores it: `[0, 0]`
/// when nothing is left.
#[inline(always)]
fn stored_span(lo: f64, hi: f64, width: f64) -> [f32; 2] {
    let (lo, hi) = (lo.max(0.0), hi.min(width));
    if lo < hi {
        [lo as f32, hi as f32]
    } else {
        [0.0; 2]
    }
}

/// A cylinder's cap y = c met by the rows' rays: where the ray meets the plane
/// inside the unit circle, (o.x·d.y + s·d.x)² + (o.z·d.y + s·d.z)² ≤ d.y² with
/// s = c − o.y and d = r + u·p, is a quadratic in u whose leading coefficient
/// `a` = x1² + z1² − p.y² (x1 = o.x·p.y + s·p.x, z1 = o.z·p.y + s·p.z) is the same on
/// every row.
#[derive(Clone, Copy, Debug, Default)]
struct Cap {
    s: f64,
    x1: f64,
    z1: f64,
    a: f64,
    inv_2a: f64,
}

impl Cap {
    fn new(o: &Vector3<f64>, p: &Vector3<f64>, c: f64) -> Cap {
        let s = c - o.y;
        let (x1, z1) = (o.x * p.y + s * p.x, o.z * p.y + s * p.z);
        let a = x1 * x1 + z1 * z1 - p.y * p.y;
        Cap {
            s,
            x1,
            z1,
            a,
            inv_2a: 0.5 / a,
        }
    }
}

/// The real roots of a·u² + b·u + c (a ≠ 0) in order, `inv_2a` being 1/(2a): the
/// centre −b/2a ± the half-width √disc/2|a|, by multiplications alone (the two
/// divisions of [`quadratic_roots`] were the longest wait of the rows' loop). Where
/// the centre is far off (a nearly 0) the nearer root would lose digits that way:
/// there the stable form. None when there are none.
#[inline]
fn roots_by_centre(a: f64, b: f64, c: f64, inv_2a: f64) -> Option<(f64, f64)> {
    let disc = b * b - 4.0 * a * c;
    centred_roots(
        disc,
        -b * inv_2a,
        || (disc.sqrt() * inv_2a).abs(),
        || quadratic_roots(a, b, c),
    )
}

/// [`roots_by_centre`]'s roots from the discriminant, the centre and the
/// half-width (`half`, asked for only where it is used); `far` gives them where
/// the centre is too far off.
#[inline(always)]
fn centred_roots(
    disc: f64,
    centre: f64,
    half: impl FnOnce() -> f64,
    far: impl FnOnce() -> Option<(f64, f64)>,
) -> Option<(f64, f64)> {
    if disc < 0.0 {
        return None;
    }
    if centre.abs() > 1e7 {
        return far();
    }
    let half = half();
    Some((centre - half, centre + half))
}

/// The real roots of a·u² + b·u + c (a ≠ 0) in order, computed stably; None when
/// there are none.
#[inline]
fn quadratic_roots(a: f64, b: f64, c: f64) -> Option<(f64, f64)> {
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return None;
    }
    let qq = -0.5 * (b + b.signum() * disc.sqrt());
    let (r1, r2) = if qq != 0.0 {
        (qq / a, c / qq)
    } else {
        (0.0, 0.0)
    };
    Some((r1.min(r2), r1.max(r2)))
}

/// The ray o + t·d against a canonical cylinder's infinite side (x² + z² = 1):
/// (a, b, c) of a·t² + 2b·t + c = 0.
#[inline]
fn side_quadratic(o: &Vector3<f64>, d: &Vector3<f64>) -> (f64, f64, f64) {
    (
        d.x * d.x + d.z * d.z,
        o.x * d.x + o.z * d.z,
        o.x * o.x + o.z * o.z - 1.0,
    )
}

/// Whether [`cylinder_interval`] finds an interval, without its divisions (it runs
/// at both ends of every row of a cylinder drawn): the side's roots and the slab's
/// bounds are compared scaled by the positive leading coefficient.
#[inline]
fn cylinder_hit(o: &Vector3<f64>, d: &Vector3<f64>) -> bool {
    let (a, b, c) = side_quadratic(o, d);
    if a < 1e-18 {
        return !(c > 0.0 || d.y.abs() < 1e-18);
    }
    let disc = b * b - a * c;
    if disc < 0.0 {
        return false;
    }
    let s = disc.sqrt();
    // a·y at the roots t = (−b ∓ s)/a, against a·0 and a·1.
    let ay = a * o.y;
    let (y0, y1) = (ay + (-b - s) * d.y, ay + (-b + s) * d.y);
    !(y0.max(y1) < 0.0 || y0.min(y1) > a)
}

fn cylinder_interval(o: &Vector3<f64>, d: &Vector3<f64>) -> Option<(f64, f64)> {
    let (a, b, c) = side_quadratic(o, d);
    if a < 1e-18 {
        // Along the axis: inside the tube or not at all.
        if c > 0.0 || d.y.abs() < 1e-18 {
            return None;
        }
        let (ta, tb) = ((0.0 - o.y) / d.y, (1.0 - o.y) / d.y);
        return Some((ta.min(tb), ta.max(tb)));
    }
    let disc = b * b - a * c;
    if disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    let (t0, t1) = ((-b - s) / a, (-b + s) / a);
    let (y0, y1) = (o.y + t0 * d.y, o.y + t1 * d.y);
    if y0.max(y1) < 0.0 || y0.min(y1) > 1.0 {
        return None;
    }
    // Clip the interval to the slab 0 ≤ y ≤ 1.
    let (mut lo, mut hi) = (t0, t1);
    if d.y.abs() > 1e-18 {
        let (ta, tb) = ((0.0 - o.y) / d.y, (1.0 - o.y) / d.y);
        lo = lo.max(ta.min(tb));
        hi = hi.min(ta.max(tb));
    }
    Some((lo, hi))
}

/// Draws the silhouette of `body` in pose `posed` seen by `cam` into `mask` (which is
/// cleared first). Allocation-free.
///
/// Compiled twice, like [`span_parts`], and run with AVX2 where the processor has
/// it; the same pixels either way.
///
/// # Panics
/// When `mask` is not the camera's size.
#[multiversion(targets("x86_64+avx2"))]
pub fn render_mask(body: &Body, posed: &Posed, cam: &Camera, mask: &mut Mask) {
    assert!(
        mask.width == cam.width && mask.height == cam.height,
        "mask size differs from the camera's"
    );
    mask.clear();
    for part in &body.parts {
        let to_cam = cam.world_to_camera * posed.joints[part.joint.index()];
        if let Some(prep) = Prepared::new(part, &to_cam, cam) {
            draw_part(&prep, mask);
        }
    }
}

/// Draws the parts of `body` whose indices `parts` lists into `mask`, on top of what
/// it holds (it is not cleared), and returns the range of rows drawn (`None` when no
/// part is on screen). The objective re-renders only the parts a search moves.
/// Allocation-free.
///
/// Compiled twice, like [`span_parts`], and run with AVX2 where the processor has
/// it; the same pixels either way.
///
/// # Panics
/// When `mask` is not the camera's size or an index is not a part's.
#[multiversion(targets("x86_64+avx2"))]
pub fn render_parts(
    body: &Body,
    posed: &Posed,
    cam: &Camera,
    parts: &[usize],
    mask: &mut Mask,
) -> Option<(u32, u32)> {
    assert!(
        mask.width == cam.width && mask.height == cam.height,
        "mask size differs from the camera's"
    );
    let mut rows: Option<(u32, u32)> = None;
    for &pi in parts {
        let part = &body.parts[pi];
        let to_cam = cam.world_to_camera * posed.joints[part.joint.index()];
        if let Some(prep) = Prepared::new(part, &to_cam, cam) {
            draw_part(&prep, mask);
            let (a, b) = (prep.y0 as u32, prep.y1 as u32);
            rows = Some(rows.map_or((a, b), |(lo, hi)| (lo.min(a), hi.max(b))));
        }
    }
    rows
}

/// Each part's span on each row's centre line in real columns, for an objective
/// that moves smoothly as a part's outline crosses a pixel (a pixel counts for the
/// share of its row's centre line the model covers) rather than in whole pixels.
#[derive(Clone, Debug)]
pub struct PartSpans {
    width: u32,
    height: u32,
    /// Per part, the rows last spanned (None: off-screen).
    rows: [Option<(u32, u32)>; PART_COUNT],
    /// `part × height + y` → `[lo, hi]`; `lo ≥ hi` where the row misses the part.
    spans: Vec<[f32; 2]>,
    /// Scratch: one part's hull roots, row by row.
    hull: HullRows,
}

/// A part's hull quadratic on each row of its box ([`Prepared::hull_rows`]): the
/// discriminant, the roots' centre and their half distance, as
/// [`roots_by_centre`] makes them.
#[derive(Clone, Debug)]
struct HullRows {
    disc: Vec<f64>,
    centre: Vec<f64>,
    half: Vec<f64>,
}

impl HullRows {
    fn new(height: u32) -> HullRows {
        let h = height as usize;
        HullRows {
            disc: vec![0.0; h],
            centre: vec![0.0; h],
            half: vec![0.0; h],
        }
    }

    /// Row k's roots, as [`roots_by_centre`] gives them; `quadratic` is the
    /// row's (a, b, c), asked for only where the centre is too far out.
    #[inline(always)]
    fn roots(&self, k: usize, quadratic: impl FnOnce() -> (f64, f64, f64)) -> Option<(f64, f64)> {
        centred_roots(
            self.disc[k],
            self.centre[k],
            || self.half[k],
            || {
                let (a, b, c) = quadratic();
                quadratic_roots(a, b, c)
            },
        )
    }
}

impl PartSpans {
    pub fn new(width: u32, height: u32) -> PartSpans {
        PartSpans {
            width,
            height,
            rows: [None; PART_COUNT],
            spans: vec![[0.0; 2]; PART_COUNT * height as usize],
            hull: HullRows::new(height),
        }
    }

    /// The rows part `i` was last spanned on (None: off-screen).
    pub fn rows(&self, i: usize) -> Option<(u32, u32)> {
        self.rows[i]
    }

    /// Part `i`'s span on row `y` (within [`PartSpans::rows`]), if any.
    #[inline]
    pub fn span(&self, i: usize, y: u32) -> Option<[f32; 2]> {
        let s = self.spans[i * self.height as usize + y as usize];
        (s[0] < s[1]).then_some(s)
    }
}

/// Spans the parts of `body` whose indices `parts` lists into `out` (the other
/// parts' spans are kept). Allocation-free.
///
/// Compiled twice, and run with AVX2 where the processor has it (the rows' roots
/// four at a time; the same arithmetic, so the same spans to the bit).
///
/// # Panics
/// When `out` is not the camera's size or an index is not a part's.
#[multiversion(targets("x86_64+avx2"))]
pub fn span_parts(body: &Body, posed: &Posed, cam: &Camera, parts: &[usize], out: &mut PartSpans) {
    assert!(
        out.width == cam.width && out.height == cam.height,
        "span table size differs from the camera's"
    );
    let (h, width) = (out.height as usize, cam.width as f64);
    for &pi in parts {
        let part = &body.parts[pi];
        let to_cam = cam.world_to_camera * posed.joints[part.joint.index()];
        out.rows[pi] = None;
        let Some(prep) = Prepared::new(part, &to_cam, cam) else {
            continue;
        };
        let spans = &mut out.spans[pi * h..(pi + 1) * h];
        if prep.proper() {
            // Each row's roots computed ahead (row_roots).
            prep.hull_rows(&mut out.hull);
            for (k, y) in (prep.y0..=prep.y1).enumerate() {
                let r = prep.row_base(y as f64 + 0.5);
                let roots = out.hull.roots(k, || prep.row_quadratic(&r));
                spans[y as usize] = prep.interval_of(&r, roots.map(Some), width);
            }
        } else {
            for y in prep.y0..=prep.y1 {
                spans[y as usize] = prep.row_interval(y, width);
            }
        }
        out.rows[pi] = Some((prep.y0 as u32, prep.y1 as u32));
    }
}

#[inline(always)]
fn draw_part(prep: &Prepared, mask: &mut Mask) {
    for y in prep.y0..=prep.y1 {
        let r = prep.row_base(y as f64 + 0.5);
        let Some((mut x0, mut x1)) = prep.row_span(&r) else {
            continue;
        };
        if prep.kind == Kind::Cylinder {
            // The finite cylinder's span is an interval inside the hull's: trim the
            // ends that miss the caps.
            let dir = |x: i64| r + (x as f64 + 0.5) * prep.p;
            while x0 <= x1 && !prep.hits(&dir(x0)) {
                x0 += 1;
            }
            while x1 >= x0 && !prep.hits(&dir(x1)) {
                x1 -= 1;
            }
            if x0 > x1 {
                continue;
            }
        }
        mask.fill_span(y as u32, x0 as u32, x1 as u32);
    }
}

/// Fraction of each pixel covered by the body, from `k × k` ray samples per pixel,
/// each tested directly (no spans): the accuracy reference for [`render_mask`].
pub fn render_coverage(body: &Body, posed: &Posed, cam: &Camera, k: u32) -> Vec<f32> {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let preps: Vec<Prepared> = body
        .parts
        .iter()
        .filter_map(|part| {
            let to_cam = cam.world_to_camera * posed.joints[part.joint.index()];
            Prepared::new(part, &to_cam, cam)
        })
        .collect();
    let mut out = vec![0f32; w * h];
    let step = 1.0 / k as f64;
    for (y, row) in out.chunks_mut(w).enumerate() {
        for (x, cov) in row.iter_mut().enumerate() {
            let mut n = 0;
            for sy in 0..k {
                for sx in 0..k {
                    let u = x as f64 + (sx as f64 + 0.5) * step;
                    let v = y as f64 + (sy as f64 + 0.5) * step;
                    let d = |p: &Prepared| p.g + u * p.p + v * p.q;
                    // A sample inside the box of a part that lies partly outside the
                    // box's pixel bounds would be missed by the fast path too, so the
                    // reference tests every part over the whole image.
                    if preps.iter().any(|p| p.hits(&d(p))) {
                        n += 1;
                    }
                }
            }
            *cov = n as f32 / (k * k) as f32;
        }
    }
    out
}

/// Per-pixel result of a shaded render: the nearest part and its surface normal.
#[derive(Clone, Debug)]
pub struct Fragments {
    pub width: u32,
    pub height: u32,
    /// Depth (cm) of the nearest surface, +∞ where no part is seen.
    pub depth: Vec<f32>,
    /// Index into `body.parts` of the nearest part (meaningless where depth is ∞).
    pub part: Vec<u8>,
    /// Unit normal of the nearest surface in the internal camera frame.
    pub normal: Vec<[f32; 3]>,
}

impl Fragments {
    pub fn new(width: u32, height: u32) -> Fragments {
        let n = width as usize * height as usize;
        Fragments {
            width,
            height,
            depth: vec![f32::INFINITY; n],
            part: vec![0; n],
            normal: vec![[0.0; 3]; n],
        }
    }

    /// The label of pixel `i`'s nearest part (`label` of its index into
    /// `body.parts`) when its four neighbours show parts of the same label; None
    /// where it or a neighbour shows no part, and on the image's border.
    pub fn inner_label<T: PartialEq>(&self, i: usize, label: impl Fn(usize) -> T) -> Option<T> {
        let w = self.width as usize;
        let (x, y) = (i % w, i / w);
        if x == 0 || y == 0 || x + 1 >= w || y + 1 >= self.height as usize {
            return None;
        }
        let of = |j: usize| {
            self.depth[j]
                .is_finite()
                .then(|| label(self.part[j] as usize))
        };
        let l = of(i)?;
        [i - 1, i + 1, i - w, i + w]
            .iter()
            .all(|&j| of(j).as_ref() == Some(&l))
            .then_some(l)
    }
}

/// Depth-tested render of the visible surface (for colour clips and previews).
///
/// # Panics
/// When `out` is not the camera's size.
pub fn render_fragments(body: &Body, posed: &Posed, cam: &Camera, out: &mut Fragments) {
    assert!(out.width == cam.width && out.height == cam.height);
    out.depth.fill(f32::INFINITY);
    for (pi, part) in body.parts.iter().enumerate() {
        let to_cam = cam.world_to_camera * posed.joints[part.joint.index()];
        let Some(prep) = Prepared::new(part, &to_cam, cam) else {
            continue;
        };
        // Canonical normal → camera normal (unnormalised): R · A⁻¹ (made here, not
        // in [`Prepared::new`], whose other callers need no normals).
        let inv_a = inverse_radii(part);
        let normal = to_cam.rotation.matrix() * Matrix3::from_diagonal(&inv_a);
        for y in prep.y0..=prep.y1 {
            let r = prep.row_base(y as f64 + 0.5);
            let Some((x0, x1)) = prep.row_span(&r) else {
                continue;
            };
            for x in x0..=x1 {
                let d = r + (x as f64 + 0.5) * prep.p;
                let Some((t, n)) = prep.entry(&d) else {
                    continue;
                };
                let i = y as usize * cam.width as usize + x as usize;
                if (t as f32) < out.depth[i] {
                    out.depth[i] = t as f32;
                    out.part[i] = pi as u8;
                    let n = (normal * n).normalize();
                    out.normal[i] = [n.x as f32, n.y as f32, n.z as f32];
                }
            }
        }
    }
}

/// Pixel positions of the 18 joints and 5 tips (None behind the camera).
pub fn project_landmarks(posed: &Posed, cam: &Camera) -> [Option<[f64; 2]>; LANDMARK_COUNT] {
    let pts = posed.landmarks();
    let mut out = [None; LANDMARK_COUNT];
    for (o, p) in out.iter_mut().zip(pts.iter()) {
        *o = cam.project(p);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::params::{self, STANDARD_SHAPE};
    use crate::body::parts::Material;
    use crate::body::skeleton::Joint;
    use nalgebra::{Translation3, Vector3};

    #[test]
    fn fill_span_sets_exactly_the_span() {
        let mut m = Mask::new(200, 3);
        m.fill_span(1, 3, 130);
        assert_eq!(m.count(), 128);
        assert!(!m.get(2, 1) && m.get(3, 1) && m.get(130, 1) && !m.get(131, 1));
        m.fill_span(2, 64, 64);
        assert!(m.get(64, 2) && m.count() == 129);
        m.fill_span(0, 0, 199);
        assert_eq!(m.count(), 329);
        let g = m.to_gray();
        assert_eq!(Mask::from_gray(&g, 128), m);
    }

    proptest::proptest! {
        #[test]
        fn cylinder_hit_agrees_with_the_interval(
            o in proptest::array::uniform3(-3.0f64..3.0),
            d in proptest::array::uniform3(-1.0f64..1.0),
        ) {
            let (o, d) = (Vector3::from(o), Vector3::from(d));
            let hit = cylinder_hit(&o, &d);
            let interval = cylinder_interval(&o, &d);
            // Only a ray grazing a cap's rim (a root's height within rounding of 0
            // or 1) may be judged apart.
            let grazing = {
                let (a, b, c) = side_quadratic(&o, &d);
                let disc = b * b - a * c;
                disc >= 0.0 && a >= 1e-18 && [-1.0, 1.0].iter().any(|sg| {
                    let y = o.y + (-b + sg * disc.sqrt()) / a * d.y;
                    y.abs() < 1e-9 || (y - 1.0).abs() < 1e-9
                })
            };
            proptest::prop_assert!(grazing || hit == interval.is_some());
        }
    }

    #[test]
    fn ceil_and_floor_match_the_library_s() {
        let mut xs = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            1.5,
            -1.5,
            2.0f64.powi(52) + 0.5,
            2.0f64.powi(53),
            -(2.0f64.powi(53)),
            9.3e18,
            -9.3e18,
            f64::MAX,
            f64::MIN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::EPSILON,
            -f64::EPSILON,
            f64::MIN_POSITIVE,
        ];
        xs.extend((-2000..2000).map(|i| i as f64 * 0.173 - 0.5));
        for x in xs {
            assert_eq!(ceil_i64(x), x.ceil() as i64, "ceil {x}");
            assert_eq!(floor_i64(x), x.floor() as i64, "floor {x}");
        }
    }

    proptest::proptest! {
        #[test]
        fn square_dilation_matches_imageproc(
            w in 1u32..200,
            h in 1u32..40,
            r in 0u32..140,
            seeds in proptest::collection::vec((0u32..200, 0u32..40), 1..12),
        ) {
            let mut m = Mask::new(w, h);
            for (x, y) in seeds {
                m.set(x % w, y % h, true);
            }
            let expect = imageproc::morphology::dilate(
                &m.to_gray(),
                imageproc::distance_transform::Norm::LInf,
                r.min(255) as u8,
            );
            proptest::prop_assert_eq!(m.dilated_square(r), Mask::from_gray(&expect, 128));
        }
    }

    #[test]
    fn an_empty_mask_dilates_to_an_empty_mask() {
        let m = Mask::new(100, 50);
        assert_eq!(m.dilated_square(5), m);
        assert_eq!(m.dilated_square(0), m);
    }

    /// A body of one sphere, to check the projection against a closed form.
    fn one_sphere(radius: f64) -> Body {
        let mut body = Body::new(&STANDARD_SHAPE);
        let sphere = Part {
            name: "ball",
            joint: Joint::Hips,
            kind: Kind::Ellipsoid,
            center: Vector3::zeros(),
            radii: Vector3::new(radius, radius, radius),
            material: Material::Skin,
        };
        body.parts = [sphere; crate::body::parts::PART_COUNT];
        body
    }

    #[test]
    fn sphere_on_axis_covers_the_closed_form_disc() {
        // A sphere of radius r at distance D on the optical axis projects to a disc of
        // radius f·r/√(D² − r²).
        let cam = Camera::new(640, 480, 50.0);
        let (r, dist) = (40.0, 500.0);
        let body = one_sphere(r);
        let mut pose = params::rest_pose();
        pose[0..3].copy_from_slice(&[0.0, 0.0, -dist]);
        let posed = body.skeleton.posed(&pose);
        let mut mask = Mask::new(640, 480);
        render_mask(&body, &posed, &cam, &mut mask);
        let rad = cam.fx * r / (dist * dist - r * r).sqrt();
        let expected = std::f64::consts::PI * rad * rad;
        let got = mask.count() as f64;
        assert!(
            (got - expected).abs() / expected < 0.005,
            "{got} vs {expected}"
        );
        // Symmetric about the principal point.
        assert!(mask.get(320, 240) && mask.get(319, 239));
        assert!(!mask.get(320 + rad as u32 + 2, 240));
    }

    #[test]
    fn fast_render_matches_direct_ray_tests_per_pixel() {
        let body = Body::new(&STANDARD_SHAPE);
        let mut pose = params::rest_pose();
        pose[params::ix::ROOT_TZ] = -400.0;
        pose[params::ix::ROOT_TY] = -10.0;
        pose[params::ix::ROOT_RY] = 35.0;
        pose[params::ix::L_SHOULDER + 1] = 80.0;
        pose[params::ix::R_ELBOW] = 100.0;
        pose[params::ix::L_KNEE] = 60.0;
        let posed = body.skeleton.posed(&pose);
        let cam = Camera::new(160, 120, 55.0).with_pose(IsometryMatrix3::from_parts(
            Translation3::new(0.0, 0.0, 0.0),
            nalgebra::Rotation3::identity(),
        ));
        let (mask, differs) = render_against_ray_tests(&body, &posed, &cam);
        assert_eq!(differs, None, "pixel (x, y) where the fast render differs");
        assert!(mask.count() > 500);
    }

    /// The fast render of `posed`, and the first pixel (x, y) where it differs from
    /// the direct ray test of every part ([`render_coverage`] at one sample a pixel).
    fn render_against_ray_tests(
        body: &Body,
        posed: &Posed,
        cam: &Camera,
    ) -> (Mask, Option<(u32, u32)>) {
        let mut mask = Mask::new(cam.width, cam.height);
        render_mask(body, posed, cam, &mut mask);
        let cov = render_coverage(body, posed, cam, 1);
        let differs = (0..cam.height)
            .flat_map(|y| (0..cam.width).map(move |x| (x, y)))
            .find(|&(x, y)| mask.get(x, y) != (cov[(y * cam.width + x) as usize] > 0.5));
        (mask, differs)
    }

    /// The standard body in the pose `unit` spreads within the joint limits (its first
    /// two values also placing the root), `depth` cm in front of a 120×90 camera,
    /// turned to `heading`.
    fn any_pose(unit: &[f64], depth: f64, heading: f64) -> (Body, Posed, Camera) {
        let body = Body::new(&STANDARD_SHAPE);
        let mut pose = params::rest_pose();
        for (k, t) in unit.iter().enumerate().skip(params::ix::ROOT_RX) {
            let m = &params::MOTION[k];
            pose[k] = m.lo + t * (m.hi - m.lo);
        }
        pose[params::ix::ROOT_TX] = (unit[0] - 0.5) * 60.0;
        pose[params::ix::ROOT_TY] = (unit[1] - 0.5) * 60.0;
        pose[params::ix::ROOT_TZ] = -depth;
        pose[params::ix::ROOT_RY] = heading;
        let posed = body.skeleton.posed(&pose);
        let cam = Camera::new(120, 90, 55.0).with_pose(IsometryMatrix3::identity());
        (body, posed, cam)
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(200))]

        /// Any pose within the joint limits and any heading, near and far, limbs
        /// pointing at the camera or across it: the fast render (row spans, cylinder
        /// ends trimmed at the caps) covers exactly the pixels whose rays meet a part.
        #[test]
        fn fast_render_matches_direct_ray_tests_in_any_pose(
            unit in proptest::collection::vec(0.0f64..1.0, params::MOTION_COUNT),
            depth in 150.0f64..600.0,
            heading in -180.0f64..180.0,
        ) {
            let (body, posed, cam) = any_pose(&unit, depth, heading);
            let (_, differs) = render_against_ray_tests(&body, &posed, &cam);
            proptest::prop_assert_eq!(differs, None, "pixel (x, y) where the fast render differs");
        }
    }

    /// Every part's row spans at the pose, and each part's projection set up.
    fn spans_and_preps(
        body: &Body,
        posed: &Posed,
        cam: &Camera,
    ) -> (PartSpans, Vec<Option<Prepared>>) {
        let mut spans = PartSpans::new(cam.width, cam.height);
        let all: Vec<usize> = (0..PART_COUNT).collect();
        span_parts(body, posed, cam, &all, &mut spans);
        let preps = body
            .parts
            .iter()
            .map(|part| {
                let to_cam = cam.world_to_camera * posed.joints[part.joint.index()];
                Prepared::new(part, &to_cam, cam)
            })
            .collect();
        (spans, preps)
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(100))]

        /// The span table, its rows' roots computed together (four at a time where
        /// the processor has AVX2), holds to the bit what each row's interval on its
        /// own gives.
        #[test]
        fn span_table_is_each_rows_own_interval(
            unit in proptest::collection::vec(0.0f64..1.0, params::MOTION_COUNT),
            depth in 150.0f64..600.0,
            heading in -180.0f64..180.0,
        ) {
            let (body, posed, cam) = any_pose(&unit, depth, heading);
            let (spans, preps) = spans_and_preps(&body, &posed, &cam);
            for (i, prep) in preps.iter().enumerate() {
                proptest::prop_assert_eq!(
                    spans.rows(i),
                    prep.as_ref().map(|p| (p.y0 as u32, p.y1 as u32))
                );
                let Some(p) = prep else { continue };
                for y in p.y0..=p.y1 {
                    let own = p.row_interval(y, cam.width as f64);
                    let held = spans.spans[i * cam.height as usize + y as usize];
                    proptest::prop_assert_eq!(
                        own.map(f32::to_bits),
                        held.map(f32::to_bits),
                        "part {} row {}", i, y
                    );
                }
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(40))]

        /// Poses as above: each part's real span on each row holds the points of the
        /// row's centre line, sampled 64 to a pixel, whose rays meet the part, to
        /// within 1/16 of a pixel at either end (a cylinder's sliver narrower than a
        /// pixel may be missed whole).
        #[test]
        fn spans_match_dense_ray_tests_along_each_row(
            unit in proptest::collection::vec(0.0f64..1.0, params::MOTION_COUNT),
            depth in 150.0f64..600.0,
            heading in -180.0f64..180.0,
        ) {
            let (body, posed, cam) = any_pose(&unit, depth, heading);
            let (spans, preps) = spans_and_preps(&body, &posed, &cam);
            let k = 64;
            for (i, (part, prep)) in body.parts.iter().zip(&preps).enumerate() {
                for y in 0..cam.height {
                    // The samples along the row's centre line whose rays meet the part.
                    let hit: Vec<f64> = match &prep {
                        Some(p) => (0..cam.width * k)
                            .map(|s| (s as f64 + 0.5) / k as f64)
                            .filter(|&u| p.hits(&(p.row_base(y as f64 + 0.5) + u * p.p)))
                            .collect(),
                        None => Vec::new(),
                    };
                    let got = spans
                        .rows(i)
                        .filter(|(a, b)| (*a..=*b).contains(&y))
                        .and_then(|_| spans.span(i, y));
                    let tol = 1.0 / 16.0;
                    match (hit.first(), hit.last(), got) {
                        (Some(&lo), Some(&hi), Some([a, b])) => {
                            proptest::prop_assert!(
                                (a as f64 - lo).abs() < tol && (b as f64 - hi).abs() < tol,
                                "part {} row {}: [{}, {}] against [{}, {}]", i, y, a, b, lo, hi
                            );
                        }
                        (Some(&lo), Some(&hi), None) => proptest::prop_assert!(
                            part.kind == Kind::Cylinder && hi - lo < 1.0,
                            "part {} row {}: missed [{}, {}]", i, y, lo, hi
                        ),
                        (None, _, Some([a, b])) => proptest::prop_assert!(
                            b - a < 2.0 * tol as f32,
                            "part {} row {}: [{}, {}] where no sample hits", i, y, a, b
                        ),
                        _ => {}
                    }
                }
            }
        }
    }
}
