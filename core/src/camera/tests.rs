//! Camera model tests: round trips, known projections, analytic Jacobians
//! against central differences, and the seed's normal-case example.
use super::*;

use crate::testkit::{test_camera, Rng};

/// The test camera's last pixel column and row.
fn format_end(cam: &Interior) -> (f64, f64) {
    ((cam.width_px - 1) as f64, (cam.height_px - 1) as f64)
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
}

#[test]
fn pixel_photo_round_trip_and_axes() {
    let cam = test_camera();
    let (cw, rh) = format_end(&cam);
    // The image centre is photo (0, 0); right is +x, up is +y.
    assert_eq!(cam.pixel_to_photo(cw / 2.0, rh / 2.0), [0.0, 0.0]);
    let [x, y] = cam.pixel_to_photo(0.0, 0.0);
    assert!(x < 0.0 && y > 0.0);
    let mut rng = Rng(1);
    for _ in 0..100 {
        let (c, r) = (rng.uniform(-5.0, cw + 5.0), rng.uniform(-5.0, rh + 5.0));
        let [x, y] = cam.pixel_to_photo(c, r);
        let [c2, r2] = cam.photo_to_pixel(x, y);
        assert!(close(c, c2, 1e-12) && close(r, r2, 1e-12));
    }
}

#[test]
fn distortion_correction_round_trip() {
    let cam = test_camera();
    let (cw, rh) = format_end(&cam);
    let mut rng = Rng(2);
    for _ in 0..500 {
        let (c, r) = (rng.uniform(0.0, cw), rng.uniform(0.0, rh));
        let [x, y] = cam.pixel_to_photo(c, r);
        let [xc, yc] = cam.correct(x, y);
        let [x2, y2] = cam.uncorrect(xc, yc).unwrap();
        assert!((x - x2).abs() < 1e-10 && (y - y2).abs() < 1e-10);
    }
    // Correction is not trivial for this lens: some micrometres at the corner.
    let [x, y] = cam.pixel_to_photo(0.0, 0.0);
    let [xc, _] = cam.correct(x, y);
    assert!((xc - (x - cam.principal_point_mm[0])).abs() > 1e-3);
}

#[test]
fn uncorrect_reports_divergence_instead_of_looping() {
    let mut cam = test_camera();
    cam.radial = [1.0, 0.0, 0.0]; // absurd lens: the correction folds over within the format
    assert!(cam.uncorrect(50.0, 50.0).is_err());
    assert_eq!(cam.uncorrect(f64::NAN, 0.0), Err(CameraError::NotFinite));
}

#[test]
fn rotation_angles_round_trip_and_orthonormal() {
    let mut rng = Rng(3);
    for _ in 0..200 {
        let a = [
            rng.uniform(-3.1, 3.1),
            rng.uniform(-1.5, 1.5),
            rng.uniform(-3.1, 3.1),
        ];
        let m = rotation(a[0], a[1], a[2]);
        assert!((m * m.transpose() - Matrix3::identity()).norm() < 1e-12);
        assert!((m.determinant() - 1.0).abs() < 1e-12);
        let b = angles_from_rotation(&m);
        for k in 0..3 {
            assert!(close(a[k], b[k], 1e-10), "{a:?} {b:?}");
        }
    }
}

#[test]
fn level_camera_looks_along_plus_y() {
    let pose = Pose::from_degrees(90.0, 0.0, 0.0, [0.0, 0.0, 0.0]);
    let f = 10.0;
    let ahead = project(&pose, f, &[0.0, 10.0, 0.0]).unwrap();
    assert!(ahead[0].abs() < 1e-12 && ahead[1].abs() < 1e-12);
    let right = project(&pose, f, &[1.0, 10.0, 0.0]).unwrap();
    assert!(close(right[0], 1.0, 1e-12) && right[1].abs() < 1e-12);
    let up = project(&pose, f, &[0.0, 10.0, 2.0]).unwrap();
    assert!(close(up[1], 2.0, 1e-12) && up[0].abs() < 1e-12);
    assert_eq!(
        project(&pose, f, &[0.0, -10.0, 0.0]),
        Err(CameraError::BehindCamera)
    );
}

/// Seed 000 normal case: B = 0.40 m, f = 34.6041 mm, x' = 2 mm, x'' = 1 mm gives
/// Y = B f / (x' - x'') = 13.84164 m and X = B x' / (x' - x'') = 0.8 m.
#[test]
fn seed_normal_case_intersection() {
    let f = 34.6041;
    let rig = Rig::rectified(Interior::pinhole_px(576, 384, f), 0.40);
    let left = Pose::from_degrees(90.0, 0.0, 0.0, [0.0, 0.0, 0.0]);
    let right = rig.right_pose(&left);
    assert!((right.centre_vec() - Vector3::new(0.40, 0.0, 0.0)).norm() < 1e-15);
    let (xl, xr) = (2.0, 1.0);
    let y = rig.base_length() * f / (xl - xr);
    let x = rig.base_length() * xl / (xl - xr);
    assert!((y - 13.84164).abs() < 5e-6 && (x - 0.8).abs() < 1e-12);
    // The collinearity model reproduces the measured photo-coordinates.
    let p = [x, y, 0.0];
    assert!(close(project(&left, f, &p).unwrap()[0], xl, 1e-12));
    assert!(close(project(&right, f, &p).unwrap()[0], xr, 1e-12));
}

