//! Motion consistency of the closed quads (LIBVISO2-style, here 3-D to 3-D): a quad
//! closes its loop but can still be wrong consistently (a repeated window matched to
//! its neighbour in both images). Each quad is triangulated at k-1 (P) and at k (Q) in
//! its left camera frame; one rigid motion `Q = R P + t` must explain them all. The
//! motion is found by a deterministic RANSAC over 3-quad samples (weighted Kabsch,
//! weights 1/Z^2 so far points with uncertain depth do not steer it), refitted on the
//! inliers; a quad is an inlier when `R P + t` reprojects into the current left and right
//! images within `threshold_px` of its observations. Image-space residuals keep far
//! points, whose depth is poor but whose reprojection is still exact, in the test.

use crate::camera::{rigid_fit, Rig, RigidMotion};
use nalgebra::{Matrix3, Vector3};

/// Parameters of the check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionCheckConfig {
    /// Largest reprojection residual of an inlier, pixels.
    pub threshold_px: f32,
    /// RANSAC samples.
    pub iterations: u32,
    /// Fewer usable quads than this skips the check.
    pub min_quads: usize,
}

impl Default for MotionCheckConfig {
    fn default() -> Self {
        MotionCheckConfig {
            threshold_px: 2.0,
            iterations: 64,
            min_quads: 8,
        }
    }
}

/// One quad's observations: previous left/right, current left/right (pixels).
pub type QuadObs = [[f32; 2]; 4];

/// Weight of a point in the fit: `1/Z^2`, so far points with uncertain depth do not
/// steer it.
fn depth_weight(p: &Vector3<f64>) -> f64 {
    1.0 / (p[2] * p[2]).max(1e-6)
}

/// Reprojection residual (mm in corrected photo-coordinates, the larger of left and
/// right) of `p` moved by `m`; `obs` holds corrected coordinates. Working in corrected
/// coordinates avoids the iterative inverse distortion in the RANSAC loop.
fn residual(
    rig: &Rig,
    mrel: &Matrix3<f64>,
    m: &RigidMotion,
    p: &Vector3<f64>,
    obs: &QuadObs,
) -> f64 {
    let q = m.r * p + m.t;
    let proj = |f: f64, x: Vector3<f64>| -> Option<[f64; 2]> {
        if x[2].is_nan() || x[2] >= -1e-9 {
            return None;
        }
        Some([-f * x[0] / x[2], -f * x[1] / x[2]])
    };
    let right = mrel * (q - Vector3::from(rig.base_m));
    let (Some(l), Some(r)) = (proj(rig.left.focal_mm, q), proj(rig.right.focal_mm, right)) else {
        return f64::INFINITY;
    };
    let el = libm::hypot(l[0] - obs[2][0] as f64, l[1] - obs[2][1] as f64);
    let er = libm::hypot(r[0] - obs[3][0] as f64, r[1] - obs[3][1] as f64);
    el.max(er)
}

/// Midpoint triangulation from corrected coordinates (left camera frame).
fn triangulate_corrected(
    rig: &Rig,
    mrel: &Matrix3<f64>,
    l: [f32; 2],
    r: [f32; 2],
) -> Option<Vector3<f64>> {
    let f64s = |p: [f32; 2]| [p[0] as f64, p[1] as f64];
    super::predict::triangulate_corrected(rig, mrel, f64s(l), f64s(r))
}

/// Converts pixel observations to corrected photo-coordinates (mm), in place.
pub fn to_corrected(rig: &Rig, obs: &mut [QuadObs]) {
    for o in obs.iter_mut() {
        for (k, p) in o.iter_mut().enumerate() {
            let cam = if k % 2 == 0 { &rig.left } else { &rig.right };
            let [x, y] = cam.pixel_to_corrected(p[0] as f64, p[1] as f64);
            *p = [x as f32, y as f32];
        }
    }
}

