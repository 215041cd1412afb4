//! The traverse's positions smoothed over all its GNSS fixes, after the run.
//!
//! On board, each epoch's position is estimated when it is the newest in the window:
//! a filter, which has seen the fixes up to that epoch only. Inside an outage it drifts
//! with the images from the last fix, and when the fixes return the epochs already
//! output keep their drift. Once the run is over every fix is known, and the classic
//! traverse between known stations applies: the misclosure where the fixes return is
//! spread over the stretch without them, and where fixes are dense each position
//! averages the neighbouring fixes through the images' steps.
//!
//! The model: the left perspective centres `C_k` are the unknowns. Each step
//! `C_k - C_{k-1}` is observed by the images (the firmware's `step_m`: both centres from
//! one window adjustment, so the fixes, which move the window as a whole, do not distort
//! it) with the white variance `q` per coordinate. Each fix observes its epoch's centre
//! (the antenna position less the lever arm turned by the epoch's attitude) with its
//! sigma. A step the firmware did not give (an epoch that was not adjusted, or after one)
//! is taken from the two output positions with [`FALLBACK_VARIANCE_FACTOR`] times `q`.
//!
//! Into an epoch without a fix, the step is also turned and scaled: `s + s x t_k + l_k s`,
//! with a small rotation `t` and a scale `l` of the images' steps as unknowns, which start
//! at each stretch without fixes with the priors [`TURN_SD_RAD`] and [`SCALE_SD`] and walk
//! by [`TURN_WALK_RAD`] and [`SCALE_WALK`] per step, and such a step's white variance is
//! at least [`OUTAGE_STEP_RELATIVE`] of its length squared (the images' own step error,
//! which the fixes no longer hold). Why: inside an outage the images' position error is
//! their attitude's and scale's error carried along the path, so where the fixes return
//! the misclosure is spread along the path's shape (a turn inside the outage included),
//! not coordinate by coordinate. On 63 outages of sixteen rendered drives it met both
//! bars of the outage on 54, against 49 for a chain per coordinate whose step variance
//! grew with the firmware's own variance of the centre; with the turn's walk at the
//! images' own rate and the steps' variance grown inside, the largest errors inside fall
//! by 5 % and at least 96 % of each outage's epochs are within 3 sd, against 91 %
//! (`bench/aiding/README.md`, 2026-12-07).
//!
//! Least squares over this chain is the fixed-interval Kalman (Rauch-Tung-Striebel)
//! smoother over the state `(C, t, l)`, O(n) with the smoothed variances, whose square
//! roots replace the firmware's standard deviations of the centres; the attitudes are not
//! changed. The right cameras follow through the rig, their standard deviations from the
//! left camera's. `q` is estimated from the data by variance component estimation
//! (Förstner's iteration `q <- q * sum(v^2 / q) / r`, `r` the redundancy numbers) on the
//! chain per coordinate of the steps between fixes, since the images' step precision
//! depends on the scene and the rig; the fixes' sigmas are taken as given.
use crate::dataset::aiding;
use crate::report::EpochRecord;
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use phototraverse_core::adjust::{right_camera_covariance, standard_deviations};
use phototraverse_core::camera::{Pose, RelativeOrientation};

/// How much less a step from two output positions weighs than one from a window
/// adjustment: the output positions each carry a fix's pull, the window's steps do not.
pub const FALLBACK_VARIANCE_FACTOR: f64 = 100.0;

/// Starting value of the step variance, m^2 (3 mm per step); the estimate replaces it.
const INITIAL_STEP_VARIANCE: f64 = 9e-6;

/// Iterations of the variance component estimation, at most; it stops when the factor
/// is within [`VCE_TOLERANCE`] of 1.
const VCE_ITERATIONS: usize = 30;
const VCE_TOLERANCE: f64 = 1e-3;

/// Bounds of the estimated step variance, m^2: 0.01 mm to 1 m per step, so that a
/// sequence with no redundancy left for the steps cannot drive it to 0 or infinity.
const STEP_VARIANCE_BOUNDS: (f64, f64) = (1e-10, 1.0);

/// Variance of a position no observation has reached yet (before the first fix), m^2.
const DIFFUSE_M2: f64 = 1e8;