fn random_pose(rng: &mut Rng) -> Pose {
    Pose {
        omega: rng.uniform(1.2, 1.9),
        phi: rng.uniform(-0.4, 0.4),
        kappa: rng.uniform(-0.4, 0.4),
        centre: [
            rng.uniform(-5.0, 5.0),
            rng.uniform(-5.0, 5.0),
            rng.uniform(-1.0, 1.0),
        ],
    }
}

#[test]
fn projection_jacobians_match_central_differences() {
    let mut rng = Rng(4);
    let f = 34.6;
    let h = 1e-6;
    for _ in 0..200 {
        let pose = random_pose(&mut rng);
        // A point in front: along the viewing direction (-z of the camera) at 5..40 m.
        let m = pose.rotation();
        let dir =
            m.transpose() * Vector3::new(rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), -1.0);
        let p = pose.centre_vec() + dir * rng.uniform(5.0, 40.0);
        let point = [p[0], p[1], p[2]];
        let proj = project_with_jacobians(&pose, f, &point).unwrap();
        assert_eq!(proj.xy, project(&pose, f, &point).unwrap());

        let params = pose.to_params();
        for k in 0..6 {
            let (mut a, mut b) = (params, params);
            a[k] += h;
            b[k] -= h;
            let pa = project(&Pose::from_params(&a), f, &point).unwrap();
            let pb = project(&Pose::from_params(&b), f, &point).unwrap();
            for i in 0..2 {
                let num = (pa[i] - pb[i]) / (2.0 * h);
                assert!(
                    close(proj.d_pose[i][k], num, 1e-6),
                    "pose {k} {i}: {} vs {num}",
                    proj.d_pose[i][k]
                );
            }
        }
        for k in 0..3 {
            let (mut a, mut b) = (point, point);
            a[k] += h;
            b[k] -= h;
            let pa = project(&pose, f, &a).unwrap();
            let pb = project(&pose, f, &b).unwrap();
            for i in 0..2 {
                let num = (pa[i] - pb[i]) / (2.0 * h);
                assert!(close(proj.d_point[i][k], num, 1e-6), "point {k} {i}");
            }
        }
        let pa = project(&pose, f + h, &point).unwrap();
        let pb = project(&pose, f - h, &point).unwrap();
        for i in 0..2 {
            assert!(close(proj.d_focal[i], (pa[i] - pb[i]) / (2.0 * h), 1e-6));
        }
    }
}

/// The test camera's lens read the other way round (OpenCV's convention), with a
/// third radial term: a lens of the same strength in the projection model.
fn projection_camera() -> Interior {
    let cam = test_camera();
    Interior {
        radial: [cam.radial[0], cam.radial[1], -2.0e-7],
        distortion_model: DistortionModel::Projection,
        ..cam
    }
}

#[test]
fn correction_jacobian_matches_central_differences() {
    for base in [test_camera(), projection_camera()] {
        let (cw, rh) = format_end(&base);
        let mut rng = Rng(5);
        for _ in 0..200 {
            let [x, y] = base.pixel_to_photo(rng.uniform(0.0, cw), rng.uniform(0.0, rh));
            let jac = base.correction_jacobian(x, y);
            let mut steps = [0.0; io_param::COUNT];
            steps[io_param::X0] = 1e-6;
            steps[io_param::Y0] = 1e-6;
            steps[io_param::K1] = 1e-7;
            steps[io_param::K2] = 1e-9;
            steps[io_param::K3] = 1e-11;
            steps[io_param::P1] = 1e-6;
            steps[io_param::P2] = 1e-6;
            for (k, &h) in steps.iter().enumerate() {
                let perturb = |s: f64| {
                    let mut c = base;
                    match k {
                        io_param::X0 => c.principal_point_mm[0] += s,
                        io_param::Y0 => c.principal_point_mm[1] += s,
                        io_param::K1 => c.radial[0] += s,
                        io_param::K2 => c.radial[1] += s,
                        io_param::K3 => c.radial[2] += s,
                        io_param::P1 => c.decentering[0] += s,
                        _ => c.decentering[1] += s,
                    }
                    c.correct(x, y)
                };
                let (a, b) = (perturb(h), perturb(-h));
                for i in 0..2 {
                    let num = (a[i] - b[i]) / (2.0 * h);
                    assert!(
                        (jac[i][k] - num).abs() <= 1e-5 * (1.0 + num.abs()),
                        "{:?} io {k} row {i}: {} vs {num}",
                        base.distortion_model,
                        jac[i][k]
                    );
                }
            }
        }
    }
}

