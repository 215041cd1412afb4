//! The photogrammetric rig file `rig.toml` (docs/conventions.md, "Dataset layouts"):
//! reading with clear errors and writing.
use super::aiding::GnssSetup;
use super::DatasetError;
use phototraverse_core::camera::{CameraError, DistortionModel, Interior, Pose, Rig};
use phototraverse_core::traverse::CalibrationPrecision;
use serde::{Deserialize, Serialize};
use std::path::Path;

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraToml {
    width_px: u32,
    height_px: u32,
    pixel_size_mm: [f64; 2],
    focal_mm: f64,
    principal_point_mm: [f64; 2],
    /// `[k1, k2]` or `[k1, k2, k3]`; absent for a camera without distortion.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    radial: Vec<f64>,
    #[serde(default, skip_serializing_if = "is_zero_pair")]
    decentering: [f64; 2],
    #[serde(default, skip_serializing_if = "is_correction")]
    distortion_model: DistortionModelToml,
}

/// `distortion_model`: which way `radial` and `decentering` act.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
enum DistortionModelToml {
    #[default]
    Correction,
    Projection,
}

fn is_zero_pair(v: &[f64; 2]) -> bool {
    *v == [0.0; 2]
}

fn is_correction(m: &DistortionModelToml) -> bool {
    *m == DistortionModelToml::Correction
}

impl From<DistortionModelToml> for DistortionModel {
    fn from(m: DistortionModelToml) -> Self {
        match m {
            DistortionModelToml::Correction => DistortionModel::Correction,
            DistortionModelToml::Projection => DistortionModel::Projection,
        }
    }
}

