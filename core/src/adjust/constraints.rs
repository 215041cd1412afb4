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
//!   window): `x_e - x_prior`, identity Jacobian, full 6x6 information.
//! - Relative orientation prior (rig estimated): `rig - rig_prior`.
//! - Base length (seed 000 eq. 44): `|C_R - C_L| - B`. With the right camera
//!   following the rig, `C_R - C_L = M_L^T b` and the rotation keeps lengths, so
//!   it is `|b| - B` with gradient `b/|b|`; it matters when the rig is estimated.
//! - Motion smoothness (seed 002's velocity constraint, as constant velocity):
//!   `(C_{k+1} - C_k)/dt_1 - (C_k - C_{k-1})/dt_0 = 0` per axis, sigma in m/s.
//! - Odometer distance: `|C_k - C_{k-1}| - d`.
//! - GNSS position of the left perspective centre: `C_k - G`.

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

/// Smoothness residual (change of velocity, m/s) for centres `c0, c1, c2` at
/// intervals `dt0 = t1 - t0`, `dt1 = t2 - t1`, with the scalar coefficients of
/// `c0, c1, c2` (the Jacobian of each axis is the coefficient times identity).
pub fn smoothness(c: [&[f64; 3]; 3], dt0: f64, dt1: f64) -> ([f64; 3], [f64; 3]) {
    let k = [1.0 / dt0, -(1.0 / dt0 + 1.0 / dt1), 1.0 / dt1];
    let mut r = [0.0; 3];
    for (a, ra) in r.iter_mut().enumerate() {
        *ra = k[0] * c[0][a] + k[1] * c[1][a] + k[2] * c[2][a];
    }
    (r, k)
}
