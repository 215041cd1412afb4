//! Dominant orientations: a 36-bin histogram of gradient directions weighted by
//! magnitude and a Gaussian of 1.5 sigma, smoothed, with every local peak of at
//! least `peak_ratio` of the highest interpolated by a parabola (Lowe, OpenCV).

use core::f32::consts::PI;

use super::config::SiftConfig;
use super::fastmath::{atan2_pos, round_i};
use super::levels::{central, farid, fits, scharr, Levels};
use super::Gradient;

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
    cfg: &SiftConfig,
    out: &mut [f32; ORI_BINS],
) -> usize {
    let mut hist = [0f32; ORI_BINS];
    let px = round_i(x) as isize;
    let py = round_i(y) as isize;
    let radius = (round_i(cfg.orientation_radius * sigma).max(0) as usize).min(MAX_RADIUS);
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
    let step = if sigma >= cfg.orientation_stride_sigma {
        2
    } else {
        1
    };
    let mut samples = WindowRow::default();
    let soft = cfg.soft_orientation;
    for i in (-r..=r).step_by(step) {
        let yy = py + i;
        if yy <= 0 || yy >= h - 1 {
            continue;
        }
        let m = lv.gradient.reach() as isize;
        if yy < m || yy >= h - m {
            continue;
        }
        let rows: [&[i16]; 5] = core::array::from_fn(|j| lv.row(k, yy + j as isize - 2));
        let gi = g[i.unsigned_abs()];
        // Keep the column phase of the window so sampling stays symmetric about px.
        let mut c0 = px - r;
        while c0 < m {
            c0 += step as isize;
        }
        let c1 = (px + r).min(w - 1 - m);
        let span = Span {
            cols: [c0, c1],
            step,
            px,
            gi,
            g: &g,
        };
        let n = samples.gradients(lv.gradient, &rows, &span);
        samples.bins(n, scale);
        if soft {
            // Each vote split between the two nearest bin centres: on a fine level the
            // window holds few samples, and rounding each to one bin makes the peak jump.
            for j in 0..n {
                let p = samples.pos[j];
                let b0 = libm::floorf(p);
                let f = p - b0;
                let b0 = (b0.max(0.0) as usize) % ORI_BINS;
                let b1 = if b0 + 1 == ORI_BINS { 0 } else { b0 + 1 };
                let v = samples.vote[j];
                hist[b0] += v * (1.0 - f);
                hist[b1] += v * f;
            }
        } else {
            for j in 0..n {
                let bin = samples.bin[j].max(0) as usize;
                let bin = if bin >= ORI_BINS { bin - ORI_BINS } else { bin };
                if let Some(b) = hist.get_mut(bin) {
                    *b += samples.vote[j];
                }
            }
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
    let thr = max * cfg.peak_ratio;
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

/// Columns `cols[0], cols[0] + step, .. <= cols[1]` of one orientation window row
/// (`cols[0] >= gradient.reach()`), around the keypoint column `px`, with the row's
/// Gaussian weight `gi` and the separable weights `g` by column distance.
#[derive(Clone, Copy)]
struct Span<'g> {
    cols: [isize; 2],
    step: usize,
    px: isize,
    gi: f32,
    g: &'g [f32; MAX_RADIUS + 1],
}

/// Samples of one window row at most.
const WINDOW: usize = 2 * MAX_RADIUS + 2;

/// Gradients of one window row and their votes: weighted magnitude and histogram bin.
#[derive(Clone, Copy, bytemuck::Zeroable)]
struct WindowRow {
    dx: [f32; WINDOW],
    dy: [f32; WINDOW],
    wgt: [f32; WINDOW],
    vote: [f32; WINDOW],
    /// Continuous bin position `atan2 * bins / 2 pi`, in `[0, ORI_BINS]`.
    pos: [f32; WINDOW],
    bin: [i32; WINDOW],
}

impl Default for WindowRow {
    fn default() -> Self {
        bytemuck::Zeroable::zeroed()
    }
}

impl WindowRow {
    /// Gradients and Gaussian weights of the window row `span`; returns how many were
    /// written. The operator fits at every column once it fits at the last (checked
    /// once), and each operator gets its own loop: this is the inner loop of the
    /// orientation.
    fn gradients(&mut self, gradient: Gradient, rows: &[&[i16]; 5], span: &Span) -> usize {
        let m = gradient.reach();
        let window = &rows[2 - m..=2 + m];
        let [c0, c1] = span.cols;
        let last = c1.min(c0 + (WINDOW as isize - 1) * span.step as isize);
        if last < c0 || !fits(window, last as usize, m) {
            return 0;
        }
        let span = Span {
            cols: [c0, last],
            ..*span
        };
        match gradient {
            Gradient::Central => self.fill(|c| central(window, c), &span),
            Gradient::Scharr => self.fill(|c| scharr(window, c), &span),
            Gradient::Farid => self.fill(|c| farid(window, c), &span),
        }
    }

    /// [`WindowRow::gradients`] with the operator `op` (generic, so it is inlined).
    #[inline(always)]
    fn fill(&mut self, op: impl Fn(usize) -> (f32, f32), span: &Span) -> usize {
        let [c0, last] = span.cols;
        let mut n = 0;
        for xx in (c0..=last).step_by(span.step) {
            (self.dx[n], self.dy[n]) = op(xx as usize);
            self.wgt[n] = span.gi * span.g[(xx - span.px).unsigned_abs().min(MAX_RADIUS)];
            n += 1;
        }
        n
    }

    /// Votes of the first `n` samples (the bin before wrapping at `ORI_BINS`).
    fn bins(&mut self, n: usize, scale: f32) {
        #[cfg(target_arch = "x86_64")]
        let done = self.bins_sse(n, scale);
        #[cfg(not(target_arch = "x86_64"))]
        let done = 0;
        self.bins_scalar(done, n, scale);
    }

    /// The scalar definition of [`WindowRow::bins`], for samples `from..n`.
    fn bins_scalar(&mut self, from: usize, n: usize, scale: f32) {
        for j in from..n.min(WINDOW) {
            let (dx, dy) = (self.dx[j], self.dy[j]);
            self.vote[j] = self.wgt[j] * libm::sqrtf(dx * dx + dy * dy);
            self.pos[j] = atan2_pos(dy, dx) * scale;
            self.bin[j] = round_i(self.pos[j]);
        }
    }

    /// Samples `0..n` rounded up to whole lanes (the arrays have room); returns `n`.
    #[cfg(target_arch = "x86_64")]
    fn bins_sse(&mut self, n: usize, scale: f32) -> usize {
        use super::fastmath::sse::{atan2_pos, floor_epi32};
        use core::arch::x86_64::*;
        const _: () = assert!(WINDOW.is_multiple_of(4));
        let n = n.min(WINDOW);
        // SAFETY: SSE2 is part of the x86_64 baseline; lanes j..j + 4 < WINDOW.
        unsafe {
            let s = _mm_set1_ps(scale);
            let half = _mm_set1_ps(0.5);
            for j in (0..n).step_by(4) {
                let dx = _mm_loadu_ps(self.dx.as_ptr().add(j));
                let dy = _mm_loadu_ps(self.dy.as_ptr().add(j));
                let w = _mm_loadu_ps(self.wgt.as_ptr().add(j));
                let m = _mm_sqrt_ps(_mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy)));
                _mm_storeu_ps(self.vote.as_mut_ptr().add(j), _mm_mul_ps(w, m));
                let p = _mm_mul_ps(atan2_pos(dy, dx), s);
                _mm_storeu_ps(self.pos.as_mut_ptr().add(j), p);
                let b = floor_epi32(_mm_add_ps(p, half));
                _mm_storeu_si128(self.bin.as_mut_ptr().add(j) as *mut __m128i, b);
            }
        }
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The SSE2 votes are the scalar definition's bits.
    #[test]
    fn vector_votes_equal_the_scalar_definition() {
        let mut seed = 99u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_103_515_245).wrapping_add(12345);
            (seed >> 8) as f32 / (1u32 << 24) as f32
        };
        for n in [0usize, 1, 5, 17, WINDOW] {
            let mut a = WindowRow::default();
            for j in 0..n {
                a.dx[j] = libm::roundf((next() - 0.5) * 4000.0);
                a.dy[j] = if j % 7 == 0 {
                    0.0
                } else {
                    libm::roundf((next() - 0.5) * 4000.0)
                };
                a.wgt[j] = next();
            }
            let mut b = a;
            a.bins(n, ORI_BINS as f32 / (2.0 * PI));
            b.bins_scalar(0, n, ORI_BINS as f32 / (2.0 * PI));
            for j in 0..n {
                assert_eq!(a.vote[j].to_bits(), b.vote[j].to_bits(), "n {n} sample {j}");
                assert_eq!(a.bin[j], b.bin[j], "n {n} sample {j}");
                assert_eq!(a.pos[j].to_bits(), b.pos[j].to_bits(), "n {n} sample {j}");
            }
        }
    }
}
