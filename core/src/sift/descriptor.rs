//! The 4x4x8 descriptor: gradients sampled on a fixed grid in the keypoint's
//! rotated frame (4 samples per spatial bin, 20x20 over the bins -1..4 that trilinear
//! interpolation reaches), Gaussian weighted, trilinearly distributed over position and
//! orientation bins, normalised, clipped at 0.2, renormalised and quantised to u8.
//!
//! Sampling a fixed grid instead of every pixel of the window makes the cost
//! independent of scale (400 samples); at 3 sigma per bin the grid step is 0.75 sigma
//! of a level already blurred by sigma, so little is lost.

use core::f32::consts::PI;

use super::config::{DESC_BINS, DESC_GRID, DESC_ORI_BINS, DESC_SAMPLES_PER_BIN};
use super::fastmath::atan2_pos;
use super::levels::Levels;
use crate::features::Descriptor;

/// Gaussian weights of the sampling grid (sigma = half the descriptor width, as Lowe).
pub fn fill_weights(weights: &mut [f32]) {
    let half = DESC_BINS as f32 * 0.5;
    let e = -1.0 / (2.0 * half * half);
    for i in 0..DESC_GRID {
        for j in 0..DESC_GRID {
            let u = grid_bin(j) - half + 0.5;
            let v = grid_bin(i) - half + 0.5;
            if let Some(w) = weights.get_mut(i * DESC_GRID + j) {
                *w = libm::expf((u * u + v * v) * e);
            }
        }
    }
}

/// Bin coordinate of grid sample `i`: uniform over (-1, DESC_BINS).
#[inline]
fn grid_bin(i: usize) -> f32 {
    -1.0 + (i as f32 + 0.5) / DESC_SAMPLES_PER_BIN as f32
}

/// Computes the descriptor of a keypoint at octave position (`x`, `y`), octave-relative
/// scale `sigma`, orientation `theta` (radians), on Gaussian level `k`.
#[allow(clippy::too_many_arguments)]
pub fn describe(
    lv: &Levels,
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
    for i in 0..DESC_GRID {
        let rbin = grid_bin(i);
        let v = (rbin - D as f32 * 0.5 + 0.5) * hw;
        for j in 0..DESC_GRID {
            let cbin = grid_bin(j);
            let u = (cbin - D as f32 * 0.5 + 0.5) * hw;
            // Keypoint frame (u along the orientation) to image offsets (y down).
            let sx = x + u * cos_t - v * sin_t;
            let sy = y + u * sin_t + v * cos_t;
            let pc = libm::roundf(sx) as isize;
            let pr = libm::roundf(sy) as isize;
            if pc < 1 || pc >= w - 1 || pr < 1 || pr >= h - 1 {
                continue;
            }
            let row = lv.row(k, pr);
            let c = pc as usize;
            let dx = (row[c + 1] as i32 - row[c - 1] as i32) as f32;
            let dy = (lv.row(k, pr + 1)[c] as i32 - lv.row(k, pr - 1)[c] as i32) as f32;
            let wgt = weights.get(i * DESC_GRID + j).copied().unwrap_or(0.0);
            let mag = libm::sqrtf(dx * dx + dy * dy) * wgt;
            if mag == 0.0 {
                continue;
            }
            let mut ori = atan2_pos(dy, dx) - theta;
            if ori < 0.0 {
                ori += 2.0 * PI;
            }
            if ori >= 2.0 * PI {
                ori -= 2.0 * PI;
            }
            accumulate(&mut hist, rbin, cbin, ori * obin_scale, mag);
        }
    }
    finish(&hist, out);
}

/// Trilinear distribution of one sample over the 2x2x2 nearest bins.
#[inline]
fn accumulate(
    hist: &mut [f32; DESC_BINS * DESC_BINS * DESC_ORI_BINS],
    rbin: f32,
    cbin: f32,
    obin: f32,
    mag: f32,
) {
    const N: usize = DESC_ORI_BINS;
    const D: isize = DESC_BINS as isize;
    let r0 = libm::floorf(rbin);
    let c0 = libm::floorf(cbin);
    let o0 = libm::floorf(obin);
    let (fr, fc, fo) = (rbin - r0, cbin - c0, obin - o0);
    let (r0, c0) = (r0 as isize, c0 as isize);
    let o0 = (o0 as isize).rem_euclid(N as isize) as usize;
    for (dr, wr) in [(0isize, 1.0 - fr), (1, fr)] {
        let rr = r0 + dr;
        if !(0..D).contains(&rr) {
            continue;
        }
        for (dc, wc) in [(0isize, 1.0 - fc), (1, fc)] {
            let cc = c0 + dc;
            if !(0..D).contains(&cc) {
                continue;
            }
            let base = ((rr * D + cc) as usize) * N;
            let m = mag * wr * wc;
            hist[base + o0] += m * (1.0 - fo);
            hist[base + (o0 + 1) % N] += m * fo;
        }
    }
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
        *o = libm::roundf(v * k).clamp(0.0, 255.0) as u8;
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

    #[test]
    fn trilinear_weights_sum_to_magnitude_inside() {
        let mut h = [0f32; 128];
        accumulate(&mut h, 1.3, 2.6, 7.5, 2.0);
        let s: f32 = h.iter().sum();
        assert!((s - 2.0).abs() < 1e-5);
        // Orientation wraps from bin 7 to bin 0.
        assert!(h[(4 + 2) * 8] > 0.0);
    }
}