/// Standard deviation of the rotation of the images' steps where a stretch without fixes
/// begins, rad: about the aided window's attitude error on entering an outage (0.8 to
/// 2.0 mrad RMS per axis on the rendered drives).
pub const TURN_SD_RAD: f64 = 1.5e-3;
/// Its random walk per step, rad: about twice the walk of the images' attitude in the
/// rendered drives' turns (0.14 mrad per root epoch in heading, 0.21 in pitch; on the
/// straights 0.075 and 0.094). With the steps' variance at `q`, a walk of 0.1 mrad left
/// a third of the rendered drives' outages under 90 % of their epochs within 3 sd; with
/// the steps' own variance inside (below), 0.2 mrad still left one at 86 %. A walk of
/// 2 mrad, which stood in for that variance, spread the misclosure worse
/// (`bench/aiding/README.md`).
pub const TURN_WALK_RAD: f64 = 4e-4;
/// The white error of a step into an epoch without a fix, per coordinate, relative to
/// the step's length, at the least. Between fixes the aided window's steps agree with
/// the fixes to `q` (3.7 to 5.3 mm per 2 m step on the rendered drives); without them a
/// step errs as the images' own do (0.3 to 0.5 % of the step per axis, images-only runs
/// of the same drives, `bench/traverse/steps.py`).
pub const OUTAGE_STEP_RELATIVE: f64 = 5e-3;
/// Standard deviation of the scale of the images' steps where a stretch without fixes
/// begins (0.1 %), and its random walk per step.
pub const SCALE_SD: f64 = 1e-3;
pub const SCALE_WALK: f64 = 1e-4;

/// What the smoothing did.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SmoothingSummary {
    /// Fixes the positions were smoothed over.
    pub fixes: usize,
    /// The images' step precision estimated from the data, m per step.
    pub step_sd_m: f64,
    /// Steps taken from output positions (no window step), at the fallback weight.
    pub fallback_steps: usize,
    /// How far the smoothing moved the positions: RMS and largest, m.
    pub rms_shift_m: f64,
    pub largest_shift_m: f64,
}

/// An observed step into an epoch: its value and its variance `q * factor + drift`.
#[derive(Clone, Copy)]
struct Step {
    value: f64,
    /// Of the images' white step variance `q` (1, or the fallback's factor).
    factor: f64,
    /// The firmware's variance growth into an epoch without a fix, m^2 (0 with one).
    drift: f64,
}

impl Step {
    fn variance(&self, q: f64) -> f64 {
        q * self.factor + self.drift
    }
}

/// One coordinate's chain: the steps into each epoch after the first, and the fixes
/// (value, variance) where there are. The step variance `q` is estimated on the three
/// chains, where the steps between fixes are what it is the variance of; inside a
/// stretch without fixes a step's variance grows by the firmware's (`drift`), and those
/// steps are left out of the estimate.
struct Chain {
    steps: Vec<Step>,
    fixes: Vec<Option<(f64, f64)>>,
}

/// The smoothed values and variances of a chain, with the quantities the variance
/// component estimation needs.
struct Smoothed {
    x: Vec<f64>,
    var: Vec<f64>,
    /// Smoothed covariance of epochs k-1 and k (index k; 0 unused).
    lag_cov: Vec<f64>,
}

/// Smooths the left centres of `epochs` over their GNSS fixes (`gnss` records), with
/// the fixes' antenna at `lever_arm_m`. Updates the centres, their standard deviations,
/// the right cameras through the rig's relative orientation `rig`, and the fixes'
/// residuals. `None` (and nothing changed) without fixes.
pub fn smooth_over_fixes(
    epochs: &mut [EpochRecord],
    lever_arm_m: [f64; 3],
    rig: &RelativeOrientation,
) -> Option<SmoothingSummary> {
    let fixes = epochs.iter().filter(|e| e.gnss.is_some()).count();
    if fixes == 0 || epochs.len() < 2 {
        return None;
    }
    let fixed = fixed_centres(epochs, lever_arm_m);
    let steps = steps(epochs);
    let chains: Vec<Chain> = (0..3).map(|c| chain(epochs, &steps, &fixed, c)).collect();
    let q = estimate_step_variance(&chains);
    let solved = smooth_turned(&steps, &fixed, q);
    let (rms_shift_m, largest_shift_m) = apply(epochs, &solved, lever_arm_m, rig);
    Some(SmoothingSummary {
        fixes,
        step_sd_m: q.sqrt(),
        fallback_steps: epochs[1..].iter().filter(|e| e.step_m.is_none()).count(),
        rms_shift_m,
        largest_shift_m,
    })
}

