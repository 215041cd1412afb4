//! Propagation of a pose covariance through a rigid connection: an epoch's precision
//! carried from the newest fixed epoch of the window, the right camera's from the left.
//!
//! Both are the same law: two poses that move as one rigid body, the Jacobian of one
//! with respect to the other ([`rigid_transport`]), and `J C J^T`.
use crate::camera::{Pose, RelativeOrientation};
use nalgebra::{Matrix3, Vector3};

/// Jacobian (6x6, row-major) of the pose `to` with respect to the pose `from` when both
/// move as one rigid body with `from`: a small rotation `d` (object frame) of `from`
/// turns `to` by the same `d` and moves its centre by `d x (C_to - C_from)`. In the
/// parameters (omega, phi, kappa, X, Y, Z): angles `E_to^-1 E_from`, centre
/// `-[C_to - C_from]x E_from` and the identity, with `E` the angles' rotation vector.
pub fn rigid_transport(from: &[f64; 6], to: &[f64; 6]) -> [f64; 36] {
    let e_from = angle_rates(from);
    let e_to_inv = angle_rates(to)
        .try_inverse()
        .unwrap_or_else(Matrix3::identity);
    transport(e_to_inv * e_from, -lever(from, to) * e_from)
}

/// [`rigid_transport`] in the window's unknowns ([`super::attitude`]: the object-frame
/// turn, then the centre): the turn carries over as it is, and moves the centre by
/// `-[C_to - C_from]x`.
pub fn rigid_transport_turn(from: &[f64; 6], to: &[f64; 6]) -> [f64; 36] {
    transport(Matrix3::identity(), -lever(from, to))
}

/// `[C_to - C_from]x`.
fn lever(from: &[f64; 6], to: &[f64; 6]) -> Matrix3<f64> {
    Vector3::new(to[3] - from[3], to[4] - from[4], to[5] - from[5]).cross_matrix()
}

/// The 6x6 (row-major) with the attitude block `a`, the centre's block `c` under the
/// attitude and the identity for the centre: a pose Jacobian whose centre moves with
/// itself alone and with the attitude as `c` says.
pub(crate) fn transport(a: Matrix3<f64>, c: Matrix3<f64>) -> [f64; 36] {
    let mut j = [0.0; 36];
    for r in 0..3 {
        for k in 0..3 {
            j[r * 6 + k] = a[(r, k)];
            j[(r + 3) * 6 + k] = c[(r, k)];
        }
        j[(r + 3) * 6 + r + 3] = 1.0;
    }
    j
}

/// `E` of the angles in `p`: column `i` is the object-frame rotation vector of a unit
/// change of angle `i` (`dR R^T = [E da]x`, `R = M^T` camera to object).
pub(crate) fn angle_rates(p: &[f64; 6]) -> Matrix3<f64> {
    let (m, d) = crate::camera::rotation_with_derivatives(p[0], p[1], p[2]);
    let mut e = Matrix3::zeros();
    for (i, di) in d.iter().enumerate() {
        let s = di.transpose() * m;
        e[(0, i)] = s[(2, 1)];
        e[(1, i)] = s[(0, 2)];
        e[(2, i)] = s[(1, 0)];
    }
    e
}

/// `J C J^T` of 6x6 row-major matrices.
pub fn propagate(j: &[f64; 36], c: &[f64; 36]) -> [f64; 36] {
    let mut jc = [0.0; 36];
    for r in 0..6 {
        for k in 0..6 {
            jc[r * 6 + k] = (0..6).map(|m| j[r * 6 + m] * c[m * 6 + k]).sum();
        }
    }
    core::array::from_fn(|i| {
        let (r, c) = (i / 6, i % 6);
        (0..6).map(|k| jc[r * 6 + k] * j[c * 6 + k]).sum::<f64>()
    })
}

/// Covariance of the right camera's pose from the left camera's covariance `cov`
/// (omega, phi, kappa rad; X, Y, Z m; row-major), with the rig's relative orientation
/// held at `rig`: the two cameras are one rigid body.
pub fn right_camera_covariance(
    left: &Pose,
    rig: &RelativeOrientation,
    cov: &[f64; 36],
) -> [f64; 36] {
    let right = rig.right_pose(left);
    propagate(&rigid_transport(&left.to_params(), &right.to_params()), cov)
}

