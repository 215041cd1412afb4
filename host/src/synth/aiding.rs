//! Simulated GNSS fixes and odometer readings of a synthetic street
//! (`gnss.txt`, `odometer.txt`; format in [`crate::dataset::aiding`]).
//!
//! A fix is the left perspective centre's true position in the traverse's object
//! frame plus white Gaussian noise of the stated sigma on each coordinate; an odometer
//! reading is the true path length since the previous reading (the polyline through
//! the epochs' true centres) times `1 + e`, `e` Gaussian with the stated relative
//! sigma, drawn per reading.
use super::realism::gaussian;
use super::ScenePlan;
use crate::dataset::aiding::{GNSS_FILE, ODOMETER_FILE};
use phototraverse_core::camera::{kitti_from_pose, pose_from_kitti, Pose};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::fmt::Write;
use std::path::Path;

/// What to simulate.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct AidingOptions {
    /// GNSS sigma per coordinate, m; `None`: no `gnss.txt`.
    pub gnss_sigma_m: Option<f64>,
    /// Fixes per second; `None`: one fix at every epoch.
    pub gnss_rate_hz: Option<f64>,
    /// Time spans without fixes, seconds.
    pub gnss_outages: Vec<(f64, f64)>,
    /// Odometer sigma relative to the distance (0.005 = 0.5 %); `None`: no `odometer.txt`.
    pub odometer_sigma: Option<f64>,
}

/// Writes the files `opts` asks for into `out`. `datum`: the dataset's datum (the
/// object frame the fixes are in); `origin`: the true left pose of epoch 0.
pub fn write_aiding(
    out: &Path,
    plan: &ScenePlan,
    (datum, origin): (&Pose, &Pose),
    opts: &AidingOptions,
    seed: u64,
) -> std::io::Result<()> {
    // The object-frame centre at time t (s): the truth as the traverse's frame sees it.
    let centre = |t: f64| {
        let p = plan.left_pose(t / plan.dt);
        pose_from_kitti(datum, &kitti_from_pose(origin, &p)).centre
    };
    let end = (plan.frames.max(1) - 1) as f64 * plan.dt;
    if let Some(sigma) = opts.gnss_sigma_m {
        let mut rng = ChaCha8Rng::seed_from_u64(super::mix(seed, 0x6e55, 1));
        let times: Vec<f64> = match opts.gnss_rate_hz {
            Some(hz) => (0..)
                .map(|j| j as f64 / hz)
                .take_while(|t| *t <= end + 1e-9)
                .collect(),
            None => (0..plan.frames).map(|k| k as f64 * plan.dt).collect(),
        };
        let mut text =
            String::from("# time_s X_m Y_m Z_m sigma_m (left perspective centre, object frame)\n");
        for t in times {
            if opts.gnss_outages.iter().any(|&(a, b)| t >= a && t <= b) {
                continue;
            }
            let c = centre(t);
            let p = c.map(|v| v + sigma * gaussian(&mut rng));
            let _ = writeln!(text, "{t:.6} {:.4} {:.4} {:.4} {sigma}", p[0], p[1], p[2]);
        }
        std::fs::write(out.join(GNSS_FILE), text)?;
    }
    if let Some(rel) = opts.odometer_sigma {
        let mut rng = ChaCha8Rng::seed_from_u64(super::mix(seed, 0x0d0, 2));
        let mut text =
            String::from("# time_s distance_m sigma_m (distance since the previous line)\n");
        let _ = writeln!(text, "{:.6} 0 {}", 0.0, 1e-6);
        let mut prev = centre(0.0);
        for k in 1..plan.frames {
            let t = k as f64 * plan.dt;
            let c = centre(t);
            let d = ((0..3).map(|a| (c[a] - prev[a]).powi(2)).sum::<f64>()).sqrt();
            let s = (rel * d).max(1e-6);
            let measured = d + s * gaussian(&mut rng);
            let _ = writeln!(text, "{t:.6} {measured:.5} {s:.6}");
            prev = c;
        }
        std::fs::write(out.join(ODOMETER_FILE), text)?;
    }
    Ok(())
}
