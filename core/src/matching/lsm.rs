//! Least-squares matching: the sub-pixel position of a template in an image by
//! Gauss-Newton on the grey values, the photogrammetric estimator of a point's
//! position once the correlation has found its pixel.
//!
//! Why: the correlation's parabola through three NCC scores is a model of the peak, and
//! where the peak is not a parabola the vertex depends on where the grid was laid
//! ([`super::refine::Correlator::recentre`] re-centres it, but a fit that lands on an edge
//! of its grid or swings between two grids stops where it is). Measured on the area tie
//! points of a 600-epoch rendered drive, moving the search's start by 0.3 px moved the
//! re-centred position by more than 0.1 px for a quarter of them and by more than 0.3 px
//! for a ninth: those positions follow the prediction the search started from, and the
//! window takes that for motion (with those observations replaced by their true
//! projections, the drive's rotation drift fell threefold). Least squares minimises the
//! grey-value differences themselves: from any start within its reach it ends on the
//! same position (from the same 0.3 px moves, 92 % of the positions within 0.01 px).
//!
//! The model: the template's grey values are a gain times the image's, shifted, plus a
//! brightness plane (an offset and a ramp across the template). The ramp is vignetting
//! and uneven light: a point that moves towards the image's edge darkens on its outer
//! side, and without the ramp least squares moved it inwards (the rendered street with
//! a typical sensor's vignetting drifted by 0.80 % instead of 0.35 %). Gain, offset and
//! ramp are solved with the shift and dropped at the end. Single precision:
//! the embedded targets have a single-precision FPU.
use super::refine::T;
use nalgebra::{SMatrix, SVector};

/// Gauss-Newton iterations at most. Of the area tie points of a rendered hand-held walk,
/// 91 % settled within them, 3.8 on average (the others keep the re-centred parabola);
/// without [`StepLength`] 57 %.
pub const ITERATIONS: usize = 6;

/// An iteration that moves the position less than this (pixels, each axis) ends them.
pub const SETTLED_PX: f32 = 0.005;

/// Farther than this from the start (pixels, each axis), the match is left to the
/// correlation: least squares has left the peak the correlation found.
pub const MAX_MOVE_PX: f32 = 1.0;

/// The largest overshoot [`StepLength`] takes from one reversal: a step more than this
/// many times the previous one, reversed, is a divergence and is cut to a fifth.
const MAX_OVERSHOOT: f32 = 4.0;

/// The length of the Gauss-Newton steps, per axis.
///
/// Why: the gradients are central differences of the resampled image, and for fine
/// texture a central difference is less steep than the image between two samples (for
/// a wave of frequency `w` per sample, `sin(w) / w` of it). The step is then too long:
/// of the hand-held walk's matches 43 % had not settled after the iterations, most of
/// them swinging about the optimum, each step reversed and nearly as long as the one
/// before (some growing). A step that reverses
/// the previous one measures the overshoot: if the previous step was `k` times the
/// distance to the optimum, the new one is `-(k - 1)` times the previous (the secant
/// through the two), so the following steps are divided by `k`. This aims at the
/// optimum itself, not at the start: halving reversed steps instead (tried) settled
/// early, near where the matching started.
#[derive(Debug, Clone, Copy)]
pub struct StepLength {
    factor: [f32; 2],
    last: [f32; 2],
}

impl Default for StepLength {
    fn default() -> Self {
        StepLength {
            factor: [1.0; 2],
            last: [0.0; 2],
        }
    }
}

impl StepLength {
    /// The step to take for the Gauss-Newton step `d`.
    pub fn take(&mut self, d: [f32; 2]) -> [f32; 2] {
        for ((&d, factor), last) in d.iter().zip(&mut self.factor).zip(&mut self.last) {
            let proposed = d * *factor;
            if proposed * *last < 0.0 {
                *factor /= 1.0 + (proposed / *last).abs().min(MAX_OVERSHOOT);
            }
            *last = d * *factor;
        }
        self.last
    }
}

/// Unknowns of a step: the shift (x, y), the gain's correction, the offset and the ramp
/// (x, y).
const UNKNOWNS: usize = 6;

/// Samples summed at once in [`shift_step`] (four partial sums of each product).
pub(super) const LANES: usize = 4;

/// A template row in whole groups of [`LANES`] (the samples beyond it are zero).
pub(super) const ROW: usize = T.div_ceil(LANES) * LANES;

/// Sums [`shift_step`] forms: 15 of the normal matrix and 6 of the right-hand side.
pub(super) const SUMS: usize = 21;

/// The brightness of the template against the image: `template = gain * image + offset
/// + ramp . (u, v)`, (u, v) a sample's place from the template's centre.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Radiometry {
    pub gain: f32,
    pub offset: f32,
    pub ramp: [f32; 2],
}

