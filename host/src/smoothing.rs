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
//! The model, per coordinate (X, Y, Z independently): the left perspective centres
//! `C_k` are the unknowns. Each step `C_k - C_{k-1}` is observed by the images (the
//! firmware's `step_m`: both centres from one window adjustment, so the fixes, which
//! move the window as a whole, do not distort it) with variance `q + D_k`. `q` is the
//! images' white step noise. `D_k`, into an epoch without a fix, is the growth of the
//! firmware's own variance of the centre (with respect to the datum) since the
//! previous epoch: the firmware propagates the attitude's uncertainty into the
//! position along the path, which independent steps would not, so an outage's
//! misclosure is spread the way the firmware expects the drift to grow, not in
//! proportion to the distance alone (Bowditch's rule). Each fix observes its epoch's
//! centre (the antenna position less the lever arm turned by the epoch's attitude)
//! with its sigma. A step the firmware did not give (an epoch that was not adjusted,
//! or after one) is taken from the two output positions with
//! [`FALLBACK_VARIANCE_FACTOR`] times `q`.
//!
//! Least squares over this chain is the fixed-interval (Rauch-Tung-Striebel) smoother
//! of a random walk, O(n) with the smoothed variances, whose square roots replace the
//! firmware's standard deviations of the centres; the attitudes are not changed. The right
//! cameras follow through the rig, their standard deviations from the left camera's. `q`
//! is estimated from the data by variance component estimation (Förstner's iteration
//! `q <- q * sum(v^2 / q) / r`, `r` the redundancy numbers of the steps without `D`),
//! since the images' step precision depends on the scene and the rig; the fixes'
//! sigmas are taken as given.
use crate::dataset::aiding;
use crate::report::EpochRecord;
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
/// (value, variance) where there are.
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
    let chains: Vec<Chain> = (0..3).map(|c| chain(epochs, &fixed, c)).collect();
    let q = estimate_step_variance(&chains);
    let solved: Vec<Smoothed> = chains.iter().map(|ch| smooth(ch, q)).collect();
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
    solved: &[Smoothed],
    lever_arm_m: [f64; 3],
    rig: &RelativeOrientation,
) -> (f64, f64) {
    let (mut sum_sq, mut largest) = (0.0f64, 0.0f64);
    for (k, e) in epochs.iter_mut().enumerate() {
        let old = [e.left.x, e.left.y, e.left.z];
        let new = [solved[0].x[k], solved[1].x[k], solved[2].x[k]];
        let shift_sq: f64 = (0..3).map(|c| (new[c] - old[c]).powi(2)).sum();
        sum_sq += shift_sq;
        largest = largest.max(shift_sq.sqrt());
        e.realtime_centre_m = Some(old);
        (e.left.x, e.left.y, e.left.z) = (new[0], new[1], new[2]);
        // An epoch without the firmware's precision (the datum epoch, a predicted one)
        // has no attitude precision either: it stays without.
        if let Some(sigma) = e.left.sigma.as_mut() {
            for c in 0..3 {
                sigma[3 + c] = solved[c].var[k].sqrt();
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

/// Coordinate `c`'s chain of `epochs`, with the centres the fixes observe.
fn chain(epochs: &[EpochRecord], fixed: &[Option<([f64; 3], f64)>], c: usize) -> Chain {
    let centre = |e: &EpochRecord| [e.left.x, e.left.y, e.left.z][c];
    let variance = |e: &EpochRecord| e.left.sigma.map(|s| s[3 + c] * s[3 + c]);
    let steps = epochs
        .windows(2)
        .map(|w| {
            let (value, factor) = match w[1].step_m {
                Some(s) => (s[c], 1.0),
                None => (centre(&w[1]) - centre(&w[0]), FALLBACK_VARIANCE_FACTOR),
            };
            let drift = match (&w[1].gnss, variance(&w[0]), variance(&w[1])) {
                (None, Some(v0), Some(v1)) => (v1 - v0).max(0.0),
                _ => 0.0,
            };
            Step {
                value,
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
        // Exact fixes outside epochs 40..=60, and steps with a 1 cm bias in X: the
        // images alone end the outage 0.21 m off; the smoothed traverse spreads that
        // misclosure over the outage, so the bias (a linear drift) is taken out
        // exactly, as Bowditch's rule would.
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
        assert!(worst < 1e-3, "largest error inside the outage {worst}");
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

    #[test]
    fn the_misclosure_is_spread_where_the_firmware_expects_the_drift() {
        // The steps of epochs 51..=60, the second half of the outage 40..=60, are 1 cm
        // off in X (as after a turn that shows an attitude error), and the firmware's
        // standard deviation grows there only. Bowditch's rule would spread the 10 cm
        // misclosure over the whole outage, 5 cm off at its middle; the firmware's
        // variance puts it where the drift was.
        let (mut records, truth) = drive(
            100,
            |k| (!(40..=60).contains(&k)).then_some([0.0, 2.0 * k as f64, 0.0]),
            |k| [if (51..=60).contains(&k) { 0.01 } else { 0.0 }, 0.0, 0.0],
        );
        for (k, r) in records.iter_mut().enumerate() {
            if let Some(g) = r.gnss.as_mut() {
                g.sigma_m = 1e-4;
            }
            // Its variance grows by (2 cm)^2 per epoch there: in proportion to the
            // distance, as the drift does.
            let grown = if (51..=60).contains(&k) {
                (k - 50) as f64 * 4e-4
            } else {
                0.0
            };
            let sd = (0.003f64.powi(2) + grown).sqrt();
            let a = 1e-4f64.to_degrees();
            r.left.sigma = Some([a, a, a, sd, sd, sd]);
        }
        // A 0.5 m base along X (the cameras look along Y).
        let rig = RelativeOrientation {
            angles: [0.0; 3],
            base: [0.5, 0.0, 0.0],
        };
        smooth_over_fixes(&mut records, [0.0; 3], &rig).unwrap();
        let worst = (40..=60)
            .map(|k| error(&records[k], truth[k]))
            .fold(0.0, f64::max);
        assert!(worst < 0.01, "largest error inside the outage {worst}");
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
        let fix_noise: Vec<[f64; 3]> = (0..400)
            .map(|_| [0; 3].map(|_: i32| 0.01 * gauss(&mut rng)))
            .collect();
        let step_noise: Vec<[f64; 3]> = (0..400)
            .map(|_| [0; 3].map(|_: i32| 0.005 * gauss(&mut rng)))
            .collect();
        let (mut records, truth) = drive(
            400,
            |k| Some([0, 1, 2].map(|c| [0.0, 2.0 * k as f64, 0.0][c] + fix_noise[k][c])),
            |k| step_noise[k],
        );
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
            .filter(|(r, t)| {
                let s = r.left.sigma.unwrap();
                [r.left.x, r.left.y, r.left.z]
                    .iter()
                    .zip(t.iter())
                    .zip(&s[3..])
                    .all(|((x, t), s)| (x - t).abs() <= 3.0 * s)
            })
            .count();
        assert!(covered >= 380, "{covered} of 400 within 3 sd");
        // The fixes' residuals are against the smoothed positions.
        let g = records[100].gnss.unwrap();
        assert!((g.residual_m[0] - (records[100].left.x - g.position[0])).abs() < 1e-12);
    }

    fn gauss(rng: &mut impl Rng) -> f64 {
        // Box-Muller.
        let (u, v): (f64, f64) = (rng.gen_range(1e-12..1.0), rng.gen_range(0.0..1.0));
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}
