//! Stereo search regions: the epipolar band of a rectified pair or of a general
//! calibrated rig, limited by a disparity (depth) range.
//!
//! General rig: with the left camera as reference, a point on the left ray
//! `lambda * d_L` (`d_L = (xc, yc, -f)`, corrected coordinates) is
//! `X_R = Mrel (lambda d_L - b)` in the right camera frame, so the epipolar line in
//! the right image is `l = E x_L` with `E = [t]x Mrel`, `t = Mrel b`, and the depth
//! range `[z_min, z_max]` (`lambda = z / f`) cuts a segment out of it. Working in
//! corrected coordinates makes the line straight; the pixel search rectangle is the
//! bounding box of the segment's samples mapped back through the distortion.

use super::config::EPIPOLAR_SAMPLES;
use super::search::SearchRegion;
use crate::camera::{Interior, Rig};
use crate::features::Keypoint;
use nalgebra::{Matrix3, Vector3};

/// Rectified: same row within `row_tol`, disparity `x_l - x_r` in `[dmin, dmax]`.
pub struct RectifiedBand {
    pub row_tol: f32,
    pub dmin: f32,
    pub dmax: f32,
}

impl SearchRegion for RectifiedBand {
    type Query = (f32, f32);

    fn prepare(&self, _qi: usize, q: &Keypoint) -> Option<([f32; 4], (f32, f32))> {
        if !(q.x.is_finite() && q.y.is_finite()) {
            return None;
        }
        let rect = [
            q.x - self.dmax,
            q.y - self.row_tol,
            q.x - self.dmin,
            q.y + self.row_tol,
        ];
        Some((rect, (q.x, q.y)))
    }

    #[inline]
    fn contains(&self, &(x, y): &(f32, f32), _ti: usize, t: &Keypoint) -> bool {
        let d = x - t.x;
        (t.y - y).abs() <= self.row_tol && d >= self.dmin && d <= self.dmax
    }
}

/// The epipolar band of a general rig, in corrected right photo-coordinates.
pub struct RigBand<'c> {
    left: Interior,
    right: Interior,
    mrel: Matrix3<f64>,
    /// `E = [t]x Mrel`.
    essential: Matrix3<f64>,
    t: Vector3<f64>,
    tol_mm: f64,
    min_depth: f64,
    max_depth: f64,
    /// Corrected reduced coordinates of the right keypoints (mm), precomputed.
    right_corrected: &'c [[f32; 2]],
}

/// Per-left-keypoint data: the line and the depth segment on it.
pub struct RigQuery {
    /// Unit normal `(a, b)` and offset `c` of the line `a x + b y + c = 0` (mm).
    line: [f64; 3],
    /// Segment end points (near, far) in corrected right coordinates.
    near: [f64; 2],
    far: [f64; 2],
}

impl<'c> RigBand<'c> {
    /// `right_corrected[i]` must hold `rig.right.pixel_to_corrected` of right keypoint `i`.
    pub fn new(
        rig: &Rig,
        tolerance_px: f32,
        min_depth_m: f64,
        max_depth_m: f64,
        right_corrected: &'c [[f32; 2]],
    ) -> Self {
        let mrel = rig.relative_rotation();
        let t = mrel * Vector3::from(rig.base_m);
        let tx = Matrix3::new(0.0, -t[2], t[1], t[2], 0.0, -t[0], -t[1], t[0], 0.0);
        let px = 0.5 * (rig.right.pixel_size_mm[0] + rig.right.pixel_size_mm[1]);
        RigBand {
            left: rig.left,
            right: rig.right,
            mrel,
            essential: tx * mrel,
            t,
            tol_mm: tolerance_px as f64 * px,
            min_depth: min_depth_m,
            max_depth: max_depth_m,
            right_corrected,
        }
    }

    /// The band over `right` keypoints, their corrected coordinates written into
    /// `buf` (at least as long as `right`).
    pub fn over(
        rig: &Rig,
        tolerance_px: f32,
        depth_m: (f64, f64),
        right: &[Keypoint],
        buf: &'c mut [[f32; 2]],
    ) -> Self {
        let n = right.len().min(buf.len());
        Self::correct_keypoints(&rig.right, &right[..n], &mut buf[..n]);
        RigBand::new(rig, tolerance_px, depth_m.0, depth_m.1, &buf[..n])
    }

