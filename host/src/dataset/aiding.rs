//! Aiding observations of a dataset: GNSS fixes (`gnss.txt`) and odometer
//! distances (`odometer.txt`), and how they are tied to the epochs
//! (docs/datasets.md, "GNSS and odometer").
//!
//! - `gnss.txt`: `time_s X_m Y_m Z_m sigma_m` per line, the antenna's position in the
//!   traverse's object frame (that of `eop.csv`): the left perspective centre's unless
//!   the `[gnss]` table gives a lever arm.
//! - `odometer.txt`: `time_s distance_m sigma_m` per line, the distance
//!   travelled since the previous line (the first line opens the count).
//!
//! - `gnss_geodetic.txt`: `time_s latitude_deg longitude_deg height_m sigma_m` (WGS84,
//!   ellipsoidal height), converted to the object frame with the `[gnss]` table.
//!
//! The `[gnss]` table (of `rig.toml`, or `gnss.toml` beside any layout) places the
//! object frame on the Earth and the antenna on the rig ([`GnssSetup`]).
//!
//! Times are on the clock of `times.txt`. Empty lines and `#` comments are skipped.
use super::DatasetError;
use phototraverse_core::camera::Pose;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// File name of a dataset's GNSS fixes.
pub const GNSS_FILE: &str = "gnss.txt";
/// File name of a dataset's geodetic GNSS fixes.
pub const GNSS_GEODETIC_FILE: &str = "gnss_geodetic.txt";
/// File name of the `[gnss]` table of a dataset without `rig.toml`.
pub const GNSS_SETUP_FILE: &str = "gnss.toml";
/// File name of a dataset's odometer distances.
pub const ODOMETER_FILE: &str = "odometer.txt";
/// A fix within this time of an epoch is used as it is, s.
pub const GNSS_SAME_TIME_S: f64 = 1e-3;
/// Two fixes at most this far apart are interpolated to an epoch between them, s.
/// Over longer gaps a straight line between fixes misses a turn's arc by more than
/// a good fix's sigma (1 m/s at 20 m radius: 2.5 cm after 0.2 s at 10 m/s).
pub const GNSS_MAX_INTERPOLATION_S: f64 = 0.2;

/// One GNSS fix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssFix {
    pub time: f64,
    /// The antenna in the object frame (the left perspective centre without a lever
    /// arm), m.
    pub position: [f64; 3],
    /// Standard deviation of each coordinate, m.
    pub sigma: f64,
}

/// Where the object frame is on the Earth, and where the GNSS antenna is on the rig:
/// the `[gnss]` table.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GnssSetup {
    /// WGS84 position of the object frame's origin: latitude, longitude (degrees) and
    /// ellipsoidal height (m). Needed for geodetic fixes only.
    #[serde(default)]
    pub origin: Option<[f64; 3]>,
    /// Azimuth of the object frame's +Y axis, degrees clockwise from north. The object
    /// frame's Z is the local vertical (up).
    #[serde(default)]
    pub heading_deg: f64,
    /// The antenna seen from the left perspective centre in the left camera's frame
    /// (x right, y up, z backwards: towards the back of the vehicle), m.
    #[serde(default)]
    pub lever_arm_m: [f64; 3],
}

/// `gnss.toml`: a file holding the `[gnss]` table.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct GnssSetupFile {
    gnss: GnssSetup,
}

impl GnssSetup {
    /// Checks the values; `path` names the file in errors.
    pub fn validated(self, path: &Path) -> Result<Self, DatasetError> {
        let bad = |problem: &str| DatasetError::RigFile {
            path: path.to_path_buf(),
            problem: format!("[gnss]: {problem}"),
        };
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !finite(&self.lever_arm_m) || !self.heading_deg.is_finite() {
            return Err(bad("lever_arm_m and heading_deg must be finite"));
        }
        if let Some([lat, lon, h]) = self.origin {
            if !finite(&[lat, lon, h]) || lat.abs() > 90.0 || lon.abs() > 360.0 {
                return Err(bad(
                    "origin must be [latitude_deg (-90..90), longitude_deg, height_m]",
                ));
            }
        }
        Ok(self)
    }

