//! Sub-pixel refinement of a stereo match by area matching: a template around the left
//! point (bilinear, at its sub-pixel position) is correlated (NCC) with the right image
//! on a grid of whole-pixel offsets around the matched position; a parabola through the
//! peak and its neighbours gives the sub-pixel offset on each axis (seed 003's
//! correlation, seed 002's 9x9 template, but centred on a descriptor match).

use super::config::{RefineConfig, MAX_REFINE_HALF, MAX_REFINE_RADIUS};
use crate::image::ImageView;

/// Why a refinement did not give a position.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefineError {
    /// The template or the search area leaves the image (the match is kept unrefined).
    Border,
    /// The template has no texture (zero variance).
    Flat,
    /// The correlation peak is below `min_ncc`.
    LowScore,
    /// The peak lies on the edge of the search area: the descriptor match and the area
    /// match disagree by more than the search radius.
    PeakOnEdge,
    /// Correlating back from the right image does not return to the left point.
    BackCheck,
    /// Another place along the epipolar line correlates nearly as well (a repeated texture).
    Ambiguous,
}

/// A correlation's result: the sub-pixel position, the NCC peak and the position's
/// standard deviation on each axis (pixels) as the peak itself gives it.
///
/// The precision is that of area matching (least-squares matching's
/// `sigma_x^2 = sigma_noise^2 / sum(g_x^2)`) written with the correlation's own
/// figures: the noise-to-signal ratio of the template against the image is
/// `(1 - rho) / rho` at the peak `rho`, and the NCC's curvature there, per pixel
/// squared, is `-rho` times the template's gradient-to-signal ratio, so
/// `sigma^2 = (1 - rho) / (n |curvature|)` over the template's `n` samples. A sharp,
/// high peak is a precise match; a low or flat one is not. An axis the search did not
/// cover (a rectified rig's stereo search along the row, whose y is the left one's)
/// takes the searched axis's value. Measured, giving that axis the configured sigma
/// instead moved single runs by their usual spread, not one way (the 90-epoch outage
/// of `host/tests/gnss_outage.rs` 0.108 -> 0.155 m, `straight` 0.040 -> 0.034 %).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Peak {
    pub at: [f32; 2],
    pub score: f32,
    pub sigma: [f32; 2],
}

/// Curvature (per pixel squared) below which a peak counts as flat in [`Peak`]'s
/// precision.
const MIN_CURVATURE: f32 = 1e-4;
/// The smallest `1 - rho` [`Peak`]'s precision uses: a perfect match still errs by its
/// sampling.
const MIN_MISMATCH: f32 = 1e-4;

