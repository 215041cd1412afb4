//! One row of the descriptor's sampling grid, in four passes: placement (pixel and
//! bins of each sample), gradients (row lookups, scalar), magnitudes and orientation
//! bins, and the trilinear scatter into the padded histogram.
//!
//! Placement and magnitudes run four samples at a time with SSE2 on x86_64 and in
//! scalar elsewhere. Both do the same IEEE operations in the same order (no fused
//! multiply-add), so a descriptor has the same bytes on the host and the
//! microcontroller; a test compares the two paths bit for bit.

use core::f32::consts::PI;

use super::config::{DESC_BINS, DESC_GRID, DESC_ORI_BINS};
#[cfg(any(test, not(target_arch = "x86_64")))]
use super::fastmath::{atan2_pos, floor_i, round_i};
use super::levels::{central, farid, fits, scharr, Gradient};

/// Padded histogram cells: positions -1..=D on both axes, orientations with a wrap slot.
pub const P: usize = DESC_BINS + 2;
pub const NO: usize = DESC_ORI_BINS + 1;
pub const PADDED: usize = P * P * NO;

/// The keypoint frame a descriptor samples in.
#[derive(Debug, Clone, Copy)]
pub struct Frame {
    pub x: f32,
    pub y: f32,
    pub cos_t: f32,
    pub sin_t: f32,
    pub inv_hw: f32,
    pub half: f32,
    /// Octave width and height.
    pub w: i32,
    pub h: i32,
}

/// One grid row of samples. A sample outside the image or the bins has `ok == 0` and,
/// after the gradient pass, zero weight (so zero magnitude: the scatter skips it).
#[derive(Debug, Clone, Copy, bytemuck::Zeroable)]
pub struct RowSamples {
    pub pc: [i32; DESC_GRID],
    pub pr: [i32; DESC_GRID],
    pub ok: [i32; DESC_GRID],
    pub rbin: [f32; DESC_GRID],
    pub cbin: [f32; DESC_GRID],
    pub dx: [f32; DESC_GRID],
    pub dy: [f32; DESC_GRID],
    pub wgt: [f32; DESC_GRID],
    pub mag: [f32; DESC_GRID],
    pub obin: [f32; DESC_GRID],
    /// Lower orientation bin (clamped into 0..N) and padded spatial bins (bin -1 is 0).
    pub o0: [i32; DESC_GRID],
    pub r0: [i32; DESC_GRID],
    pub c0: [i32; DESC_GRID],
    /// Fractions towards the next orientation, row and column bin.
    pub fo: [f32; DESC_GRID],
    pub fr: [f32; DESC_GRID],
    pub fc: [f32; DESC_GRID],
}

impl Default for RowSamples {
    fn default() -> Self {
        bytemuck::Zeroable::zeroed()
    }
}

impl RowSamples {
    /// Places the samples of a grid row: sample `j` is at (`x + ucos[j] - vsin`,
    /// `y + usin[j] + vcos`), rounded to the nearest pixel; its bins come from the exact
    /// position of that pixel, so rounding does not blur the spatial binning under rotation.
    pub fn place(
        &mut self,
        f: &Frame,
        ucos: &[f32; DESC_GRID],
        usin: &[f32; DESC_GRID],
        vsin: f32,
        vcos: f32,
        n: usize,
    ) {
        #[cfg(target_arch = "x86_64")]
        simd::place(self, f, ucos, usin, vsin, vcos, n);
        #[cfg(not(target_arch = "x86_64"))]
        self.place_scalar(f, ucos, usin, vsin, vcos, n);
    }

