//! Dominant orientations: a 36-bin histogram of gradient directions weighted by
//! magnitude and a Gaussian of 1.5 sigma, smoothed, with every local peak of at
//! least `peak_ratio` of the highest interpolated by a parabola (Lowe, OpenCV).

use core::f32::consts::PI;

use super::fastmath::{atan2_pos, round_i};
use super::levels::Levels;

/// Histogram bins.
pub const ORI_BINS: usize = 36;
/// Largest window radius sampled (octave pixels).
const MAX_RADIUS: usize = 31;

/// Orientations (radians, `[0, 2 pi)`) of a keypoint at octave position (`x`, `y`) with
/// octave-relative scale `sigma` on Gaussian level `k`. Returns how many were written.
pub fn orientations(
    lv: &Levels,
    k: usize,
    x: f32,
    y: f32,
    sigma: f32,
    peak_ratio: f32,
    out: &mut [f32; ORI_BINS],
) -> usize {
    let mut hist = [0f32; ORI_BINS];
    let px = round_i(x) as isize;
    let py = round_i(y) as isize;
    let radius = (round_i(4.5 * sigma).max(0) as usize).min(MAX_RADIUS);
    let sw = 1.5 * sigma;
    let e = -1.0 / (2.0 * sw * sw);
    // Separable Gaussian weights: exp(-(i^2 + j^2) / 2 sw^2) = g(i) g(j).
    let mut g = [0f32; MAX_RADIUS + 1];
    for (i, gi) in g.iter_mut().enumerate().take(radius + 1) {
        *gi = libm::expf((i * i) as f32 * e);
    }
    let (w, h) = (lv.w as isize, lv.h as isize);
    let scale = ORI_BINS as f32 / (2.0 * PI);
    let r = radius as isize;
    // Large windows are sampled every other pixel: the level is blurred by sigma, so a
    // 2-pixel step above sigma 3 loses little and quarters the cost.
    let step = if sigma >= 3.0 { 2 } else { 1 };
    for i in (-r..=r).step_by(step) {
        let yy = py + i;
        if yy <= 0 || yy >= h - 1 {
            continue;
        }
        let up = lv.row(k, yy - 1);
        let row = lv.row(k, yy);
        let down = lv.row(k, yy + 1);
        let gi = g[i.unsigned_abs()];
        // Keep the column phase of the window so sampling stays symmetric about px.
        let mut c0 = px - r;
        while c0 < 1 {
            c0 += step as isize;
        }
        let c1 = (px + r).min(w - 2);
        for xx in (c0..=c1).step_by(step) {
            let c = xx as usize;
            let dx = (row[c + 1] as i32 - row[c - 1] as i32) as f32;
            let dy = (down[c] as i32 - up[c] as i32) as f32;
            let wgt = gi * g[(xx - px).unsigned_abs()];
            let mag = libm::sqrtf(dx * dx + dy * dy);
            let mut bin = round_i(atan2_pos(dy, dx) * scale).max(0) as usize;
            if bin >= ORI_BINS {
                bin -= ORI_BINS;
            }
            hist[bin] += wgt * mag;
        }
    }
    // Circular [1 4 6 4 1] / 16 smoothing.
    let mut smooth = [0f32; ORI_BINS];
    for (j, s) in smooth.iter_mut().enumerate() {
        let at = |o: isize| hist[((j as isize + o).rem_euclid(ORI_BINS as isize)) as usize];
        *s = (at(-2) + at(2)) * (1.0 / 16.0)
            + (at(-1) + at(1)) * (4.0 / 16.0)
            + at(0) * (6.0 / 16.0);
    }
    let max = smooth.iter().fold(0f32, |m, &v| m.max(v));
    if max.is_nan() || max <= 0.0 {
        return 0;
    }
    let thr = max * peak_ratio;
    let mut n = 0;
    for j in 0..ORI_BINS {
        let l = smooth[(j + ORI_BINS - 1) % ORI_BINS];
        let rr = smooth[(j + 1) % ORI_BINS];
        let v = smooth[j];
        if v > l && v > rr && v >= thr {
            let denom = l - 2.0 * v + rr;
            let off = if denom != 0.0 {
                0.5 * (l - rr) / denom
            } else {
                0.0
            };
            let mut b = j as f32 + off;
            if b < 0.0 {
                b += ORI_BINS as f32;
            }
            if b >= ORI_BINS as f32 {
                b -= ORI_BINS as f32;
            }
            let mut a = b * (2.0 * PI / ORI_BINS as f32);
            if a >= 2.0 * PI {
                a = 0.0;
            }
            out[n] = a;
            n += 1;
        }
    }
    n
}