/// The search of the right position around `right` (as [`refine_match`]), then the
/// left-right check of [`RefineConfig::back_check_px`].
///
/// On a rectified rig (`rows_only`) the position returned then ends with least-squares
/// matching along the row, or where that does not settle the re-centred parabola
/// ([`Correlator::recentre`]): the single fit leans towards the descriptor's right
/// keypoint, where its grid starts, and the re-centred one by an amount of each
/// texture's own, a disparity error the window takes for scale. The check still
/// compares the single fits both ways, so which matches pass is unchanged; re-centring
/// took 100 rendered epochs of `photo-curves` from 0.060 to 0.049 %, `hard` from 0.129
/// to 0.102 %, and least squares the drift of five unseen draws' rectified streets to
/// 0.86..0.95 of that at 640x480 and 0.78..0.94 at 320x240 (`docs/traverse.md`). Off
/// the rows (the general rig geometry's two-axis search: a converging rig,
/// lens distortion, a calibration with a relative rotation) the re-centred position
/// was worse (`seed2014` 0.086 -> 0.112 %); there least-squares matching
/// ([`Correlator::least_squares`]) ends the search instead, and where it does not
/// settle the single fit stays. The single fit's lean towards its grid is a lean of
/// the disparities, which the window takes for scale: on 24 draws of the converging
/// rig's streets the drift fell to 0.75 of what it was with the single fit, and
/// none of them missed the benchmark's bar, against 5 (`bench/traverse/README.md`,
/// "Least squares on the stereo of a converging rig, adopted").
pub fn refine_checked(
    buf: &mut Correlator,
    left_img: &ImageView<'_>,
    right_img: &ImageView<'_>,
    left: [f32; 2],
    right: [f32; 2],
    cfg: &RefineConfig,
) -> Result<Peak, RefineError> {
    let (tpl, h) = left_template(left_img, left, cfg)?;
    let found = search_right(buf, &tpl, h, right_img, left, right, cfg)?;
    let p = found.at;
    if cfg.back_check_px > 0.0 {
        let back_cfg = RefineConfig {
            min_ncc: f32::MIN,
            ..*cfg
        };
        let q = refine_match(buf, right_img, left_img, p, left, &back_cfg)
            .map_err(|e| {
                if e == RefineError::Border {
                    e
                } else {
                    RefineError::BackCheck
                }
            })?
            .at;
        if (q[0] - left[0]).abs() > cfg.back_check_px || (q[1] - left[1]).abs() > cfg.back_check_px
        {
            return Err(RefineError::BackCheck);
        }
    }
    if !cfg.rows_only {
        let settled = buf.least_squares(&tpl, h, right_img, p, (1, 1));
        return Ok(settled.map_or(found, |at| Peak { at, ..found }));
    }
    // A first pass centred on the checked position, then the re-centring passes.
    let found = buf
        .correlate(&tpl, h, right_img, p, (1, 0), cfg.min_ncc)
        .unwrap_or(found);
    Ok(buf.recentre(&tpl, h, right_img, found, (1, 0), cfg.min_ncc))
}

/// Side of the largest template.
pub(super) const T: usize = 2 * MAX_REFINE_HALF + 1;
const S: usize = 2 * MAX_REFINE_RADIUS + 1;
/// Side of the largest sampled search region (template plus search on both sides):
/// every lane of [`window_sums`] reads inside a row.
const R: usize = T + S - 1;

/// The bilinear sample between columns `c`, `c + 1` of the rows `top` and `bot` at the
/// fractions `fx` across and `fy` down: the one formula every sampler here uses (of the
/// image's grey levels and of a template's samples), so their samples agree to the bit.
#[inline]
fn bilinear<P: Copy + Into<f32>>(top: &[P], bot: &[P], c: usize, fx: f32, fy: f32) -> f32 {
    let t = top[c].into() * (1.0 - fx) + top[c + 1].into() * fx;
    let b = bot[c].into() * (1.0 - fx) + bot[c + 1].into() * fx;
    t * (1.0 - fy) + b * fy
}

/// NCC of a window (its sum, sum of squares and cross product with the zero-mean
/// template of squared norm `tnorm`, over `cnt` samples); -1 for a flat window.
#[inline]
fn ncc(sum: f32, sum2: f32, cross: f32, cnt: f32, tnorm: f32) -> f32 {
    let var = sum2 - sum * sum / cnt;
    if var > 1e-3 * cnt {
        cross / libm::sqrtf(var * tnorm)
    } else {
        -1.0
    }
}

/// Zero-mean copy of the `n x n` template and its squared norm; `None` when flat.
fn zero_mean(tpl: &[f32; TEMPLATE_LEN], n: usize) -> Option<([f32; TEMPLATE_LEN], f32)> {
    let cnt = (n * n) as f32;
    let mean = tpl[..n * n].iter().sum::<f32>() / cnt;
    let mut zt = [0f32; TEMPLATE_LEN];
    let mut tnorm = 0f32;
    for (z, &t) in zt.iter_mut().zip(&tpl[..n * n]) {
        *z = t - mean;
        tnorm += *z * *z;
    }
    (tnorm >= 1e-3 * cnt).then_some((zt, tnorm))
}

