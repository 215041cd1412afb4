//! Stereo calibrations made by other tools, brought to the photogrammetric rig
//! (docs/conventions.md, "Calibrations from OpenCV and Kalibr"):
//!
//! - OpenCV's FileStorage, YAML or XML, as `stereoCalibrate` users save it: camera
//!   matrices `M1`/`M2` (or `K1`/`K2`, `cameraMatrix1`/`cameraMatrix2`), distortion
//!   `D1`/`D2` (or `distCoeffs1`/`distCoeffs2`), `R`, `T` and the image size;
//! - Kalibr's camchain YAML: `cam0`, `cam1`, ... with `pinhole` cameras, `radtan`
//!   distortion and `T_cn_cnm1`.
//!
//! Both describe pixel cameras (`fx, fy, cx, cy`) whose distortion maps ideal
//! normalised coordinates to measured ones; [`PixelStereo::to_rig`] states them
//! exactly in the photogrammetric model with [`DistortionModel::Projection`].
use nalgebra::{Matrix3, Vector3};
use phototraverse_core::camera::{angles_from_rotation, DistortionModel, Interior, Rig};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// A calibration file that cannot be read, with the field at fault.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {problem}")]
pub struct CalibrationError {
    pub path: PathBuf,
    pub problem: String,
}

/// One camera as OpenCV and Kalibr state it: pixels, the top-left pixel's centre at
/// `(0, 0)`, distortion `[k1, k2, k3]`, `[p1, p2]` of ideal normalised coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelCamera {
    pub width_px: u32,
    pub height_px: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub radial: [f64; 3],
    pub tangential: [f64; 2],
}

/// A stereo calibration in the computer-vision convention: a point `X` in the left
/// camera's frame (x right, y down, z forward) is `R X + T` in the right one's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelStereo {
    pub left: PixelCamera,
    pub right: PixelCamera,
    pub rotation: Matrix3<f64>,
    /// `T`, metres.
    pub translation_m: Vector3<f64>,
}

/// Which tool wrote the calibration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CalibrationFormat {
    /// OpenCV FileStorage (YAML or XML) from `stereoCalibrate`.
    Opencv,
    /// Kalibr's camchain YAML.
    Kalibr,
}

/// The computer-vision camera frame (y down, z forward) to the photogrammetric one
/// (y up, z backward, the camera looking along -z).
fn flip() -> Matrix3<f64> {
    Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0))
}

impl PixelCamera {
    /// The photogrammetric interior orientation with pixel size `pixel_mm` in x
    /// (y follows from `fx / fy`): the same projection, exactly.
    pub fn to_interior(&self, pixel_mm: f64) -> Interior {
        let sx = pixel_mm;
        let sy = pixel_mm * self.fx / self.fy;
        let f = self.fx * sx;
        let cc = (self.width_px as f64 - 1.0) * 0.5;
        let rc = (self.height_px as f64 - 1.0) * 0.5;
        let [k1, k2, k3] = self.radial;
        let [p1, p2] = self.tangential;
        // Reduced photo-coordinates are f times the normalised ones, y flipped: the
        // powers of r take powers of f, and the flip swaps and signs p1, p2.
        Interior {
            width_px: self.width_px,
            height_px: self.height_px,
            pixel_size_mm: [sx, sy],
            focal_mm: f,
            principal_point_mm: [(self.cx - cc) * sx, -(self.cy - rc) * sy],
            radial: [k1 / f.powi(2), k2 / f.powi(4), k3 / f.powi(6)],
            decentering: [p2 / f, -p1 / f],
            distortion_model: DistortionModel::Projection,
        }
    }
}

impl PixelStereo {
    /// The rig: `Mrel = F R F` and `b = -F R^T T` with `F = diag(1, -1, -1)`.
    pub fn to_rig(&self, pixel_mm: f64) -> Rig {
        let f = flip();
        let mrel = f * self.rotation * f;
        let base = -(f * self.rotation.transpose() * self.translation_m);
        Rig {
            left: self.left.to_interior(pixel_mm),
            right: self.right.to_interior(pixel_mm),
            relative_angles: angles_from_rotation(&mrel),
            base_m: [base[0], base[1], base[2]],
        }
    }
}