    /// Fills `out[i]` with the corrected coordinates of each right keypoint.
    fn correct_keypoints(right: &Interior, keypoints: &[Keypoint], out: &mut [[f32; 2]]) {
        for (o, kp) in out.iter_mut().zip(keypoints) {
            let [x, y] = right.pixel_to_corrected(kp.x as f64, kp.y as f64);
            *o = [x as f32, y as f32];
        }
    }

    /// Corrected right coordinates of the left ray at depth `z` (`None` behind the camera).
    fn at_depth(&self, d_l: &Vector3<f64>, z: f64) -> Option<[f64; 2]> {
        let p = if z.is_finite() {
            self.mrel * (d_l * (z / self.left.focal_mm)) - self.t
        } else {
            // The vanishing point of the ray.
            self.mrel * d_l
        };
        if p[2].is_nan() || p[2] >= -1e-12 {
            return None;
        }
        let f = self.right.focal_mm;
        Some([-f * p[0] / p[2], -f * p[1] / p[2]])
    }
}

impl RigBand<'_> {
    /// Signed distance (mm) of right keypoint `ti` from the epipolar line of left
    /// keypoint `left`, and the line's unit normal: the right point sits at its line
    /// plus `distance * normal`.
    pub fn across(&self, left: &Keypoint, ti: usize) -> Option<(f64, [f64; 2])> {
        let (line, _) = self.line_of(left)?;
        let &p = self.right_corrected.get(ti)?;
        Some((distance(&line, p), [line[0], line[1]]))
    }

    /// The epipolar line of left keypoint `q` in corrected right photo-coordinates
    /// (unit normal and offset, mm) and the left ray it comes from.
    fn line_of(&self, q: &Keypoint) -> Option<([f64; 3], Vector3<f64>)> {
        if !(q.x.is_finite() && q.y.is_finite()) {
            return None;
        }
        let [xc, yc] = self.left.pixel_to_corrected(q.x as f64, q.y as f64);
        let d_l = Vector3::new(xc, yc, -self.left.focal_mm);
        let l = self.essential * d_l;
        // Right image point (x, y, -f): a x + b y - f c = 0.
        let norm = libm::sqrt(l[0] * l[0] + l[1] * l[1]);
        if norm.is_nan() || norm <= 0.0 {
            return None;
        }
        let line = [l[0] / norm, l[1] / norm, -self.right.focal_mm * l[2] / norm];
        Some((line, d_l))
    }
}

/// Signed distance of the point `p` from the unit-normal line `line`.
fn distance(line: &[f64; 3], [x, y]: [f32; 2]) -> f64 {
    line[0] * x as f64 + line[1] * y as f64 + line[2]
}