    /// The scalar definition of [`RowSamples::place`].
    #[cfg(any(test, not(target_arch = "x86_64")))]
    pub fn place_scalar(
        &mut self,
        f: &Frame,
        ucos: &[f32; DESC_GRID],
        usin: &[f32; DESC_GRID],
        vsin: f32,
        vcos: f32,
        n: usize,
    ) {
        let d = DESC_BINS as f32;
        for j in 0..lanes(n) {
            let pc = round_i(f.x + ucos[j] - vsin);
            let pr = round_i(f.y + usin[j] + vcos);
            let (ox, oy) = (pc as f32 - f.x, pr as f32 - f.y);
            let cbin = (ox * f.cos_t + oy * f.sin_t) * f.inv_hw + f.half;
            let rbin = (oy * f.cos_t - ox * f.sin_t) * f.inv_hw + f.half;
            let inside = pc >= 1 && pc < f.w - 1 && pr >= 1 && pr < f.h - 1;
            let binned = cbin > -1.0 && cbin < d && rbin > -1.0 && rbin < d;
            self.pc[j] = pc;
            self.pr[j] = pr;
            self.ok[j] = -((inside && binned) as i32);
            self.cbin[j] = cbin;
            self.rbin[j] = rbin;
        }
    }

    /// Gradients of the placed samples from the window's rows (`rows[i]` is image row
    /// `r_lo + i`), and their Gaussian weights. A sample whose neighbours fall outside the
    /// window keeps weight 0.
    pub fn gradients(
        &mut self,
        rows: &[&[i16]],
        r_lo: isize,
        weights: &[f32],
        op: Gradient,
        n: usize,
    ) {
        let weights = &weights[..lanes(n).min(weights.len())];
        let m = op.reach();
        // One loop per operator, so each is inlined into its own loop.
        match op {
            Gradient::Central => self.gradients_with(rows, r_lo, weights, m, central),
            Gradient::Scharr => self.gradients_with(rows, r_lo, weights, m, scharr),
            Gradient::Farid => self.gradients_with(rows, r_lo, weights, m, farid),
        }
    }

    #[inline(always)]
    fn gradients_with(
        &mut self,
        rows: &[&[i16]],
        r_lo: isize,
        weights: &[f32],
        m: usize,
        op: impl Fn(&[&[i16]], usize) -> (f32, f32),
    ) {
        for (j, &weight) in weights.iter().enumerate().take(DESC_GRID) {
            self.dx[j] = 0.0;
            self.dy[j] = 0.0;
            self.wgt[j] = 0.0;
            if self.ok[j] == 0 {
                continue;
            }
            let i = self.pr[j] as isize - m as isize - r_lo;
            let Some(window) = (i >= 0)
                .then(|| rows.get(i as usize..i as usize + 2 * m + 1))
                .flatten()
            else {
                continue;
            };
            let c = self.pc[j] as usize;
            if !fits(window, c, m) {
                continue;
            }
            (self.dx[j], self.dy[j]) = op(window, c);
            self.wgt[j] = weight;
        }
    }

    /// Weighted magnitudes and orientation bins relative to `theta`.
    pub fn magnitudes_and_bins(&mut self, theta: f32, obin_scale: f32, n: usize) {
        #[cfg(target_arch = "x86_64")]
        simd::magnitudes_and_bins(self, theta, obin_scale, n);
        #[cfg(not(target_arch = "x86_64"))]
        self.magnitudes_and_bins_scalar(theta, obin_scale, n);
    }

    /// The scalar definition of [`RowSamples::magnitudes_and_bins`].
    #[cfg(any(test, not(target_arch = "x86_64")))]
    pub fn magnitudes_and_bins_scalar(&mut self, theta: f32, obin_scale: f32, n: usize) {
        for j in 0..lanes(n) {
            let (dx, dy) = (self.dx[j], self.dy[j]);
            self.mag[j] = libm::sqrtf(dx * dx + dy * dy) * self.wgt[j];
            let ori = atan2_pos(dy, dx) - theta;
            let ori = if ori < 0.0 { ori + 2.0 * PI } else { ori };
            let obin = ori * obin_scale;
            self.obin[j] = obin;
            let o0 = floor_i(obin).clamp(0, DESC_ORI_BINS as i32 - 1);
            let (rf, cf) = (floor_i(self.rbin[j]), floor_i(self.cbin[j]));
            self.o0[j] = o0;
            self.r0[j] = rf + 1;
            self.c0[j] = cf + 1;
            self.fo[j] = obin - o0 as f32;
            self.fr[j] = self.rbin[j] - rf as f32;
            self.fc[j] = self.cbin[j] - cf as f32;
        }
    }