impl Radiometry {
    /// The gain that best maps the image samples (the interior of `region`, see
    /// [`shift_step`]) onto the zero-mean template `zt` and no offset or ramp; `None`
    /// for a flat or anti-correlated image.
    pub fn initial(region: &[f32], stride: usize, zt: &[f32], n: usize) -> Option<Self> {
        let (mut s, mut ss, mut st) = (0f32, 0f32, 0f32);
        for v in 0..n {
            let row = &region[(v + 1) * stride + 1..];
            for (u, &i) in row[..n].iter().enumerate() {
                s += i;
                ss += i * i;
                st += i * zt[v * n + u];
            }
        }
        let cnt = (n * n) as f32;
        let var = ss - s * s / cnt;
        let gain = st / var;
        (var > 1e-3 * cnt && gain > 0.0).then_some(Radiometry {
            gain,
            offset: -gain * s / cnt,
            ramp: [0.0; 2],
        })
    }
}

/// One Gauss-Newton step: `region` holds the image resampled on the template's grid
/// with a one-sample border (`n + 2` samples a side, row stride `stride`) at the
/// current position, `zt` the zero-mean template (`n x n`), `radiometry` the current
/// brightness model (updated). Returns the shift to add to the position (zero on an
/// axis not solved: `axes`), `None` when the shift is not determined (an edge fixes
/// the shift across it only) or the image turns anti-correlated.
pub fn shift_step(
    region: &[f32],
    stride: usize,
    zt: &[f32],
    n: usize,
    axes: (bool, bool),
    radiometry: &mut Radiometry,
) -> Option<[f32; 2]> {
    let Radiometry {
        gain: g,
        offset,
        ramp,
    } = *radiometry;
    let hf = (n / 2) as f32;
    // Sums of the products of the columns j = (a, b, i, 1, u, v) of the design matrix
    // (a, b: gain times the image gradient; i: the image; u, v: the sample's place) and
    // of the residual r. The normal matrix is symmetric and its block of (1, u, v) is
    // the same at every step, so 21 sums are formed. A row is summed LANES samples at a
    // time into LANES partial sums (SIMD registers; this runs several times on every
    // tie point), which also fixes the order of summation on every target.
    let mut pu = [0f32; ROW];
    for (u, x) in pu[..n].iter_mut().enumerate() {
        *x = u as f32 - hf;
    }
    let mut acc = [[0f32; LANES]; SUMS];
    for v in 0..n {
        let pv = v as f32 - hf;
        // The row's columns a, b, i, r and u (zero beyond the template).
        let mut cols = [[0f32; ROW]; 5];
        cols[U] = pu;
        let (up, row, down) = (
            &region[v * stride..],
            &region[(v + 1) * stride..],
            &region[(v + 2) * stride..],
        );
        for u in 0..n {
            let i = row[u + 1];
            cols[I][u] = i;
            if axes.0 {
                cols[A][u] = g * (0.5 * (row[u + 2] - row[u]));
            }
            if axes.1 {
                cols[B][u] = g * (0.5 * (down[u + 1] - up[u + 1]));
            }
            let model = g * i + offset + ramp[0] * pu[u] + ramp[1] * pv;
            cols[RES][u] = zt[v * n + u] - model;
        }
        let mut line = [[0f32; LANES]; 4];
        sum_row(&cols, n, &mut acc, &mut line);
        // The sums with the column of ones, and with v (the same along the row).
        for (k, x) in line.iter().enumerate() {
            for l in 0..LANES {
                acc[13 + k][l] += x[l];
                acc[17 + k][l] += pv * x[l];
            }
        }
    }
    let s = acc.map(|x| (x[0] + x[1]) + (x[2] + x[3]));
    // Sums over the grid of 1, u, v and their products: whole numbers, exact in f32.
    let uu = pu.iter().map(|k| k * k).sum::<f32>() * n as f32;
    let cnt = (n * n) as f32;
    let mut normal = SMatrix::<f32, UNKNOWNS, UNKNOWNS>::from_row_slice(&[
        s[0], s[1], s[2], s[13], s[3], s[17], //
        s[1], s[4], s[5], s[14], s[6], s[18], //
        s[2], s[5], s[7], s[15], s[8], s[19], //
        s[13], s[14], s[15], cnt, 0.0, 0.0, //
        s[3], s[6], s[8], 0.0, uu, 0.0, //
        s[17], s[18], s[19], 0.0, 0.0, uu, //
    ]);
    let rhs = SVector::<f32, UNKNOWNS>::from([s[9], s[10], s[11], s[16], s[12], s[20]]);
    // An axis not solved keeps its row and column at zero: a unit diagonal leaves it 0.
    for (a, solved) in [axes.0, axes.1].into_iter().enumerate() {
        if !solved {
            normal[(a, a)] = 1.0;
        }
    }
    let d = normal.cholesky()?.solve(&rhs);
    *radiometry = Radiometry {
        gain: g + d[2],
        offset: offset + d[3],
        ramp: [ramp[0] + d[4], ramp[1] + d[5]],
    };
    let [dx, dy] = [d[0], d[1]];
    (dx.is_finite() && dy.is_finite() && radiometry.gain > 0.0).then_some([dx, dy])
}

/// Columns of a row in [`shift_step`]: the gradient terms, the image, the residual and
/// the sample's place along the row.
const A: usize = 0;
const B: usize = 1;
const I: usize = 2;
const RES: usize = 3;
const U: usize = 4;