/// Bilinear samples of the `w x h` grid at `origin + (u, v)` into `out` (row stride
/// [`R`]); the caller guarantees the grid lies inside the image with a pixel to spare.
fn sample_region(
    img: &ImageView<'_>,
    origin: [f32; 2],
    (w, h): (usize, usize),
    out: &mut [f32; R * R],
) {
    let (c0, r0) = (origin[0] as usize, origin[1] as usize);
    let (fx, fy) = (origin[0] - c0 as f32, origin[1] - r0 as f32);
    for v in 0..h {
        let (top, bot) = (img.row(r0 + v), img.row(r0 + v + 1));
        let (top, bot) = (&top[c0..c0 + w + 1], &bot[c0..c0 + w + 1]);
        for u in 0..w {
            out[v * R + u] = bilinear(top, bot, u, fx, fy);
        }
    }
}

fn inside(img: &ImageView<'_>, x: f32, y: f32, margin: f32) -> bool {
    x - margin >= 0.0
        && y - margin >= 0.0
        && x + margin < (img.width() - 1) as f32
        && y + margin < (img.height() - 1) as f32
}

/// The vertex of a parabola through the NCC scores `(-1, a)`, `(0, b)`, `(1, c)` (b the
/// maximum) over `cnt` samples: its sub-pixel offset and the offset's standard
/// deviation in pixels ([`Peak`]), both from the parabola's curvature.
#[inline]
fn vertex(a: f32, b: f32, c: f32, cnt: f32) -> (f32, f32) {
    let den = a - 2.0 * b + c;
    let offset = if den < -1e-9 {
        (0.5 * (a - c) / den).clamp(-0.5, 0.5)
    } else {
        0.0
    };
    let curvature = (-den).max(MIN_CURVATURE);
    let sigma = libm::sqrtf((1.0 - b).max(MIN_MISMATCH) / (cnt * curvature));
    (offset, sigma)
}

/// Refines the right position `right` of the left point `left` in the buffers `buf`:
/// the refined right position with the NCC peak and its precision.
pub fn refine_match(
    buf: &mut Correlator,
    left_img: &ImageView<'_>,
    right_img: &ImageView<'_>,
    left: [f32; 2],
    right: [f32; 2],
    cfg: &RefineConfig,
) -> Result<Peak, RefineError> {
    let (tpl, h) = left_template(left_img, left, cfg)?;
    search_right(buf, &tpl, h, right_img, left, right, cfg)
}

/// The template of `left` and its half-size.
fn left_template(
    left_img: &ImageView<'_>,
    left: [f32; 2],
    cfg: &RefineConfig,
) -> Result<([f32; TEMPLATE_LEN], usize), RefineError> {
    let h = (cfg.half_window as usize).min(MAX_REFINE_HALF);
    let mut tpl = [0f32; TEMPLATE_LEN];
    sample_template(left_img, left, h, &mut tpl)?;
    Ok((tpl, h))
}

/// The search of [`refine_match`] with the left template (half-size `h`) sampled.
fn search_right(
    buf: &mut Correlator,
    tpl: &[f32; TEMPLATE_LEN],
    h: usize,
    right_img: &ImageView<'_>,
    left: [f32; 2],
    right: [f32; 2],
    cfg: &RefineConfig,
) -> Result<Peak, RefineError> {
    let centre = if cfg.rows_only {
        [right[0], left[1]]
    } else {
        right
    };
    let rad = (cfg.search_radius as usize).clamp(1, MAX_REFINE_RADIUS);
    let (rx, ry) = if cfg.rows_only { (rad, 0) } else { (rad, rad) };
    buf.correlate(tpl, h, right_img, centre, (rx, ry), cfg.min_ncc)
}

/// Values of the largest template ([`MAX_REFINE_HALF`]).
pub const TEMPLATE_LEN: usize = T * T;