/// The step variance `q` by Förstner's iteration from [`INITIAL_STEP_VARIANCE`].
fn estimate_step_variance(chains: &[Chain]) -> f64 {
    let mut q = INITIAL_STEP_VARIANCE;
    for _ in 0..VCE_ITERATIONS {
        let solved: Vec<Smoothed> = chains.iter().map(|ch| smooth(ch, q)).collect();
        let factor = variance_factor(chains, &solved, q);
        let next = (q * factor).clamp(STEP_VARIANCE_BOUNDS.0, STEP_VARIANCE_BOUNDS.1);
        let converged = (factor - 1.0).abs() < VCE_TOLERANCE || next == q;
        q = next;
        if converged {
            break;
        }
    }
    q
}

/// Puts the smoothed centres and their standard deviations into `epochs` (keeping the
/// firmware's centres as `realtime_centre_m`), places the right cameras again with
/// their standard deviations, and updates the fixes' residuals. Returns how far the
/// centres moved: RMS and largest.
fn apply(
    epochs: &mut [EpochRecord],
    solved: &[Centre],
    lever_arm_m: [f64; 3],
    rig: &RelativeOrientation,
) -> (f64, f64) {
    let (mut sum_sq, mut largest) = (0.0f64, 0.0f64);
    for (e, solved) in epochs.iter_mut().zip(solved) {
        let old = [e.left.x, e.left.y, e.left.z];
        let new = solved.x;
        let shift_sq: f64 = (0..3).map(|c| (new[c] - old[c]).powi(2)).sum();
        sum_sq += shift_sq;
        largest = largest.max(shift_sq.sqrt());
        e.realtime_centre_m = Some(old);
        (e.left.x, e.left.y, e.left.z) = (new[0], new[1], new[2]);
        // An epoch without the firmware's precision (the datum epoch, a predicted one)
        // has no attitude precision either: it stays without.
        if let Some(sigma) = e.left.sigma.as_mut() {
            for c in 0..3 {
                sigma[3 + c] = solved.var[c].sqrt();
            }
        }
        let left = e.left.to_pose();
        e.right = crate::report::CameraEop::from_pose(
            &rig.right_pose(&left),
            e.left.sigma.map(|s| right_sigma(&left, rig, &s)),
        );
        if let Some(g) = e.gnss.as_mut() {
            let antenna = aiding::antenna_position(&e.left.to_pose(), lever_arm_m);
            g.residual_m = [0, 1, 2].map(|c| antenna[c] - g.position[c]);
        }
    }
    ((sum_sq / epochs.len() as f64).sqrt(), largest)
}

/// The right camera's standard deviations (radians and metres) from the left's
/// `sigma_deg_m` (attitude from the firmware, centre smoothed), through the rig: the
/// attitude's uncertainty turns the base onto the right centre. The correlations
/// between attitude and centre are left out: the smoothing changed the centres'
/// precision without them.
fn right_sigma(left: &Pose, rig: &RelativeOrientation, sigma_deg_m: &[f64; 6]) -> [f64; 6] {
    let mut cov = [0.0; 36];
    for (k, s) in sigma_deg_m.iter().enumerate() {
        let s = if k < 3 { s.to_radians() } else { *s };
        cov[k * 7] = s * s;
    }
    standard_deviations(&right_camera_covariance(left, rig, &cov))
}

/// Each fix as an observation of its epoch's centre, with its variance per coordinate.
/// The fix observes the antenna: the centre is the fix less the lever arm turned by the
/// epoch's attitude (its error is the attitude's times the arm).
fn fixed_centres(epochs: &[EpochRecord], lever_arm_m: [f64; 3]) -> Vec<Option<([f64; 3], f64)>> {
    epochs
        .iter()
        .map(|e| {
            e.gnss.map(|g| {
                let pose = e.left.to_pose();
                let antenna = aiding::antenna_position(&pose, lever_arm_m);
                let centre = [0, 1, 2].map(|c| g.position[c] - (antenna[c] - pose.centre[c]));
                (centre, g.sigma_m * g.sigma_m)
            })
        })
        .collect()
}

/// Coordinate `c`'s chain of `epochs` with their `steps` ([`steps`]), and the centres
/// the fixes observe.
fn chain(
    epochs: &[EpochRecord],
    steps: &[([f64; 3], f64)],
    fixed: &[Option<([f64; 3], f64)>],
    c: usize,
) -> Chain {
    let variance = |e: &EpochRecord| e.left.sigma.map(|s| s[3 + c] * s[3 + c]);
    let steps = epochs
        .windows(2)
        .zip(steps)
        .map(|(w, &(value, factor))| {
            let drift = match (&w[1].gnss, variance(&w[0]), variance(&w[1])) {
                (None, Some(v0), Some(v1)) => (v1 - v0).max(0.0),
                _ => 0.0,
            };
            Step {
                value: value[c],
                factor,
                drift,
            }
        })
        .collect();
    let fixes = fixed.iter().map(|f| f.map(|(x, r)| (x[c], r))).collect();
    Chain { steps, fixes }
}

