//! The projection and constraint Jacobians against central differences, intersection,
//! Cholesky and the chi-square quantiles.
use super::*;

// ---------- Jacobians ----------

#[test]
fn rig_projection_jacobians_match_central_differences() {
    let mut rng = Rng(11);
    for trial in 0..200 {
        let left = Pose::from_params(&[
            rng.uniform(1.3, 1.8),
            rng.uniform(-0.2, 0.2),
            rng.uniform(-0.3, 0.3),
            rng.uniform(-1.0, 1.0),
            rng.uniform(-1.0, 1.0),
            rng.uniform(0.0, 2.0),
        ]);
        let rig = RelativeOrientation {
            angles: [
                rng.uniform(-0.05, 0.05),
                rng.uniform(-0.05, 0.05),
                rng.uniform(-0.05, 0.05),
            ],
            base: [
                rng.uniform(0.3, 0.6),
                rng.uniform(-0.02, 0.02),
                rng.uniform(-0.02, 0.02),
            ],
        };
        let cam = if trial % 2 == 0 {
            Camera::Left
        } else {
            Camera::Right
        };
        let f = 8.0;
        // A point in front of the left camera.
        let m = left.rotation();
        let q = nalgebra::Vector3::new(
            rng.uniform(-3.0, 3.0),
            rng.uniform(-2.0, 2.0),
            -rng.uniform(5.0, 30.0),
        );
        let pw = left.centre_vec() + m.transpose() * q;
        let point = [pw[0], pw[1], pw[2]];
        let Ok(pr) = project_rig(&left, &rig, cam, f, &point) else {
            continue;
        };
        let h = 1e-6;
        let proj = |l: &Pose, r: &RelativeOrientation, p: &[f64; 3]| {
            project_rig(l, r, cam, f, p).unwrap().xy
        };
        for i in 0..6 {
            let mut a = left.to_params();
            let mut b = left.to_params();
            a[i] += h;
            b[i] -= h;
            let (pa, pb) = (
                proj(&Pose::from_params(&a), &rig, &point),
                proj(&Pose::from_params(&b), &rig, &point),
            );
            for c in 0..2 {
                let num = (pa[c] - pb[c]) / (2.0 * h);
                assert!(
                    close(num, pr.d_pose[c][i], 1e-6),
                    "pose {i} coord {c}: {num} vs {}",
                    pr.d_pose[c][i]
                );
            }
            let mut ra = rig.to_array();
            let mut rb = rig.to_array();
            ra[i] += h;
            rb[i] -= h;
            let (pa, pb) = (
                proj(&left, &RelativeOrientation::from_array(&ra), &point),
                proj(&left, &RelativeOrientation::from_array(&rb), &point),
            );
            for c in 0..2 {
                let num = (pa[c] - pb[c]) / (2.0 * h);
                assert!(
                    close(num, pr.d_rig[c][i], 1e-6),
                    "rig {i} coord {c}: {num} vs {}",
                    pr.d_rig[c][i]
                );
            }
        }
        for k in 0..3 {
            let mut a = point;
            let mut b = point;
            a[k] += h;
            b[k] -= h;
            let (pa, pb) = (proj(&left, &rig, &a), proj(&left, &rig, &b));
            for c in 0..2 {
                let num = (pa[c] - pb[c]) / (2.0 * h);
                assert!(close(num, pr.d_point[c][k], 1e-6));
            }
        }
        // Interior orientation corrections of both cameras: the focal length goes into
        // the projection, the principal point shifts it (only this camera's three count).
        let corr = [0.002, -0.003, 0.01, -0.001, 0.004, -0.02];
        let with = |c: &[f64; 6]| {
            let fc = geometry::corrected_focal([f, f], cam, c);
            let pr = project_rig(&left, &rig, cam, fc, &point).unwrap();
            geometry::with_interior(pr, cam, fc, c)
        };
        let pi = with(&corr);
        for i in 0..6 {
            let (mut a, mut b) = (corr, corr);
            a[i] += h;
            b[i] -= h;
            let (pa, pb) = (with(&a).xy, with(&b).xy);
            for c in 0..2 {
                let num = (pa[c] - pb[c]) / (2.0 * h);
                assert!(
                    close(num, pi.d_interior[c][i], 1e-6),
                    "interior {i} coord {c}: {num} vs {}",
                    pi.d_interior[c][i]
                );
            }
        }
        // The right camera through the rig equals the explicit right pose.
        if cam == Camera::Right {
            let rp = geometry::camera_pose(&left, &rig, Camera::Right);
            let direct = project(&rp, f, &point).unwrap();
            assert!(close(direct[0], pr.xy[0], 1e-12) && close(direct[1], pr.xy[1], 1e-12));
        }
    }
}