/// Samples the `(2h + 1)^2` template around `at` (bilinear) into `tpl`, row by row.
pub fn sample_template(
    img: &ImageView<'_>,
    at: [f32; 2],
    h: usize,
    tpl: &mut [f32; TEMPLATE_LEN],
) -> Result<(), RefineError> {
    let h = h.min(MAX_REFINE_HALF);
    let (n, hf) = (2 * h + 1, h as f32);
    if !at.iter().all(|v| v.is_finite()) || !inside(img, at[0], at[1], hf) {
        return Err(RefineError::Border);
    }
    // Bilinear samples at `at + (u, v) - h`, the whole and fractional parts of each
    // column and row computed once rather than per sample. They are computed per column
    // and per row, not once for the grid: where a coordinate crosses a power of two its
    // rounding, and so its fraction, changes.
    let mut cols = [(0usize, 0f32); T];
    for (u, col) in cols[..n].iter_mut().enumerate() {
        let x = at[0] + u as f32 - hf;
        let c = x as usize;
        *col = (c, x - c as f32);
    }
    for v in 0..n {
        let y = at[1] + v as f32 - hf;
        let r = y as usize;
        let fy = y - r as f32;
        let (r0, r1) = (img.row(r), img.row(r + 1));
        for (t, &(c, fx)) in tpl[v * n..(v + 1) * n].iter_mut().zip(&cols[..n]) {
            *t = bilinear(r0, r1, c, fx, fy);
        }
    }
    Ok(())
}

/// The template `tpl` (half-size `h`) as it appears `scale` (>= 1) times larger: each
/// sample is read (bilinear) from the original at `1 / scale` of its distance to the
/// centre, so the centre stays the same surface point. A scale below 1 would read
/// outside the template and is refused, as is one above 2.
pub fn magnify_template(
    tpl: &[f32; TEMPLATE_LEN],
    h: usize,
    scale: f32,
    out: &mut [f32; TEMPLATE_LEN],
) -> bool {
    let h = h.min(MAX_REFINE_HALF);
    if h == 0 || !(scale.is_finite() && (1.0..=2.0).contains(&scale)) {
        return false;
    }
    let (n, hf) = (2 * h + 1, h as f32);
    let inv = 1.0 / scale;
    for v in 0..n {
        let y = hf + (v as f32 - hf) * inv;
        for u in 0..n {
            let x = hf + (u as f32 - hf) * inv;
            out[v * n + u] = template_sample(tpl, n, x, y);
        }
    }
    true
}

/// The bilinear sample of the `n x n` template `tpl` at (`x`, `y`) in `0..=n - 1`,
/// template pixels from its top left sample.
pub fn template_sample(tpl: &[f32; TEMPLATE_LEN], n: usize, x: f32, y: f32) -> f32 {
    let (c, fx) = split(x, n);
    let (r, fy) = split(y, n);
    bilinear(&tpl[r * n..], &tpl[(r + 1) * n..], c, fx, fy)
}

/// Whole and fractional parts of a template coordinate, the whole part kept below
/// `n - 1` so its right (or lower) neighbour exists.
fn split(x: f32, n: usize) -> (usize, f32) {
    let i = (x.max(0.0) as usize).min(n - 2);
    (i, x - i as f32)
}

/// Re-centring passes after the search (see [`Correlator::recentre`]).
const RECENTRE_PASSES: usize = 2;

/// A re-centring pass that moves the estimate less than this (pixels) ends them.
const RECENTRE_SETTLED_PX: f32 = 0.02;