impl From<DistortionModel> for DistortionModelToml {
    fn from(m: DistortionModel) -> Self {
        match m {
            DistortionModel::Correction => DistortionModelToml::Correction,
            DistortionModel::Projection => DistortionModelToml::Projection,
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RelativeToml {
    omega_deg: f64,
    phi_deg: f64,
    kappa_deg: f64,
    base_mm: [f64; 3],
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct DatumToml {
    omega_deg: f64,
    phi_deg: f64,
    kappa_deg: f64,
    position_m: [f64; 3],
}

/// `[precision]`: the calibration's standard deviations; a key left out keeps the
/// unstated value ([`CalibrationPrecision::UNSTATED`]).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct PrecisionToml {
    principal_point_px: f64,
    /// Relative: 0.001 is 0.1 % of the focal length.
    focal_relative: f64,
    angles_deg: f64,
    base_mm: f64,
}

impl Default for PrecisionToml {
    fn default() -> Self {
        let u = CalibrationPrecision::UNSTATED;
        PrecisionToml {
            principal_point_px: u.principal_point_px,
            focal_relative: u.focal,
            angles_deg: u.angles_rad.to_degrees(),
            base_mm: u.base_m * 1e3,
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RigToml {
    left: CameraToml,
    right: CameraToml,
    right_from_left: RelativeToml,
    #[serde(skip_serializing_if = "Option::is_none")]
    datum: Option<DatumToml>,
    #[serde(skip_serializing_if = "Option::is_none")]
    precision: Option<PrecisionToml>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    gnss: Option<GnssSetup>,
}

/// What `rig.toml` states: the rig, the datum, the calibration's precision and the
/// GNSS setup.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigFile {
    pub rig: Rig,
    pub datum: Pose,
    pub precision: CalibrationPrecision,
    /// The `[gnss]` table, when stated.
    pub gnss: Option<GnssSetup>,
}

/// The default datum: a level camera looking along +Y at the origin.
pub fn default_datum() -> Pose {
    Pose::from_degrees(90.0, 0.0, 0.0, [0.0; 3])
}

fn camera_from(c: &CameraToml, name: &'static str, path: &Path) -> Result<Interior, DatasetError> {
    let bad = |problem: String| DatasetError::BadCamera {
        path: path.to_path_buf(),
        camera: name,
        problem,
    };
    if c.focal_mm.is_nan() || c.focal_mm <= 0.0 {
        return Err(bad(format!(
            "non-positive focal length focal_mm = {}",
            c.focal_mm
        )));
    }
    if c.width_px == 0 || c.height_px == 0 {
        return Err(bad(format!(
            "image size {}x{} must be positive",
            c.width_px, c.height_px
        )));
    }
    if !(c.pixel_size_mm[0] > 0.0 && c.pixel_size_mm[1] > 0.0) {
        return Err(bad(format!(
            "pixel_size_mm = {:?} must be positive",
            c.pixel_size_mm
        )));
    }
    if c.radial.len() == 1 || c.radial.len() > 3 {
        return Err(bad(format!(
            "radial has {} terms; it takes [k1, k2] or [k1, k2, k3]",
            c.radial.len()
        )));
    }
    let mut radial = [0.0; 3];
    radial[..c.radial.len()].copy_from_slice(&c.radial);
    let cam = Interior {
        width_px: c.width_px,
        height_px: c.height_px,
        pixel_size_mm: c.pixel_size_mm,
        focal_mm: c.focal_mm,
        principal_point_mm: c.principal_point_mm,
        radial,
        decentering: c.decentering,
        distortion_model: c.distortion_model.into(),
    };
    cam.validate().map_err(|e| match e {
        CameraError::DistortionDiverged => bad(
            "the distortion (radial, decentering) cannot be undone everywhere on the \
             image: it folds the format over itself"
                .into(),
        ),
        e => bad(e.to_string()),
    })?;
    Ok(cam)
}

fn camera_to(c: &Interior) -> CameraToml {
    CameraToml {
        width_px: c.width_px,
        height_px: c.height_px,
        pixel_size_mm: c.pixel_size_mm,
        focal_mm: c.focal_mm,
        principal_point_mm: c.principal_point_mm,
        radial: match c.radial {
            [0.0, 0.0, 0.0] => Vec::new(),
            [k1, k2, 0.0] => vec![k1, k2],
            k => k.to_vec(),
        },
        decentering: c.decentering,
        distortion_model: c.distortion_model.into(),
    }
}

/// Parses rig.toml text; `path` names the file in errors.
pub fn parse_rig(text: &str, path: &Path) -> Result<(Rig, Pose), DatasetError> {
    parse_rig_file(text, path).map(|f| (f.rig, f.datum))
}

/// A TOML error on one line. toml's message names the missing or bad key and its
/// table, e.g. "missing field `focal_mm`" in `left`.
pub(super) fn toml_problem(e: &toml::de::Error) -> String {
    e.to_string()
        .lines()
        .filter(|l| !l.trim().is_empty())
        .collect::<Vec<_>>()
        .join(" | ")
}

/// Parses rig.toml text, the calibration's precision included.
pub fn parse_rig_file(text: &str, path: &Path) -> Result<RigFile, DatasetError> {
    let file: RigToml = toml::from_str(text).map_err(|e| DatasetError::RigFile {
        path: path.to_path_buf(),
        problem: toml_problem(&e),
    })?;
    let left = camera_from(&file.left, "left", path)?;
    let right = camera_from(&file.right, "right", path)?;
    let rel = &file.right_from_left;
    let rig = Rig {
        left,
        right,
        relative_angles: [
            rel.omega_deg.to_radians(),
            rel.phi_deg.to_radians(),
            rel.kappa_deg.to_radians(),
        ],
        base_m: [
            rel.base_mm[0] * 1e-3,
            rel.base_mm[1] * 1e-3,
            rel.base_mm[2] * 1e-3,
        ],
    };
    rig.validate().map_err(|e| DatasetError::RigFile {
        path: path.to_path_buf(),
        problem: format!("right_from_left: {e}"),
    })?;
    if rig.base_length().is_nan() || rig.base_length() <= 0.0 {
        return Err(DatasetError::RigFile {
            path: path.to_path_buf(),
            problem: "right_from_left: base_mm is zero".into(),
        });
    }
    let datum = match &file.datum {
        None => default_datum(),
        Some(d) => {
            let pose = Pose::from_degrees(d.omega_deg, d.phi_deg, d.kappa_deg, d.position_m);
            if !pose.to_params().iter().all(|v| v.is_finite()) {
                return Err(DatasetError::RigFile {
                    path: path.to_path_buf(),
                    problem: "datum: value not finite".into(),
                });
            }
            pose
        }
    };
    let precision = match &file.precision {
        None => CalibrationPrecision::UNSTATED,
        Some(p) => {
            let c = CalibrationPrecision {
                principal_point_px: p.principal_point_px,
                focal: p.focal_relative,
                angles_rad: p.angles_deg.to_radians(),
                base_m: p.base_mm * 1e-3,
            };
            if !c.valid() {
                return Err(DatasetError::RigFile {
                    path: path.to_path_buf(),
                    problem: "precision: every value must be positive and finite".into(),
                });
            }
            c
        }
    };
    let gnss = file.gnss.map(|g| g.validated(path)).transpose()?;
    Ok(RigFile {
        rig,
        datum,
        precision,
        gnss,
    })
}

/// Reads `rig.toml`.
pub fn read_rig(path: &Path) -> Result<(Rig, Pose), DatasetError> {
    read_rig_file(path).map(|f| (f.rig, f.datum))
}

/// Reads `rig.toml`, the calibration's precision included.
pub fn read_rig_file(path: &Path) -> Result<RigFile, DatasetError> {
    let text = std::fs::read_to_string(path).map_err(|source| DatasetError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_rig_file(&text, path)
}

/// rig.toml text of a rig and datum (full precision, read back exactly up to
/// the degree/radian and mm/m conversions).
pub fn rig_toml_text(rig: &Rig, datum: &Pose) -> String {
    let [w, p, k] = rig.relative_angles;
    let file = RigToml {
        left: camera_to(&rig.left),
        right: camera_to(&rig.right),
        right_from_left: RelativeToml {
            omega_deg: w.to_degrees(),
            phi_deg: p.to_degrees(),
            kappa_deg: k.to_degrees(),
            base_mm: [
                rig.base_m[0] * 1e3,
                rig.base_m[1] * 1e3,
                rig.base_m[2] * 1e3,
            ],
        },
        datum: Some(DatumToml {
            omega_deg: datum.omega.to_degrees(),
            phi_deg: datum.phi.to_degrees(),
            kappa_deg: datum.kappa.to_degrees(),
            position_m: datum.centre,
        }),
        precision: None,
        gnss: None,
    };
    let body = toml::to_string(&file).unwrap_or_default();
    format!("# phototraverse rig file (docs/conventions.md, Dataset layouts)\n{body}")
}

/// Writes `rig.toml`.
pub fn write_rig(path: &Path, rig: &Rig, datum: &Pose) -> Result<(), DatasetError> {
    std::fs::write(path, rig_toml_text(rig, datum)).map_err(|source| DatasetError::Io {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) const SEED_RIG: &str = r#"
[left]
width_px = 576
height_px = 384
pixel_size_mm = [0.0387, 0.0387]
focal_mm = 34.6041
principal_point_mm = [0.4171, -0.3096]
radial = [-3.3147e-05, 1.30582e-07]
decentering = [9.086e-05, -7.7278e-05]
[right]
width_px = 576
height_px = 384
pixel_size_mm = [0.0387, 0.0387]
focal_mm = 35.1727
principal_point_mm = [0.2309, -0.1701]
radial = [-3.7141e-05, 1.77645e-07]
decentering = [7.00283e-05, -1.4916e-05]
[right_from_left]
omega_deg = 0.0
phi_deg = -0.3
kappa_deg = 0.0
base_mm = [400.0, 0.0, 0.0]
"#;

    #[test]
    fn reads_the_design_example() {
        let (rig, datum) = parse_rig(SEED_RIG, Path::new("rig.toml")).unwrap();
        assert_eq!(rig.left.focal_mm, 34.6041);
        assert_eq!(rig.right.decentering, [7.00283e-05, -1.4916e-05]);
        assert!((rig.base_length() - 0.4).abs() < 1e-15);
        assert!((rig.relative_angles[1] - (-0.3f64).to_radians()).abs() < 1e-15);
        assert_eq!(datum, default_datum());
    }

    #[test]
    fn write_read_round_trip() {
        let (rig, _) = parse_rig(SEED_RIG, Path::new("rig.toml")).unwrap();
        let datum = Pose::from_degrees(90.5, -0.25, 1.0, [1.0, 2.0, 1.65]);
        let (back, d) = parse_rig(&rig_toml_text(&rig, &datum), Path::new("x")).unwrap();
        assert_eq!(back.left, rig.left);
        assert_eq!(back.right, rig.right);
        for i in 0..3 {
            assert!((back.relative_angles[i] - rig.relative_angles[i]).abs() < 1e-15);
            assert!((back.base_m[i] - rig.base_m[i]).abs() < 1e-15);
        }
        assert!((d.omega - datum.omega).abs() < 1e-15 && d.centre == datum.centre);
    }

    #[test]
    fn precision_is_read_per_key_with_the_unstated_values_for_the_rest() {
        let f = parse_rig_file(SEED_RIG, Path::new("rig.toml")).unwrap();
        assert_eq!(f.precision, CalibrationPrecision::UNSTATED);
        let text = format!("{SEED_RIG}[precision]\nprincipal_point_px = 0.3\nangles_deg = 0.01\n");
        let p = parse_rig_file(&text, Path::new("rig.toml"))
            .unwrap()
            .precision;
        assert_eq!(p.principal_point_px, 0.3);
        assert!((p.angles_rad - 0.01f64.to_radians()).abs() < 1e-18);
        assert_eq!(p.focal, CalibrationPrecision::UNSTATED.focal);
        assert!((p.base_m - CalibrationPrecision::UNSTATED.base_m).abs() < 1e-18);
        let bad = format!("{SEED_RIG}[precision]\nfocal_relative = -0.001\n");
        let e = parse_rig_file(&bad, Path::new("r/rig.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("r/rig.toml") && e.contains("precision"), "{e}");
        let unknown = format!("{SEED_RIG}[precision]\nfocal_pct = 0.1\n");
        let e = parse_rig_file(&unknown, Path::new("rig.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("focal_pct"), "{e}");
    }

    #[test]
    fn missing_key_is_named() {
        let text = SEED_RIG.replacen("focal_mm = 34.6041\n", "", 1);
        let e = parse_rig(&text, Path::new("d/rig.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("d/rig.toml") && e.contains("focal_mm") && e.contains("missing"),
            "{e}"
        );
        let text = SEED_RIG.replacen("[right_from_left]", "[other]", 1);
        let e = parse_rig(&text, Path::new("rig.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("other") || e.contains("right_from_left"), "{e}");
    }

    #[test]
    fn non_positive_focal_is_rejected() {
        let text = SEED_RIG.replacen("focal_mm = 35.1727", "focal_mm = 0.0", 1);
        let e = parse_rig(&text, Path::new("rig.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("right camera") && e.contains("non-positive focal length"),
            "{e}"
        );
    }

    #[test]
    fn bad_values_are_rejected() {
        let text = SEED_RIG.replacen("focal_mm = 34.6041", "focal_mm = \"x\"", 1);
        let e = parse_rig(&text, Path::new("rig.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("focal_mm") || e.contains("invalid type"), "{e}");
        let text = SEED_RIG.replacen(
            "base_mm = [400.0, 0.0, 0.0]",
            "base_mm = [0.0, 0.0, 0.0]",
            1,
        );
        let e = parse_rig(&text, Path::new("rig.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("base_mm is zero"), "{e}");
    }

    #[test]
    fn a_pinhole_needs_no_distortion_keys_and_a_third_radial_term_round_trips() {
        let pinhole = SEED_RIG
            .lines()
            .filter(|l| !l.starts_with("radial") && !l.starts_with("decentering"))
            .collect::<Vec<_>>()
            .join("\n");
        let (rig, _) = parse_rig(&pinhole, Path::new("rig.toml")).unwrap();
        assert!(rig.left.is_distortion_free() && rig.right.is_distortion_free());
        assert_eq!(rig.left.distortion_model, DistortionModel::Correction);

        let k3 = SEED_RIG.replacen(
            "radial = [-3.3147e-05, 1.30582e-07]",
            "radial = [-3.3147e-05, 1.30582e-07, -2e-10]\ndistortion_model = \"projection\"",
            1,
        );
        let (rig, datum) = parse_rig(&k3, Path::new("rig.toml")).unwrap();
        assert_eq!(rig.left.radial[2], -2e-10);
        assert_eq!(rig.left.distortion_model, DistortionModel::Projection);
        assert_eq!(rig.right.distortion_model, DistortionModel::Correction);
        let (back, _) = parse_rig(&rig_toml_text(&rig, &datum), Path::new("x")).unwrap();
        assert_eq!(back.left, rig.left);
        assert_eq!(back.right, rig.right);

        let four = SEED_RIG.replacen("1.30582e-07]", "1.30582e-07, 0.0, 1.0]", 1);
        let e = parse_rig(&four, Path::new("rig.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("radial has 4 terms"), "{e}");
        let folded = SEED_RIG.replacen("1.30582e-07]", "1.30582e-07, -1e-4]", 1);
        let e = parse_rig(&folded, Path::new("rig.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("left camera") && e.contains("folds the format"),
            "{e}"
        );
    }
}
