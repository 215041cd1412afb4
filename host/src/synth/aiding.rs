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
use crate::dataset::aiding::{
    antenna_position, within, GnssSetup, GNSS_FILE, GNSS_GEODETIC_FILE, GNSS_SETUP_FILE,
    ODOMETER_FILE,
};
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
    /// The antenna in the left camera's frame, m (the fixes are the antenna's).
    pub lever_arm_m: [f64; 3],
    /// Write the fixes as `gnss_geodetic.txt` with the object frame's origin at this
    /// WGS84 position (latitude, longitude deg, height m) and its +Y at this heading
    /// (deg from north): `[lat, lon, h, heading]`. `None`: `gnss.txt` in the object frame.
    pub geodetic: Option<[f64; 4]>,
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
    // The object-frame pose at time t (s): the truth as the traverse's frame sees it.
    let pose = |t: f64| {
        let p = plan.left_pose(t / plan.dt);
        pose_from_kitti(datum, &kitti_from_pose(origin, &p))
    };
    let centre = |t: f64| pose(t).centre;
    // The antenna: the centre plus the lever arm turned into the object frame (M^T l).
    let antenna = |t: f64| antenna_position(&pose(t), opts.lever_arm_m);
    let setup = GnssSetup {
        origin: opts.geodetic.map(|g| [g[0], g[1], g[2]]),
        heading_deg: opts.geodetic.map_or(0.0, |g| g[3]),
        lever_arm_m: opts.lever_arm_m,
    };
    if opts.gnss_sigma_m.is_some() && setup != GnssSetup::default() {
        let text = toml::to_string(&SetupFile { gnss: setup }).unwrap_or_default();
        std::fs::write(out.join(GNSS_SETUP_FILE), text)?;
    }
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
        let mut text = String::from(match opts.geodetic {
            None => "# time_s X_m Y_m Z_m sigma_m (the antenna, object frame)\n",
            Some(_) => {
                "# time_s latitude_deg longitude_deg height_m sigma_m (the antenna, WGS84)\n"
            }
        });
        for t in times {
            if within(&opts.gnss_outages, t) {
                continue;
            }
            let p = antenna(t).map(|v| v + sigma * gaussian(&mut rng));
            let _ = match opts.geodetic {
                None => writeln!(text, "{t:.6} {:.4} {:.4} {:.4} {sigma}", p[0], p[1], p[2]),
                Some(g) => {
                    let [lat, lon, h] = geodetic_of(p, g);
                    writeln!(text, "{t:.6} {lat:.10} {lon:.10} {h:.4} {sigma}")
                }
            };
        }
        let file = if opts.geodetic.is_some() {
            GNSS_GEODETIC_FILE
        } else {
            GNSS_FILE
        };
        std::fs::write(out.join(file), text)?;
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
            // A distance is never negative, however large the sigma asked for.
            let measured = (d + s * gaussian(&mut rng)).max(0.0);
            let _ = writeln!(text, "{t:.6} {measured:.5} {s:.6}");
            prev = c;
        }
        std::fs::write(out.join(ODOMETER_FILE), text)?;
    }
    Ok(())
}

/// `gnss.toml`'s one table.
#[derive(serde::Serialize)]
struct SetupFile {
    gnss: GnssSetup,
}

/// WGS84 latitude, longitude (deg) and height (m) of an object-frame point, the frame's
/// origin and heading `[lat, lon, h, heading]` (the inverse of [`GnssSetup::to_object`]).
fn geodetic_of(p: [f64; 3], g: [f64; 4]) -> [f64; 3] {
    let (sh, ch) = g[3].to_radians().sin_cos();
    let (e, n) = (p[0] * ch + p[1] * sh, -p[0] * sh + p[1] * ch);
    let (lat, lon, h) = map_3d::enu2geodetic(
        e,
        n,
        p[2],
        g[0].to_radians(),
        g[1].to_radians(),
        g[2],
        map_3d::Ellipsoid::WGS84,
    );
    [lat.to_degrees(), lon.to_degrees(), h]
}
