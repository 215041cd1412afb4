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
use super::propagation::{angle_rates, propagate, transport};
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
    propagate(&transport(e_inv, Matrix3::zeros()), cov)
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
        // Away from the singularity: the angles' Jacobian by the turn, from the stored
        // angles of turned poses, carries a correlated turn covariance as `to_angles`
        // does; the centre's block passes as it is.
        let p = POSES[1];
        let h = 1e-6;
        let jac: [[f64; 3]; 3] = core::array::from_fn(|r| {
            core::array::from_fn(|k| {
                let (mut plus, mut minus, mut d) = (p, p, [0.0; 3]);
                d[k] = h;
                turn(&mut plus, d);
                d[k] = -h;
                turn(&mut minus, d);
                (plus[r] - minus[r]) / (2.0 * h)
            })
        });
        let mut cov = [0.0; 36];
        let turn_cov = [
            [4e-6, 1e-6, -2e-6],
            [1e-6, 9e-6, 3e-6],
            [-2e-6, 3e-6, 1.6e-5],
        ];
        for r in 0..3 {
            for c in 0..3 {
                cov[r * 6 + c] = turn_cov[r][c];
            }
            cov[(r + 3) * 6 + r + 3] = 0.01;
            cov[(r + 3) * 6 + r] = 1e-5;
            cov[r * 6 + r + 3] = 1e-5;
        }
        let angles = to_angles(&p, &cov);
        for r in 0..3 {
            for c in 0..3 {
                let numeric: f64 = (0..3)
                    .flat_map(|a| (0..3).map(move |b| (a, b)))
                    .map(|(a, b)| jac[r][a] * turn_cov[a][b] * jac[c][b])
                    .sum();
                let got = angles[r * 6 + c];
                assert!(
                    (got - numeric).abs() < 1e-6 * numeric.abs().max(1e-6),
                    "{r} {c}: {got} against {numeric}"
                );
            }
            assert_eq!(angles[(r + 3) * 6 + r + 3], 0.01);
        }
    }
}