/// The 13 products summed per sample (the others are a column's plain sum or its sum
/// times the row's v): a a, a b, a i, a u, b b, b i, b u, i i, i u, a r, b r, i r, u r.
const PAIRS: [(usize, usize); 13] = [
    (A, A),
    (A, B),
    (A, I),
    (A, U),
    (B, B),
    (B, I),
    (B, U),
    (I, I),
    (I, U),
    (A, RES),
    (B, RES),
    (I, RES),
    (U, RES),
];

/// The groups of [`LANES`] samples that start below `n`, the template's width (at
/// most [`ROW`]): their products into the partial sums `acc[k]` ([`PAIRS`]) and the
/// plain sums of a, b, i and r into `line`, [`LANES`] samples at a time.
///
/// Past the template the columns hold +0.0 only, and adding +0.0 changes a float sum
/// only if it is -0.0, which these sums, begun at +0.0, never are (-0.0 is only ever
/// -0.0 + -0.0): the groups there are skipped.
#[inline]
pub(super) fn sum_row(
    cols: &[[f32; ROW]; 5],
    n: usize,
    acc: &mut [[f32; LANES]; SUMS],
    line: &mut [[f32; LANES]; 4],
) {
    #[cfg(target_arch = "x86_64")]
    return sse::sum_row(cols, n, acc, line);
    #[allow(unreachable_code)]
    sum_row_scalar(cols, n, acc, line)
}

/// The definition of [`sum_row`], and the kernel of targets without SSE: lane `l` of
/// every sum takes the samples `l, l + LANES, ...` in order, as the SSE kernel does, so
/// both give the same sums.
#[cfg_attr(target_arch = "x86_64", allow(dead_code))]
pub(super) fn sum_row_scalar(
    cols: &[[f32; ROW]; 5],
    n: usize,
    acc: &mut [[f32; LANES]; SUMS],
    line: &mut [[f32; LANES]; 4],
) {
    for c in (0..n.min(ROW)).step_by(LANES) {
        for l in 0..LANES {
            for (s, &(x, y)) in acc.iter_mut().zip(&PAIRS) {
                s[l] += cols[x][c + l] * cols[y][c + l];
            }
            for (s, col) in line.iter_mut().zip(cols) {
                s[l] += col[c + l];
            }
        }
    }
}

/// [`sum_row`] on SSE (the x86_64 baseline): one register per sum. The compiler did
/// not vectorise the scalar form: least-squares matching took 1.1 to 2.0 G
/// instructions on 100 epochs of the hand-held walk with it (callgrind).
#[cfg(target_arch = "x86_64")]
pub(super) mod sse {
    use super::{LANES, PAIRS, ROW, SUMS};
    use core::arch::x86_64::*;

    #[inline]
    pub fn sum_row(
        cols: &[[f32; ROW]; 5],
        n: usize,
        acc: &mut [[f32; LANES]; SUMS],
        line: &mut [[f32; LANES]; 4],
    ) {
        // A constant count of groups, so that the loop unrolls as over the whole row
        // (to a run-time bound it cost more than the skipped groups saved). Any count
        // past three takes the whole row: the groups past the template add nothing.
        match n.div_ceil(LANES) {
            0 => {}
            1 => groups::<1>(cols, acc, line),
            2 => groups::<2>(cols, acc, line),
            3 => groups::<3>(cols, acc, line),
            _ => groups::<{ ROW / LANES }>(cols, acc, line),
        }
    }

    /// [`sum_row`] over the first `G` groups of the row (at most the row's).
    #[inline(always)]
    fn groups<const G: usize>(
        cols: &[[f32; ROW]; 5],
        acc: &mut [[f32; LANES]; SUMS],
        line: &mut [[f32; LANES]; 4],
    ) {
        // SAFETY: SSE is part of the x86_64 baseline; every load and store reads or
        // writes LANES = 4 floats inside an array (ROW is a multiple of LANES, and the
        // groups start below ROW).
        unsafe {
            let mut s: [__m128; 13] = core::array::from_fn(|k| _mm_loadu_ps(acc[k].as_ptr()));
            let mut t: [__m128; 4] = core::array::from_fn(|k| _mm_loadu_ps(line[k].as_ptr()));
            for c in (0..(G * LANES).min(ROW)).step_by(LANES) {
                let x: [__m128; 5] =
                    core::array::from_fn(|k| _mm_loadu_ps(cols[k].as_ptr().add(c)));
                for (s, &(p, q)) in s.iter_mut().zip(&PAIRS) {
                    *s = _mm_add_ps(*s, _mm_mul_ps(x[p], x[q]));
                }
                for (t, x) in t.iter_mut().zip(&x) {
                    *t = _mm_add_ps(*t, *x);
                }
            }
            for (k, s) in s.iter().enumerate() {
                _mm_storeu_ps(acc[k].as_mut_ptr(), *s);
            }
            for (k, t) in t.iter().enumerate() {
                _mm_storeu_ps(line[k].as_mut_ptr(), *t);
            }
        }
    }
}
