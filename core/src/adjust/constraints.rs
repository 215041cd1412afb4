//! Weighted constraints on the camera parameters (seed 000 eqs. 44-49, seed 002).
//!
//! Every constraint is a pseudo-observation `g(x) = g_obs` with a standard
//! deviation: its residual `g(x) - g_obs` enters the normal equations through
//! its Jacobian and weight `1/sigma^2`, and its `v^T P v` enters sigma0 and the
//! chi-square test (seed 000 eq. 46: `vTPv + vxTPxvx` over `n + n_x - u`).
//! Constraints only involve epoch poses and the rig, never tie points, so they
//! are added straight to the reduced camera system.
//!
//! - Pose prior (datum of the first epoch, or the prior carried by the sliding
//!   window): the turn from the prior's attitude to the epoch's
//!   ([`super::attitude::residual`]) and `C_e - C_prior`, identity Jacobian in the
//!   window's unknowns, full 6x6 information.
//! - Relative orientation prior (rig estimated): `rig - rig_prior`.
//! - Base length (seed 000 eq. 44): `|C_R - C_L| - B`. With the right camera
//!   following the rig, `C_R - C_L = M_L^T b` and the rotation keeps lengths, so
//!   it is `|b| - B` with gradient `b/|b|`; it matters when the rig is estimated.
//! - Motion smoothness (seed 002's velocity constraint, as constant velocity in the
//!   camera's own frame): `M_k (C_{k+1} - C_k)/dt_1 - M_{k-1} (C_k - C_{k-1})/dt_0 = 0`
//!   per camera axis, sigma in m/s. A vehicle keeps its velocity as it sees it: in a
//!   turn of constant rate the chord of each step turns with the camera, and tying
//!   velocities in the object frame instead would pull every turn straight and carry
//!   a turn's sideways velocity out of it.
//! - Odometer distance: `|C_k - C_{k-1}| - d`.
//! - GNSS position of the left perspective centre: `C_k - G`.

use nalgebra::Vector3;

use super::attitude::{self, with_turn_derivatives};

/// Wraps an angle difference into `(-pi, pi]`.
pub fn wrap_angle(a: f64) -> f64 {
    let two_pi = 2.0 * core::f64::consts::PI;
    let mut r = libm::fmod(a, two_pi);
    if r > core::f64::consts::PI {
        r -= two_pi;
    } else if r <= -core::f64::consts::PI {
        r += two_pi;
    }
    r
}

/// Residual of a pose or rig prior: parameter differences, angles wrapped.
pub fn prior_residual(params: &[f64; 6], prior: &[f64; 6]) -> [f64; 6] {
    let mut r = [0.0; 6];
    for i in 0..6 {
        r[i] = params[i] - prior[i];
        if i < 3 {
            r[i] = wrap_angle(r[i]);
        }
    }
    r
}

/// Residual of an epoch's pose prior in the window's unknowns: the object-frame turn
/// from the prior's attitude to the pose's, then the centre's difference.
pub fn pose_prior_residual(params: &[f64; 6], prior: &[f64; 6]) -> [f64; 6] {
    let [a, b, c] = attitude::residual(params, prior);
    [
        a,
        b,
        c,
        params[3] - prior[3],
        params[4] - prior[4],
        params[5] - prior[5],
    ]
}

/// Base length residual `|b| - length` and its gradient with respect to `b`.
pub fn base_length(b: &[f64; 3], length: f64) -> (f64, [f64; 3]) {
    let n = libm::sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
    if !(n > 0.0) {
        return (-length, [0.0; 3]);
    }
    (n - length, [b[0] / n, b[1] / n, b[2] / n])
}

/// Distance residual `|c1 - c0| - d` and its gradient with respect to `c1`
/// (the gradient with respect to `c0` is its negative).
pub fn distance(c0: &[f64; 3], c1: &[f64; 3], d: f64) -> (f64, [f64; 3]) {
    let diff = [c1[0] - c0[0], c1[1] - c0[1], c1[2] - c0[2]];
    base_length(&diff, d)
}

/// Smoothness residual (change of velocity in the camera frame, m/s) of three
/// epochs' parameters `[omega, phi, kappa, X0, Y0, Z0]` at intervals
/// `dt0 = t1 - t0`, `dt1 = t2 - t1`, with its Jacobian: one row per camera axis, over
/// the three epochs' unknowns (turn and centre, as the window solves for them; the last
/// epoch's attitude does not enter).
pub fn smoothness(p: [&[f64; 6]; 3], dt0: f64, dt1: f64) -> ([f64; 3], [[f64; 18]; 3]) {
    let (m0, dm0) = with_turn_derivatives(p[0][0], p[0][1], p[0][2]);
    let (m1, dm1) = with_turn_derivatives(p[1][0], p[1][1], p[1][2]);
    let centre = |e: usize| Vector3::new(p[e][3], p[e][4], p[e][5]);
    // Velocities over the two intervals, in the object frame.
    let v0 = (centre(1) - centre(0)) / dt0;
    let v1 = (centre(2) - centre(1)) / dt1;
    let r = m1 * v1 - m0 * v0;
    let mut jac = [[0.0; 18]; 3];
    for (a, row) in jac.iter_mut().enumerate() {
        for q in 0..3 {
            row[q] = -(dm0[q] * v0)[a];
            row[6 + q] = (dm1[q] * v1)[a];
            row[3 + q] = m0[(a, q)] / dt0;
            row[9 + q] = -m1[(a, q)] / dt1 - m0[(a, q)] / dt0;
            row[15 + q] = m1[(a, q)] / dt1;
        }
    }
    ([r[0], r[1], r[2]], jac)
}