impl Correlator {
    /// The sub-pixel position of the peak `found` (a result of [`Correlator::correlate`]
    /// searching `step`: `(1, 0)` along rows only, `(1, 1)` on both axes): by
    /// least-squares matching ([`super::lsm`]) on the axes searched, and where that
    /// does not settle near `found`, [`Correlator::correlate`] repeated on grids
    /// centred on the estimate.
    ///
    /// The parabola is biased towards the sampled grid (pixel locking), and the grid is
    /// the search's start plus whole pixels: the estimate leans towards the start. For a
    /// tie point the start is the keypoint's own position, displaced along the image
    /// motion, or the motion prediction. Re-centred, the parabola's vertex is near its
    /// middle sample, but it still leans by an amount of the texture's own, since the
    /// peak is not a parabola (test
    /// `a_rectified_rigs_stereo_match_does_not_lean_with_its_texture`). Least squares
    /// has neither a grid nor a model of the peak. Used for the temporal correlations
    /// and for the measured stereo position of a rectified rig ([`refine_checked`]). A
    /// pass that fails keeps the last estimate. The score and the precision stay those
    /// of the correlation.
    pub fn recentre(
        &mut self,
        tpl: &[f32; TEMPLATE_LEN],
        h: usize,
        img: &ImageView<'_>,
        found: Peak,
        step: (usize, usize),
        min_ncc: f32,
    ) -> Peak {
        if let Some(at) = self.least_squares(tpl, h, img, found.at, step) {
            return Peak { at, ..found };
        }
        let mut peak = found;
        for _ in 0..RECENTRE_PASSES {
            let Ok(next) = self.correlate(tpl, h, img, peak.at, step, min_ncc) else {
                break;
            };
            let moved = (next.at[0] - peak.at[0])
                .abs()
                .max((next.at[1] - peak.at[1]).abs());
            peak = next;
            if moved < RECENTRE_SETTLED_PX {
                break;
            }
        }
        peak
    }

    /// Least-squares matching of `tpl` (half-size `h`) in `img` from `start` on the axes
    /// of `step` ([`super::lsm`]): the position where it settles, `None` where it does
    /// not within [`super::lsm::ITERATIONS`] or leaves the start by more than
    /// [`super::lsm::MAX_MOVE_PX`].
    pub fn least_squares(
        &mut self,
        tpl: &[f32; TEMPLATE_LEN],
        h: usize,
        img: &ImageView<'_>,
        start: [f32; 2],
        step: (usize, usize),
    ) -> Option<[f32; 2]> {
        use super::lsm::{shift_step, Radiometry, StepLength, ITERATIONS, MAX_MOVE_PX, SETTLED_PX};
        let h = h.min(MAX_REFINE_HALF);
        let (n, hf) = (2 * h + 1, h as f32);
        let (zt, _) = zero_mean(tpl, n)?;
        let mut at = start;
        let mut radiometry: Option<Radiometry> = None;
        let mut length = StepLength::default();
        for _ in 0..ITERATIONS {
            // The template's grid and a one-sample border (for the gradients), and a
            // pixel to spare for the bilinear samples.
            if !at.iter().all(|v| v.is_finite()) || !inside(img, at[0], at[1], hf + 2.0) {
                return None;
            }
            let origin = [at[0] - hf - 1.0, at[1] - hf - 1.0];
            sample_region(img, origin, (n + 2, n + 2), &mut self.region);
            let r = match radiometry.as_mut() {
                Some(r) => r,
                None => radiometry.insert(Radiometry::initial(&self.region, R, &zt, n)?),
            };
            let d = length.take(shift_step(
                &self.region,
                R,
                &zt,
                n,
                (step.0 > 0, step.1 > 0),
                r,
            )?);
            at = [at[0] + d[0], at[1] + d[1]];
            if (at[0] - start[0]).abs() > MAX_MOVE_PX || (at[1] - start[1]).abs() > MAX_MOVE_PX {
                return None;
            }
            if d[0].abs() < SETTLED_PX && d[1].abs() < SETTLED_PX {
                return Some(at);
            }
        }
        None
    }
}

/// Sum, sum of squares and cross product with `zt` of the `n x n` windows that start at
/// the first columns of `rows` (a region of row stride [`R`]), into `out` (its first
/// `L` or all of it). The `L` offsets of a row are accumulated side by side, which the
/// compiler vectorises: a window-by-window loop was the search's inner loop, one
/// dependent addition per sample.
#[inline]
fn window_sums<const L: usize>(rows: &[f32], zt: &[f32], n: usize, out: &mut [[f32; 3]]) {
    debug_assert!(n - 1 + L <= R);
    // One quantity per pass: with a single accumulator array the lanes map onto
    // vector registers (three interleaved arrays were vectorised across them instead).
    let sum = lane_pass::<L>(rows, zt, n, |x, _| x);
    let sum2 = lane_pass::<L>(rows, zt, n, |x, _| x * x);
    let cross = lane_pass::<L>(rows, zt, n, |x, z| x * z);
    for (k, o) in out.iter_mut().enumerate().take(L) {
        *o = [sum[k], sum2[k], cross[k]];
    }
}