    /// Trilinear distribution of the row's samples over the padded histogram.
    pub fn scatter(&self, padded: &mut [f32; PADDED], n: usize) {
        // The four cells of a sample: (r0, c0), (r0, c0 + 1), (r0 + 1, c0), (r0 + 1, c0 + 1).
        const SPAN: usize = (P + 1) * NO + 2;
        for j in 0..lanes(n) {
            let mag = self.mag[j];
            if mag == 0.0 {
                continue;
            }
            let (r0, c0, o0) = (self.r0[j], self.c0[j], self.o0[j]);
            if r0 < 0 || c0 < 0 || o0 < 0 {
                continue;
            }
            let base = (r0 as usize * P + c0 as usize) * NO + o0 as usize;
            let Some(cells) = padded.get_mut(base..base + SPAN) else {
                continue;
            };
            let (fo, fr, fc) = (self.fo[j], self.fr[j], self.fc[j]);
            let m_r = [mag * (1.0 - fr), mag * fr];
            let w_c = [1.0 - fc, fc];
            for (dr, &mr) in m_r.iter().enumerate() {
                for (dc, &wc) in w_c.iter().enumerate() {
                    let m = mr * wc;
                    let at = dr * P * NO + dc * NO;
                    cells[at] += m * (1.0 - fo);
                    cells[at + 1] += m * fo;
                }
            }
        }
    }
}

/// Samples of a row of `n`: at most `DESC_GRID`, rounded down to whole vector lanes.
#[inline]
pub fn lanes(n: usize) -> usize {
    n.min(DESC_GRID) & !3
}

#[cfg(target_arch = "x86_64")]
mod simd {
    use super::super::fastmath::sse::{atan2_pos, clamp_epi32, floor_epi32, select};
    use super::{lanes, Frame, RowSamples, DESC_BINS, DESC_GRID, DESC_ORI_BINS, PI};
    use core::arch::x86_64::*;

    // SAFETY (whole module): SSE2 is part of the x86_64 baseline; every load and store
    // reads or writes lanes `j..j + 4` of arrays of DESC_GRID (a multiple of 4) values.
    const _: () = assert!(DESC_GRID.is_multiple_of(4));

