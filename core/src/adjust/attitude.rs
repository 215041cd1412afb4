//! The attitude unknowns of an adjustment: a small turn of the camera in the object
//! frame, not corrections of the angles.
//!
//! Poses are stored and reported as `(omega, phi, kappa)`, `M = R_kappa R_phi R_omega`.
//! Corrections of these angles are singular at `phi = +-90 deg`, where omega and kappa
//! turn about one axis. With the datum's omega of 90 deg (the camera level, looking
//! along Y), phi is the heading: a vehicle that turns a quarter from its start drives
//! along that line. On the rendered 1.2 km drive a quarter of the epochs lie within
//! 8 deg of it; there the window needed a third more iterations and once stopped at
//! its limit (a step 1.16 m and 2.6 deg off, at the onset of a turn).
//!
//! So the unknowns are `d`, a rotation vector in the object frame (`d = E da`, the
//! [`angle_rates`] of the angles): `M(d) = M exp(-[d]x)`, whose Jacobian
//! `dM/dd_i = -M [e_i]x` is regular at every attitude. A solution's step turns the
//! stored angles ([`turn`]); a prior's residual is the turn between the prior and the
//! pose ([`residual`]); covariances in these coordinates become covariances of the
//! angles only where they are reported ([`to_angles`]).
use super::propagation::{angle_rates, propagate};
use crate::camera::{angles_from_rotation, rotation};
use nalgebra::{Matrix3, Rotation3, Vector3};

/// `M` of the angles and its derivatives by the object-frame turn `d`:
/// `dM/dd_i = -M [e_i]x`.
pub fn with_turn_derivatives(
    omega: f64,
    phi: f64,
    kappa: f64,
) -> (Matrix3<f64>, [Matrix3<f64>; 3]) {
    let m = rotation(omega, phi, kappa);
    let d = core::array::from_fn(|i| -m * Vector3::ith(i, 1.0).cross_matrix());
    (m, d)
}

/// Turns the attitude of `params` (`[omega, phi, kappa, ...]`) by the object-frame
/// rotation vector `d`: `M <- M exp(-[d]x)`.
pub fn turn(params: &mut [f64; 6], d: [f64; 3]) {
    let m = rotation(params[0], params[1], params[2]);
    let step = Rotation3::new(Vector3::from(d)).into_inner();
    let [omega, phi, kappa] = angles_from_rotation(&(m * step.transpose()));
    params[..3].copy_from_slice(&[omega, phi, kappa]);
}

/// The object-frame turn from the attitude of `prior` to that of `params`: `r` with
/// `M = M_prior exp(-[r]x)`, so that [`turn`]ing `prior` by `r` gives `params`. Its
/// derivative by a turn of `params` is the identity to first order in `r`.
pub fn residual(params: &[f64; 6], prior: &[f64; 6]) -> [f64; 3] {
    let m = rotation(params[0], params[1], params[2]);
    let m0 = rotation(prior[0], prior[1], prior[2]);
    let r = Rotation3::from_matrix_unchecked(m.transpose() * m0).scaled_axis();
    [r[0], r[1], r[2]]
}

/// A pose covariance in the turn's coordinates (`[d, X, Y, Z]`, 6x6 row-major) as one
/// of the angles of `params`: `da = E^-1 d`. At phi = +-90 deg `E` is singular and
/// omega and kappa have no standard deviation of their own; there the turn's is given.
pub fn to_angles(params: &[f64; 6], cov: &[f64; 36]) -> [f64; 36] {
    let e_inv = angle_rates(params)
        .try_inverse()
        .unwrap_or_else(Matrix3::identity);
    let mut j = [0.0; 36];
    for r in 0..3 {
        for c in 0..3 {
            j[r * 6 + c] = e_inv[(r, c)];
        }
        j[(r + 3) * 6 + r + 3] = 1.0;
    }
    propagate(&j, cov)
}

#[cfg(test)]
mod tests {
    use super::*;

    const POSES: [[f64; 6]; 4] = [
        [1.6, 0.0, 0.0, 0.0, 0.0, 0.0],
        [0.3, -0.4, 1.2, 1.0, 2.0, 3.0],
        // Within a hundredth of a degree of the angles' singularity.
        [-1.9, 1.57063, 2.4, 0.0, 0.0, 0.0],
        [0.7, -1.5706, -0.5, 0.0, 0.0, 0.0],
    ];

    #[test]
    fn the_turn_derivatives_match_a_numeric_turn_at_every_attitude() {
        // Central differences through the stored angles: near the singularity a turn
        // moves omega and kappa by 1/cos(phi) times as much, and their rounding with it.
        let h = 1e-5;
        let turned = |p: [f64; 6], i: usize, s: f64| {
            let (mut q, mut step) = (p, [0.0; 3]);
            step[i] = s;
            turn(&mut q, step);
            rotation(q[0], q[1], q[2])
        };
        for p in POSES {
            let (_, d) = with_turn_derivatives(p[0], p[1], p[2]);
            for i in 0..3 {
                let numeric = (turned(p, i, h) - turned(p, i, -h)) / (2.0 * h);
                let err = (numeric - d[i]).norm();
                assert!(err < 1e-6, "pose {p:?} axis {i}: off by {err}");
            }
        }
    }

    #[test]
    fn the_residual_is_the_turn_that_leads_from_the_prior_to_the_pose() {
        for p in POSES {
            let d = [0.02, -0.01, 0.03];
            let mut turned = p;
            turn(&mut turned, d);
            let r = residual(&turned, &p);
            for a in 0..3 {
                assert!(
                    (r[a] - d[a]).abs() < 1e-12,
                    "pose {p:?}: {r:?} against {d:?}"
                );
            }
            assert!(residual(&p, &p).iter().all(|v| v.abs() < 1e-12));
        }
    }

    #[test]
    fn a_turn_covariance_becomes_that_of_the_angles() {
        // Away from the singularity, a small turn of known spread moves the angles by
        // E^-1 d: compare with the angles' differences of turned poses.
        let p = POSES[1];
        let sd = [1e-3, 2e-3, 3e-3];
        let mut cov = [0.0; 36];
        for a in 0..3 {
            cov[a * 6 + a] = sd[a] * sd[a];
            cov[(a + 3) * 6 + a + 3] = 0.01;
        }
        let angles = to_angles(&p, &cov);
        let e_inv = angle_rates(&p).try_inverse().unwrap();
        for r in 0..3 {
            let expected: f64 = (0..3).map(|k| e_inv[(r, k)].powi(2) * sd[k] * sd[k]).sum();
            assert!((angles[r * 6 + r] - expected).abs() < 1e-12 * expected.max(1e-12));
            let mut turned = p;
            let mut d = [0.0; 3];
            d[0] = 1e-6;
            turn(&mut turned, d);
            assert!(((turned[r] - p[r]) / 1e-6 - e_inv[(r, 0)]).abs() < 1e-4);
        }
        assert_eq!(angles[3 * 6 + 3], 0.01);
    }
}
