//! Read access to the Gaussian rings of one octave: rows addressed by their image
//! row, clamped into the octave, columns clamped into the row.

use super::config::Geometry;

/// The Gaussian levels of the octave being processed, as rings of rows.
#[derive(Clone, Copy)]
pub struct Levels<'x> {
    pub data: &'x [i16],
    /// Row stride of the rings (the configured maximum width).
    pub stride: usize,
    /// Octave width and height.
    pub w: usize,
    pub h: usize,
    pub geo: &'x Geometry,
    /// Gradient operator of orientations and descriptors on these levels.
    pub gradient: Gradient,
}

impl<'x> Levels<'x> {
    /// Row `r` (clamped into the octave) of level `k`. The caller keeps `r` inside the
    /// ring's window; outside it the row holds other data but the access stays in bounds.
    #[inline]
    pub fn row(&self, k: usize, r: isize) -> &'x [i16] {
        let k = k.min(self.geo.n - 1);
        let r = r.clamp(0, self.h as isize - 1) as usize;
        let slot = self.geo.gring_row0[k] + r % self.geo.depth[k];
        let start = slot * self.stride;
        self.data.get(start..start + self.w).unwrap_or(&[])
    }

    /// Pixel of level `k` with clamped coordinates, as i32 (grey levels times 64).
    #[inline]
    pub fn px(&self, k: usize, r: isize, c: isize) -> i32 {
        let row = self.row(k, r);
        if row.is_empty() {
            return 0;
        }
        row[c.clamp(0, row.len() as isize - 1) as usize] as i32
    }

    /// Difference of Gaussians of layer `k` (level k+1 minus level k).
    #[inline]
    pub fn dog(&self, k: usize, r: isize, c: isize) -> i32 {
        self.px(k + 1, r, c) - self.px(k, r, c)
    }
}

/// Gradient operators (all scaled to grey levels per pixel).
///
/// On a level blurred by only about one pixel, central differences bend directions
/// towards the diagonals by several degrees (a wave of 1.5 rad/px at 30 deg reads 35
/// deg); Scharr's cross smoothing cancels most of it (0.3 deg), Farid and Simoncelli's
/// 5-tap pair is optimised for rotation-equivariant gradients over a wider band.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Gradient {
    /// `[-1 0 1] / 2` (Lowe, OpenCV), here unscaled: `[-1 0 1]`.
    Central,
    /// Central differences smoothed across by `[3 10 3] / 16`.
    Scharr,
    /// Farid and Simoncelli's 5-tap derivative and prefilter.
    Farid,
}

impl Gradient {
    /// Columns (and rows) the operator reaches on each side of the sample.
    pub const fn reach(self) -> usize {
        match self {
            Gradient::Central | Gradient::Scharr => 1,
            Gradient::Farid => 2,
        }
    }

    /// Gradient (dx, dy) at column `c` of `rows[2]`, with `rows[i]` the image row `i - 2`
    /// rows away; `None` when the operator does not fit inside the rows.
    #[inline]
    pub fn at(self, rows: &[&[i16]; 5], c: usize) -> Option<(f32, f32)> {
        let m = self.reach();
        let window = &rows[2 - m..=2 + m];
        if !fits(window, c, m) {
            return None;
        }
        Some(match self {
            Gradient::Central => central(window, c),
            Gradient::Scharr => scharr(window, c),
            Gradient::Farid => farid(window, c),
        })
    }
}

/// Do columns `c - m..=c + m` exist in every row of `window`?
#[inline(always)]
pub fn fits(window: &[&[i16]], c: usize, m: usize) -> bool {
    c >= m && window.iter().all(|r| c + m < r.len())
}

/// Central differences on rows `window[0..3]` (the caller checked [`fits`]).
#[inline(always)]
pub fn central(window: &[&[i16]], c: usize) -> (f32, f32) {
    let (up, row, down) = (window[0], window[1], window[2]);
    (
        (row[c + 1] as i32 - row[c - 1] as i32) as f32,
        (down[c] as i32 - up[c] as i32) as f32,
    )
}

/// Scharr's operator on rows `window[0..3]`, scaled like [`central`].
#[inline(always)]
pub fn scharr(window: &[&[i16]], c: usize) -> (f32, f32) {
    let (up, row, down) = (window[0], window[1], window[2]);
    let d = |r: &[i16]| r[c + 1] as i32 - r[c - 1] as i32;
    let v = |i: usize| down[i] as i32 - up[i] as i32;
    let dx = 3 * (d(up) + d(down)) + 10 * d(row);
    let dy = 3 * (v(c - 1) + v(c + 1)) + 10 * v(c);
    (dx as f32 * 0.0625, dy as f32 * 0.0625)
}

/// Farid and Simoncelli's 5-tap operator on rows `window[0..5]`, scaled like [`central`].
#[inline(always)]
pub fn farid(window: &[&[i16]], c: usize) -> (f32, f32) {
    const P: [f32; 5] = [0.037659, 0.249153, 0.426375, 0.249153, 0.037659];
    const D: [f32; 5] = [-0.109604, -0.276691, 0.0, 0.276691, 0.109604];
    let mut dx = 0.0;
    let mut dy = 0.0;
    for (i, r) in window.iter().enumerate().take(5) {
        let mut sx = 0.0;
        let mut sp = 0.0;
        for j in 0..5 {
            let p = r[c + j - 2] as f32;
            sx += D[j] * p;
            sp += P[j] * p;
        }
        dx += P[i] * sx;
        dy += D[i] * sp;
    }
    (dx * 2.0, dy * 2.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On a linear ramp every operator reads the ramp's slope times two (the unscaled
    /// central difference), Farid's within its 1 % of design error.
    #[test]
    fn operators_read_the_slope_of_a_ramp() {
        let (a, b) = (7i32, -3i32);
        let rows: [[i16; 9]; 5] = core::array::from_fn(|r| {
            core::array::from_fn(|c| (100 + a * c as i32 + b * r as i32) as i16)
        });
        let refs: [&[i16]; 5] = core::array::from_fn(|r| &rows[r][..]);
        for op in [Gradient::Central, Gradient::Scharr, Gradient::Farid] {
            let (dx, dy) = op.at(&refs, 4).unwrap();
            let tol = if op == Gradient::Farid { 0.02 } else { 0.0 };
            assert!(
                (dx - 2.0 * a as f32).abs() <= tol * (2 * a).abs() as f32,
                "{op:?} dx {dx}"
            );
            assert!(
                (dy - 2.0 * b as f32).abs() <= tol * (2 * b).abs() as f32,
                "{op:?} dy {dy}"
            );
        }
        // Columns the operator cannot reach give nothing.
        assert_eq!(Gradient::Central.at(&refs, 0), None);
        assert!(Gradient::Central.at(&refs, 7).is_some());
        assert_eq!(Gradient::Farid.at(&refs, 1), None);
        assert_eq!(Gradient::Farid.at(&refs, 7), None);
    }
}
