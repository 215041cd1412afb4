//! KITTI odometry calibration (`calib.txt`) to a photogrammetric rig.
//!
//! docs/conventions.md, "Dataset layouts": pixel units serve as photo units, `sx = 1`,
//! `sy = fx/fy`, `f = fx`, `x0 = cx - (W-1)/2`, `y0 = -(cy - (H-1)/2) sy`, no
//! distortion, base `B = -P1[0][3] / fx` along x.
use super::DatasetError;
use phototraverse_core::camera::{DistortionModel, Interior, Rig};
use phototraverse_core::traverse::CalibrationPrecision;

/// The precision a KITTI `calib.txt` is taken to have: it states none, and its
/// rectification leaves no relative orientation to state, so the unstated values
/// (wide enough for a pixel of principal point and a few tenths of a percent of focal
/// length on a rectified rig).
pub const CALIBRATION_PRECISION: CalibrationPrecision = CalibrationPrecision::UNSTATED;
use std::path::Path;

/// A 3x4 projection matrix, row-major.
pub type Projection = [[f64; 4]; 3];

/// The `P0:` to `P3:` rows of a KITTI `calib.txt` (grey pair 0/1, colour pair 2/3), each
/// `None` when absent. Other rows (`Tr`) are accepted and ignored; a row with a wrong
/// number of values is an error.
pub fn parse_calib(text: &str, path: &Path) -> Result<[Option<Projection>; 4], DatasetError> {
    let mut rows = [None; 4];
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let bad = |problem: String| DatasetError::Calib {
            path: path.to_path_buf(),
            line: i + 1,
            problem,
        };
        let Some((key, rest)) = line.split_once(':') else {
            return Err(bad(format!("`{}` has no `NAME:` prefix", truncate(line))));
        };
        let mut values = Vec::with_capacity(12);
        for token in rest.split_whitespace() {
            let v: f64 = token
                .parse()
                .map_err(|_| bad(format!("{key}: `{token}` is not a number")))?;
            if !v.is_finite() {
                return Err(bad(format!("{key}: `{token}` is not finite")));
            }
            values.push(v);
        }
        if values.len() != 12 {
            return Err(bad(format!(
                "{key}: expected 12 numbers, found {}",
                values.len()
            )));
        }
        let mut m = [[0.0; 4]; 3];
        for (k, v) in values.iter().enumerate() {
            m[k / 4][k % 4] = *v;
        }
        let camera = match key.trim() {
            "P0" => 0,
            "P1" => 1,
            "P2" => 2,
            "P3" => 3,
            _ => continue,
        };
        let (fx, fy) = (m[0][0], m[1][1]);
        if !(fx > 0.0 && fy > 0.0) {
            // Caught here, where the line is known, rather than in rig_from_calib.
            return Err(bad(format!(
                "{key}: non-positive focal length (fx = {fx}, fy = {fy})"
            )));
        }
        rows[camera] = Some(m);
    }
    Ok(rows)
}

/// The rows of cameras `pair` (left, right) of [`parse_calib`]'s result.
pub fn pair_rows(
    rows: &[Option<Projection>; 4],
    pair: (usize, usize),
    path: &Path,
) -> Result<(Projection, Projection), DatasetError> {
    const NAMES: [&str; 4] = ["P0", "P1", "P2", "P3"];
    let row = |c: usize| {
        rows[c].ok_or(DatasetError::MissingCalibRow {
            path: path.to_path_buf(),
            row: NAMES[c],
        })
    };
    Ok((row(pair.0)?, row(pair.1)?))
}

/// The perspective centre of a rectified KITTI camera in camera 0's frame (m):
/// `P = K [I | t]` puts it at `-t = -K^-1 P[:, 3]`.
pub fn centre_in_camera0(p: &Projection) -> [f64; 3] {
    let (fx, fy, cx, cy) = (p[0][0], p[1][1], p[0][2], p[1][2]);
    let tz = p[2][3];
    let ty = (p[1][3] - cy * tz) / fy;
    let tx = (p[0][3] - cx * tz) / fx;
    [-tx, -ty, -tz]
}

fn truncate(s: &str) -> &str {
    match s.char_indices().nth(40) {
        Some((i, _)) => &s[..i],
        None => s,
    }
}

