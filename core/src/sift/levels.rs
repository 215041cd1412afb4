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