impl SearchRegion for RigBand<'_> {
    type Query = RigQuery;

    fn prepare(&self, _qi: usize, q: &Keypoint) -> Option<([f32; 4], RigQuery)> {
        let (line, d_l) = self.line_of(q)?;
        let near = self.at_depth(&d_l, self.min_depth)?;
        let far = self.at_depth(&d_l, self.max_depth)?;
        // Bounding box in pixels of samples along the (straight, corrected) segment.
        let mut rect = [f32::MAX, f32::MAX, f32::MIN, f32::MIN];
        let mut any = false;
        for s in 0..EPIPOLAR_SAMPLES {
            let a = s as f64 / (EPIPOLAR_SAMPLES - 1) as f64;
            let x = near[0] + a * (far[0] - near[0]);
            let y = near[1] + a * (far[1] - near[1]);
            if let Ok([c, r]) = self.right.corrected_to_pixel(x, y) {
                rect[0] = rect[0].min(c as f32);
                rect[1] = rect[1].min(r as f32);
                rect[2] = rect[2].max(c as f32);
                rect[3] = rect[3].max(r as f32);
                any = true;
            }
        }
        if !any {
            return None;
        }
        // Tolerance plus the bow of the distorted curve between samples.
        let pad = (self.tol_mm / self.right.pixel_size_mm[0].min(self.right.pixel_size_mm[1]))
            as f32
            + 1.0;
        let rect = [rect[0] - pad, rect[1] - pad, rect[2] + pad, rect[3] + pad];
        Some((rect, RigQuery { line, near, far }))
    }

    #[inline]
    fn contains(&self, q: &RigQuery, ti: usize, _t: &Keypoint) -> bool {
        let Some(&p) = self.right_corrected.get(ti) else {
            return false;
        };
        if distance(&q.line, p).abs() > self.tol_mm {
            return false;
        }
        let [x, y] = p.map(|v| v as f64);
        // Position along the segment: within [near, far] up to the tolerance.
        let (sx, sy) = (q.far[0] - q.near[0], q.far[1] - q.near[1]);
        let len2 = sx * sx + sy * sy;
        let along = (x - q.near[0]) * sx + (y - q.near[1]) * sy;
        let slack = self.tol_mm * libm::sqrt(len2);
        along >= -slack && along <= len2 + slack
    }
}

/// Where the right keypoints lie across their epipolar lines
/// ([`super::Matcher::epipolar_offset`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpipolarOffset {
    /// Median signed distance from the lines, pixels, along `normal`.
    pub median_px: f64,
    /// The lines' mean unit normal in the right camera's photo-coordinates.
    pub normal: [f64; 2],
    /// Matches the median is taken over.
    pub matches: u32,
}

/// A median over a bounded range without storing the values: counts in bins of
/// `BinnedMedian::STEP` pixels, the median interpolated within its bin.
pub(crate) struct BinnedMedian {
    counts: [u32; BinnedMedian::BINS],
    low: f64,
    n: usize,
}

impl BinnedMedian {
    const BINS: usize = 200;
    const STEP: f64 = 0.05;

    /// Values within `+- half_width` pixels, at most `BINS * STEP / 2` (5 px); those
    /// beyond count at the ends, which moves no median inside the range.
    pub(crate) fn new(half_width: f64) -> Self {
        let half = half_width.min(Self::BINS as f64 * Self::STEP / 2.0);
        BinnedMedian {
            counts: [0; Self::BINS],
            low: -half,
            n: 0,
        }
    }

    pub(crate) fn add(&mut self, v: f64) {
        if !v.is_finite() {
            return;
        }
        let b = ((v - self.low) / Self::STEP).max(0.0) as usize;
        let b = b.min(Self::BINS - 1);
        self.counts[b] = self.counts[b].saturating_add(1);
        self.n += 1;
    }

    pub(crate) fn count(&self) -> usize {
        self.n
    }

    pub(crate) fn median(&self) -> Option<f64> {
        let half = self.n as f64 / 2.0;
        let mut below = 0.0;
        for (b, &c) in self.counts.iter().enumerate() {
            let c = c as f64;
            if c > 0.0 && below + c >= half {
                let frac = (half - below) / c;
                return Some(self.low + (b as f64 + frac) * Self::STEP);
            }
            below += c;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::BinnedMedian;

    #[test]
    fn binned_median_interpolates_within_its_bin() {
        let mut m = BinnedMedian::new(5.0);
        assert_eq!(m.median(), None);
        // Four values in the bin [1.50, 1.55), three below it (one beyond the range,
        // counted at its end), one above, and a non-finite one, not counted. The median
        // (the 4th of 8) is a quarter into the bin, its values taken as spread evenly.
        for v in [1.51, 1.51, 1.52, 1.53, -1.0, -2.0, -9.0, 3.0, f64::NAN] {
            m.add(v);
        }
        assert_eq!(m.count(), 8);
        let median = m.median().unwrap();
        assert!((median - 1.5125).abs() < 1e-9, "{median}");
        let mut even = BinnedMedian::new(2.0);
        (0..100).for_each(|i| even.add(-1.98 + 0.04 * i as f64));
        assert!(even.median().unwrap().abs() < 1e-9);
    }
}