/// Interior orientation of one rectified KITTI camera in pixel units.
fn interior(
    p: &Projection,
    width: u32,
    height: u32,
    camera: &'static str,
    path: &Path,
) -> Result<Interior, DatasetError> {
    let (fx, fy, cx, cy) = (p[0][0], p[1][1], p[0][2], p[1][2]);
    if !(fx > 0.0 && fy > 0.0) {
        return Err(DatasetError::BadCamera {
            path: path.to_path_buf(),
            camera,
            problem: format!("non-positive focal length (fx = {fx}, fy = {fy})"),
        });
    }
    let sy = fx / fy;
    Ok(Interior {
        width_px: width,
        height_px: height,
        pixel_size_mm: [1.0, sy],
        focal_mm: fx,
        principal_point_mm: [
            cx - (width as f64 - 1.0) * 0.5,
            -(cy - (height as f64 - 1.0) * 0.5) * sy,
        ],
        radial: [0.0; 3],
        decentering: [0.0; 2],
        distortion_model: DistortionModel::Correction,
    })
}

/// The rig of a KITTI sequence whose images are `width` x `height`.
pub fn rig_from_calib(
    p0: &Projection,
    p1: &Projection,
    width: u32,
    height: u32,
    path: &Path,
) -> Result<Rig, DatasetError> {
    let left = interior(p0, width, height, "left", path)?;
    let right = interior(p1, width, height, "right", path)?;
    // P = K [I | t]: the base is the difference of the centres along x (for cameras 0
    // and 1, P0[0][3] = 0 and P1[0][3] = -fx B).
    let base = centre_in_camera0(p1)[0] - centre_in_camera0(p0)[0];
    if base.is_nan() || base <= 0.0 {
        return Err(DatasetError::BadCamera {
            path: path.to_path_buf(),
            camera: "right",
            problem: format!(
                "base (right centre minus left centre along x) = {base} must be positive"
            ),
        });
    }
    Ok(Rig {
        left,
        right,
        relative_angles: [0.0; 3],
        base_m: [base, 0.0, 0.0],
    })
}