/// A value of a calibration file: a matrix, a list or a number.
#[derive(Debug, Clone, PartialEq)]
enum Value {
    Matrix {
        rows: usize,
        cols: usize,
        data: Vec<f64>,
    },
    Numbers(Vec<f64>),
}

impl Value {
    fn numbers(&self) -> &[f64] {
        match self {
            Value::Matrix { data, .. } => data,
            Value::Numbers(v) => v,
        }
    }
}

/// The named values of one or more calibration files, with the file each came from.
struct Fields {
    values: HashMap<String, (Value, PathBuf)>,
    first: PathBuf,
}

impl Fields {
    fn error(&self, problem: String) -> CalibrationError {
        CalibrationError {
            path: self.first.clone(),
            problem,
        }
    }

    /// The first of `names` present.
    fn any(&self, names: &[&str]) -> Option<(&Value, &Path)> {
        names
            .iter()
            .find_map(|n| self.values.get(*n))
            .map(|(v, p)| (v, p.as_path()))
    }

    fn require(&self, names: &[&str]) -> Result<(&Value, &Path), CalibrationError> {
        self.any(names)
            .ok_or_else(|| self.error(format!("no {} in the calibration", names.join(" or "))))
    }

    /// A matrix of `rows x cols` finite numbers under one of `names` (a vector may be
    /// stated as a row or a column), and the file it came from.
    fn matrix(
        &self,
        names: &[&str],
        rows: usize,
        cols: usize,
    ) -> Result<(Vec<f64>, PathBuf), CalibrationError> {
        let (value, path) = self.require(names)?;
        let bad = |problem: String| CalibrationError {
            path: path.to_path_buf(),
            problem: format!("{}: {problem}", names[0]),
        };
        let data = value.numbers();
        let shape_ok = match value {
            Value::Matrix {
                rows: r, cols: c, ..
            } => (*r, *c) == (rows, cols) || (rows.min(cols) == 1 && r * c == rows * cols),
            Value::Numbers(_) => true,
        };
        if !shape_ok || data.len() != rows * cols {
            return Err(bad(format!(
                "must be a {rows}x{cols} matrix, found {} values",
                data.len()
            )));
        }
        if let Some(v) = data.iter().find(|v| !v.is_finite()) {
            return Err(bad(format!("holds the non-finite value {v}")));
        }
        Ok((data.to_vec(), path.to_path_buf()))
    }
}

fn read_text(path: &Path) -> Result<String, CalibrationError> {
    std::fs::read_to_string(path).map_err(|e| CalibrationError {
        path: path.to_path_buf(),
        problem: e.to_string(),
    })
}

fn is_xml(text: &str) -> bool {
    text.trim_start().starts_with('<')
}

/// OpenCV's YAML: a `%YAML:1.0` directive YAML 1.2 parsers refuse, then a mapping
/// whose matrices are tagged `!!opencv-matrix` with `rows`, `cols`, `data`.
fn yaml_document(text: &str, path: &Path) -> Result<yaml_rust2::Yaml, CalibrationError> {
    let body: String = text
        .lines()
        .filter(|l| !l.starts_with('%'))
        .collect::<Vec<_>>()
        .join("\n");
    let mut docs = yaml_rust2::YamlLoader::load_from_str(&body).map_err(|e| CalibrationError {
        path: path.to_path_buf(),
        problem: format!("not YAML: {e}"),
    })?;
    if docs.is_empty() {
        return Err(CalibrationError {
            path: path.to_path_buf(),
            problem: "empty file".into(),
        });
    }
    Ok(docs.swap_remove(0))
}