#[test]
fn fewer_partials_give_the_same_projection_and_point_partials() {
    use super::geometry::{project_epoch, right_rotation, EpochRotations, Partials, Rotations};
    let left = Pose::from_params(&[1.55, 0.04, -0.1, 0.3, -0.2, 1.1]);
    let rig = RelativeOrientation {
        angles: [0.01, -0.02, 0.005],
        base: [0.5, 0.01, -0.02],
    };
    let (l, r) = (
        Rotations::new(left.omega, left.phi, left.kappa),
        Rotations::new(rig.angles[0], rig.angles[1], rig.angles[2]),
    );
    let right = right_rotation(&l, &r);
    let rot = EpochRotations {
        left: &l,
        rel: &r,
        right: &right,
    };
    let m = left.rotation();
    let pw = left.centre_vec() + m.transpose() * nalgebra::Vector3::new(0.7, -0.4, -12.0);
    let point = [pw[0], pw[1], pw[2]];
    for cam in [Camera::Left, Camera::Right] {
        let full = project_rig(&left, &rig, cam, 8.0, &point).unwrap();
        let at = |p| project_epoch(&rot, &left.centre, &rig.base, cam, 8.0, &point, p).unwrap();
        assert_eq!(at(Partials::PoseAndRig), full, "{cam:?}");
        let pose = at(Partials::Pose);
        assert_eq!(
            (pose.xy, pose.d_point, pose.d_pose),
            (full.xy, full.d_point, full.d_pose)
        );
        assert_eq!(pose.d_rig, [[0.0; 6]; 2]);
        let point_only = at(Partials::Point);
        assert_eq!((point_only.xy, point_only.d_point), (full.xy, full.d_point));
        for c in 0..2 {
            assert_eq!(point_only.d_pose[c][..3], [0.0; 3]);
            // The centre's partials are the point's, negated: free with the point's.
            assert_eq!(point_only.d_pose[c][3..], full.d_pose[c][3..]);
        }
    }
}