/// `sum f(sample, template value)` over the `n x n` windows at the first `L` columns.
#[inline(always)]
fn lane_pass<const L: usize>(
    rows: &[f32],
    zt: &[f32],
    n: usize,
    f: impl Fn(f32, f32) -> f32,
) -> [f32; L] {
    let mut acc = [0f32; L];
    for v in 0..n {
        let row = &rows[v * R..v * R + R];
        // A sum per template row, then the rows: the rows' additions are independent
        // and overlap, where one running sum would wait on every previous addition.
        let mut part = [0f32; L];
        for (u, &z) in zt[v * n..(v + 1) * n].iter().enumerate() {
            let s: &[f32; L] = row[u..u + L].try_into().unwrap_or(&[0.0; L]);
            for (a, &x) in part.iter_mut().zip(s) {
                *a += f(x, z);
            }
        }
        for (a, p) in acc.iter_mut().zip(part) {
            *a += p;
        }
    }
    acc
}

/// Positions a line search scores at most (whole-pixel steps): [`LineSegment`] cuts a
/// longer one at its near end, where points are fewest.
pub const MAX_LINE_STEPS: usize = 512;

/// Steepest epipolar line [`search_line`] follows (rows per column): each chunk of
/// [`S`] positions is read on one row, which then strays by up to `4 x slope` pixels.
pub const MAX_LINE_SLOPE: f32 = 0.2;

/// A stretch of an epipolar line in the right image: `steps` positions a whole pixel
/// apart in x from `start` (the near end, largest disparity), `y` rising by `slope`
/// per step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineSegment {
    pub start: [f32; 2],
    pub slope: f32,
    pub steps: usize,
}

impl LineSegment {
    /// The row of a rectified pair at disparities `dmin..=dmax` of the left point `left`.
    pub fn row(left: [f32; 2], (dmin, dmax): (usize, usize)) -> Self {
        let dmax = dmax.min(dmin.saturating_add(MAX_LINE_STEPS - 1));
        LineSegment {
            start: [left[0] - dmax as f32, left[1]],
            slope: 0.0,
            steps: dmax.checked_sub(dmin).map_or(0, |n| n + 1),
        }
    }

    /// From its near end `near` to its far end `far` (pixels); `None` when an end is not
    /// finite, the line runs the wrong way (the far end left of the near one: a right
    /// camera that is not to the right of the left one) or is steeper than
    /// [`MAX_LINE_SLOPE`]. A segment longer than [`MAX_LINE_STEPS`] keeps its far end.
    pub fn between(near: [f32; 2], far: [f32; 2]) -> Option<Self> {
        let (dx, dy) = (far[0] - near[0], far[1] - near[1]);
        if !(dx.is_finite() && dx >= 1.0 && dy.abs() <= MAX_LINE_SLOPE * dx) {
            return None;
        }
        let slope = dy / dx;
        let steps = dx.min((MAX_LINE_STEPS - 1) as f32) as usize + 1;
        let back = (steps - 1) as f32;
        Some(LineSegment {
            start: [far[0] - back, far[1] - back * slope],
            slope,
            steps,
        })
    }

    fn at(&self, k: usize) -> [f32; 2] {
        [
            self.start[0] + k as f32,
            self.start[1] + k as f32 * self.slope,
        ]
    }
}