fn yaml_number(y: &yaml_rust2::Yaml) -> Option<f64> {
    match y {
        yaml_rust2::Yaml::Real(s) => s.parse().ok(),
        yaml_rust2::Yaml::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

fn yaml_numbers(y: &yaml_rust2::Yaml) -> Option<Vec<f64>> {
    match y {
        yaml_rust2::Yaml::Array(items) => items
            .iter()
            .map(|i| match i {
                yaml_rust2::Yaml::Array(_) => yaml_numbers(i),
                _ => yaml_number(i).map(|v| vec![v]),
            })
            .collect::<Option<Vec<_>>>()
            .map(|v| v.concat()),
        _ => yaml_number(y).map(|v| vec![v]),
    }
}

fn yaml_value(y: &yaml_rust2::Yaml) -> Option<Value> {
    if let Some(data) = y["data"].as_vec().and(yaml_numbers(&y["data"])) {
        let rows = y["rows"].as_i64()? as usize;
        let cols = y["cols"].as_i64()? as usize;
        return Some(Value::Matrix { rows, cols, data });
    }
    yaml_numbers(y).map(Value::Numbers)
}

fn xml_fields(text: &str, path: &Path) -> Result<Vec<(String, Value)>, CalibrationError> {
    let doc = roxmltree::Document::parse(text).map_err(|e| CalibrationError {
        path: path.to_path_buf(),
        problem: format!("not XML: {e}"),
    })?;
    let numbers =
        |s: &str| -> Option<Vec<f64>> { s.split_whitespace().map(|t| t.parse().ok()).collect() };
    let child = |n: roxmltree::Node, name: &str| {
        n.children()
            .find(|c| c.has_tag_name(name))
            .and_then(|c| c.text())
            .map(str::trim)
            .map(str::to_owned)
    };
    let mut out = Vec::new();
    for node in doc.root_element().children().filter(|n| n.is_element()) {
        let name = node.tag_name().name().to_string();
        let value = if node.attribute("type_id") == Some("opencv-matrix") {
            let (rows, cols, data) = (
                child(node, "rows"),
                child(node, "cols"),
                child(node, "data"),
            );
            match (rows, cols, data) {
                (Some(r), Some(c), Some(d)) => match (r.parse(), c.parse(), numbers(&d)) {
                    (Ok(rows), Ok(cols), Some(data)) => Some(Value::Matrix { rows, cols, data }),
                    _ => None,
                },
                _ => None,
            }
        } else {
            node.text().and_then(numbers).map(Value::Numbers)
        };
        // A value that does not read stays, empty, so that the error names it.
        out.push((name, value.unwrap_or(Value::Numbers(Vec::new()))));
    }
    Ok(out)
}

fn opencv_fields(paths: &[PathBuf]) -> Result<Fields, CalibrationError> {
    let mut values = HashMap::new();
    for path in paths {
        let text = read_text(path)?;
        let fields = if is_xml(&text) {
            xml_fields(&text, path)?
        } else {
            let doc = yaml_document(&text, path)?;
            doc.as_hash()
                .map(|h| {
                    h.iter()
                        .filter_map(|(k, v)| {
                            // A value that does not read stays, empty, so that the
                            // error names it.
                            let value = yaml_value(v).unwrap_or(Value::Numbers(Vec::new()));
                            Some((k.as_str()?.to_string(), value))
                        })
                        .collect()
                })
                .unwrap_or_default()
        };
        for (name, value) in fields {
            values.insert(name, (value, path.clone()));
        }
    }
    Ok(Fields {
        values,
        first: paths.first().cloned().unwrap_or_default(),
    })
}

/// OpenCV's distortion vector: `k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 [tx ty]]]]`.
/// The terms past k3 (rational, thin prism, tilt) have no place in the model and
/// must be zero.
fn opencv_distortion(
    d: &[f64],
    name: &str,
    path: &Path,
) -> Result<([f64; 3], [f64; 2]), CalibrationError> {
    let bad = |problem: String| CalibrationError {
        path: path.to_path_buf(),
        problem,
    };
    if ![4, 5, 8, 12, 14].contains(&d.len()) || d.iter().any(|v| !v.is_finite()) {
        return Err(bad(format!(
            "{name} must hold 4, 5, 8, 12 or 14 finite coefficients, found {}",
            d.len()
        )));
    }
    if d.iter().skip(5).any(|v| *v != 0.0) {
        return Err(bad(format!(
            "{name} uses OpenCV's rational, thin-prism or tilt terms (beyond k3); \
             calibrate without CALIB_RATIONAL_MODEL, CALIB_THIN_PRISM_MODEL and \
             CALIB_TILTED_MODEL"
        )));
    }
    let k3 = d.get(4).copied().unwrap_or(0.0);
    Ok(([d[0], d[1], k3], [d[2], d[3]]))
}

fn opencv_camera(
    fields: &Fields,
    matrix: &[&str],
    distortion: &[&str],
    size: (u32, u32),
) -> Result<PixelCamera, CalibrationError> {
    let (k, k_path) = fields.matrix(matrix, 3, 3)?;
    let (d, path) = fields.require(distortion)?;
    let (radial, tangential) = opencv_distortion(d.numbers(), distortion[0], path)?;
    let bad = |problem: String| CalibrationError {
        path: k_path.clone(),
        problem: format!("{}: {problem}", matrix[0]),
    };
    if k[1] != 0.0 {
        return Err(bad(format!(
            "has a skew term ({}): the photogrammetric model has none",
            k[1]
        )));
    }
    if k[3] != 0.0 || k[6..] != [0.0, 0.0, 1.0] {
        return Err(bad(
            "is not a camera matrix [fx 0 cx; 0 fy cy; 0 0 1]".into()
        ));
    }
    camera(size, [k[0], k[4], k[2], k[5]], radial, tangential).map_err(bad)
}

fn camera(
    (width_px, height_px): (u32, u32),
    [fx, fy, cx, cy]: [f64; 4],
    radial: [f64; 3],
    tangential: [f64; 2],
) -> Result<PixelCamera, String> {
    if !(fx > 0.0 && fy > 0.0 && fx.is_finite() && fy.is_finite()) {
        return Err(format!(
            "focal lengths fx = {fx}, fy = {fy} must be positive"
        ));
    }
    if width_px == 0 || height_px == 0 {
        return Err(format!(
            "image size {width_px}x{height_px} must be positive"
        ));
    }
    Ok(PixelCamera {
        width_px,
        height_px,
        fx,
        fy,
        cx,
        cy,
        radial,
        tangential,
    })
}

/// A pixel count: a positive integer.
fn pixels(v: f64) -> Option<u32> {
    (v >= 1.0 && v <= u32::MAX as f64 && v.fract() == 0.0).then_some(v as u32)
}

/// The image size: `image_width`/`image_height` or `imageSize`, else `size`.
fn opencv_size(fields: &Fields, size: Option<(u32, u32)>) -> Result<(u32, u32), CalibrationError> {
    let single = |names: &[&str]| {
        fields
            .any(names)
            .map(|(v, _)| v.numbers().first().copied().unwrap_or(f64::NAN))
    };
    let stated = match (
        single(&["image_width", "width"]),
        single(&["image_height", "height"]),
    ) {
        (Some(w), Some(h)) => Some([w, h]),
        _ => fields
            .any(&["imageSize", "image_size"])
            .map(|(v, _)| match v.numbers() {
                [w, h] => [*w, *h],
                _ => [f64::NAN; 2],
            }),
    };
    match stated {
        Some([w, h]) => match (pixels(w), pixels(h)) {
            (Some(w), Some(h)) => Ok((w, h)),
            _ => Err(fields.error(format!(
                "image size {w} x {h}: width and height must be positive integers"
            ))),
        },
        None => size.ok_or_else(|| {
            fields.error(
                "no image size (image_width and image_height, or imageSize): give --size WxH"
                    .into(),
            )
        }),
    }
}

/// Reads OpenCV FileStorage files (YAML or XML; an intrinsics and an extrinsics file
/// may be given together). `T` is in the units of the calibration target;
/// `translation_unit_m` is that unit in metres.
pub fn read_opencv(
    paths: &[PathBuf],
    translation_unit_m: f64,
    size: Option<(u32, u32)>,
) -> Result<PixelStereo, CalibrationError> {
    let fields = opencv_fields(paths)?;
    let size = opencv_size(&fields, size)?;
    let left = opencv_camera(
        &fields,
        &["M1", "K1", "cameraMatrix1"],
        &["D1", "distCoeffs1"],
        size,
    )?;
    let right = opencv_camera(
        &fields,
        &["M2", "K2", "cameraMatrix2"],
        &["D2", "distCoeffs2"],
        size,
    )?;
    let (r, r_path) = fields.matrix(&["R"], 3, 3)?;
    let (t, _) = fields.matrix(&["T"], 3, 1)?;
    stereo(left, right, &r, &t, translation_unit_m).map_err(|problem| CalibrationError {
        path: r_path,
        problem,
    })
}

fn stereo(
    left: PixelCamera,
    right: PixelCamera,
    r: &[f64],
    t: &[f64],
    unit_m: f64,
) -> Result<PixelStereo, String> {
    let rotation = Matrix3::from_row_slice(r);
    let orthonormal = (rotation.transpose() * rotation - Matrix3::identity())
        .abs()
        .max()
        < 1e-6
        && rotation.determinant() > 0.0;
    if !orthonormal {
        return Err("R is not a rotation (orthonormal, determinant +1)".into());
    }
    let translation_m = Vector3::new(t[0], t[1], t[2]) * unit_m;
    if translation_m.norm() == 0.0 {
        return Err("T is zero: the cameras share a centre".into());
    }
    Ok(PixelStereo {
        left,
        right,
        rotation,
        translation_m,
    })
}

/// Reads a Kalibr camchain: cameras `cam{first}` and `cam{second}`, `first <
/// second`, the transformation between them chained from the `T_cn_cnm1` of the
/// cameras after `first`.
pub fn read_kalibr(
    path: &Path,
    first: usize,
    second: usize,
) -> Result<PixelStereo, CalibrationError> {
    let err = |problem: String| CalibrationError {
        path: path.to_path_buf(),
        problem,
    };
    if first >= second {
        return Err(err(format!(
            "--cameras {first},{second}: the first must come before the second"
        )));
    }
    let doc = yaml_document(&read_text(path)?, path)?;
    let cam = |i: usize| -> Result<PixelCamera, CalibrationError> {
        let c = &doc[format!("cam{i}").as_str()];
        if c.is_badvalue() {
            return Err(err(format!("no cam{i} in the camchain")));
        }
        let model = c["camera_model"].as_str().unwrap_or("pinhole");
        if model != "pinhole" {
            return Err(err(format!(
                "cam{i}: camera_model {model} is not supported (pinhole only)"
            )));
        }
        let distortion = c["distortion_model"].as_str().unwrap_or("none");
        let coeffs = yaml_numbers(&c["distortion_coeffs"]).unwrap_or_default();
        let (radial, tangential) = match (distortion, coeffs.as_slice()) {
            ("radtan", [k1, k2, p1, p2]) => ([*k1, *k2, 0.0], [*p1, *p2]),
            ("none", []) => ([0.0; 3], [0.0; 2]),
            (m, c) => {
                return Err(err(format!(
                    "cam{i}: distortion_model {m} with {} coefficients is not supported \
                     (radtan with k1, k2, r1, r2, or none)",
                    c.len()
                )))
            }
        };
        let intrinsics = yaml_numbers(&c["intrinsics"]).unwrap_or_default();
        let resolution = yaml_numbers(&c["resolution"]).unwrap_or_default();
        let (Ok(k), [w, h]) = (
            <[f64; 4]>::try_from(intrinsics.as_slice()),
            resolution.as_slice(),
        ) else {
            return Err(err(format!(
                "cam{i}: intrinsics must be [fu, fv, pu, pv] and resolution [width, height]"
            )));
        };
        let (Some(w), Some(h)) = (pixels(*w), pixels(*h)) else {
            return Err(err(format!(
                "cam{i}: resolution must be two positive integers"
            )));
        };
        camera((w, h), k, radial, tangential).map_err(|p| err(format!("cam{i}: {p}")))
    };
    let left = cam(first)?;
    let right = cam(second)?;
    let mut chain = nalgebra::Matrix4::<f64>::identity();
    for i in first + 1..=second {
        let t = yaml_numbers(&doc[format!("cam{i}").as_str()]["T_cn_cnm1"])
            .filter(|t| t.len() == 16 && t.iter().all(|v| v.is_finite()))
            .ok_or_else(|| err(format!("cam{i}: T_cn_cnm1 must be a 4x4 matrix")))?;
        chain = nalgebra::Matrix4::from_row_slice(&t) * chain;
    }
    let r: Vec<f64> = (0..3)
        .flat_map(|i| (0..3).map(move |j| (i, j)))
        .map(|(i, j)| chain[(i, j)])
        .collect();
    let t = [chain[(0, 3)], chain[(1, 3)], chain[(2, 3)]];
    stereo(left, right, &r, &t, 1.0).map_err(err)
}

/// Tells the two formats apart: a camchain has `cam0`.
pub fn detect_format(path: &Path) -> Result<CalibrationFormat, CalibrationError> {
    let text = read_text(path)?;
    if is_xml(&text) {
        return Ok(CalibrationFormat::Opencv);
    }
    let doc = yaml_document(&text, path)?;
    Ok(if doc["cam0"].is_badvalue() {
        CalibrationFormat::Opencv
    } else {
        CalibrationFormat::Kalibr
    })
}