#[test]
fn constraint_jacobians_match_central_differences() {
    let mut rng = Rng(5);
    let h = 1e-7;
    for _ in 0..50 {
        let b = [
            rng.uniform(-1.0, 1.0),
            rng.uniform(-1.0, 1.0),
            rng.uniform(-1.0, 1.0),
        ];
        let (_, g) = base_length(&b, 0.4);
        let c0 = [
            rng.uniform(-5.0, 5.0),
            rng.uniform(-5.0, 5.0),
            rng.uniform(-5.0, 5.0),
        ];
        let (_, gd) = distance(&c0, &b, 1.0);
        for k in 0..3 {
            let (mut bp, mut bm) = (b, b);
            bp[k] += h;
            bm[k] -= h;
            let num = (base_length(&bp, 0.4).0 - base_length(&bm, 0.4).0) / (2.0 * h);
            assert!(close(num, g[k], 1e-6));
            let num = (distance(&c0, &bp, 1.0).0 - distance(&c0, &bm, 1.0).0) / (2.0 * h);
            assert!(close(num, gd[k], 1e-6));
            // With respect to c0 the gradient is the negative.
            let (mut cp, mut cm) = (c0, c0);
            cp[k] += h;
            cm[k] -= h;
            let num = (distance(&cp, &b, 1.0).0 - distance(&cm, &b, 1.0).0) / (2.0 * h);
            assert!(close(num, -gd[k], 1e-6));
        }
        // Smoothness: every partial over the three epochs' unknowns (a turn of the
        // attitude, the centre's coordinates), near the angles' singularity too.
        let mut p = [[0.0; 6]; 3];
        for pe in p.iter_mut() {
            for (q, v) in pe.iter_mut().enumerate() {
                *v = if q < 3 {
                    rng.uniform(-1.5, 1.5)
                } else {
                    rng.uniform(-5.0, 5.0)
                };
            }
        }
        p[1][1] = core::f64::consts::FRAC_PI_2 - 1e-4;
        // A wider step: near the singularity the turned angles round 1/cos(phi) worse.
        let h = 1e-5;
        let (dt0, dt1) = (0.1, 0.15);
        let (_, jac) = smoothness([&p[0], &p[1], &p[2]], dt0, dt1);
        for col in 0..18 {
            let (mut pp, mut pm) = (p, p);
            nudge(&mut pp[col / 6], col % 6, h);
            nudge(&mut pm[col / 6], col % 6, -h);
            let rp = smoothness([&pp[0], &pp[1], &pp[2]], dt0, dt1).0;
            let rm = smoothness([&pm[0], &pm[1], &pm[2]], dt0, dt1).0;
            for a in 0..3 {
                let num = (rp[a] - rm[a]) / (2.0 * h);
                assert!(
                    close(num, jac[a][col], 1e-5),
                    "row {a} col {col}: {num} vs {}",
                    jac[a][col]
                );
            }
        }
    }
    // Seed 000 App. B: dB/dX1 = (X1 - X2)/B.
    let (e, g) = distance(&[0.0, 0.0, 0.0], &[0.3, 0.4, 0.0], 0.4);
    assert!(close(e, 0.1, 1e-12) && close(g[0], 0.6, 1e-12) && close(g[1], 0.8, 1e-12));
    assert!(close(
        wrap_angle(2.0 * core::f64::consts::PI + 0.1),
        0.1,
        1e-12
    ));
    let r = prior_residual(
        &[3.1, 0.0, 0.0, 1.0, 0.0, 0.0],
        &[-3.1, 0.0, 0.0, 0.5, 0.0, 0.0],
    );
    assert!(close(r[0], 6.2 - 2.0 * core::f64::consts::PI, 1e-12) && close(r[3], 0.5, 1e-12));
}

// ---------- intersection ----------

#[test]
fn seed_normal_case_intersection() {
    // Seed 000 §5.2: B = 0.40 m, f = 34.6041 mm, x' = 2 mm, x'' = 1 mm.
    let f = 34.6041;
    let left = Pose::from_degrees(90.0, 0.0, 0.0, [0.0, 0.0, 0.0]);
    let right = Pose::from_degrees(90.0, 0.0, 0.0, [0.4, 0.0, 0.0]);
    let rays = [
        Ray {
            pose: left,
            focal_mm: f,
            xy: [2.0, 0.0],
        },
        Ray {
            pose: right,
            focal_mm: f,
            xy: [1.0, 0.0],
        },
    ];
    let p = intersect(&rays, 1e-4).unwrap();
    assert!((p.point[1] - 13.84164).abs() < 1e-6, "Y = {}", p.point[1]);
    assert!((p.point[0] - 0.8).abs() < 1e-9);
    assert!(p.point[2].abs() < 1e-9);
}