/// The NCC scores of the `n x n` template `zt` (zero-mean, squared norm `tnorm`) at the
/// [`S`] whole-pixel offsets `origin.x + 0 ..= S - 1` of one row of `img` (`origin`: the
/// top-left corner of the first window, inside the image with a pixel to spare).
fn row_scores(img: &ImageView<'_>, zt: &[f32], tnorm: f32, n: usize, origin: [f32; 2]) -> [f32; S] {
    let mut region = [0f32; R * R];
    sample_region(img, origin, (n + S - 1, n), &mut region);
    let mut window = [[0f32; 3]; S];
    window_sums::<S>(&region, zt, n, &mut window);
    let cnt = (n * n) as f32;
    window.map(|[sum, sum2, cross]| ncc(sum, sum2, cross, cnt, tnorm))
}

/// Finds the left template `tpl` (half-size `h`) along the epipolar `line` of the right
/// image `img`; returns the position of the best score, whole-pixel along the line.
///
/// For a left keypoint the descriptors gave no right partner (the detector did not
/// fire at the same spot in the right image, or the ratio test refused it): the area
/// alone then decides, so the peak must stand out. It must reach `min_ncc`, and its
/// NCC distance `sqrt(1 - ncc)` must be below `ratio` times that of the best other
/// local peak of the line (the descriptors' ratio test, on the correlation), which
/// refuses a template that repeats along the line (windows of a facade). The position
/// is whole-pixel: [`refine_checked`] from there gives the sub-pixel one and checks it
/// back.
pub fn search_line(
    tpl: &[f32; TEMPLATE_LEN],
    h: usize,
    img: &ImageView<'_>,
    line: LineSegment,
    (min_ncc, ratio): (f32, f32),
) -> Result<[f32; 2], RefineError> {
    let h = h.min(MAX_REFINE_HALF);
    let (n, hf) = (2 * h + 1, h as f32);
    let steps = line.steps.min(MAX_LINE_STEPS);
    if !(line.start.iter().all(|v| v.is_finite()) && line.slope.abs() <= MAX_LINE_SLOPE) {
        return Err(RefineError::Border);
    }
    let Some((zt, tnorm)) = zero_mean(tpl, n) else {
        return Err(RefineError::Flat);
    };
    // The positions whose chunk windows lie inside the image, with a pixel to spare;
    // the positions are a straight line, so those form one run.
    let margin = hf + 1.0 + (S / 2) as f32 * line.slope.abs();
    let fits = |k: usize| {
        let [x, y] = line.at(k);
        inside(img, x, y, margin)
    };
    let Some(first) = (0..steps).find(|&k| fits(k)) else {
        return Err(RefineError::Border);
    };
    let last = (first..steps)
        .take_while(|&k| fits(k))
        .last()
        .unwrap_or(first);
    let count = last - first + 1;
    if count < S {
        return Err(RefineError::Border);
    }
    // Chunks of S positions, each read on the row of its middle one; the last chunk is
    // moved back to end at the run's end rather than read past it.
    let mut score = [f32::MIN; MAX_LINE_STEPS];
    let mut k = 0;
    while k < count {
        let begin = k.min(count - S);
        let [x, _] = line.at(first + begin);
        let [_, y] = line.at(first + begin + S / 2);
        let chunk = row_scores(img, &zt, tnorm, n, [x - hf, y - hf]);
        score[begin..begin + S].copy_from_slice(&chunk);
        k = begin + S;
    }
    let score = &score[..count];
    let (best, peak) = score
        .iter()
        .copied()
        .enumerate()
        .fold((0, f32::MIN), |b, (i, v)| if v > b.1 { (i, v) } else { b });
    if peak < min_ncc {
        return Err(RefineError::LowScore);
    }
    if best == 0 || best == count - 1 {
        return Err(RefineError::PeakOnEdge);
    }
    let rival = (1..count - 1)
        .filter(|&i| i != best && score[i] >= score[i - 1] && score[i] >= score[i + 1])
        .map(|i| score[i])
        .fold(f32::MIN, f32::max);
    // Floored so that a perfect peak still loses to a perfect repeat.
    let distance = |v: f32| libm::sqrtf((1.0 - v).max(1e-4));
    if rival > f32::MIN && distance(peak) >= ratio * distance(rival) {
        return Err(RefineError::Ambiguous);
    }
    Ok(line.at(first + best))
}