    /// Reads `gnss.toml`.
    pub fn read(path: &Path) -> Result<Self, DatasetError> {
        let text = std::fs::read_to_string(path).map_err(|source| DatasetError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let file: GnssSetupFile = toml::from_str(&text).map_err(|e| DatasetError::RigFile {
            path: path.to_path_buf(),
            problem: super::rigfile::toml_problem(&e),
        })?;
        file.gnss.validated(path)
    }

    /// Object-frame coordinates of a WGS84 position (degrees, degrees, m): east, north
    /// and up at the origin, turned by the heading (`X = E cos h - N sin h`,
    /// `Y = E sin h + N cos h`, `Z = U`). `None` without an origin.
    pub fn to_object(&self, lat_deg: f64, lon_deg: f64, height_m: f64) -> Option<[f64; 3]> {
        let [lat0, lon0, h0] = self.origin?;
        let (e, n, u) = map_3d::geodetic2enu(
            lat_deg.to_radians(),
            lon_deg.to_radians(),
            height_m,
            lat0.to_radians(),
            lon0.to_radians(),
            h0,
            map_3d::Ellipsoid::WGS84,
        );
        let (sh, ch) = self.heading_deg.to_radians().sin_cos();
        Some([e * ch - n * sh, e * sh + n * ch, u])
    }
}

/// Reads `gnss_geodetic.txt` and converts its fixes to the object frame with `setup`.
pub fn read_gnss_geodetic(path: &Path, setup: &GnssSetup) -> Result<Vec<GnssFix>, DatasetError> {
    let fixes = read_fixes(path, "time_s latitude_deg longitude_deg height_m sigma_m")?;
    if setup.origin.is_none() && !fixes.is_empty() {
        return Err(DatasetError::AidingLine {
            path: path.to_path_buf(),
            line: 1,
            problem: "geodetic fixes need the object frame's origin: `origin = [latitude_deg, \
                      longitude_deg, height_m]` and `heading_deg` in the [gnss] table of \
                      rig.toml or gnss.toml"
                .into(),
        });
    }
    Ok(fixes
        .into_iter()
        .filter_map(|f| {
            let [lat, lon, h] = f.position;
            Some(GnssFix {
                position: setup.to_object(lat, lon, h)?,
                ..f
            })
        })
        .collect())
}

/// One odometer reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometerReading {
    pub time: f64,
    /// Distance travelled since the previous reading, m.
    pub distance: f64,
    /// Its standard deviation, m.
    pub sigma: f64,
}

/// Reads `gnss.txt`.
pub fn read_gnss(path: &Path) -> Result<Vec<GnssFix>, DatasetError> {
    read_fixes(path, "time_s X_m Y_m Z_m sigma_m")
}

/// Fixes of `path`, whose lines are `format` (a time, three coordinates, a sigma).
fn read_fixes(path: &Path, format: &str) -> Result<Vec<GnssFix>, DatasetError> {
    let rows = read_rows::<5>(path, format)?;
    let mut fixes = Vec::with_capacity(rows.len());
    for (line, v) in rows {
        let bad = line_error(path, line);
        if v[4] <= 0.0 {
            return Err(bad(format!("sigma_m {} is not positive", v[4])));
        }
        check_order(fixes.last().map(|f: &GnssFix| f.time), v[0]).map_err(bad)?;
        fixes.push(GnssFix {
            time: v[0],
            position: [v[1], v[2], v[3]],
            sigma: v[4],
        });
    }
    Ok(fixes)
}

/// Reads `odometer.txt`.
pub fn read_odometer(path: &Path) -> Result<Vec<OdometerReading>, DatasetError> {
    let rows = read_rows::<3>(path, "time_s distance_m sigma_m")?;
    let mut readings = Vec::with_capacity(rows.len());
    for (line, v) in rows {
        let bad = line_error(path, line);
        if v[1] < 0.0 {
            return Err(bad(format!("distance_m {} is negative", v[1])));
        }
        if v[2] <= 0.0 {
            return Err(bad(format!("sigma_m {} is not positive", v[2])));
        }
        check_order(readings.last().map(|r: &OdometerReading| r.time), v[0]).map_err(bad)?;
        readings.push(OdometerReading {
            time: v[0],
            distance: v[1],
            sigma: v[2],
        });
    }
    Ok(readings)
}

fn check_order(prev: Option<f64>, t: f64) -> Result<(), String> {
    match prev {
        Some(p) if t <= p => Err(format!(
            "time {t} s is not after the previous line's {p} s (times must increase)"
        )),
        _ => Ok(()),
    }
}

/// The numeric rows of a text file: `(line number, values)`, `N` finite numbers per line.
fn read_rows<const N: usize>(
    path: &Path,
    format: &str,
) -> Result<Vec<(usize, [f64; N])>, DatasetError> {
    let text = std::fs::read_to_string(path).map_err(|source| DatasetError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut rows = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let bad = line_error(path, i + 1);
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.len() != N {
            return Err(bad(format!(
                "{} fields, expected {N} ({format})",
                fields.len()
            )));
        }
        let mut v = [0.0; N];
        for (k, f) in fields.iter().enumerate() {
            v[k] = f
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| bad(format!("`{f}` is not a finite number ({format})")))?;
        }
        rows.push((i + 1, v));
    }
    Ok(rows)
}