/// The Kalman filter forward and the Rauch-Tung-Striebel pass backward over a random
/// walk whose step into epoch k has variance `steps[k - 1].variance(q)`.
fn smooth(ch: &Chain, q: f64) -> Smoothed {
    let n = ch.fixes.len();
    let (mut xf, mut pf) = (vec![0.0; n], vec![0.0; n]);
    let (mut xp, mut pp) = (vec![0.0; n], vec![0.0; n]);
    for k in 0..n {
        (xp[k], pp[k]) = if k == 0 {
            (0.0, DIFFUSE_M2)
        } else {
            let step = ch.steps[k - 1];
            (xf[k - 1] + step.value, pf[k - 1] + step.variance(q))
        };
        (xf[k], pf[k]) = match ch.fixes[k] {
            Some((z, r)) => {
                let gain = pp[k] / (pp[k] + r);
                (xp[k] + gain * (z - xp[k]), (1.0 - gain) * pp[k])
            }
            None => (xp[k], pp[k]),
        };
    }
    let (mut x, mut var, mut lag_cov) = (xf.clone(), pf.clone(), vec![0.0; n]);
    for k in (0..n - 1).rev() {
        let g = pf[k] / pp[k + 1];
        x[k] = xf[k] + g * (x[k + 1] - xp[k + 1]);
        var[k] = pf[k] + g * g * (var[k + 1] - pp[k + 1]);
        lag_cov[k + 1] = g * var[k + 1];
    }
    Smoothed { x, var, lag_cov }
}

/// A smoothed centre and its variance per coordinate.
struct Centre {
    x: [f64; 3],
    var: [f64; 3],
}

/// The state of [`smooth_turned`]: the centre, the turn and the scale of the steps.
type State = SVector<f64, 7>;
type StateCov = SMatrix<f64, 7, 7>;

/// The step into an epoch, `C_k = C_{k-1} + s + s x t_k + l_k s` (the turn and scale
/// terms only into an epoch without a fix), as the transition from the previous state:
/// the matrix, the shift and the process covariance. `t` and `l` walk on from the
/// previous epoch inside a stretch without fixes and start from their priors elsewhere
/// (where a fix holds the epoch they are not coupled and stay at their priors).
fn transition(
    s: [f64; 3],
    step_var: f64,
    turned: bool,
    walks: bool,
) -> (StateCov, State, StateCov) {
    let step = Vector3::from(s);
    let cross = step.cross_matrix();
    // The noise (white step, turn, scale) enters as G w.
    let mut g = StateCov::identity();
    if turned {
        g.fixed_view_mut::<3, 3>(0, 3).copy_from(&cross);
        g.fixed_view_mut::<3, 1>(0, 6).copy_from(&step);
    }
    let mut f = g;
    if !walks {
        f.fixed_view_mut::<7, 4>(0, 3).fill(0.0);
    }
    let (turn, scale) = if walks {
        (TURN_WALK_RAD, SCALE_WALK)
    } else {
        (TURN_SD_RAD, SCALE_SD)
    };
    let w = independent(step_var, turn, scale);
    let mut shift = State::zeros();
    shift.fixed_rows_mut::<3>(0).copy_from(&step);
    (f, shift, g * w * g.transpose())
}

/// The covariance of independent `(C, t, l)`: the centre's variance per coordinate, the
/// turn's and the scale's standard deviations.
fn independent(centre_var: f64, turn: f64, scale: f64) -> StateCov {
    let (t, l) = (turn * turn, scale * scale);
    StateCov::from_diagonal(&State::from_column_slice(&[
        centre_var, centre_var, centre_var, t, t, t, l,
    ]))
}

/// The step into each epoch after the first and its variance factor of `q`.
fn steps(epochs: &[EpochRecord]) -> Vec<([f64; 3], f64)> {
    let centre = |e: &EpochRecord| [e.left.x, e.left.y, e.left.z];
    epochs
        .windows(2)
        .map(|w| match w[1].step_m {
            Some(s) => (s, 1.0),
            None => {
                let (a, b) = (centre(&w[0]), centre(&w[1]));
                ([0, 1, 2].map(|c| b[c] - a[c]), FALLBACK_VARIANCE_FACTOR)
            }
        })
        .collect()
}

