//! Space resection of one camera from tie points already in object space.
//!
//! Minimal solver: Grunert's P3P (in the form of Haralick et al. 1994): with
//! the distances `s1, s2, s3` along three unit rays, `s2 = u s1`, `s3 = v s1`,
//! the law of cosines on the three sides gives a quartic in `v`; every real
//! root gives the three camera-frame points, and the rotation and centre follow
//! from the absolute orientation of three point pairs (SVD). Up to four
//! solutions are scored on all correspondences.
//!
//! Robustness: a deterministic RANSAC (fixed-seed LCG, fixed number of
//! samples), inliers by reprojection error; then Gauss-Newton (with
//! Levenberg-Marquardt damping) on the six parameters over the inliers.
//! Nothing is allocated: inlier status is recomputed from the pose.

use super::attitude;
use super::propagation::standard_deviations;
use crate::camera::{project, project_with_rotation, rigid_fit, Pose};
use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

/// An object point and its corrected photo-coordinates (mm) in the camera.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Correspondence {
    pub point: [f64; 3],
    pub xy: [f64; 2],
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResectionConfig {
    /// Most RANSAC samples drawn.
    pub samples: usize,
    /// Probability that at least one sample drawn is free of outliers: the search
    /// stops once the best hypothesis's inlier ratio makes `samples` more than that
    /// needs (the standard adaptive stopping rule, never fewer than
    /// `MIN_RANSAC_SAMPLES`). 1.0 draws all `samples`.
    pub confidence: f64,
    /// Inlier threshold on the reprojection error, mm.
    pub threshold_mm: f64,
    /// LCG seed (deterministic results).
    pub seed: u64,
    /// Least-squares iterations of the refinement.
    pub max_iterations: usize,
    /// Fewest inliers accepted.
    pub min_inliers: usize,
}

impl Default for ResectionConfig {
    fn default() -> Self {
        ResectionConfig {
            samples: 200,
            confidence: 0.9999,
            threshold_mm: 0.02,
            seed: 0x5eed,
            max_iterations: 20,
            min_inliers: 6,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResectionResult {
    pub pose: Pose,
    pub inliers: usize,
    /// RMS reprojection error of the inliers after refinement, mm.
    pub rms_mm: f64,
    /// Standard deviations of (omega, phi, kappa, X, Y, Z) from the refinement.
    pub std: [f64; 6],
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResectionError {
    /// Fewer than four correspondences, or fewer inliers than required.
    TooFewPoints,
    /// Every sample was degenerate (points collinear or coincident).
    Degenerate,
    /// An input value is NaN or infinite.
    NotFinite,
    /// The refinement's normal matrix is singular.
    Singular,
}

impl core::fmt::Display for ResectionError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            ResectionError::TooFewPoints => "too few points (or inliers) for a resection",
            ResectionError::Degenerate => "degenerate point configuration (collinear points)",
            ResectionError::NotFinite => "resection input is not finite",
            ResectionError::Singular => "resection normal matrix is singular",
        })
    }
}

/// Deterministic linear congruential generator (Knuth's MMIX constants).
pub struct Lcg(pub u64);

impl Lcg {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0
    }

    /// Uniform integer in `0..n` (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        ((self.next_u64() >> 33) % n as u64) as usize
    }
}

/// Real roots of `a x^2 + b x + c`.
fn quadratic_roots(a: f64, b: f64, c: f64, out: &mut [f64; 4]) -> usize {
    if a.abs() < 1e-300 {
        if b.abs() < 1e-300 {
            return 0;
        }
        out[0] = -c / b;
        return 1;
    }
    let d = b * b - 4.0 * a * c;
    if d < 0.0 {
        return 0;
    }
    let q = -0.5 * (b + libm::copysign(libm::sqrt(d), b));
    if q == 0.0 {
        out[0] = 0.0;
        return 1;
    }
    out[0] = q / a;
    out[1] = c / q;
    2
}

fn poly_eval(c: &[f64], x: f64) -> f64 {
    // c[0] is the leading coefficient.
    c.iter().fold(0.0, |acc, &k| acc * x + k)
}