/// A command-line time span `START..END` in seconds, START <= END.
pub fn parse_span(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s
        .split_once("..")
        .ok_or_else(|| format!("`{s}`: expected START_S..END_S, e.g. 120..150"))?;
    let num = |v: &str| {
        v.trim()
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("`{v}` is not a number of seconds"))
    };
    let (a, b) = (num(a)?, num(b)?);
    if b < a {
        return Err(format!("`{s}`: the end is before the start"));
    }
    Ok((a, b))
}

/// The error of line `line` of `path`.
fn line_error(path: &Path, line: usize) -> impl Fn(String) -> DatasetError + '_ {
    move |problem| DatasetError::AidingLine {
        path: path.to_path_buf(),
        line,
        problem,
    }
}

/// Whether time `t` lies in one of `spans` (`[start, end]`, seconds).
pub fn within(spans: &[(f64, f64)], t: f64) -> bool {
    spans.iter().any(|&(a, b)| t >= a && t <= b)
}

/// The position of an antenna at `lever_arm` (left camera frame) from the pose's
/// perspective centre: `C + M^T l`, the point a fix measures.
pub fn antenna_position(pose: &Pose, lever_arm: [f64; 3]) -> [f64; 3] {
    let l = pose.rotation().transpose() * nalgebra::Vector3::from(lever_arm);
    [0, 1, 2].map(|k| pose.centre[k] + l[k])
}

/// The fixes outside every span `[start, end]` of `outages` (seconds).
pub fn withhold(fixes: &[GnssFix], outages: &[(f64, f64)]) -> Vec<GnssFix> {
    fixes
        .iter()
        .filter(|f| !within(outages, f.time))
        .copied()
        .collect()
}

/// The GNSS position and sigma at time `t`: the fix at that time
/// ([`GNSS_SAME_TIME_S`]), or the linear interpolation of the two fixes around it
/// when they are at most [`GNSS_MAX_INTERPOLATION_S`] apart (sigma: the larger of
/// theirs). `fixes` in time order.
pub fn gnss_at(fixes: &[GnssFix], t: f64) -> Option<([f64; 3], f64)> {
    let i = fixes.partition_point(|f| f.time < t);
    let near = |f: &GnssFix| (f.time - t).abs() <= GNSS_SAME_TIME_S;
    let (before, after) = (i.checked_sub(1).map(|j| &fixes[j]), fixes.get(i));
    if let Some(f) = [before, after].into_iter().flatten().find(|f| near(f)) {
        return Some((f.position, f.sigma));
    }
    let (a, b) = (before?, after?);
    if b.time - a.time > GNSS_MAX_INTERPOLATION_S {
        return None;
    }
    let s = (t - a.time) / (b.time - a.time);
    let p = [0, 1, 2].map(|k| a.position[k] + s * (b.position[k] - a.position[k]));
    Some((p, a.sigma.max(b.sigma)))
}

/// The odometer's count at time `t`: the distance travelled since the first reading
/// and its sigma, interpolated linearly in time between readings (distance and
/// variance), when the readings span `t`. The traverse differences the counts of
/// consecutive window epochs. `readings` in time order.
pub fn odometer_at(readings: &[OdometerReading], t: f64) -> Option<(f64, f64)> {
    cumulative(readings, t).map(|(d, v)| (d, v.sqrt()))
}

