//! The rotation of the current left camera from its temporal matches alone, for the
//! epochs that neither resection poses: at the exit of a tight turn on a sparse image,
//! the constant-velocity prediction keeps turning (4 to 6 degrees off after one step
//! of a 20 m turn at 2 m per epoch), too few quads close and too few of the previous
//! stereo points are found again for a resection, yet many previous keypoints are.
//! Points far against the step move on the image by the rotation alone, so the
//! rotation that carries the previous rays onto the current ones, found robustly, is a
//! far better guess than the prediction's; the position stays the prediction's.

use nalgebra::{Matrix3, Vector3};

use crate::adjust::Correspondence;
use crate::camera::proper_rotation;

/// Settings of the rotation search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TurnConfig {
    /// Largest angle between a moved previous ray and its current ray, radians.
    pub threshold_rad: f64,
    /// Fewest inliers of an accepted rotation.
    pub min_inliers: usize,
    /// RANSAC samples (pairs of matches) at most.
    pub samples: u32,
}

/// Wahba's problem: the rotation `R` that best carries each `a_i` onto `b_i` (unit
/// rays, least squares), by the SVD of `sum b_i a_i^T`.
pub fn fit_rotation(
    pairs: impl Iterator<Item = (Vector3<f64>, Vector3<f64>)>,
) -> Option<Matrix3<f64>> {
    let mut h = Matrix3::zeros();
    for (a, b) in pairs {
        h += b * a.transpose();
    }
    let svd = h.svd(true, true);
    proper_rotation(&svd.u?, &svd.v_t?)
}

/// How many of the matches `r` (object frame to the current camera) explains within
/// the threshold (see [`robust_rotation`] for `corr`).
pub fn inliers(
    corr: &[Correspondence],
    focal_mm: f64,
    threshold_rad: f64,
    r: &Matrix3<f64>,
) -> usize {
    (0..corr.len())
        .filter(|&i| fits(corr, focal_mm, threshold_rad, r, i))
        .count()
}

/// Whether `r` carries match `i`'s previous ray onto its current ray within `threshold_rad`
/// (the chord between two unit rays: the angle, for small angles).
fn fits(
    corr: &[Correspondence],
    focal_mm: f64,
    threshold_rad: f64,
    r: &Matrix3<f64>,
    i: usize,
) -> bool {
    let c = &corr[i];
    let cur = Vector3::new(c.xy[0], c.xy[1], -focal_mm).normalize();
    (r * Vector3::from(c.point) - cur).norm() <= threshold_rad
}

/// The rotation (object frame to the current camera) that carries the previous rays
/// onto the current ones, and its inliers: `corr[i].point` is the previous ray in the
/// object frame (unit), `corr[i].xy` the current corrected photo-coordinates (mm) of
/// the same keypoint; `focal_mm` the current camera's focal length. A deterministic
/// RANSAC over pairs, refitted on the inliers.
pub fn robust_rotation(
    corr: &[Correspondence],
    focal_mm: f64,
    cfg: &TurnConfig,
) -> Option<(Matrix3<f64>, usize)> {
    let n = corr.len();
    if n < cfg.min_inliers.max(2) {
        return None;
    }
    let prev = |i: usize| Vector3::from(corr[i].point);
    let cur = |i: usize| Vector3::new(corr[i].xy[0], corr[i].xy[1], -focal_mm).normalize();
    let fits = |r: &Matrix3<f64>, i: usize| fits(corr, focal_mm, cfg.threshold_rad, r, i);
    let count = |r: &Matrix3<f64>| inliers(corr, focal_mm, cfg.threshold_rad, r);
    let mut rng = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = || {
        rng = rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (rng >> 33) as usize % n
    };
    let mut best: Option<(usize, Matrix3<f64>)> = None;
    for _ in 0..cfg.samples {
        let (a, b) = (next(), next());
        if a == b {
            continue;
        }
        let Some(r) = fit_rotation([a, b].into_iter().map(|i| (prev(i), cur(i)))) else {
            continue;
        };
        let k = count(&r);
        if best.as_ref().is_none_or(|(bk, _)| k > *bk) {
            best = Some((k, r));
        }
    }
    let (_, r) = best?;
    let r = fit_rotation((0..n).filter(|&i| fits(&r, i)).map(|i| (prev(i), cur(i))))?;
    let k = count(&r);
    (k >= cfg.min_inliers).then_some((r, k))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::rotation;

    /// Far points seen before and after a 2 m step that turned the camera by 4 degrees,
    /// with a third of the matches wrong and some points near enough for parallax: the
    /// rotation comes back to a few hundredths of a degree, and only the far, right
    /// matches are inliers.
    #[test]
    fn finds_the_rotation_of_a_turn_among_wrong_and_near_matches() {
        let f = 4.0;
        let m_prev = rotation(1.57, 0.2, 0.01);
        let m_cur = rotation(1.57, 0.2 + 4f64.to_radians(), 0.01);
        let c_prev = Vector3::new(0.0, 0.0, 1.5);
        let c_cur = c_prev + m_prev.transpose() * Vector3::new(0.0, 0.0, -2.0);
        let mut corr = [Correspondence {
            point: [0.0; 3],
            xy: [0.0; 2],
        }; 60];
        let mut rng = 7u64;
        let mut uniform = |a: f64, b: f64| {
            rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            a + (b - a) * ((rng >> 11) as f64 / (1u64 << 53) as f64)
        };
        let mut far = 0;
        for (i, c) in corr.iter_mut().enumerate() {
            // Ahead of the previous camera: 8 m (near) or 200..400 m (far).
            let depth = if i % 6 == 5 {
                8.0
            } else {
                uniform(200.0, 400.0)
            };
            let cam = Vector3::new(
                uniform(-0.5, 0.5) * depth,
                uniform(-0.4, 0.4) * depth,
                -depth,
            );
            let x = c_prev + m_prev.transpose() * cam;
            let ray_prev = m_prev.transpose() * cam.normalize();
            let mut seen = m_cur * (x - c_cur);
            if i % 3 == 2 {
                // A wrong match: a keypoint elsewhere in the image.
                seen = Vector3::new(uniform(-0.5, 0.5), uniform(-0.4, 0.4), -1.0);
            } else if depth > 100.0 {
                far += 1;
            }
            c.point = [ray_prev[0], ray_prev[1], ray_prev[2]];
            c.xy = [-f * seen[0] / seen[2], -f * seen[1] / seen[2]];
        }
        let cfg = TurnConfig {
            threshold_rad: 3.0 * 0.01 / f,
            min_inliers: 8,
            samples: 64,
        };
        let (r, inliers) = robust_rotation(&corr, f, &cfg).unwrap();
        let err = (r * m_cur.transpose()).trace();
        let angle = libm::acos(((err - 1.0) / 2.0).clamp(-1.0, 1.0)).to_degrees();
        assert!(angle < 0.03, "rotation off by {angle} deg");
        assert_eq!(inliers, far, "inliers {inliers}, far right matches {far}");
        // The prediction's test: the true rotation explains the same matches, the
        // rotation before the turn (4 degrees off) none of them.
        let count = |r: &Matrix3<f64>| super::inliers(&corr, f, cfg.threshold_rad, r);
        assert_eq!(count(&m_cur), far);
        assert_eq!(count(&m_prev), 0);
        // Too few matches: no rotation.
        assert!(robust_rotation(&corr[..7], f, &cfg).is_none());
    }
}