#[test]
fn intersection_of_many_rays_is_exact_and_checks_geometry() {
    let mut rng = Rng(3);
    let f = 8.0;
    let truth = [1.0, 12.0, 2.0];
    let mut rays = Vec::new();
    for k in 0..5 {
        let pose = Pose::from_degrees(
            90.0 + rng.uniform(-2.0, 2.0),
            rng.uniform(-2.0, 2.0),
            rng.uniform(-2.0, 2.0),
            [0.3 * k as f64, 0.5 * k as f64, 1.0],
        );
        rays.push(Ray {
            pose,
            focal_mm: f,
            xy: project(&pose, f, &truth).unwrap(),
        });
    }
    let p = intersect(&rays, 1e-3).unwrap();
    for a in 0..3 {
        assert!((p.point[a] - truth[a]).abs() < 1e-9);
    }
    // Identical rays (zero base / point at infinity): refused.
    let same = [rays[0], rays[0]];
    assert_eq!(intersect(&same, 1e-3), Err(IntersectError::SmallRayAngle));
    assert_eq!(intersect(&rays[..1], 1e-3), Err(IntersectError::TooFewRays));
    let mut nan = rays.clone();
    nan[1].xy[0] = f64::NAN;
    assert_eq!(intersect(&nan, 1e-3), Err(IntersectError::NotFinite));
    // Rays that meet behind the cameras.
    let l = Pose::from_degrees(90.0, 0.0, 0.0, [0.0, 0.0, 0.0]);
    let r = Pose::from_degrees(90.0, 0.0, 0.0, [0.4, 0.0, 0.0]);
    let behind = [
        Ray {
            pose: l,
            focal_mm: f,
            xy: [-1.0, 0.0],
        },
        Ray {
            pose: r,
            focal_mm: f,
            xy: [1.0, 0.0],
        },
    ];
    assert_eq!(intersect(&behind, 1e-4), Err(IntersectError::BehindCamera));
}

// ---------- Cholesky and chi-square ----------

#[test]
fn cholesky_solves_and_inverts() {
    let mut rng = Rng(9);
    let n = 12;
    type M = nalgebra::SMatrix<f64, 12, 12>;
    let b = M::from_fn(|_, _| rng.uniform(-1.0, 1.0));
    let a = b * b.transpose() + M::identity() * 0.5;
    let mut m: Vec<f64> = (0..n * n).map(|k| a[(k / n, k % n)]).collect();
    cholesky::factor(&mut m, n, cholesky::PIVOT_REL_TOL).unwrap();
    let rhs: Vec<f64> = (0..n).map(|i| i as f64 - 3.0).collect();
    let mut x = rhs.clone();
    cholesky::solve(&m, n, &mut x);
    let ax = a * nalgebra::SVector::<f64, 12>::from_column_slice(&x);
    for i in 0..n {
        assert!((ax[i] - rhs[i]).abs() < 1e-10);
    }
    cholesky::invert_in_place(&mut m, n);
    let inv = M::from_row_slice(&m);
    let id = a * inv;
    for i in 0..n {
        for j in 0..n {
            assert!((id[(i, j)] - if i == j { 1.0 } else { 0.0 }).abs() < 1e-9);
        }
    }
    // Singular (rank-deficient) matrix refused.
    let mut s = vec![1.0, 1.0, 1.0, 1.0];
    assert!(cholesky::factor(&mut s, 2, cholesky::PIVOT_REL_TOL).is_err());
    let mut nan = vec![f64::NAN, 0.0, 0.0, 1.0];
    assert!(cholesky::factor(&mut nan, 2, cholesky::PIVOT_REL_TOL).is_err());
}

#[test]
fn chi_square_quantiles_match_tables() {
    for (q, dof, expected) in [
        (0.95, 1.0, 3.841459),
        (0.975, 10.0, 20.483177),
        (0.025, 10.0, 3.246973),
        (0.999, 2.0, 13.815511),
        (0.975, 1000.0, 1089.531),
        (0.025, 1000.0, 914.2572),
    ] {
        let got = chi2_quantile(q, dof);
        assert!(
            (got - expected).abs() < 1e-4 * expected,
            "chi2({q}, {dof}) = {got}"
        );
    }
    let t = ChiSquareTest::new(10.0, 10);
    assert!(t.passed);
    assert!(!ChiSquareTest::new(30.0, 10).passed);
    assert!(!ChiSquareTest::new(1.0, 0).passed);
}

/// Moves unknown `q` of a pose by `h` as the window does: a turn of the attitude about
/// object axis `q` (0..3), the centre's coordinate `q - 3` (3..6).
fn nudge(p: &mut [f64; 6], q: usize, h: f64) {
    if q < 3 {
        let mut d = [0.0; 3];
        d[q] = h;
        crate::adjust::attitude::turn(p, d);
    } else {
        p[q] += h;
    }
}