/// Distance and variance accumulated from the first reading to time `t`.
fn cumulative(readings: &[OdometerReading], t: f64) -> Option<(f64, f64)> {
    let first = readings.first()?;
    let last = readings.last()?;
    if t < first.time - GNSS_SAME_TIME_S || t > last.time + GNSS_SAME_TIME_S {
        return None;
    }
    let (mut d, mut v) = (0.0, 0.0);
    for w in readings.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        if t >= b.time {
            d += b.distance;
            v += b.sigma * b.sigma;
        } else {
            let s = ((t - a.time) / (b.time - a.time)).max(0.0);
            d += s * b.distance;
            v += s * b.sigma * b.sigma;
            break;
        }
    }
    Some((d, v))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Writes `text` to `name` in `dir`, which the test owns and removes when it ends.
    fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> std::path::PathBuf {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn reads_fixes_and_names_the_bad_line() {
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str, text: &str| write(&dir, name, text);
        let p = write("gnss.txt", "# t X Y Z s\n0 0 0 0 0.02\n\n0.1 0 1 0 0.02\n");
        let f = read_gnss(&p).unwrap();
        assert_eq!(f.len(), 2);
        assert_eq!(f[1].position, [0.0, 1.0, 0.0]);
        let p = write("gnss2.txt", "0 0 0 0 0.02\n0.1 0 x 0 0.02\n");
        let e = read_gnss(&p).unwrap_err().to_string();
        assert!(e.contains("gnss2.txt: line 2") && e.contains("`x`"), "{e}");
        let p = write("gnss3.txt", "0 0 0 0 0.02\n0 0 1 0 0.02\n");
        let e = read_gnss(&p).unwrap_err().to_string();
        assert!(e.contains("line 2") && e.contains("not after"), "{e}");
        let p = write("gnss4.txt", "0 0 0 0\n");
        let e = read_gnss(&p).unwrap_err().to_string();
        assert!(e.contains("4 fields, expected 5"), "{e}");
        let p = write("odo.txt", "0 0 0.01\n1 -1 0.01\n");
        let e = read_odometer(&p).unwrap_err().to_string();
        assert!(e.contains("line 2") && e.contains("negative"), "{e}");
    }

    #[test]
    fn a_fix_at_the_epoch_or_an_interpolation_over_a_short_gap() {
        let fix = |t: f64, y: f64| GnssFix {
            time: t,
            position: [0.0, y, 0.0],
            sigma: 0.02,
        };
        let fixes = [fix(0.0, 0.0), fix(0.1, 1.0), fix(0.2, 2.0), fix(1.0, 10.0)];
        assert_eq!(gnss_at(&fixes, 0.1).unwrap().0, [0.0, 1.0, 0.0]);
        let (p, s) = gnss_at(&fixes, 0.15).unwrap();
        assert!((p[1] - 1.5).abs() < 1e-12 && s == 0.02);
        // 0.8 s between the fixes around 0.5 s: too long to interpolate.
        assert!(gnss_at(&fixes, 0.5).is_none());
        assert!(gnss_at(&fixes, 1.5).is_none());
        let kept = withhold(&fixes, &[(0.05, 0.25)]);
        assert_eq!(kept.len(), 2);
    }

    #[test]
    fn geodetic_fixes_land_in_the_object_frame() {
        let setup = GnssSetup {
            origin: Some([48.0, 11.0, 500.0]),
            heading_deg: 90.0,
            lever_arm_m: [0.0; 3],
        };
        // 100 m north of the origin, 2 m up: with +Y pointing east, north is -X.
        let lat = 48.0 + 100.0 / 111_200.0;
        let p = setup.to_object(lat, 11.0, 502.0).unwrap();
        assert!((p[0] + 100.0).abs() < 0.5 && p[1].abs() < 1e-6, "{p:?}");
        assert!((p[2] - 2.0).abs() < 0.01, "{p:?}");
        assert!(GnssSetup::default().to_object(lat, 11.0, 0.0).is_none());
        let dir = tempfile::tempdir().unwrap();
        let p = write(&dir, "gnss_geodetic.txt", "0 48 11 500 0.02\n");
        let e = read_gnss_geodetic(&p, &GnssSetup::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("origin"), "{e}");
        let f = read_gnss_geodetic(&p, &setup).unwrap();
        assert!(f[0].position.iter().all(|v| v.abs() < 1e-6), "{:?}", f[0]);
    }

    #[test]
    fn odometer_legs_add_up_with_their_variances() {
        let r = |t: f64, d: f64| OdometerReading {
            time: t,
            distance: d,
            sigma: 0.01,
        };
        let readings = [r(0.0, 0.0), r(1.0, 2.0), r(2.0, 2.0), r(3.0, 4.0)];
        let leg = |t0: f64, t1: f64| {
            let ((d0, s0), (d1, s1)) = (odometer_at(&readings, t0)?, odometer_at(&readings, t1)?);
            Some((d1 - d0, (s1 * s1 - s0 * s0).sqrt()))
        };
        let (d, s) = leg(1.0, 3.0).unwrap();
        assert!((d - 6.0).abs() < 1e-12);
        assert!((s - (2.0f64 * 1e-4).sqrt()).abs() < 1e-12);
        let (d, _) = leg(0.5, 1.5).unwrap();
        assert!((d - 2.0).abs() < 1e-12);
        assert!(odometer_at(&readings, 3.5).is_none());
        assert_eq!(odometer_at(&readings, 0.0), Some((0.0, 0.0)));
    }
}
