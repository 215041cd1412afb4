//! Intersection, resection and incremental bundle adjustment.
//!
//! Scalar type: `f64` throughout (see docs/adjustment.md): the normal
//! equations mix weights from 1e5 to 1e12, beyond the 7 digits of `f32`; the
//! cost is twice the memory and software doubles on an FPU without them.
//!
//! Coordinates inside a [`Window`] are relative to a local origin (the first
//! epoch's left centre when the window is created) so sums of squares never
//! mix kilometres with millimetres.
//!
//! - [`geometry`]: collinearity of the left and right cameras of the rig with
//!   analytic Jacobians (chain rule through the relative orientation).
//! - `intersection`: linear intersection of two or more rays (seed 000, §5.4).
//! - `resection`: P3P (Grunert) in a deterministic RANSAC, then least squares.
//! - `attitude`: the adjustment's attitude unknowns, a small turn in the object frame
//!   (regular where the angles' corrections are not, at phi = +-90 deg).
//! - `cholesky`: in-place Cholesky factorisation, solve and inverse.
//! - `constraints`: datum/prior, base length, relative orientation prior,
//!   motion smoothness, odometer distance, GNSS position.
//! - [`weighting`]: seed 000 weighting schemes and the robust re-weighting.
//! - `propagation`: a pose covariance carried through a rigid connection (the
//!   newest fixed epoch to the window's, the left camera to the right).
//! - [`quality`]: sigma0, chi-square quantiles and the global test.
//! - `window`: the sliding-window adjuster (storage from the arena, normal
//!   equations with the Schur complement, Levenberg-Marquardt).

// `!(x > 0.0)` is deliberate throughout: it is also true for NaN, so invalid
// input is refused instead of slipping through a `x <= 0.0` test. Index loops
// mirror the matrix formulas they implement.
#![allow(
    clippy::neg_cmp_op_on_partial_ord,
    clippy::nonminimal_bool,
    clippy::needless_range_loop,
    clippy::type_complexity
)]

pub(crate) mod attitude;
pub(crate) mod cholesky;
pub(crate) mod constraints;
pub mod geometry;
pub(crate) mod intersection;
pub(crate) mod propagation;
pub mod quality;
pub(crate) mod resection;
pub mod weighting;
pub(crate) mod window;

#[cfg(test)]
mod bias_tests;
#[cfg(test)]
mod tests;

pub use constraints::wrap_angle;
pub use geometry::InteriorCorrections;
pub use intersection::{intersect, IntersectError, Intersection, Ray};
pub use propagation::{right_camera_covariance, standard_deviations};
pub use resection::{resect, Correspondence, ResectionConfig, ResectionError, ResectionResult};
pub use window::{
    AdjustConfig, AdjustError, CalibrationTest, ConstraintSigmas, InteriorSigmas, Observation,
    Report, Robust, Window,
};