/// Marks the quads consistent with one rigid motion. `obs[i]` are quad `i`'s four
/// observations in corrected photo-coordinates (see [`to_corrected`]); `pts` is scratch for the triangulations (at least `2 * obs.len()`);
/// `inlier[i]` receives the verdict. Returns the motion, or `None` when the check could
/// not run (too few usable quads): then every quad is kept.
pub fn check_motion(
    rig: &Rig,
    cfg: &MotionCheckConfig,
    obs: &[QuadObs],
    pts: &mut [[f64; 3]],
    inlier: &mut [u8],
    seed: u32,
) -> Option<RigidMotion> {
    let n = obs.len().min(pts.len() / 2).min(inlier.len());
    inlier[..n].fill(1);
    let mrel = rig.relative_rotation();
    // Triangulate; a quad that does not triangulate in both epochs is an outlier.
    let mut usable = 0;
    for i in 0..n {
        let o = &obs[i];
        let tri = |l: [f32; 2], r: [f32; 2]| triangulate_corrected(rig, &mrel, l, r);
        match (tri(o[0], o[1]), tri(o[2], o[3])) {
            (Some(p), Some(q)) => {
                pts[2 * i] = [p[0], p[1], p[2]];
                pts[2 * i + 1] = [q[0], q[1], q[2]];
                usable += 1;
            }
            _ => {
                pts[2 * i] = [f64::NAN; 3];
                inlier[i] = 0;
            }
        }
    }
    if usable < cfg.min_quads {
        inlier[..n].fill(1);
        return None;
    }
    let v = |i: usize, k: usize| Vector3::from(pts[2 * i + k]);
    // The threshold in mm on the image plane.
    let px = 0.5 * (rig.left.pixel_size_mm[0] + rig.left.pixel_size_mm[1]);
    let thr = cfg.threshold_px as f64 * px;
    let count = |m: &RigidMotion| {
        (0..n)
            .filter(|&i| {
                pts[2 * i][0].is_finite() && residual(rig, &mrel, m, &v(i, 0), &obs[i]) <= thr
            })
            .count()
    };
    let mut rng = seed as u64 ^ 0x9E37_79B9_7F4A_7C15;
    let mut next = || {
        rng = rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (rng >> 33) as usize % n
    };
    let mut best: Option<(usize, RigidMotion)> = None;
    // Adaptive RANSAC: stop once a sample of three inliers has been drawn with 99.9 %
    // probability given the best inlier share so far (at most `iterations` samples).
    let mut needed = cfg.iterations as f64;
    let mut it = 0u32;
    while (it as f64) < needed.min(cfg.iterations as f64) {
        it += 1;
        let (a, b, c) = (next(), next(), next());
        if a == b || b == c || a == c || [a, b, c].iter().any(|&i| !pts[2 * i][0].is_finite()) {
            continue;
        }
        let sample = [a, b, c].map(|i| (v(i, 0), v(i, 1), depth_weight(&v(i, 0))));
        let Some(m) = rigid_fit(sample.into_iter()) else {
            continue;
        };
        let k = count(&m);
        let better = match &best {
            None => true,
            Some((bk, _)) => k > *bk,
        };
        if better {
            best = Some((k, m));
            let w = k as f64 / usable as f64;
            let miss = 1.0 - w * w * w;
            needed = if miss <= 1e-9 {
                0.0
            } else {
                libm::log(1e-3) / libm::log(miss)
            };
        }
    }
    let (mut best_k, mut m) = best?;
    // Refit on the inliers (twice: the inlier set settles), accumulating the weighted
    // sums directly so no buffer is needed.
    // A refit is kept only when it explains at least as many quads.
    for _ in 0..2 {
        if let Some(refit) = refit_inliers(rig, &mrel, &m, obs, pts, n, thr) {
            let k = count(&refit);
            if k >= best_k {
                (best_k, m) = (k, refit);
            }
        }
    }
    if best_k < cfg.min_quads {
        // No motion explains enough quads: no verdict rather than rejecting them all.
        inlier[..n].fill(1);
        return None;
    }
    for i in 0..n {
        inlier[i] =
            (pts[2 * i][0].is_finite() && residual(rig, &mrel, &m, &v(i, 0), &obs[i]) <= thr) as u8;
    }
    Some(m)
}

/// Weighted Kabsch over every inlier of `m`.
fn refit_inliers(
    rig: &Rig,
    mrel: &Matrix3<f64>,
    m: &RigidMotion,
    obs: &[QuadObs],
    pts: &[[f64; 3]],
    n: usize,
    thr: f64,
) -> Option<RigidMotion> {
    let inliers = (0..n).filter_map(move |i| {
        let (p, q) = (Vector3::from(pts[2 * i]), Vector3::from(pts[2 * i + 1]));
        (p[0].is_finite() && residual(rig, mrel, m, &p, &obs[i]) <= thr)
            .then(|| (p, q, depth_weight(&p)))
    });
    rigid_fit(inliers)
}