/// Real roots of a polynomial of degree <= 4 (`c[0]` leading) by bracketing
/// between the roots of its derivative and bisection, refined by Newton.
fn poly_roots(c: &[f64], out: &mut [f64; 4]) -> usize {
    let deg = c.len() - 1;
    if deg == 2 {
        return quadratic_roots(c[0], c[1], c[2], out);
    }
    if c[0].abs() < 1e-14 * c.iter().fold(0.0f64, |m, v| m.max(v.abs())) {
        return poly_roots(&c[1..], out);
    }
    // Critical points from the derivative.
    let mut dc = [0.0; 4];
    for i in 0..deg {
        dc[i] = c[i] * (deg - i) as f64;
    }
    let mut crit = [0.0; 4];
    let nc = poly_roots(&dc[..deg], &mut crit);
    crit[..nc].sort_unstable_by(|a, b| a.total_cmp(b));
    // Cauchy bound on the roots.
    let bound = 1.0 + c[1..].iter().fold(0.0f64, |m, v| m.max((v / c[0]).abs()));
    let mut edges = [0.0; 6];
    edges[0] = -bound;
    let mut ne = 1;
    for &x in &crit[..nc] {
        if x > -bound && x < bound {
            edges[ne] = x;
            ne += 1;
        }
    }
    edges[ne] = bound;
    ne += 1;
    let mut n = 0;
    for k in 0..ne - 1 {
        let (mut lo, mut hi) = (edges[k], edges[k + 1]);
        let (mut flo, fhi) = (poly_eval(c, lo), poly_eval(c, hi));
        if flo == 0.0 {
            if n < 4 && (n == 0 || (out[n - 1] - lo).abs() > 1e-12) {
                out[n] = lo;
                n += 1;
            }
            continue;
        }
        if flo * fhi > 0.0 {
            continue;
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            let fm = poly_eval(c, mid);
            if (fm < 0.0) == (flo < 0.0) {
                lo = mid;
                flo = fm;
            } else {
                hi = mid;
            }
            if hi - lo <= 1e-15 * (1.0 + mid.abs()) {
                break;
            }
        }
        if n < 4 {
            out[n] = 0.5 * (lo + hi);
            n += 1;
        }
    }
    n
}

/// Rotation `M` and centre `C` with `q_i = M (p_i - C)` from three pairs: the rigid
/// fit of the camera-frame points `q` onto the object points `p`, `p = M^T q + C`.
fn absolute_orientation(
    p: &[Vector3<f64>; 3],
    q: &[Vector3<f64>; 3],
) -> Option<(Matrix3<f64>, Vector3<f64>)> {
    let back = rigid_fit(q.iter().zip(p).map(|(q, p)| (*q, *p, 1.0)))?;
    Some((back.r.transpose(), back.t))
}

/// Grunert's P3P: up to four poses from three correspondences.
pub fn p3p(corr: &[Correspondence; 3], focal_mm: f64, out: &mut [Pose; 4]) -> usize {
    let mut rays = [Vector3::zeros(); 3];
    let mut pts = [Vector3::zeros(); 3];
    for i in 0..3 {
        let d = Vector3::new(corr[i].xy[0], corr[i].xy[1], -focal_mm);
        rays[i] = d / d.norm();
        pts[i] = Vector3::from(corr[i].point);
    }
    let a2 = (pts[1] - pts[2]).norm_squared();
    let b2 = (pts[0] - pts[2]).norm_squared();
    let c2 = (pts[0] - pts[1]).norm_squared();
    if !(a2 > 1e-18 && b2 > 1e-18 && c2 > 1e-18) {
        return 0;
    }
    let ca = rays[1].dot(&rays[2]);
    let cb = rays[0].dot(&rays[2]);
    let cg = rays[0].dot(&rays[1]);
    let amc = (a2 - c2) / b2;
    let apc = (a2 + c2) / b2;
    let a4 = (amc - 1.0) * (amc - 1.0) - 4.0 * c2 / b2 * ca * ca;
    let a3 = 4.0 * (amc * (1.0 - amc) * cb - (1.0 - apc) * ca * cg + 2.0 * c2 / b2 * ca * ca * cb);
    let a2c = 2.0
        * (amc * amc - 1.0 + 2.0 * amc * amc * cb * cb + 2.0 * (b2 - c2) / b2 * ca * ca
            - 4.0 * apc * ca * cb * cg
            + 2.0 * (b2 - a2) / b2 * cg * cg);
    let a1 = 4.0 * (-amc * (1.0 + amc) * cb + 2.0 * a2 / b2 * cg * cg * cb - (1.0 - apc) * ca * cg);
    let a0 = (1.0 + amc) * (1.0 + amc) - 4.0 * a2 / b2 * cg * cg;
    let mut roots = [0.0; 4];
    let nr = poly_roots(&[a4, a3, a2c, a1, a0], &mut roots);
    let mut n = 0;
    for &v in &roots[..nr] {
        let den = 2.0 * (cg - v * ca);
        if den.abs() < 1e-14 {
            continue;
        }
        let u = ((-1.0 + amc) * v * v - 2.0 * amc * cb * v + 1.0 + amc) / den;
        let s1sq = b2 / (1.0 + v * v - 2.0 * v * cb);
        if !(s1sq > 0.0) || !(u > 0.0) || !(v > 0.0) {
            continue;
        }
        let s1 = libm::sqrt(s1sq);
        let q = [rays[0] * s1, rays[1] * (u * s1), rays[2] * (v * s1)];
        if let Some((m, c)) = absolute_orientation(&pts, &q) {
            if m.iter().chain(c.iter()).all(|x| x.is_finite()) && n < 4 {
                out[n] = Pose::from_rotation(&m, [c[0], c[1], c[2]]);
                n += 1;
            }
        }
    }
    n
}