/// The buffers of a correlation search (2.4 KB, on the caller's stack), for the
/// searches of one point in a row: initialising them for every search cost as much as
/// a sixth of the search. A search reads only what it wrote itself.
pub struct Correlator {
    region: [f32; R * R],
    score: [f32; S * S],
}

impl Default for Correlator {
    fn default() -> Self {
        Self::new()
    }
}

impl Correlator {
    pub fn new() -> Self {
        Correlator {
            region: [0.0; R * R],
            score: [0.0; S * S],
        }
    }

    /// Correlates the template `tpl` (half-size `h`, as [`sample_template`] wrote it)
    /// with `img` at whole-pixel offsets up to `(rx, ry)` around `centre`; a parabola
    /// through the peak and its neighbours gives the sub-pixel position on each
    /// searched axis.
    ///
    /// The region's columns past the searched width keep what an earlier search left
    /// there: only the lanes of offsets beyond the search read them, and those are dropped.
    pub fn correlate(
        &mut self,
        tpl: &[f32; TEMPLATE_LEN],
        h: usize,
        img: &ImageView<'_>,
        centre: [f32; 2],
        (rx, ry): (usize, usize),
        min_ncc: f32,
    ) -> Result<Peak, RefineError> {
        let h = h.min(MAX_REFINE_HALF);
        let (rx, ry) = (rx.min(MAX_REFINE_RADIUS), ry.min(MAX_REFINE_RADIUS));
        let (n, hf) = (2 * h + 1, h as f32);
        let reach = hf + rx.max(ry) as f32 + 1.0;
        if !centre.iter().all(|v| v.is_finite()) || !inside(img, centre[0], centre[1], reach) {
            return Err(RefineError::Border);
        }
        let cnt = (n * n) as f32;
        let Some((zt, tnorm)) = zero_mean(tpl, n) else {
            return Err(RefineError::Flat);
        };
        // Every position of the search shares the fractional part of `centre`: sample the
        // region once (bilinear) and slide the template over it by whole pixels.
        let (rw, rh) = (n + 2 * rx, n + 2 * ry);
        let Correlator { region, score } = self;
        sample_region(
            img,
            [centre[0] - rx as f32 - hf, centre[1] - ry as f32 - hf],
            (rw, rh),
            region,
        );
        let mut best = (0usize, 0usize, f32::MIN);
        let cols = 2 * rx + 1;
        for oy in 0..=2 * ry {
            let rows = &region[oy * R..];
            let mut window = [[0f32; 3]; S];
            match cols {
                0..=4 => window_sums::<4>(rows, &zt, n, &mut window),
                5..=8 => window_sums::<8>(rows, &zt, n, &mut window),
                _ => window_sums::<S>(rows, &zt, n, &mut window),
            }
            for (ox, &[sum, sum2, cross]) in window[..cols].iter().enumerate() {
                let ncc = ncc(sum, sum2, cross, cnt, tnorm);
                score[oy * S + ox] = ncc;
                if ncc > best.2 {
                    best = (ox, oy, ncc);
                }
            }
        }
        let (bx, by, peak) = best;
        if peak < min_ncc {
            return Err(RefineError::LowScore);
        }
        if bx == 0 || bx == 2 * rx || (ry > 0 && (by == 0 || by == 2 * ry)) {
            return Err(RefineError::PeakOnEdge);
        }
        let at = |x: usize, y: usize| score[y * S + x];
        let (dx, sx) = vertex(at(bx - 1, by), peak, at(bx + 1, by), cnt);
        let (dy, sy) = if ry > 0 {
            vertex(at(bx, by - 1), peak, at(bx, by + 1), cnt)
        } else {
            (0.0, sx)
        };
        Ok(Peak {
            at: [
                centre[0] + bx as f32 - rx as f32 + dx,
                centre[1] + by as f32 - ry as f32 + dy,
            ],
            score: peak,
            sigma: [sx, sy],
        })
    }
}