/// The Kalman filter forward and the Rauch-Tung-Striebel pass backward over the state
/// `(C, t, l)` of the model in the module's documentation, with the step variance `q`.
fn smooth_turned(
    steps: &[([f64; 3], f64)],
    fixed: &[Option<([f64; 3], f64)>],
    q: f64,
) -> Vec<Centre> {
    rts(&filter(steps, fixed, q))
        .iter()
        .map(|(x, p)| Centre {
            x: [x[0], x[1], x[2]],
            var: [p[(0, 0)], p[(1, 1)], p[(2, 2)]],
        })
        .collect()
}

/// The filter's pass: per epoch the predicted and the filtered state with their
/// covariances, and the transition into each epoch after the first (index `k - 1`).
struct Forward {
    predicted: Vec<(State, StateCov)>,
    filtered: Vec<(State, StateCov)>,
    transitions: Vec<StateCov>,
}

/// The Kalman filter forward over the epochs, from a diffuse centre and the priors of
/// the turn and scale.
fn filter(steps: &[([f64; 3], f64)], fixed: &[Option<([f64; 3], f64)>], q: f64) -> Forward {
    let n = fixed.len();
    let mut prior = (
        State::zeros(),
        independent(DIFFUSE_M2, TURN_SD_RAD, SCALE_SD),
    );
    let mut pass = Forward {
        predicted: Vec::with_capacity(n),
        filtered: Vec::with_capacity(n),
        transitions: Vec::with_capacity(n),
    };
    for k in 0..n {
        if k > 0 {
            let (s, factor) = steps[k - 1];
            let turned = fixed[k].is_none();
            let walks = turned && fixed[k - 1].is_none();
            let white = q * factor;
            let step_var = if turned {
                white.max(outage_step_variance(s))
            } else {
                white
            };
            let (f, shift, process) = transition(s, step_var, turned, walks);
            let (x, p) = &pass.filtered[k - 1];
            prior = (f * x + shift, f * p * f.transpose() + process);
            pass.transitions.push(f);
        }
        pass.filtered.push(match fixed[k] {
            Some((z, r)) => update(&prior.0, &prior.1, Vector3::from(z), r),
            None => prior,
        });
        pass.predicted.push(prior);
    }
    pass
}

/// The least variance of a step `s` into an epoch without a fix, per coordinate
/// ([`OUTAGE_STEP_RELATIVE`]).
fn outage_step_variance(s: [f64; 3]) -> f64 {
    let length = Vector3::from(s).norm();
    (OUTAGE_STEP_RELATIVE * length).powi(2)
}

/// The Rauch-Tung-Striebel pass backward over the filter's.
fn rts(pass: &Forward) -> Vec<(State, StateCov)> {
    let mut smoothed = pass.filtered.clone();
    for k in (0..smoothed.len().saturating_sub(1)).rev() {
        let (xf, pf) = &pass.filtered[k];
        let (xp, pp) = &pass.predicted[k + 1];
        // The gain J = P_f F^T P_p^-1; a predicted covariance that cannot be inverted
        // (never, with the priors above) leaves the filtered state.
        let Some(gain) = pp
            .cholesky()
            .map(|c| c.solve(&(pass.transitions[k] * pf)).transpose())
        else {
            continue;
        };
        let (xs, ps) = smoothed[k + 1];
        smoothed[k] = (
            xf + gain * (xs - xp),
            pf + gain * (ps - pp) * gain.transpose(),
        );
    }
    smoothed
}

/// The filter's update by a fix `z` of the centre with variance `r` per coordinate.
fn update(x: &State, p: &StateCov, z: Vector3<f64>, r: f64) -> (State, StateCov) {
    let innovation_cov = p.fixed_view::<3, 3>(0, 0) + Matrix3::identity() * r;
    let Some(chol) = innovation_cov.cholesky() else {
        return (*x, *p);
    };
    // K = P H^T S^-1, H = [I 0]: the first three columns of P.
    let gain = chol
        .solve(&p.fixed_view::<3, 7>(0, 0).into_owned())
        .transpose();
    let x = x + gain * (z - x.fixed_rows::<3>(0));
    let p = p - gain * p.fixed_view::<3, 7>(0, 0);
    (x, (p + p.transpose()) * 0.5)
}