fn reprojection_error(pose: &Pose, focal: f64, c: &Correspondence) -> f64 {
    match project(pose, focal, &c.point) {
        Ok(xy) => libm::hypot(xy[0] - c.xy[0], xy[1] - c.xy[1]),
        Err(_) => f64::INFINITY,
    }
}

fn score(pose: &Pose, focal: f64, corr: &[Correspondence], thr: f64) -> (usize, f64) {
    let mut n = 0;
    let mut sum = 0.0;
    for c in corr {
        let e = reprojection_error(pose, focal, c);
        if e <= thr {
            n += 1;
            sum += e * e;
        } else {
            sum += thr * thr;
        }
    }
    (n, sum)
}

/// Twice the area of the triangle of three points: zero when collinear.
fn triangle_area2(a: &[f64; 3], b: &[f64; 3], c: &[f64; 3]) -> f64 {
    let ab = Vector3::from(*b) - Vector3::from(*a);
    let ac = Vector3::from(*c) - Vector3::from(*a);
    ab.cross(&ac).norm()
}

/// Fewest RANSAC samples drawn whatever the inlier ratio: a first lucky sample with
/// a wrong pose that most points happen to fit must not end the search.
pub const MIN_RANSAC_SAMPLES: usize = 16;

/// Samples a RANSAC of minimal size 3 needs to draw one outlier-free sample with
/// probability `confidence` when `inliers` of `n` correspondences are inliers.
pub(crate) fn samples_needed(inliers: usize, n: usize, confidence: f64) -> usize {
    let w = inliers as f64 / n.max(1) as f64;
    let clean = w * w * w;
    if !(confidence < 1.0) || clean <= 0.0 {
        return usize::MAX;
    }
    if clean >= 1.0 {
        return 0;
    }
    let k = libm::log(1.0 - confidence) / libm::log(1.0 - clean);
    if k.is_finite() && k < usize::MAX as f64 {
        libm::ceil(k) as usize
    } else {
        usize::MAX
    }
}

/// Robust resection of a camera with focal length `focal_mm`.
pub fn resect(
    corr: &[Correspondence],
    focal_mm: f64,
    cfg: &ResectionConfig,
) -> Result<ResectionResult, ResectionError> {
    if corr
        .iter()
        .any(|c| !c.point.iter().chain(c.xy.iter()).all(|v| v.is_finite()))
        || !(focal_mm > 0.0 && focal_mm.is_finite())
    {
        return Err(ResectionError::NotFinite);
    }
    // Fewer correspondences than the inliers required cannot succeed: no sample is drawn.
    if corr.len() < cfg.min_inliers.max(4) {
        return Err(ResectionError::TooFewPoints);
    }
    // Scale of the scene for the collinearity test.
    let mut extent = 0.0f64;
    for c in corr {
        for a in 0..3 {
            extent = extent.max((c.point[a] - corr[0].point[a]).abs());
        }
    }
    let mut rng = Lcg(cfg.seed);
    let mut best: Option<(Pose, usize, f64)> = None;
    let mut candidates = [Pose::default(); 4];
    let mut needed = cfg.samples;
    for drawn in 0..cfg.samples {
        if drawn >= needed.max(MIN_RANSAC_SAMPLES) {
            break;
        }
        let i = rng.below(corr.len());
        let mut j = rng.below(corr.len() - 1);
        if j >= i {
            j += 1;
        }
        let mut k = rng.below(corr.len() - 2);
        for idx in [i.min(j), i.max(j)] {
            if k >= idx {
                k += 1;
            }
        }
        let sample = [corr[i], corr[j], corr[k]];
        if triangle_area2(&sample[0].point, &sample[1].point, &sample[2].point)
            < 1e-6 * extent * extent
        {
            continue;
        }
        let n = p3p(&sample, focal_mm, &mut candidates);
        for pose in &candidates[..n] {
            let (inl, sum) = score(pose, focal_mm, corr, cfg.threshold_mm);
            let better = match best {
                None => true,
                Some((_, bi, bs)) => inl > bi || (inl == bi && sum < bs),
            };
            if better {
                best = Some((*pose, inl, sum));
                needed = needed.min(samples_needed(inl, corr.len(), cfg.confidence));
            }
        }
    }
    let (pose, inliers, _) = best.ok_or(ResectionError::Degenerate)?;
    if inliers < cfg.min_inliers.max(4) {
        return Err(ResectionError::TooFewPoints);
    }
    let first = refine(pose, corr, focal_mm, cfg)?;
    // The inliers of the refined pose, refined once more: the result no longer depends
    // on which sample's pose won (the search may stop at the first with enough
    // inliers), and correspondences the sample's pose just missed take part.
    match refine(first.pose, corr, focal_mm, cfg) {
        Ok(again) if again.inliers >= first.inliers => Ok(again),
        _ => Ok(first),
    }
}

