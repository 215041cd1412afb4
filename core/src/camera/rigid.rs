//! The least-squares rigid motion between two weighted sets of points (Kabsch): the one
//! fit of the matcher's motion check (its 3-D to 3-D quads: a RANSAC sample and the
//! refit on the inliers) and of the resection's absolute orientation (P3P's camera-frame
//! points onto the object points).
use super::proper_rotation;
use nalgebra::{Matrix3, Vector3};

/// A rigid motion `q = r p + t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidMotion {
    pub r: Matrix3<f64>,
    pub t: Vector3<f64>,
}

/// The rotation and translation minimising `sum w |r p + t - q|^2` over the `(p, q, w)`
/// of `pairs` (walked twice: the weighted centroids, then the cross-covariance). `None`
/// with fewer than three pairs, weights that do not sum to a positive number, or a fit
/// that is not finite.
pub fn rigid_fit<I>(pairs: I) -> Option<RigidMotion>
where
    I: Iterator<Item = (Vector3<f64>, Vector3<f64>, f64)> + Clone,
{
    let (mut sw, mut cp, mut cq, mut k) = (0.0, Vector3::zeros(), Vector3::zeros(), 0);
    for (p, q, w) in pairs.clone() {
        sw += w;
        cp += p * w;
        cq += q * w;
        k += 1;
    }
    if k < 3 || sw.is_nan() || sw <= 0.0 {
        return None;
    }
    cp /= sw;
    cq /= sw;
    let mut h = Matrix3::zeros();
    for (p, q, w) in pairs {
        h += (p - cp) * (q - cq).transpose() * w;
    }
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let r = proper_rotation(&vt.transpose(), &u.transpose())?;
    let t = cq - r * cp;
    (r.iter().chain(t.iter()).all(|x| x.is_finite())).then_some(RigidMotion { r, t })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::rotation;

    /// A known motion is recovered from noise-free points, whatever their weights; a
    /// reflection is never returned; degenerate input is refused.
    #[test]
    fn recovers_a_rigid_motion_and_refuses_degenerate_sets() {
        let r = rotation(0.3, -0.2, 1.1);
        let t = Vector3::new(0.5, -2.0, 7.0);
        let p = [
            Vector3::new(1.0, 0.0, -5.0),
            Vector3::new(-2.0, 1.0, -9.0),
            Vector3::new(0.5, 3.0, -4.0),
            Vector3::new(2.0, -1.0, -12.0),
        ];
        let pairs = p
            .iter()
            .enumerate()
            .map(|(i, p)| (*p, r * p + t, 1.0 + i as f64));
        let m = rigid_fit(pairs).unwrap();
        assert!(
            (m.r - r).norm() < 1e-12 && (m.t - t).norm() < 1e-12,
            "{m:?}"
        );
        assert!((m.r.determinant() - 1.0).abs() < 1e-12);
        // A mirrored set is fitted by a rotation, not the mirror.
        let mirror = p.iter().map(|p| (*p, Vector3::new(-p[0], p[1], p[2]), 1.0));
        assert!((rigid_fit(mirror).unwrap().r.determinant() - 1.0).abs() < 1e-12);
        let two = p[..2].iter().map(|p| (*p, *p, 1.0));
        assert_eq!(rigid_fit(two), None);
        let weightless = p.iter().map(|p| (*p, *p, 0.0));
        assert_eq!(rigid_fit(weightless), None);
    }
}