    pub fn place(
        s: &mut RowSamples,
        f: &Frame,
        ucos: &[f32; DESC_GRID],
        usin: &[f32; DESC_GRID],
        vsin: f32,
        vcos: f32,
        n: usize,
    ) {
        unsafe {
            let (x, y) = (_mm_set1_ps(f.x), _mm_set1_ps(f.y));
            let (vs, vc) = (_mm_set1_ps(vsin), _mm_set1_ps(vcos));
            let (cs, sn) = (_mm_set1_ps(f.cos_t), _mm_set1_ps(f.sin_t));
            let (inv, half) = (_mm_set1_ps(f.inv_hw), _mm_set1_ps(f.half));
            let point5 = _mm_set1_ps(0.5);
            let (lo, d) = (_mm_set1_ps(-1.0), _mm_set1_ps(DESC_BINS as f32));
            let zero = _mm_setzero_si128();
            let (wm1, hm1) = (_mm_set1_epi32(f.w - 1), _mm_set1_epi32(f.h - 1));
            for j in (0..lanes(n)).step_by(4) {
                let uc = _mm_loadu_ps(ucos.as_ptr().add(j));
                let us = _mm_loadu_ps(usin.as_ptr().add(j));
                let sx = _mm_sub_ps(_mm_add_ps(x, uc), vs);
                let sy = _mm_add_ps(_mm_add_ps(y, us), vc);
                let pc = floor_epi32(_mm_add_ps(sx, point5));
                let pr = floor_epi32(_mm_add_ps(sy, point5));
                let ox = _mm_sub_ps(_mm_cvtepi32_ps(pc), x);
                let oy = _mm_sub_ps(_mm_cvtepi32_ps(pr), y);
                let cbin = _mm_add_ps(
                    _mm_mul_ps(_mm_add_ps(_mm_mul_ps(ox, cs), _mm_mul_ps(oy, sn)), inv),
                    half,
                );
                let rbin = _mm_add_ps(
                    _mm_mul_ps(_mm_sub_ps(_mm_mul_ps(oy, cs), _mm_mul_ps(ox, sn)), inv),
                    half,
                );
                // 1 <= pc < w - 1 and 1 <= pr < h - 1, as pc > 0 and w - 1 > pc.
                let inside = _mm_and_si128(
                    _mm_and_si128(_mm_cmpgt_epi32(pc, zero), _mm_cmpgt_epi32(wm1, pc)),
                    _mm_and_si128(_mm_cmpgt_epi32(pr, zero), _mm_cmpgt_epi32(hm1, pr)),
                );
                let binned = _mm_and_ps(
                    _mm_and_ps(_mm_cmpgt_ps(cbin, lo), _mm_cmplt_ps(cbin, d)),
                    _mm_and_ps(_mm_cmpgt_ps(rbin, lo), _mm_cmplt_ps(rbin, d)),
                );
                let ok = _mm_and_si128(inside, _mm_castps_si128(binned));
                _mm_storeu_si128(s.pc.as_mut_ptr().add(j) as *mut __m128i, pc);
                _mm_storeu_si128(s.pr.as_mut_ptr().add(j) as *mut __m128i, pr);
                _mm_storeu_si128(s.ok.as_mut_ptr().add(j) as *mut __m128i, ok);
                _mm_storeu_ps(s.cbin.as_mut_ptr().add(j), cbin);
                _mm_storeu_ps(s.rbin.as_mut_ptr().add(j), rbin);
            }
        }
    }