/// `calib.txt` text for a rectified rig in pixel units (inverse of
/// [`rig_from_calib`]; requires no distortion and no relative rotation, which
/// the caller checks).
pub fn calib_text(rig: &Rig) -> String {
    let row = |name: &str, cam: &Interior, tx: f64| {
        let fx = cam.focal_mm / cam.pixel_size_mm[0];
        let fy = cam.focal_mm / cam.pixel_size_mm[1];
        let cx =
            cam.principal_point_mm[0] / cam.pixel_size_mm[0] + (cam.width_px as f64 - 1.0) * 0.5;
        let cy =
            -cam.principal_point_mm[1] / cam.pixel_size_mm[1] + (cam.height_px as f64 - 1.0) * 0.5;
        format!(
            "{name}: {fx:e} 0 {cx:e} {:e} 0 {fy:e} {cy:e} 0 0 0 1 0\n",
            tx * fx
        )
    };
    let mut s = row("P0", &rig.left, 0.0);
    s.push_str(&row("P1", &rig.right, -rig.base_m[0]));
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    const KITTI_00: &str = "P0: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 0.000000000000e+00 0.000000000000e+00 7.188560000000e+02 1.852157000000e+02 0.000000000000e+00 0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 0.000000000000e+00
P1: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 -3.861448000000e+02 0.000000000000e+00 7.188560000000e+02 1.852157000000e+02 0.000000000000e+00 0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 0.000000000000e+00
P2: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 4.538225000000e+01 0.000000000000e+00 7.188560000000e+02 1.852157000000e+02 -1.130887000000e-01 0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 3.779761000000e-03
P3: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 -3.372877000000e+02 0.000000000000e+00 7.188560000000e+02 1.852157000000e+02 2.369057000000e+00 0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 4.915215000000e-03
Tr: 4.276802385584e-04 -9.999672484946e-01 -8.084491683471e-03 -1.198459927713e-02 -7.210626507497e-03 8.081198471645e-03 -9.999413164504e-01 -5.403984729748e-02 9.999738645903e-01 4.859485810390e-04 -7.206933692422e-03 -2.921968648686e-01
";

    /// The grey pair's rows.
    fn grey(text: &str, path: &Path) -> Result<(Projection, Projection), DatasetError> {
        pair_rows(&parse_calib(text, path)?, (0, 1), path)
    }

    #[test]
    fn the_colour_pair_of_kitti_00() {
        let path = Path::new("calib.txt");
        let (p2, p3) = pair_rows(&parse_calib(KITTI_00, path).unwrap(), (2, 3), path).unwrap();
        let rig = rig_from_calib(&p2, &p3, 1241, 376, path).unwrap();
        // Camera 2 sits 6 cm left of camera 0, camera 3 47 cm right of it.
        let (c2, c3) = (centre_in_camera0(&p2), centre_in_camera0(&p3));
        assert!(
            (c2[0] + 0.0599).abs() < 1e-3 && (c3[0] - 0.4734).abs() < 1e-3,
            "{c2:?} {c3:?}"
        );
        assert!((rig.base_length() - (c3[0] - c2[0])).abs() < 1e-12);
        assert!((rig.base_length() - 0.5332).abs() < 1e-3);
        // A missing row is named.
        let only_grey = KITTI_00.lines().take(2).collect::<Vec<_>>().join("\n");
        let e = pair_rows(&parse_calib(&only_grey, path).unwrap(), (2, 3), path)
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing calibration row P2"), "{e}");
    }

    #[test]
    fn kitti_00_calibration() {
        let (p0, p1) = grey(KITTI_00, Path::new("calib.txt")).unwrap();
        let rig = rig_from_calib(&p0, &p1, 1241, 376, Path::new("calib.txt")).unwrap();
        assert!((rig.base_length() - 386.1448 / 718.856).abs() < 1e-12);
        assert_eq!(rig.left.focal_mm, 718.856);
        assert!((rig.left.principal_point_mm[0] - (607.1928 - 620.0)).abs() < 1e-9);
        assert!((rig.left.principal_point_mm[1] - -(185.2157 - 187.5)).abs() < 1e-9);
        // The principal point projects to pixel (cx, cy).
        let px = rig.left.corrected_to_pixel(0.0, 0.0).unwrap();
        assert!((px[0] - 607.1928).abs() < 1e-9 && (px[1] - 185.2157).abs() < 1e-9);
        // Writing and reading back gives the same rig.
        let (q0, q1) = grey(&calib_text(&rig), Path::new("x")).unwrap();
        let back = rig_from_calib(&q0, &q1, 1241, 376, Path::new("x")).unwrap();
        assert_eq!(back, rig);
    }

    #[test]
    fn anisotropic_pixels() {
        let text = "P0: 500 0 320 0 0 400 240 0 0 0 1 0\nP1: 500 0 320 -250 0 400 240 0 0 0 1 0\n";
        let (p0, p1) = grey(text, Path::new("c")).unwrap();
        let rig = rig_from_calib(&p0, &p1, 640, 480, Path::new("c")).unwrap();
        assert_eq!(rig.left.pixel_size_mm, [1.0, 1.25]);
        assert_eq!(rig.base_m, [0.5, 0.0, 0.0]);
        // A point 10 m ahead and 1 m up projects fy * 0.1 = 40 rows above cy.
        let pose = phototraverse_core::camera::Pose::from_degrees(90.0, 0.0, 0.0, [0.0; 3]);
        let px = phototraverse_core::camera::project_to_pixel(&pose, &rig.left, &[0.0, 10.0, 1.0])
            .unwrap();
        assert!(
            (px[0] - 320.0).abs() < 1e-9 && (px[1] - 200.0).abs() < 1e-9,
            "{px:?}"
        );
    }

    #[test]
    fn calib_errors() {
        let e = parse_calib("P0: 1 2 3\n", Path::new("calib.txt"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("calib.txt") && e.contains("line 1") && e.contains("found 3"),
            "{e}"
        );
        let e = parse_calib("P0 1 2 3\n", Path::new("calib.txt"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("no `NAME:` prefix"), "{e}");
        let e = parse_calib("P0: 1 0 0 0 0 1 0 0 0 0 1 zz\n", Path::new("c"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("`zz` is not a number"), "{e}");
        let e = grey("P0: 1 0 0 0 0 1 0 0 0 0 1 0\n", Path::new("c"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing calibration row P1"), "{e}");
        let text = "P0: 500 0 320 0 0 400 240 0 0 0 1 0\nP1: 0 0 320 -250 0 400 240 0 0 0 1 0\n";
        let e = parse_calib(text, Path::new("c")).unwrap_err().to_string();
        assert!(
            e.contains("line 2") && e.contains("P1: non-positive focal length"),
            "{e}"
        );
        let mut p0 = [[0.0; 4]; 3];
        p0[0][0] = -5.0;
        p0[1][1] = 400.0;
        let e = rig_from_calib(&p0, &p0, 640, 480, Path::new("c"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("left camera") && e.contains("non-positive focal length"),
            "{e}"
        );
    }
}