/// Least-squares refinement over the inliers of `pose` (damped Gauss-Newton), its
/// attitude unknowns a turn in the object frame as the window's ([`attitude`]).
pub fn refine(
    mut pose: Pose,
    corr: &[Correspondence],
    focal_mm: f64,
    cfg: &ResectionConfig,
) -> Result<ResectionResult, ResectionError> {
    // The inlier set is fixed by the starting pose (recomputed, not stored),
    // so the cost stays comparable between iterations.
    let start = pose;
    let member = |c: &Correspondence| reprojection_error(&start, focal_mm, c) <= cfg.threshold_mm;
    let mask_count: usize = corr.iter().filter(|c| member(c)).count();
    if mask_count < 4 {
        return Err(ResectionError::TooFewPoints);
    }
    let cost_of = |p: &Pose| -> f64 {
        corr.iter()
            .filter(|c| member(c))
            .map(|c| match project(p, focal_mm, &c.point) {
                Ok(xy) => {
                    (xy[0] - c.xy[0]) * (xy[0] - c.xy[0]) + (xy[1] - c.xy[1]) * (xy[1] - c.xy[1])
                }
                Err(_) => 1e30,
            })
            .sum()
    };
    let mut cost = cost_of(&pose);
    let mut lambda = 1e-6;
    let mut normal = Matrix6::<f64>::zeros();
    for _ in 0..cfg.max_iterations {
        normal = Matrix6::zeros();
        let mut g = Vector6::zeros();
        let rotation = attitude::with_turn_derivatives(pose.omega, pose.phi, pose.kappa);
        for c in corr.iter().filter(|c| member(c)) {
            let Ok(pr) = project_with_rotation(&pose, rotation, focal_mm, &c.point) else {
                continue;
            };
            for k in 0..2 {
                let j = Vector6::from_row_slice(&pr.d_pose[k]);
                let r = c.xy[k] - pr.xy[k];
                normal += j * j.transpose();
                g += j * r;
            }
        }
        let mut damped = normal;
        for i in 0..6 {
            damped[(i, i)] *= 1.0 + lambda;
        }
        let Some(ch) = damped.cholesky() else {
            return Err(ResectionError::Singular);
        };
        let dx = ch.solve(&g);
        let mut p = pose.to_params();
        attitude::turn(&mut p, [dx[0], dx[1], dx[2]]);
        for i in 3..6 {
            p[i] += dx[i];
        }
        let cand = Pose::from_params(&p);
        let new_cost = cost_of(&cand);
        if new_cost <= cost {
            let done = cost - new_cost <= 1e-14 * cost.max(1e-300);
            pose = cand;
            cost = new_cost;
            lambda *= 0.1;
            if done {
                break;
            }
        } else {
            lambda *= 10.0;
            if lambda > 1e8 {
                break;
            }
        }
    }
    let dof = (2 * mask_count).saturating_sub(6).max(1);
    let s02 = cost / dof as f64;
    let cov = normal.cholesky().ok_or(ResectionError::Singular)?.inverse() * s02;
    let turn_cov = core::array::from_fn(|i| cov[(i / 6, i % 6)]);
    let std = standard_deviations(&attitude::to_angles(&pose.to_params(), &turn_cov));
    Ok(ResectionResult {
        pose,
        inliers: mask_count,
        rms_mm: libm::sqrt(cost / mask_count as f64),
        std,
    })
}