/// Förstner's factor for the step variance: the steps' weighted squared residuals over
/// their redundancy, all three coordinates together; the steps with a drift term are
/// left out (their variance is mostly the firmware's, not `q`).
fn variance_factor(chains: &[Chain], solved: &[Smoothed], q: f64) -> f64 {
    let (mut vtpv, mut redundancy) = (0.0, 0.0);
    for (ch, s) in chains.iter().zip(solved) {
        for k in 1..s.x.len() {
            let step = ch.steps[k - 1];
            if step.drift > 0.0 {
                continue;
            }
            let variance = step.variance(q);
            let v = s.x[k] - s.x[k - 1] - step.value;
            vtpv += v * v / variance;
            let step_var = s.var[k] + s.var[k - 1] - 2.0 * s.lag_cov[k];
            redundancy += 1.0 - step_var / variance;
        }
    }
    if redundancy > 0.5 {
        vtpv / redundancy
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::{CameraEop, EpochStatus, GnssRecord};
    use rand::{Rng, SeedableRng};

    /// A rig whose right camera is the left one: the tests of the centres alone.
    const ONE_PLACE: RelativeOrientation = RelativeOrientation {
        angles: [0.0; 3],
        base: [0.0; 3],
    };

    /// A straight drive along Y at 2 m per epoch; the records carry the images' steps
    /// with `step_error(k)` added and their positions are the sum of those steps.
    fn drive(
        n: usize,
        fix: impl Fn(usize) -> Option<[f64; 3]>,
        step_error: impl Fn(usize) -> [f64; 3],
    ) -> (Vec<EpochRecord>, Vec<[f64; 3]>) {
        let truth: Vec<[f64; 3]> = (0..n).map(|k| [0.0, 2.0 * k as f64, 0.0]).collect();
        let records = records_of(&truth, fix, |k, _| step_error(k));
        (records, truth)
    }

    /// Records along `truth` whose steps carry `step_error(k, true step)`.
    fn records_of(
        truth: &[[f64; 3]],
        fix: impl Fn(usize) -> Option<[f64; 3]>,
        step_error: impl Fn(usize, [f64; 3]) -> [f64; 3],
    ) -> Vec<EpochRecord> {
        let n = truth.len();
        let mut at = truth[0];
        (0..n)
            .map(|k| {
                let step = (k > 0).then(|| {
                    let d = [0, 1, 2].map(|c| truth[k][c] - truth[k - 1][c]);
                    let e = step_error(k, d);
                    [0, 1, 2].map(|c| d[c] + e[c])
                });
                if let Some(s) = step {
                    at = [0, 1, 2].map(|c| at[c] + s[c]);
                }
                let eop = CameraEop {
                    omega_deg: 90.0,
                    phi_deg: 0.0,
                    kappa_deg: 0.0,
                    x: at[0],
                    y: at[1],
                    z: at[2],
                    // The firmware's precision: a few millimetres, as with fixes.
                    sigma: Some([1e-4, 1e-4, 1e-4, 0.003, 0.003, 0.003]),
                };
                let mut r =
                    EpochRecord::posed(k, Some(k as f64 * 0.1), EpochStatus::Ok, (eop, eop));
                r.step_m = step;
                r.gnss = fix(k).map(|position| GnssRecord {
                    position,
                    sigma_m: 0.01,
                    residual_m: [0.0; 3],
                });
                r
            })
            .collect()
    }

    fn error(r: &EpochRecord, t: [f64; 3]) -> f64 {
        ((r.left.x - t[0]).powi(2) + (r.left.y - t[1]).powi(2) + (r.left.z - t[2]).powi(2)).sqrt()
    }

    #[test]
    fn nothing_changes_without_fixes() {
        let (mut records, _) = drive(20, |_| None, |_| [0.001, 0.0, 0.0]);
        let before = records.clone();
        assert_eq!(smooth_over_fixes(&mut records, [0.0; 3], &ONE_PLACE), None);
        assert_eq!(format!("{records:?}"), format!("{before:?}"));
    }

    #[test]
    fn an_outage_is_closed_on_the_fixes_at_both_ends_as_a_traverse() {
        // Exact fixes outside epochs 40..=60, and steps with a 1 cm bias in X (a turn of
        // 5 mrad, constant): the images alone end the outage 0.21 m off. The smoothed
        // traverse spreads that misclosure over the outage. The model expects a turn
        // that grows from the entry (a random walk), not a constant one, so it leaves
        // 0.009 m of the drift, where Bowditch's rule would take this one out exactly
        // (0.04 m with the turn walking by 2 mrad per step, as it did before 2026-12-07).
        let (mut records, truth) = drive(
            100,
            |k| (!(40..=60).contains(&k)).then_some([0.0, 2.0 * k as f64, 0.0]),
            |_| [0.01, 0.0, 0.0],
        );
        for r in records.iter_mut() {
            if let Some(g) = r.gnss.as_mut() {
                g.sigma_m = 1e-4;
            }
        }
        let summary = smooth_over_fixes(&mut records, [0.0; 3], &ONE_PLACE).unwrap();
        assert_eq!(summary.fixes, 79);
        let worst = (40..=60)
            .map(|k| error(&records[k], truth[k]))
            .fold(0.0, f64::max);
        assert!(worst < 0.02, "largest error inside the outage {worst}");
        // The precision is that of a bridge: largest in the middle of the outage.
        let sd = |k: usize| records[k].left.sigma.unwrap()[3];
        assert!(
            sd(50) > sd(42) && sd(50) > sd(58) && sd(42) > sd(30),
            "{} {} {}",
            sd(30),
            sd(42),
            sd(50)
        );
    }

    /// A path along Y that turns a quarter circle of 20 m radius (epochs 31 to 46) and
    /// goes on along X, at 2 m per epoch.
    fn turning_path(n: usize) -> Vec<[f64; 3]> {
        let mut at = [0.0; 3];
        let mut heading = 0.0f64;
        (0..n)
            .map(|k| {
                if k > 0 {
                    if (31..=46).contains(&k) {
                        heading += 0.1;
                    }
                    at = [
                        at[0] + 2.0 * heading.sin(),
                        at[1] + 2.0 * heading.cos(),
                        0.0,
                    ];
                }
                at
            })
            .collect()
    }

    #[test]
    fn a_turn_of_the_steps_is_closed_along_the_path() {
        // The outage 25..=60 holds the quarter turn, and the images' steps inside it are
        // turned by 2 mrad about the vertical (the attitude error the window enters an
        // outage with): 0.2 m of misclosure across the turn. A chain per coordinate
        // spreads each coordinate's misclosure along that coordinate (0.038 m off at
        // worst); the turn of the steps puts it where the path's shape makes it
        // (0.014 m).
        let truth = turning_path(100);
        let outage = 25..=60;
        let turn = 2e-3f64;
        let mut records = records_of(
            &truth,
            |k| (!outage.contains(&k)).then_some(truth[k]),
            |k, d| {
                if outage.contains(&k) {
                    let (s, c) = turn.sin_cos();
                    [c * d[0] - s * d[1] - d[0], s * d[0] + c * d[1] - d[1], 0.0]
                } else {
                    [0.0; 3]
                }
            },
        );
        for r in records.iter_mut() {
            if let Some(g) = r.gnss.as_mut() {
                g.sigma_m = 1e-4;
            }
            let a = 1e-4f64.to_degrees();
            r.left.sigma = Some([a, a, a, 0.003, 0.003, 0.003]);
        }
        let worst_of = |x: &dyn Fn(usize) -> [f64; 3]| {
            outage
                .clone()
                .map(|k| {
                    let p = x(k);
                    (0..3)
                        .map(|c| (p[c] - truth[k][c]).powi(2))
                        .sum::<f64>()
                        .sqrt()
                })
                .fold(0.0, f64::max)
        };
        let fixed = fixed_centres(&records, [0.0; 3]);
        let steps = steps(&records);
        let chains: Vec<Chain> = (0..3).map(|c| chain(&records, &steps, &fixed, c)).collect();
        let q = estimate_step_variance(&chains);
        let per_coordinate: Vec<Smoothed> = chains.iter().map(|ch| smooth(ch, q)).collect();
        let chained = worst_of(&|k| [0, 1, 2].map(|c| per_coordinate[c].x[k]));
        // A 0.5 m base along X (the cameras look along Y).
        let rig = RelativeOrientation {
            angles: [0.0; 3],
            base: [0.5, 0.0, 0.0],
        };
        smooth_over_fixes(&mut records, [0.0; 3], &rig).unwrap();
        let turned = worst_of(&|k| [records[k].left.x, records[k].left.y, records[k].left.z]);
        assert!(
            turned < 0.02 && turned < chained / 2.0,
            "largest error inside: turned {turned}, per coordinate {chained}"
        );
        // The right cameras sit 0.5 m to the right with the smoothed left centres'
        // precision, plus the attitude's 0.1 mrad turning the base: (0.05 mm)^2 in Y
        // (phi) and Z (kappa), nothing along the base.
        for r in &records {
            let (l, rt) = (r.left.sigma.unwrap(), r.right.sigma.unwrap());
            assert!((r.right.x - r.left.x - 0.5).abs() < 1e-12);
            assert!((0..3).all(|k| (rt[k] - l[k]).abs() < 1e-15), "{l:?} {rt:?}");
            let added = [3, 4, 5].map(|c| rt[c].powi(2) - l[c].powi(2));
            assert!(added[0].abs() < 1e-15, "{added:?}");
            assert!(
                added[1..].iter().all(|a| (a - 2.5e-9).abs() < 1e-13),
                "{added:?}"
            );
        }
    }

    #[test]
    fn noisy_fixes_are_averaged_through_the_steps_and_the_step_precision_is_estimated() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let fix_noise = noise(&mut rng, 400, |_| 0.01);
        let step_noise = noise(&mut rng, 400, |_| 0.005);
        let (mut records, truth) =
            drive(400, |k| Some(on_line(k, fix_noise[k])), |k| step_noise[k]);
        let summary = smooth_over_fixes(&mut records, [0.0; 3], &ONE_PLACE).unwrap();
        // Estimated within 15 % of the 5 mm the steps were drawn with (the steps'
        // redundancy, about 300 here, makes that about 4 % one sigma).
        assert!((summary.step_sd_m - 0.005).abs() < 7.5e-4, "{summary:?}");
        let rms = (records
            .iter()
            .zip(&truth)
            .map(|(r, t)| error(r, *t).powi(2))
            .sum::<f64>()
            / 400.0)
            .sqrt();
        // The fixes alone: 1 cm per coordinate, 1.7 cm in 3D.
        assert!(rms < 0.0125, "RMS {rms}");
        // The standard deviations cover the errors as they should (about 97 % within 3 sd
        // on all three coordinates of a Gaussian error).
        let covered = records
            .iter()
            .zip(&truth)
            .filter(|(r, t)| within_3_sd(r, **t))
            .count();
        assert!(covered >= 380, "{covered} of 400 within 3 sd");
        // The fixes' residuals are against the smoothed positions.
        let g = records[100].gnss.unwrap();
        assert!((g.residual_m[0] - (records[100].left.x - g.position[0])).abs() < 1e-12);
    }

    #[test]
    fn inside_an_outage_the_steps_err_as_the_images_own_and_the_precision_says_so() {
        // Between fixes the steps agree to 2 mm, as the aided window's do; inside the ten
        // outages of 10 epochs each they err by 1 cm per coordinate (0.5 % of the 2 m
        // step), as the images' own steps do. A Gaussian error is within 3 sd on all three
        // coordinates 99 % of the time: 99 of the 100 outage epochs are. With the steps'
        // variance left at the 2 mm estimated between fixes, the turn's and the scale's
        // priors took up most of it, but 93 were.
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let outage = |k: usize| k >= 20 && k % 30 >= 20;
        let step_noise = noise(&mut rng, 300, |k| if outage(k) { 0.01 } else { 0.002 });
        let fix_noise = noise(&mut rng, 300, |_| 0.01);
        let (mut records, truth) = drive(
            300,
            |k| (!outage(k)).then(|| on_line(k, fix_noise[k])),
            |k| step_noise[k],
        );
        smooth_over_fixes(&mut records, [0.0; 3], &ONE_PLACE).unwrap();
        let covered = (0..300)
            .filter(|&k| outage(k) && within_3_sd(&records[k], truth[k]))
            .count();
        assert!(covered >= 97, "{covered} of 100 outage epochs within 3 sd");
    }

    /// Normal errors on three coordinates for each of `n` epochs, of sd `sd(k)`.
    fn noise(rng: &mut impl Rng, n: usize, sd: impl Fn(usize) -> f64) -> Vec<[f64; 3]> {
        (0..n)
            .map(|k| {
                let sd = sd(k);
                [0; 3].map(|_: i32| sd * gauss(rng))
            })
            .collect()
    }

    /// The point of [`drive`]'s line at epoch `k`, moved by `error`.
    fn on_line(k: usize, error: [f64; 3]) -> [f64; 3] {
        [error[0], 2.0 * k as f64 + error[1], error[2]]
    }

    /// Whether the record's centre is within 3 of its standard deviations of `truth` on
    /// every coordinate.
    fn within_3_sd(r: &EpochRecord, truth: [f64; 3]) -> bool {
        let s = r.left.sigma.unwrap();
        [r.left.x, r.left.y, r.left.z]
            .iter()
            .zip(truth.iter())
            .zip(&s[3..])
            .all(|((x, t), s)| (x - t).abs() <= 3.0 * s)
    }

    fn gauss(rng: &mut impl Rng) -> f64 {
        // Box-Muller.
        let (u, v): (f64, f64) = (rng.gen_range(1e-12..1.0), rng.gen_range(0.0..1.0));
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}