/// Standard deviations: the square roots of a 6x6 covariance's diagonal (a negative
/// rounding residue reads as zero).
pub fn standard_deviations(cov: &[f64; 36]) -> [f64; 6] {
    core::array::from_fn(|k| libm::sqrt(cov[k * 6 + k].max(0.0)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adjust::geometry::camera_pose;
    use crate::camera::Camera;

    /// The rigid transport against moving both poses numerically: a small rotation
    /// about the first pose's centre (object frame) and a shift.
    #[test]
    fn rigid_transport_matches_a_rigid_motion_of_both_poses() {
        use crate::camera::{angles_from_rotation, rotation};
        let from = [1.62, 0.05, -0.1, 1.0, 2.0, 3.0];
        let to = [1.5, -0.02, 0.3, 5.0, 20.0, 1.0];
        let j = rigid_transport(&from, &to);
        let e_from = angle_rates(&from);
        let h = 1e-6;
        for axis in 0..6 {
            // The motion: a rotation vector (object frame) or a shift, size h.
            let mut d = Vector3::zeros();
            let mut shift = Vector3::zeros();
            if axis < 3 {
                d[axis] = h;
            } else {
                shift[axis - 3] = h;
            }
            let turn = nalgebra::Rotation3::new(d).into_inner();
            let moved = |p: &[f64; 6]| {
                let r = rotation(p[0], p[1], p[2]).transpose();
                let c = Vector3::new(p[3], p[4], p[5]) - Vector3::new(from[3], from[4], from[5]);
                let m = (turn * r).transpose();
                let a = angles_from_rotation(&m);
                let c = turn * c + Vector3::new(from[3], from[4], from[5]) + shift;
                [a[0], a[1], a[2], c[0], c[1], c[2]]
            };
            let (f2, t2) = (moved(&from), moved(&to));
            let df: [f64; 6] = core::array::from_fn(|k| f2[k] - from[k]);
            let dt: [f64; 6] = core::array::from_fn(|k| t2[k] - to[k]);
            // The angles' change of `from` is the rotation vector through E.
            let da = e_from.try_inverse().unwrap() * d;
            for k in 0..3 {
                assert!((df[k] - da[k]).abs() < 1e-9, "axis {axis}: E");
            }
            for r in 0..6 {
                let predicted: f64 = (0..6).map(|k| j[r * 6 + k] * df[k]).sum();
                assert!(
                    (predicted - dt[r]).abs() < 1e-3 * h,
                    "axis {axis}, row {r}: {predicted} against {}",
                    dt[r]
                );
            }
        }
    }

    /// The analytic propagation against central differences of the right pose.
    #[test]
    fn right_camera_covariance_matches_numeric_differentiation() {
        let left = Pose::from_degrees(92.0, -4.0, 31.0, [12.0, -3.0, 1.5]);
        let rig = RelativeOrientation {
            angles: [0.004, -0.012, 0.002],
            base: [0.54, 0.01, -0.02],
        };
        // A covariance with correlations between attitude and position.
        let mut cov = [0.0; 36];
        for r in 0..6 {
            for c in 0..6 {
                let s = |k: usize| if k < 3 { 1e-3 } else { 0.05 };
                let rho = if r == c { 1.0 } else { 0.3 };
                cov[r * 6 + c] = rho * s(r) * s(c);
            }
        }
        let h = 1e-7;
        let mut j = [0.0; 36];
        for k in 0..6 {
            let (mut a, mut b) = (left.to_params(), left.to_params());
            a[k] += h;
            b[k] -= h;
            let pa = camera_pose(&Pose::from_params(&a), &rig, Camera::Right).to_params();
            let pb = camera_pose(&Pose::from_params(&b), &rig, Camera::Right).to_params();
            for i in 0..6 {
                j[i * 6 + k] = (pa[i] - pb[i]) / (2.0 * h);
            }
        }
        let numeric = propagate(&j, &cov);
        let analytic = right_camera_covariance(&left, &rig, &cov);
        for i in 0..36 {
            let scale = libm::sqrt(numeric[(i / 6) * 7] * numeric[(i % 6) * 7]);
            assert!(
                (analytic[i] - numeric[i]).abs() < 1e-6 * scale,
                "element {i}: {} against {}",
                analytic[i],
                numeric[i]
            );
        }
        // The right centre is the left one plus the turned base: the attitude's
        // uncertainty adds to its position's, the base's length times the angle.
        let (l, r) = (standard_deviations(&cov), standard_deviations(&analytic));
        assert!(r[3] > l[3] || r[4] > l[4] || r[5] > l[5]);
    }
}
