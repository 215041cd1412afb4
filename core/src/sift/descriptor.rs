//! The 4x4x8 descriptor: gradients sampled on a fixed grid in the keypoint's
//! rotated frame (4 samples per spatial bin, 20x20 over the bins -1..4 that trilinear
//! interpolation reaches), Gaussian weighted, trilinearly distributed over position and
//! orientation bins, normalised, clipped at 0.2, renormalised and quantised to u8.
//!
//! Sampling a fixed grid instead of every pixel of the window makes the cost
//! independent of scale (400 samples); at 3 sigma per bin the grid step is 0.75 sigma
//! of a level already blurred by sigma, so little is lost.

use core::f32::consts::PI;

use super::config::{DESC_BINS, DESC_GRID, DESC_ORI_BINS};
use super::desc_samples::{lanes, Frame, RowSamples, NO, P, PADDED};
use super::fastmath::{floor_i, round_i};
use super::levels::Levels;
use crate::features::Descriptor;

/// Rows a descriptor window may span (larger windows lose their outer rows).
const MAX_ROWS: usize = 192;

/// Gaussian weights of the sampling grid (sigma = half the descriptor width, as Lowe).
/// for a grid of `n` x `n` samples (row stride `n`).
pub fn fill_weights(weights: &mut [f32], n: usize) {
    let half = DESC_BINS as f32 * 0.5;
    let e = -1.0 / (2.0 * half * half);
    for i in 0..n {
        for j in 0..n {
            let u = grid_bin(j, n) - half + 0.5;
            let v = grid_bin(i, n) - half + 0.5;
            if let Some(w) = weights.get_mut(i * n + j) {
                *w = libm::expf((u * u + v * v) * e);
            }
        }
    }
}

/// Bin coordinate of sample `i` of a grid of `n`: uniform over (-1, DESC_BINS).
#[inline]
fn grid_bin(i: usize, n: usize) -> f32 {
    -1.0 + (i as f32 + 0.5) * ((DESC_BINS + 1) as f32 / n as f32)
}

/// Computes the descriptor of a keypoint at octave position (`x`, `y`), octave-relative
/// scale `sigma`, orientation `theta` (radians), on Gaussian level `k`, sampling a grid of
/// `grid` x `grid` (a multiple of 4, at most `DESC_GRID`) with `weights` from
/// [`fill_weights`].
#[allow(clippy::too_many_arguments)]
pub fn describe(
    lv: &Levels,
    grid: usize,
    k: usize,
    x: f32,
    y: f32,
    sigma: f32,
    theta: f32,
    weights: &[f32],
    out: &mut Descriptor,
) {
    const N: usize = DESC_ORI_BINS;
    const D: usize = DESC_BINS;
    let mut hist = [0f32; D * D * N];
    let hw = 3.0 * sigma; // bin width in octave pixels
    let (sin_t, cos_t) = (libm::sinf(theta), libm::cosf(theta));
    let (w, h) = (lv.w as isize, lv.h as isize);
    let obin_scale = N as f32 / (2.0 * PI);
    // Row slices of the sampled window, looked up once (ring slots need a division).
    let reach = hw * (D as f32 + 1.0) * 0.5 * 1.4143 + 2.0;
    let r_lo = (floor_i(y - reach) as isize).max(0);
    let r_hi = (floor_i(y + reach) as isize + 1).min(h - 1);
    let mut rows: [&[i16]; MAX_ROWS] = [&[]; MAX_ROWS];
    let n_rows = ((r_hi - r_lo + 1).max(0) as usize).min(MAX_ROWS);
    for (i, row) in rows.iter_mut().enumerate().take(n_rows) {
        *row = lv.row(k, r_lo + i as isize);
    }
    let inv_hw = 1.0 / hw;
    let half = D as f32 * 0.5 - 0.5;
    let mut ucos = [0f32; DESC_GRID];
    let mut usin = [0f32; DESC_GRID];
    let n = lanes(grid);
    for j in 0..n {
        let b = grid_bin(j, n);
        let u = (b - D as f32 * 0.5 + 0.5) * hw;
        ucos[j] = u * cos_t;
        usin[j] = u * sin_t;
    }
    // Padded histogram: (D + 2) x (D + 2) positions x (N + 1) orientations, folded at the end.
    let mut padded = [0f32; PADDED];
    // One grid row at a time: placement, gradients, magnitudes and bins, scatter
    // (`desc_samples`).
    let frame = Frame {
        x,
        y,
        cos_t,
        sin_t,
        inv_hw,
        half,
        w: w as i32,
        h: h as i32,
    };
    let mut row = RowSamples::default();
    for i in 0..n {
        // The grid is square: row i has v = u_i, so v sin = usin[i] and v cos = ucos[i].
        row.place(&frame, &ucos, &usin, usin[i], ucos[i], n);
        let wrow = weights.get(i * n..(i + 1) * n).unwrap_or(&[]);
        row.gradients(&rows[..n_rows], r_lo, wrow, lv.gradient, n);
        row.magnitudes_and_bins(theta, obin_scale, n);
        row.scatter(&mut padded, n);
    }
    // Fold the wrapped orientation slot and drop the outer spatial ring.
    for r in 0..D {
        for c in 0..D {
            let src = ((r + 1) * P + c + 1) * NO;
            let dst = (r * D + c) * N;
            hist[dst..dst + N].copy_from_slice(&padded[src..src + N]);
            hist[dst] += padded[src + N];
        }
    }
    finish(&hist, out);
}

/// Normalise, clip at 0.2, renormalise and quantise (512 scale, saturating, as OpenCV).
fn finish(hist: &[f32; 128], out: &mut Descriptor) {
    let norm2: f32 = hist.iter().map(|v| v * v).sum();
    let thr = libm::sqrtf(norm2) * 0.2;
    let mut clipped = [0f32; 128];
    let mut n2 = 0.0;
    for (c, &v) in clipped.iter_mut().zip(hist.iter()) {
        *c = v.min(thr);
        n2 += *c * *c;
    }
    let k = 512.0 / libm::sqrtf(n2).max(f32::EPSILON);
    for (o, &v) in out.iter_mut().zip(clipped.iter()) {
        *o = round_i(v * k).clamp(0, 255) as u8;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finish_clips_and_saturates() {
        let mut h = [0f32; 128];
        h[0] = 100.0;
        h[1] = 1.0;
        let mut d = [0u8; 128];
        finish(&h, &mut d);
        // After clipping, h0 = 0.2 * |h|, h1 = 1: h0 dominates and saturates.
        assert_eq!(d[0], 255);
        assert!(d[1] > 0 && d[1] < 40);
        let mut z = [1u8; 128];
        finish(&[0.0; 128], &mut z);
        assert!(z.iter().all(|&v| v == 0));
    }
}