    pub fn magnitudes_and_bins(s: &mut RowSamples, theta: f32, obin_scale: f32, n: usize) {
        unsafe {
            let th = _mm_set1_ps(theta);
            let scale = _mm_set1_ps(obin_scale);
            let two_pi = _mm_set1_ps(2.0 * PI);
            let zero = _mm_setzero_ps();
            for j in (0..lanes(n)).step_by(4) {
                let dx = _mm_loadu_ps(s.dx.as_ptr().add(j));
                let dy = _mm_loadu_ps(s.dy.as_ptr().add(j));
                let w = _mm_loadu_ps(s.wgt.as_ptr().add(j));
                let n2 = _mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy));
                _mm_storeu_ps(s.mag.as_mut_ptr().add(j), _mm_mul_ps(_mm_sqrt_ps(n2), w));
                let ori = _mm_sub_ps(atan2_pos(dy, dx), th);
                let ori = select(_mm_cmplt_ps(ori, zero), _mm_add_ps(ori, two_pi), ori);
                let obin = _mm_mul_ps(ori, scale);
                _mm_storeu_ps(s.obin.as_mut_ptr().add(j), obin);
                let o0 = clamp_epi32(floor_epi32(obin), 0, DESC_ORI_BINS as i32 - 1);
                let rbin = _mm_loadu_ps(s.rbin.as_ptr().add(j));
                let cbin = _mm_loadu_ps(s.cbin.as_ptr().add(j));
                let (rf, cf) = (floor_epi32(rbin), floor_epi32(cbin));
                let one = _mm_set1_epi32(1);
                _mm_storeu_si128(s.o0.as_mut_ptr().add(j) as *mut __m128i, o0);
                _mm_storeu_si128(
                    s.r0.as_mut_ptr().add(j) as *mut __m128i,
                    _mm_add_epi32(rf, one),
                );
                _mm_storeu_si128(
                    s.c0.as_mut_ptr().add(j) as *mut __m128i,
                    _mm_add_epi32(cf, one),
                );
                _mm_storeu_ps(
                    s.fo.as_mut_ptr().add(j),
                    _mm_sub_ps(obin, _mm_cvtepi32_ps(o0)),
                );
                _mm_storeu_ps(
                    s.fr.as_mut_ptr().add(j),
                    _mm_sub_ps(rbin, _mm_cvtepi32_ps(rf)),
                );
                _mm_storeu_ps(
                    s.fc.as_mut_ptr().add(j),
                    _mm_sub_ps(cbin, _mm_cvtepi32_ps(cf)),
                );
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(seed: &mut u32) -> f32 {
        *seed = seed.wrapping_mul(1_103_515_245).wrapping_add(12345);
        (*seed >> 8) as f32 / (1u32 << 24) as f32
    }

    /// The dispatched passes (SSE2 on x86_64) give the scalar definition's bits.
    #[test]
    fn vector_passes_equal_the_scalar_definition() {
        let mut seed = 7u32;
        for _ in 0..2000 {
            let theta = lcg(&mut seed) * 2.0 * PI;
            let hw = 0.5 + 12.0 * lcg(&mut seed);
            let f = Frame {
                x: -20.0 + 700.0 * lcg(&mut seed),
                y: -20.0 + 520.0 * lcg(&mut seed),
                cos_t: libm::cosf(theta),
                sin_t: libm::sinf(theta),
                inv_hw: 1.0 / hw,
                half: 1.5,
                w: 640,
                h: 480,
            };
            let ucos: [f32; DESC_GRID] =
                core::array::from_fn(|_| (lcg(&mut seed) - 0.5) * 8.0 * hw);
            let usin: [f32; DESC_GRID] =
                core::array::from_fn(|_| (lcg(&mut seed) - 0.5) * 8.0 * hw);
            let (vsin, vcos) = (
                (lcg(&mut seed) - 0.5) * 8.0 * hw,
                (lcg(&mut seed) - 0.5) * 8.0 * hw,
            );
            let mut a = RowSamples::default();
            let mut b = RowSamples::default();
            a.place(&f, &ucos, &usin, vsin, vcos, DESC_GRID);
            b.place_scalar(&f, &ucos, &usin, vsin, vcos, DESC_GRID);
            assert_eq!((a.pc, a.pr, a.ok), (b.pc, b.pr, b.ok));
            assert_eq!(a.cbin.map(f32::to_bits), b.cbin.map(f32::to_bits));
            assert_eq!(a.rbin.map(f32::to_bits), b.rbin.map(f32::to_bits));
            for j in 0..DESC_GRID {
                // Integer gradients of level values, including zeros and axis directions.
                let pick = |v: f32| {
                    if v < 0.1 {
                        0.0
                    } else {
                        libm::roundf((v - 0.55) * 2.0 * 16320.0)
                    }
                };
                a.dx[j] = pick(lcg(&mut seed));
                a.dy[j] = pick(lcg(&mut seed));
                a.wgt[j] = lcg(&mut seed);
            }
            b.dx = a.dx;
            b.dy = a.dy;
            b.wgt = a.wgt;
            a.magnitudes_and_bins(theta, 8.0 / (2.0 * PI), DESC_GRID);
            b.magnitudes_and_bins_scalar(theta, 8.0 / (2.0 * PI), DESC_GRID);
            assert_eq!(a.mag.map(f32::to_bits), b.mag.map(f32::to_bits));
            assert_eq!(a.obin.map(f32::to_bits), b.obin.map(f32::to_bits));
            for j in 0..DESC_GRID {
                if b.ok[j] == 0 {
                    continue; // Placement outside the image: bins unused.
                }
                assert_eq!((a.o0[j], a.r0[j], a.c0[j]), (b.o0[j], b.r0[j], b.c0[j]));
                assert_eq!(
                    [a.fo[j], a.fr[j], a.fc[j]].map(f32::to_bits),
                    [b.fo[j], b.fr[j], b.fc[j]].map(f32::to_bits)
                );
            }
        }
    }
}