#[test]
fn projection_model_distorts_ideal_points_and_inverts_over_the_format() {
    let cam = projection_camera();
    let (cw, rh) = format_end(&cam);
    assert_eq!(cam.validate(), Ok(()));
    // The defining equation: an ideal point is measured at xc + d(xc).
    let (xc, yc) = (2.5, -1.5);
    let [x, y] = cam.uncorrect(xc, yc).unwrap();
    let [dx, dy] = cam.distortion(xc, yc);
    let [x0, y0] = cam.principal_point_mm;
    assert!((x - (x0 + xc + dx)).abs() < 1e-15 && (y - (y0 + yc + dy)).abs() < 1e-15);
    // Its inverse, by Newton, over the whole format.
    let mut rng = Rng(11);
    for _ in 0..500 {
        let [x, y] = cam.pixel_to_photo(rng.uniform(0.0, cw), rng.uniform(0.0, rh));
        let [xc, yc] = cam.correct(x, y);
        let [x2, y2] = cam.uncorrect(xc, yc).unwrap();
        assert!((x - x2).abs() < 1e-10 && (y - y2).abs() < 1e-10);
    }
    // The two models differ at second order: the same coefficients do not give the
    // same correction at the corner.
    let [x, y] = cam.pixel_to_photo(0.0, 0.0);
    let proj = cam.correct(x, y);
    let corr = Interior {
        distortion_model: DistortionModel::Correction,
        ..cam
    }
    .correct(x, y);
    assert!((proj[0] - corr[0]).abs() > 1e-6);
}

#[test]
fn a_lens_that_folds_the_format_is_refused() {
    // A third radial term fitted far beyond its data turns the distortion back
    // within the format: no inverse exists there.
    let cam = Interior {
        radial: [0.0, 0.0, -1e-2],
        ..projection_camera()
    };
    assert_eq!(cam.validate(), Err(CameraError::DistortionDiverged));
    // An S-shaped radial curve (k1 < 0, k3 > 0, as OpenCV fits a wide lens) turns
    // back and rises again within the format: every measured point still has a root
    // that comes back, but some lie on the folded branch.
    let s_curve = Interior {
        radial: [-0.08, 0.0, 2e-4],
        ..projection_camera()
    };
    assert_eq!(s_curve.validate(), Err(CameraError::DistortionDiverged));
    assert_eq!(projection_camera().validate(), Ok(()));
    assert_eq!(test_camera().validate(), Ok(()));
}

#[test]
fn right_camera_from_relative_orientation() {
    let mut rig = Rig::rectified(test_camera(), 0.4);
    rig.relative_angles = [0.01, -0.02, 0.005];
    let left = Pose::from_degrees(92.0, 1.0, -2.0, [1.0, 2.0, 3.0]);
    let right = rig.right_pose(&left);
    // The base vector expressed in the left camera frame is b, its length the base.
    let b = left.rotation() * (right.centre_vec() - left.centre_vec());
    assert!((b - Vector3::from(rig.base_m)).norm() < 1e-12);
    let rel = right.rotation() * left.rotation().transpose();
    assert!((rel - rig.relative_rotation()).norm() < 1e-12);
}

#[test]
fn kitti_pose_round_trip_and_conventions() {
    let origin = Pose::from_degrees(90.0, 0.0, 0.0, [0.0, 0.0, 0.0]);
    // Identity at the origin.
    let k0 = kitti_from_pose(&origin, &origin);
    for (i, row) in k0.iter().enumerate() {
        for (j, v) in row.iter().enumerate() {
            let want = if i == j { 1.0 } else { 0.0 };
            assert!((v - want).abs() < 1e-12);
        }
    }
    // One metre forward (+Y) is +z in KITTI; one metre up is -y (KITTI y down).
    let fwd = Pose {
        centre: [0.0, 1.0, 0.5],
        ..origin
    };
    let k = kitti_from_pose(&origin, &fwd);
    assert!((k[2][3] - 1.0).abs() < 1e-12 && (k[1][3] + 0.5).abs() < 1e-12);
    let mut rng = Rng(6);
    for _ in 0..100 {
        let o = random_pose(&mut rng);
        let p = random_pose(&mut rng);
        let back = pose_from_kitti(&o, &kitti_from_pose(&o, &p));
        assert!((back.rotation() - p.rotation()).norm() < 1e-12);
        assert!((back.centre_vec() - p.centre_vec()).norm() < 1e-12);
    }
}
