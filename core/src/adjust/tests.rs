//! Adjustment tests: Jacobians against central differences, the seed's
//! normal-case intersection, P3P/RANSAC, chi-square quantiles, and synthetic
//! windows with known truth (clean, with blunders, degenerate).
extern crate std;

use super::constraints::{base_length, distance, prior_residual, smoothness, wrap_angle};
use super::geometry::{project_rig, Camera, RigParams};
use super::quality::{chi2_quantile, ChiSquareTest};
use super::*;
use crate::budget::{Arena, MemoryBudget};
use crate::camera::{project, Interior, Pose, Rig};
use nalgebra::Vector3;
use std::vec;
use std::vec::Vec;

/// Deterministic uniform and normal numbers (no std RNG in the core).
pub(crate) struct Rng(pub(crate) u64);
impl Rng {
    pub(crate) fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        lo + (hi - lo) * ((self.0 >> 11) as f64 / (1u64 << 53) as f64)
    }
    pub(crate) fn normal(&mut self) -> f64 {
        let u1 = self.uniform(1e-12, 1.0);
        let u2 = self.uniform(0.0, 1.0);
        libm::sqrt(-2.0 * libm::log(u1)) * libm::cos(2.0 * core::f64::consts::PI * u2)
    }
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
}

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
        let rig = RigParams {
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
        let proj = |l: &Pose, r: &RigParams, p: &[f64; 3]| project_rig(l, r, cam, f, p).unwrap().xy;
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
                proj(&left, &RigParams::from_array(&ra), &point),
                proj(&left, &RigParams::from_array(&rb), &point),
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
    let rig = RigParams {
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
        // Smoothness: every partial over the three epochs' parameters.
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
        let (dt0, dt1) = (0.1, 0.15);
        let (_, jac) = smoothness([&p[0], &p[1], &p[2]], dt0, dt1);
        for col in 0..18 {
            let (mut pp, mut pm) = (p, p);
            pp[col / 6][col % 6] += h;
            pm[col / 6][col % 6] -= h;
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

// ---------- resection ----------

/// Makes the correspondences `wrong` picks outliers (x off by 0.05 to 0.3 mm, either
/// side; y too when `both_axes`) and adds image noise of `sigma` mm to the others.
fn add_outliers_and_noise(
    rng: &mut Rng,
    c: &mut [Correspondence],
    sigma: f64,
    wrong: impl Fn(usize) -> bool,
    both_axes: bool,
) {
    for (i, ci) in c.iter_mut().enumerate() {
        if wrong(i) {
            ci.xy[0] += rng.uniform(0.05, 0.3) * if i % 2 == 0 { 1.0 } else { -1.0 };
            if both_axes {
                ci.xy[1] -= rng.uniform(0.05, 0.3);
            }
        } else {
            ci.xy[0] += sigma * rng.normal();
            ci.xy[1] += sigma * rng.normal();
        }
    }
}

fn resection_scene(rng: &mut Rng, n: usize, f: f64, pose: &Pose) -> Vec<Correspondence> {
    let m = pose.rotation();
    let mut out = Vec::new();
    while out.len() < n {
        let q = nalgebra::Vector3::new(
            rng.uniform(-4.0, 4.0),
            rng.uniform(-3.0, 3.0),
            -rng.uniform(5.0, 30.0),
        );
        let p = pose.centre_vec() + m.transpose() * q;
        let point = [p[0], p[1], p[2]];
        let xy = project(pose, f, &point).unwrap();
        if xy[0].abs() < 3.2 && xy[1].abs() < 2.4 {
            out.push(Correspondence { point, xy });
        }
    }
    out
}

#[test]
fn p3p_recovers_the_true_pose() {
    let mut rng = Rng(21);
    let f = 8.0;
    for _ in 0..50 {
        let truth = Pose::from_params(&[
            rng.uniform(1.4, 1.7),
            rng.uniform(-0.2, 0.2),
            rng.uniform(-0.2, 0.2),
            rng.uniform(-2.0, 2.0),
            rng.uniform(-2.0, 2.0),
            rng.uniform(0.0, 2.0),
        ]);
        let c = resection_scene(&mut rng, 3, f, &truth);
        let mut sols = [Pose::default(); 4];
        let n = p3p(&[c[0], c[1], c[2]], f, &mut sols);
        assert!(n >= 1);
        let best = sols[..n]
            .iter()
            .map(|s| {
                let a = s.to_params();
                let b = truth.to_params();
                (0..6).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max)
            })
            .fold(f64::INFINITY, f64::min);
        assert!(best < 1e-6, "best P3P solution off by {best}");
    }
}

use super::resection::p3p;

#[test]
fn ransac_resection_with_outliers_and_degenerate_input() {
    let mut rng = Rng(33);
    let f = 8.0;
    let sigma = 0.0015; // 0.3 px of 5 um
    let truth = Pose::from_degrees(91.0, 1.5, -2.0, [0.4, 3.0, 1.5]);
    let mut c = resection_scene(&mut rng, 60, f, &truth);
    add_outliers_and_noise(&mut rng, &mut c, sigma, |i| i % 3 == 0, false);
    let cfg = ResectionConfig {
        threshold_mm: 4.0 * sigma,
        ..ResectionConfig::default()
    };
    let r = resect(&c, f, &cfg).unwrap();
    assert_eq!(r.inliers, 40);
    let (a, b) = (r.pose.to_params(), truth.to_params());
    for i in 0..6 {
        assert!(
            (a[i] - b[i]).abs() <= 4.0 * r.std[i] + 1e-12,
            "param {i}: {} vs {} (std {})",
            a[i],
            b[i],
            r.std[i]
        );
    }
    // Same input, same answer (deterministic RANSAC).
    assert_eq!(resect(&c, f, &cfg).unwrap(), r);
    // Too few points, collinear points, NaN.
    assert_eq!(resect(&c[..3], f, &cfg), Err(ResectionError::TooFewPoints));
    let line: Vec<Correspondence> = (0..10)
        .map(|k| {
            let point = [0.5 * k as f64 - 2.0, 15.0, 1.0];
            Correspondence {
                point,
                xy: project(&truth, f, &point).unwrap(),
            }
        })
        .collect();
    assert!(resect(&line, f, &cfg).is_err());
    let mut nan = c.clone();
    nan[5].xy[1] = f64::NAN;
    assert_eq!(resect(&nan, f, &cfg), Err(ResectionError::NotFinite));
}

/// The adaptive stopping rule: the textbook sample counts, and on a set with more
/// outliers than inliers it still finds every inlier, as drawing all samples does.
#[test]
fn ransac_stops_when_the_inlier_ratio_allows_and_not_before() {
    use super::resection::{samples_needed, MIN_RANSAC_SAMPLES};
    // ln(1e-4) / ln(1 - 0.5^3) = 68.97; ln(1e-4) / ln(1 - 0.9^3) = 7.03.
    assert_eq!(samples_needed(50, 100, 0.9999), 69);
    assert_eq!(samples_needed(90, 100, 0.9999), 8);
    assert_eq!(samples_needed(10, 10, 0.9999), 0);
    assert_eq!(samples_needed(0, 10, 0.9999), usize::MAX);
    assert_eq!(samples_needed(5, 10, 1.0), usize::MAX);
    const { assert!(MIN_RANSAC_SAMPLES >= 8) };

    let mut rng = Rng(71);
    let f = 8.0;
    let sigma = 0.0015;
    let truth = Pose::from_degrees(90.5, -1.0, 3.0, [-0.2, 5.0, 1.4]);
    let mut c = resection_scene(&mut rng, 60, f, &truth);
    // 36 of 60 wrong by 0.05 to 0.3 mm (10 to 60 px).
    add_outliers_and_noise(&mut rng, &mut c, sigma, |i| i % 5 < 3, true);
    let adaptive = ResectionConfig {
        threshold_mm: 4.0 * sigma,
        ..ResectionConfig::default()
    };
    let every = ResectionConfig {
        confidence: 1.0,
        ..adaptive
    };
    let (a, e) = (
        resect(&c, f, &adaptive).unwrap(),
        resect(&c, f, &every).unwrap(),
    );
    assert_eq!((a.inliers, e.inliers), (24, 24));
    let (pa, pe) = (a.pose.to_params(), e.pose.to_params());
    for i in 0..6 {
        assert!(
            (pa[i] - pe[i]).abs() <= 1e-3 * a.std[i],
            "param {i}: {} vs {}",
            pa[i],
            pe[i]
        );
    }
}

// ---------- synthetic windows ----------

pub(crate) struct Scene {
    pub rig: Rig,
    pub poses: Vec<Pose>,
    pub points: Vec<[f64; 3]>,
    /// (epoch, camera, point, xy observed, true error added beyond noise)
    pub obs: Vec<(usize, u8, usize, [f64; 2], bool)>,
}

pub(crate) const PIXEL_MM: f64 = 0.005;
pub(crate) const SIGMA_MM: f64 = 0.3 * PIXEL_MM;

/// A random drive: `epochs` stereo pairs about 1 m apart with random attitude,
/// `n_points` street points each seen in at least two epochs, 0.3 px noise,
/// and a fraction `gross` of observations with a 10..50 px blunder.
pub(crate) fn scene(seed: u64, epochs: usize, n_points: usize, gross: f64) -> Scene {
    let mut rng = Rng(seed);
    let cam = Interior {
        width_px: 1280,
        height_px: 960,
        pixel_size_mm: [PIXEL_MM, PIXEL_MM],
        focal_mm: 8.0,
        principal_point_mm: [0.0, 0.0],
        radial: [0.0, 0.0],
        decentering: [0.0, 0.0],
    };
    let mut rig = Rig::rectified(cam, 0.5);
    rig.relative_angles = [0.002, -0.004, 0.001];
    rig.base_m = [0.5, 0.003, -0.002];
    let mut poses = Vec::new();
    let mut y = 0.0;
    let mut x = 0.0;
    for k in 0..epochs {
        if k > 0 {
            y += rng.uniform(0.8, 1.2);
            x += rng.uniform(-0.1, 0.1);
        }
        poses.push(Pose::from_degrees(
            90.0 + rng.uniform(-2.0, 2.0),
            rng.uniform(-2.0, 2.0),
            rng.uniform(-2.0, 2.0),
            [x, y, 1.5 + rng.uniform(-0.05, 0.05)],
        ));
    }
    let half = [3.2 - 0.01, 2.4 - 0.01];
    let mut points = Vec::new();
    let mut obs = Vec::new();
    while points.len() < n_points {
        let p = [
            rng.uniform(-8.0, 8.0),
            rng.uniform(4.0, y + 25.0),
            rng.uniform(-1.0, 6.0),
        ];
        let mut seen = Vec::new();
        for (e, pose) in poses.iter().enumerate() {
            for cam in [Camera::Left, Camera::Right] {
                let rp = RigParams::from_rig(&rig);
                if let Ok(pr) = project_rig(pose, &rp, cam, 8.0, &p) {
                    let depth_ok = (pose.to_camera(&p)[2]) < -3.0;
                    if pr.xy[0].abs() < half[0] && pr.xy[1].abs() < half[1] && depth_ok {
                        seen.push((e, cam as u8, pr.xy));
                    }
                }
            }
        }
        let epochs_seen = {
            let mut v: Vec<usize> = seen.iter().map(|s| s.0).collect();
            v.dedup();
            v.len()
        };
        if epochs_seen < 2 || seen.len() < 4 {
            continue;
        }
        let id = points.len();
        points.push(p);
        for (e, c, xy) in seen {
            let mut m = [
                xy[0] + SIGMA_MM * rng.normal(),
                xy[1] + SIGMA_MM * rng.normal(),
            ];
            let blunder = rng.uniform(0.0, 1.0) < gross;
            if blunder {
                let mag = rng.uniform(10.0, 50.0) * PIXEL_MM;
                let ang = rng.uniform(0.0, 2.0 * core::f64::consts::PI);
                m[0] += mag * libm::cos(ang);
                m[1] += mag * libm::sin(ang);
            }
            obs.push((e, c, id, m, blunder));
        }
    }
    Scene {
        rig,
        poses,
        points,
        obs,
    }
}

/// Loads a scene into a window with perturbed initial values; returns the
/// window and the point indices.
pub(crate) fn load<'a>(
    s: &Scene,
    cfg: AdjustConfig,
    arena: &mut Arena<'a>,
    seed: u64,
) -> (Window<'a>, Vec<u32>) {
    let mut rng = Rng(seed);
    let mut w = Window::new(cfg, &s.rig, arena).unwrap();
    for (k, p) in s.poses.iter().enumerate() {
        let mut q = p.to_params();
        if k > 0 {
            for (i, qi) in q.iter_mut().enumerate() {
                *qi += if i < 3 {
                    rng.uniform(-0.01, 0.01)
                } else {
                    rng.uniform(-0.1, 0.1)
                };
            }
        }
        w.add_epoch(&Pose::from_params(&q), k as f64 * 0.2).unwrap();
    }
    let ids: Vec<u32> = s
        .points
        .iter()
        .map(|p| {
            w.add_point([
                p[0] + rng.uniform(-0.2, 0.2),
                p[1] + rng.uniform(-0.2, 0.2),
                p[2] + rng.uniform(-0.2, 0.2),
            ])
            .unwrap()
        })
        .collect();
    let wt = 1.0 / (SIGMA_MM * SIGMA_MM);
    for (e, c, p, xy, _) in &s.obs {
        let cam = if *c == 0 { Camera::Left } else { Camera::Right };
        w.add_observation(Observation::new(*e as u32, cam, ids[*p], *xy, [wt, wt]))
            .unwrap();
    }
    (w, ids)
}

/// Fraction of parameters (poses and points) within `k` sigma of the truth.
pub(crate) fn within(w: &Window, s: &Scene, ids: &[u32], k: f64) -> (usize, usize) {
    let (mut ok, mut n) = (0, 0);
    for (e, truth) in s.poses.iter().enumerate() {
        let est = w.epoch_pose(e).unwrap().to_params();
        let std = w.epoch_std(e).unwrap();
        let t = truth.to_params();
        for i in 0..6 {
            n += 1;
            // The datum epoch has sigma ~1e-6: compare at that scale.
            if (est[i] - t[i]).abs() <= k * std[i] + 1e-9 {
                ok += 1;
            }
        }
    }
    for (p, truth) in s.points.iter().enumerate() {
        let (Some(est), Some(std)) = (w.point(ids[p]), w.point_std(ids[p])) else {
            continue;
        };
        for a in 0..3 {
            n += 1;
            if (est[a] - truth[a]).abs() <= k * std[a] {
                ok += 1;
            }
        }
    }
    (ok, n)
}

fn arena_for(cfg: &AdjustConfig) -> Vec<u8> {
    let mut b = MemoryBudget::new();
    cfg.budget(&mut b);
    vec![0u8; b.total()]
}

#[test]
fn budget_matches_what_the_window_takes() {
    let cfg = AdjustConfig {
        window: 8,
        max_points: 300,
        max_observations: 1200,
        ..AdjustConfig::default()
    };
    let mut b = MemoryBudget::new();
    cfg.budget(&mut b);
    let mut mem = vec![0u8; b.total()];
    let mut arena = Arena::new(&mut mem);
    let s = scene(1, 3, 30, 0.0);
    let (_w, _) = load(&s, cfg, &mut arena, 2);
    assert!(arena.used() <= b.total_with_prefix("adjust."));
    assert!(
        arena.used() + 128 >= b.total_with_prefix("adjust."),
        "used {} predicted {}",
        arena.used(),
        b.total()
    );
}

#[test]
fn clean_windows_are_unbiased_with_unit_sigma0() {
    let (mut ok, mut n) = (0, 0);
    for (seed, epochs, points) in [
        (1u64, 2usize, 50usize),
        (2, 5, 200),
        (3, 8, 300),
        (4, 20, 500),
    ] {
        let s = scene(seed, epochs, points, 0.0);
        let cfg = AdjustConfig {
            window: epochs,
            max_points: points,
            max_observations: s.obs.len(),
            robust: Robust::None,
            ..AdjustConfig::default()
        };
        let mut mem = arena_for(&cfg);
        let mut arena = Arena::new(&mut mem);
        let (mut w, ids) = load(&s, cfg, &mut arena, seed + 100);
        let r = w.solve().unwrap();
        assert!(r.converged, "{r:?}");
        assert!(
            (r.sigma0 - 1.0).abs() < 0.1,
            "seed {seed}: sigma0 {}",
            r.sigma0
        );
        assert!(r.chi2.passed, "seed {seed}: {:?}", r.chi2);
        assert_eq!(r.excluded_points, 0);
        let (o, t) = within(&w, &s, &ids, 3.0);
        ok += o;
        n += t;
    }
    let frac = ok as f64 / n as f64;
    assert!(frac >= 0.99, "{ok}/{n} within 3 sigma");
}

/// The per-point observation lists of the last adjustment hold exactly each point's
/// observations, and are withdrawn as soon as an observation or a point is added.
#[test]
fn point_observation_lists_follow_the_last_adjustment() {
    let s = scene(5, 3, 60, 0.0);
    let cfg = AdjustConfig {
        window: 3,
        max_points: 61,
        max_observations: s.obs.len() + 1,
        ..AdjustConfig::default()
    };
    let mut mem = arena_for(&cfg);
    let mut arena = Arena::new(&mut mem);
    let (mut w, ids) = load(&s, cfg, &mut arena, 9);
    assert!(
        w.point_observations(ids[0]).is_none(),
        "no index before a solve"
    );
    w.solve().unwrap();
    let mut listed = 0;
    for &id in &ids {
        let list = w.point_observations(id).expect("indexed after the solve");
        let expected: Vec<u32> = (0..w.observations().len() as u32)
            .filter(|&i| w.observations()[i as usize].point == id)
            .collect();
        assert_eq!(list, &expected[..], "point {id}");
        listed += list.len();
    }
    assert_eq!(listed, s.obs.len());
    let extra = w.add_point(s.points[0]).unwrap();
    assert!(
        w.point_observations(ids[0]).is_none(),
        "stale after add_point"
    );
    w.solve().unwrap();
    assert_eq!(w.point_observations(extra), Some(&[][..]));
    let (e, c, _, xy, _) = s.obs[0];
    let cam = if c == 0 { Camera::Left } else { Camera::Right };
    w.add_observation(Observation::new(e as u32, cam, extra, xy, [1.0, 1.0]))
        .unwrap();
    assert!(
        w.point_observations(extra).is_none(),
        "stale after add_observation"
    );
}

#[test]
fn robust_default_flags_blunders_on_clean_and_dirty_data() {
    // Clean data: the default (snooping) flags almost nothing.
    let s = scene(7, 6, 300, 0.0);
    let cfg = AdjustConfig {
        window: 6,
        max_points: 300,
        max_observations: s.obs.len(),
        ..AdjustConfig::default()
    };
    let mut mem = arena_for(&cfg);
    let mut arena = Arena::new(&mut mem);
    let (mut w, _) = load(&s, cfg, &mut arena, 8);
    let r = w.solve().unwrap();
    assert!(r.flagged as f64 <= 0.01 * s.obs.len() as f64, "{r:?}");
    assert!(r.chi2.passed, "{r:?}");

    // 10 % gross errors of 10..50 px.
    let (mut caught, mut blunders, mut false_flags, mut good) = (0, 0, 0, 0);
    let (mut ok, mut n) = (0, 0);
    for seed in [11u64, 12] {
        let s = scene(seed, 6, 300, 0.10);
        let cfg = AdjustConfig {
            window: 6,
            max_points: 300,
            max_observations: s.obs.len(),
            ..AdjustConfig::default()
        };
        let mut mem = arena_for(&cfg);
        let mut arena = Arena::new(&mut mem);
        let (mut w, ids) = load(&s, cfg, &mut arena, seed);
        let r = w.solve().unwrap();
        for (i, o) in w.observations().iter().enumerate() {
            if s.obs[i].4 {
                blunders += 1;
                caught += o.is_flagged() as usize;
            } else {
                good += 1;
                false_flags += o.is_flagged() as usize;
            }
        }
        assert!((r.sigma0 - 1.0).abs() < 0.1, "{r:?}");
        let (o, t) = within(&w, &s, &ids, 3.0);
        ok += o;
        n += t;
    }
    assert!(
        caught as f64 >= 0.99 * blunders as f64,
        "caught {caught}/{blunders}"
    );
    assert!(
        false_flags as f64 <= 0.01 * good as f64,
        "false {false_flags}/{good}"
    );
    assert!(ok as f64 >= 0.99 * n as f64, "{ok}/{n} within 3 sigma");
}

#[test]
fn estimated_rig_and_sliding_window_stay_within_three_sigma() {
    // Rig estimated with a prior, perturbed start; then slide through 8 epochs with a window of 4.
    let s = scene(21, 8, 400, 0.0);
    let cfg = AdjustConfig {
        window: 4,
        max_points: 400,
        max_observations: s.obs.len(),
        estimate_rig: true,
        sigmas: ConstraintSigmas {
            rig_angle_rad: 0.01,
            rig_base_m: 0.01,
            base_length_m: 0.01,
            velocity_change_mps: 5.0,
            ..ConstraintSigmas::default()
        },
        ..AdjustConfig::default()
    };
    let mut mem = arena_for(&cfg);
    let mut arena = Arena::new(&mut mem);
    let mut w = Window::new(cfg, &s.rig, &mut arena).unwrap();
    let wt = 1.0 / (SIGMA_MM * SIGMA_MM);
    let mut ids = vec![u32::MAX; s.points.len()];
    let (mut ok, mut n) = (0, 0);
    for k in 0..8 {
        if w.n_epochs() == 4 {
            let dropped = w.slide().unwrap();
            let t = s.poses[k - 4].to_params();
            let d = dropped.to_params();
            for i in 0..6 {
                assert!(
                    (d[i] - t[i]).abs() < 0.01,
                    "dropped epoch {} param {i}",
                    k - 4
                );
            }
        }
        let mut q = s.poses[k].to_params();
        if k > 0 {
            q[4] += 0.05;
            q[0] += 0.003;
        }
        let id = w.add_epoch(&Pose::from_params(&q), 0.2 * k as f64).unwrap();
        assert_eq!(id as usize, k);
        for (e, c, p, xy, _) in &s.obs {
            if *e != k {
                continue;
            }
            if ids[*p] == u32::MAX
                || w.point_excluded(ids[*p])
                    && w.point(ids[*p]).is_none()
                    && w.observations().iter().all(|o| o.point != ids[*p])
            {
                let t = s.points[*p];
                ids[*p] = w.add_point([t[0] + 0.1, t[1] - 0.1, t[2] + 0.05]).unwrap();
            }
            let cam = if *c == 0 { Camera::Left } else { Camera::Right };
            w.add_observation(Observation::new(k as u32, cam, ids[*p], *xy, [wt, wt]))
                .unwrap();
        }
        if k == 0 {
            continue;
        }
        let r = w.solve().unwrap();
        assert!(r.converged && r.chi2.passed, "epoch {k}: {r:?}");
        let first = w.epoch_id(0).unwrap() as usize;
        for slot in 0..w.n_epochs() {
            let est = w.epoch_pose(slot).unwrap().to_params();
            let sd = w.epoch_std(slot).unwrap();
            let t = s.poses[first + slot].to_params();
            for i in 0..6 {
                n += 1;
                ok += ((est[i] - t[i]).abs() <= 3.0 * sd[i] + 1e-9) as usize;
            }
        }
        let rs = w.rig_std();
        let est = w.rig().to_array();
        let truth = RigParams::from_rig(&s.rig).to_array();
        for i in 0..6 {
            n += 1;
            ok += ((est[i] - truth[i]).abs() <= 3.0 * rs[i]) as usize;
        }
    }
    assert!(ok as f64 >= 0.97 * n as f64, "{ok}/{n}");
}

#[test]
fn degenerate_input_errors_or_flags_never_panics() {
    let cam = Interior::pinhole_px(1280, 960, 1600.0);
    // Zero base.
    let cfg = AdjustConfig {
        window: 3,
        max_points: 50,
        max_observations: 400,
        ..AdjustConfig::default()
    };
    let mut mem = arena_for(&cfg);
    {
        let mut arena = Arena::new(&mut mem);
        assert!(matches!(
            Window::new(cfg, &Rig::rectified(cam, 0.0), &mut arena),
            Err(AdjustError::ZeroBase)
        ));
    }
    // Out of memory, invalid config.
    {
        let mut small = [0u8; 64];
        let mut arena = Arena::new(&mut small);
        assert!(matches!(
            Window::new(cfg, &Rig::rectified(cam, 0.5), &mut arena),
            Err(AdjustError::OutOfMemory(_))
        ));
        let mut arena = Arena::new(&mut mem);
        let bad = AdjustConfig { window: 0, ..cfg };
        assert!(matches!(
            Window::new(bad, &Rig::rectified(cam, 0.5), &mut arena),
            Err(AdjustError::InvalidConfig)
        ));
    }
    let s = scene(31, 3, 40, 0.0);
    let wt = 1.0 / (SIGMA_MM * SIGMA_MM);
    // NaN observation, NaN pose, unknown ids, capacity.
    {
        let mut arena = Arena::new(&mut mem);
        let (mut w, ids) = load(&s, cfg, &mut arena, 1);
        let nan = Observation::new(0, Camera::Left, ids[0], [f64::NAN, 0.0], [wt, wt]);
        assert_eq!(w.add_observation(nan), Err(AdjustError::NotFinite));
        let zero_w = Observation::new(0, Camera::Left, ids[0], [0.0, 0.0], [0.0, wt]);
        assert_eq!(w.add_observation(zero_w), Err(AdjustError::NotFinite));
        assert_eq!(
            w.add_observation(Observation::new(
                9,
                Camera::Left,
                ids[0],
                [0.0; 2],
                [wt, wt]
            )),
            Err(AdjustError::Unknown)
        );
        assert_eq!(
            w.add_epoch(&Pose::from_params(&[f64::NAN; 6]), 0.0),
            Err(AdjustError::NotFinite)
        );
        assert_eq!(w.add_epoch(&s.poses[0], 1.0), Err(AdjustError::WindowFull));
        for _ in 0..20 {
            let _ = w.add_point([0.0, 10.0, 0.0]);
        }
        assert!(w.dropped().0 > 0);
        // Still solvable: points without observations are simply excluded.
        let r = w.solve().unwrap();
        assert!(r.excluded_points > 0 && r.chi2.passed, "{r:?}");
    }
    // Too few points: one point seen in two epochs cannot fix epoch 1.
    {
        let mut arena = Arena::new(&mut mem);
        let mut w = Window::new(cfg, &s.rig, &mut arena).unwrap();
        w.add_epoch(&s.poses[0], 0.0).unwrap();
        w.add_epoch(&s.poses[1], 0.2).unwrap();
        let p = w.add_point(s.points[0]).unwrap();
        for (e, c, pi, xy, _) in s.obs.iter().filter(|o| o.2 == 0 && o.0 < 2) {
            let cam = if *c == 0 { Camera::Left } else { Camera::Right };
            let _ = pi;
            w.add_observation(Observation::new(*e as u32, cam, p, *xy, [wt, wt]))
                .unwrap();
        }
        let r = w.solve();
        assert!(
            matches!(
                r,
                Err(AdjustError::Singular { .. }) | Err(AdjustError::NoRedundancy)
            ),
            "{r:?}"
        );
    }
    // All points on a line: the second epoch can rotate about it.
    {
        let mut arena = Arena::new(&mut mem);
        let mut w = Window::new(cfg, &s.rig, &mut arena).unwrap();
        w.add_epoch(&s.poses[0], 0.0).unwrap();
        w.add_epoch(&s.poses[1], 0.2).unwrap();
        let rp = RigParams::from_rig(&s.rig);
        for k in 0..30 {
            let pt = [-3.0 + 0.2 * k as f64, 15.0, 1.0];
            let id = w.add_point(pt).unwrap();
            for e in 0..2 {
                for cam in [Camera::Left, Camera::Right] {
                    let xy = project_rig(&s.poses[e], &rp, cam, 8.0, &pt).unwrap().xy;
                    w.add_observation(Observation::new(e as u32, cam, id, xy, [wt, wt]))
                        .unwrap();
                }
            }
        }
        let r = w.solve();
        assert!(
            matches!(r, Err(AdjustError::Singular { epoch: 1 })),
            "{r:?}"
        );
        assert_eq!(w.singular_epoch(), Some(1));
    }
    // A point at infinity (identical rays) is excluded, the rest adjusts.
    {
        let mut arena = Arena::new(&mut mem);
        let (mut w, _) = load(&s, cfg, &mut arena, 3);
        let far = w.add_point([0.0, 1e12, 0.0]).unwrap();
        let xy = [0.0, 0.0];
        for e in 0..3u32 {
            w.add_observation(Observation::new(e, Camera::Left, far, xy, [wt, wt]))
                .unwrap();
            w.add_observation(Observation::new(e, Camera::Right, far, xy, [wt, wt]))
                .unwrap();
        }
        let r = w.solve().unwrap();
        assert!(w.point_excluded(far), "{r:?}");
        assert!(r.excluded_points >= 1);
    }
    // Too few epochs to slide, nothing to solve.
    {
        let mut arena = Arena::new(&mut mem);
        let mut w = Window::new(cfg, &s.rig, &mut arena).unwrap();
        assert_eq!(w.solve(), Err(AdjustError::TooFewEpochs));
        assert_eq!(w.slide(), Err(AdjustError::TooFewEpochs));
        w.add_epoch(&s.poses[0], 0.0).unwrap();
        assert_eq!(w.solve(), Err(AdjustError::NoRedundancy));
    }
}

#[test]
fn seed_weighting_schemes_and_seed_reweighting() {
    use super::weighting::{weights, Scheme, SEED_EQUAL_WEIGHT};
    // Parallax: p_x = pa_x^2, p_y = 1/pa_y^2 (seed 000 L1245-1247).
    let w = weights(Scheme::Parallax, [2.0, 0.5], Some([1.0, 0.3]));
    assert!(close(w[0], 1.0, 1e-12) && close(w[1], 25.0, 1e-12));
    // Zero y-parallax is bounded, never a division by zero.
    assert!(weights(Scheme::Parallax, [2.0, 0.5], Some([1.0, 0.5]))[1].is_finite());
    assert!(close(
        weights(Scheme::Radial, [3.0, 4.0], None)[0],
        5.0,
        1e-12
    ));
    assert_eq!(
        weights(Scheme::Equal, [3.0, 4.0], None),
        [SEED_EQUAL_WEIGHT; 2]
    );
    assert!(close(
        weights(Scheme::Sigma(0.002), [0.0; 2], None)[1],
        250000.0,
        1e-12
    ));

    // Seed 000's re-weighting: residual_x above the pixel size -> weight 1e-5, once.
    let s = scene(41, 4, 200, 0.05);
    let cfg = AdjustConfig {
        window: 4,
        max_points: 200,
        max_observations: s.obs.len(),
        robust: Robust::SeedReweight {
            threshold_mm: PIXEL_MM,
        },
        ..AdjustConfig::default()
    };
    let mut mem = arena_for(&cfg);
    let mut arena = Arena::new(&mut mem);
    let (mut w, _) = load(&s, cfg, &mut arena, 4);
    let r = w.solve().unwrap();
    assert_eq!(r.robust_rounds, 1);
    let flagged: Vec<usize> = w.flagged().map(|(i, _)| i).collect();
    assert!(!flagged.is_empty());
    for &i in &flagged {
        assert_eq!(
            w.observations()[i].weight,
            // Stored in f32 (see `Observation`).
            [super::weighting::SEED_REWEIGHT as f32; 2]
        );
    }
    // Most blunders have an x residual above one pixel.
    let caught = flagged.iter().filter(|&&i| s.obs[i].4).count();
    let blunders = s.obs.iter().filter(|o| o.4).count();
    assert!(
        caught as f64 >= 0.6 * blunders as f64,
        "{caught}/{blunders}"
    );
}

#[test]
fn gnss_and_odometer_constraints_enter_the_adjustment() {
    // GNSS on the first and last epochs only (an outage in between) and odometer legs.
    let s = scene(51, 6, 150, 0.0);
    let cfg = AdjustConfig {
        window: 6,
        max_points: 150,
        max_observations: s.obs.len(),
        sigmas: ConstraintSigmas {
            velocity_change_mps: 2.0,
            ..ConstraintSigmas::default()
        },
        ..AdjustConfig::default()
    };
    let mut mem = arena_for(&cfg);
    let mut arena = Arena::new(&mut mem);
    let (mut w, ids) = load(&s, cfg, &mut arena, 52);
    let mut rng = Rng(53);
    for e in [0usize, 5] {
        let c = s.poses[e].centre;
        let g = [
            c[0] + 0.02 * rng.normal(),
            c[1] + 0.02 * rng.normal(),
            c[2] + 0.02 * rng.normal(),
        ];
        w.set_gnss(e as u32, g, 0.02).unwrap();
    }
    for e in 1..6 {
        let (a, b) = (s.poses[e - 1].centre, s.poses[e].centre);
        let d = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2) + (b[2] - a[2]).powi(2)).sqrt();
        w.set_odometer(e as u32, d + 0.01 * rng.normal(), 0.01)
            .unwrap();
    }
    assert_eq!(w.set_gnss(9, [0.0; 3], 1.0), Err(AdjustError::Unknown));
    assert_eq!(w.set_odometer(1, 1.0, 0.0), Err(AdjustError::NotFinite));
    let r = w.solve().unwrap();
    // 6 datum + 2 x 3 GNSS + 5 odometer + 4 x 3 smoothness equations.
    assert_eq!(r.constraints, 6 + 6 + 5 + 12);
    assert!(r.chi2.passed && (r.sigma0 - 1.0).abs() < 0.1, "{r:?}");
    let (ok, n) = within(&w, &s, &ids, 3.0);
    assert!(ok as f64 >= 0.99 * n as f64, "{ok}/{n}");
}

#[test]
fn control_points_carry_a_loose_datum() {
    // Datum almost free (0.1 rad, 1 m); eight control points at 5 mm fix the block.
    let s = scene(61, 4, 200, 0.0);
    let cfg = AdjustConfig {
        window: 4,
        max_points: 200,
        max_observations: s.obs.len(),
        sigmas: ConstraintSigmas {
            datum_angle_rad: 0.1,
            datum_position_m: 1.0,
            ..ConstraintSigmas::default()
        },
        ..AdjustConfig::default()
    };
    let mut mem = arena_for(&cfg);
    let mut arena = Arena::new(&mut mem);
    let (mut w, ids) = load(&s, cfg, &mut arena, 62);
    let mut rng = Rng(63);
    for k in 0..8 {
        let p = s.points[k * 20];
        let c = [
            p[0] + 0.005 * rng.normal(),
            p[1] + 0.005 * rng.normal(),
            p[2] + 0.005 * rng.normal(),
        ];
        w.set_point_prior(ids[k * 20], c, 0.005).unwrap();
    }
    assert_eq!(
        w.set_point_prior(9999, [0.0; 3], 1.0),
        Err(AdjustError::Unknown)
    );
    let r = w.solve().unwrap();
    assert_eq!(r.constraints, 6 + 8 * 3);
    assert!(r.chi2.passed, "{r:?}");
    let (ok, n) = within(&w, &s, &ids, 3.0);
    assert!(ok as f64 >= 0.99 * n as f64, "{ok}/{n}");
    // The first epoch is now determined by the control (cm level), not by its 1 m prior.
    assert!(w.epoch_std(0).unwrap()[3] < 0.05);
}

#[test]
fn absurd_configurations_give_a_budget_and_an_error_not_a_panic() {
    for cfg in [
        AdjustConfig {
            window: usize::MAX,
            max_points: usize::MAX,
            max_observations: usize::MAX,
            ..AdjustConfig::default()
        },
        AdjustConfig {
            window: 5000,
            ..AdjustConfig::default()
        },
        AdjustConfig {
            max_points: 0,
            ..AdjustConfig::default()
        },
    ] {
        let mut b = MemoryBudget::new();
        cfg.budget(&mut b);
        assert!(b.total() > 0);
        let mut mem = [0u8; 256];
        let mut arena = Arena::new(&mut mem);
        let rig = Rig::rectified(Interior::pinhole_px(100, 100, 100.0), 0.5);
        assert!(Window::new(cfg, &rig, &mut arena).is_err());
    }
}

#[test]
fn perturbed_rig_is_recovered_and_survives_slides() {
    // Observations from the true rig; the window starts from a rig with its relative
    // angles off by ~0.2 deg and its base direction off by 5 mm (the base length is
    // the calibrated one: images alone carry no scale). Window of 4 over 10 epochs.
    let s = scene(33, 10, 500, 0.0);
    let mut start = s.rig;
    start.relative_angles = [
        s.rig.relative_angles[0] + 0.003,
        s.rig.relative_angles[1] - 0.002,
        s.rig.relative_angles[2] + 0.004,
    ];
    start.base_m = [
        s.rig.base_m[0],
        s.rig.base_m[1] + 0.004,
        s.rig.base_m[2] - 0.003,
    ];
    let cfg = AdjustConfig {
        window: 4,
        max_points: 500,
        max_observations: s.obs.len(),
        estimate_rig: true,
        sigmas: loose_rig_prior(),
        ..AdjustConfig::default()
    };
    let mut mem = arena_for(&cfg);
    let mut arena = Arena::new(&mut mem);
    let mut w = Window::new(cfg, &start, &mut arena).unwrap();
    w.set_base_length(s.rig.base_length());
    let truth = RigParams::from_rig(&s.rig).to_array();
    let wt = 1.0 / (SIGMA_MM * SIGMA_MM);
    let mut ids = vec![u32::MAX; s.points.len()];
    let mut first_full_std = None;
    for k in 0..10 {
        if w.n_epochs() == 4 {
            let before = w.rig();
            w.slide().unwrap();
            // A shared parameter: the slide keeps its value.
            assert_eq!(w.rig(), before, "slide before epoch {k}");
        }
        w.add_epoch(&s.poses[k], 0.2 * k as f64).unwrap();
        for (e, c, p, xy, _) in &s.obs {
            if *e != k {
                continue;
            }
            let alive = ids[*p] != u32::MAX && w.point(ids[*p]).is_some();
            if !alive {
                let t = s.points[*p];
                ids[*p] = w
                    .add_point([t[0] + 0.05, t[1] - 0.05, t[2] + 0.02])
                    .unwrap();
            }
            let cam = if *c == 0 { Camera::Left } else { Camera::Right };
            w.add_observation(Observation::new(k as u32, cam, ids[*p], *xy, [wt, wt]))
                .unwrap();
        }
        if k == 0 {
            continue;
        }
        let r = w.solve().unwrap();
        assert!(r.converged, "epoch {k}: {r:?}");
        let est = w.rig().to_array();
        let sd = w.rig_std();
        for i in 0..6 {
            assert!(sd[i] > 0.0, "epoch {k}: std {i} {sd:?}");
            assert!(
                (est[i] - truth[i]).abs() <= 3.0 * sd[i],
                "epoch {k}: rig parameter {i}: {} vs truth {} (std {})",
                est[i],
                truth[i],
                sd[i]
            );
        }
        if k == 3 {
            first_full_std = Some(sd);
        }
        if k == 9 {
            // What the six dropped epochs told about the rig is kept: with a window
            // of four, about 10/4 of the first full window's information.
            let f = first_full_std.unwrap();
            for i in 0..3 {
                assert!(sd[i] < 0.85 * f[i], "angle {i}: {} vs {}", sd[i], f[i]);
            }
        }
    }
    // Started 0.2 deg and 5 mm away: now within a fraction of that.
    let est = w.rig().to_array();
    for i in 0..3 {
        assert!((est[i] - truth[i]).abs() < 3e-4, "angle {i}: {est:?}");
    }
    for i in 4..6 {
        assert!((est[i] - truth[i]).abs() < 1e-3, "base {i}: {est:?}");
    }
}

/// A loose prior on the rig (10 mrad, 1 cm) with the base length held (0.1 mm).
fn loose_rig_prior() -> ConstraintSigmas {
    ConstraintSigmas {
        rig_angle_rad: 0.01,
        rig_base_m: 0.01,
        base_length_m: 1e-4,
        ..ConstraintSigmas::default()
    }
}

/// Every epoch, point and observation of `s` in `w` (the base length held at the
/// truth's); `right` maps each right observation. The window indices of the points.
fn fill_whole_scene(w: &mut Window, s: &Scene, right: impl Fn([f64; 2]) -> [f64; 2]) -> Vec<u32> {
    w.set_base_length(s.rig.base_length());
    for p in &s.poses {
        w.add_epoch(p, 0.0).unwrap();
    }
    let ids: Vec<u32> = s.points.iter().map(|p| w.add_point(*p).unwrap()).collect();
    let wt = 1.0 / (SIGMA_MM * SIGMA_MM);
    for (e, c, p, xy, _) in &s.obs {
        let (cam, xy) = if *c == 0 {
            (Camera::Left, *xy)
        } else {
            (Camera::Right, right(*xy))
        };
        w.add_observation(Observation::new(*e as u32, cam, ids[*p], xy, [wt, wt]))
            .unwrap();
    }
    ids
}

/// RMS error of the adjusted points `ids` against the truth of `s`, metres.
fn point_rms(w: &Window, ids: &[u32], s: &Scene) -> f64 {
    let sq: f64 = ids
        .iter()
        .zip(&s.points)
        .filter_map(|(id, t)| {
            w.point(*id)
                .map(|p| (0..3).map(|a| (p[a] - t[a]).powi(2)).sum::<f64>())
        })
        .sum();
    libm::sqrt(sq / ids.len() as f64)
}

/// A window over the whole scene (`Robust::None`, loose rig prior, base length held),
/// solved; `right` maps each right observation (a calibration error of that camera).
fn solve_with_right_error(
    s: &Scene,
    start: &Rig,
    estimate_rig: bool,
    self_calibration: Option<InteriorSigmas>,
    right: impl Fn([f64; 2]) -> [f64; 2],
) -> (RigParams, [f64; 6], InteriorCorrections, [f64; 6], f64, f64) {
    let cfg = AdjustConfig {
        window: s.poses.len(),
        max_points: s.points.len(),
        max_observations: s.obs.len(),
        estimate_rig,
        self_calibration,
        robust: Robust::None,
        sigmas: loose_rig_prior(),
        ..AdjustConfig::default()
    };
    let mut mem = arena_for(&cfg);
    let mut arena = Arena::new(&mut mem);
    let mut w = Window::new(cfg, start, &mut arena).unwrap();
    let ids = fill_whole_scene(&mut w, s, right);
    let r = w.solve().unwrap();
    assert!(r.converged, "{r:?}");
    let rms = point_rms(&w, &ids, s);
    (
        w.rig(),
        w.rig_std(),
        w.interior(),
        w.interior_std(),
        r.sigma0,
        rms,
    )
}

#[test]
fn right_principal_point_error_is_absorbed_by_the_rig_phi() {
    // The right camera's calibrated principal point is 1 px off in x: every right
    // observation is shifted by one pixel, a disparity offset. A relative rotation phi
    // of about 1/f rad moves the right image the same way (up to (x/f)^2 off the
    // centre), so the estimated rig takes it and the residuals stay at the noise.
    let s = scene(91, 5, 300, 0.0);
    let shift = |xy: [f64; 2]| [xy[0] + PIXEL_MM, xy[1]];
    // The equivalent angle: the shift over d(xc)/d(phi) at the right image's centre.
    let left = s.poses[0];
    let rp = RigParams::from_rig(&s.rig);
    let right_pose = geometry::camera_pose(&left, &rp, Camera::Right);
    let ahead =
        right_pose.centre_vec() + right_pose.rotation().transpose() * Vector3::new(0.0, 0.0, -10.0);
    let pr = project_rig(
        &left,
        &rp,
        Camera::Right,
        8.0,
        &[ahead[0], ahead[1], ahead[2]],
    )
    .unwrap();
    let equivalent = PIXEL_MM / pr.d_rig[0][1];
    assert!((equivalent.abs() - PIXEL_MM / 8.0).abs() < 1e-3 * PIXEL_MM / 8.0);

    let (rig, sd, _, _, sigma0, rms) = solve_with_right_error(&s, &s.rig, true, None, shift);
    let dphi = rig.angles[1] - s.rig.relative_angles[1];
    assert!(
        (dphi - equivalent).abs() < 0.1 * equivalent.abs(),
        "phi moved by {dphi} rad, the 1 px equivalent is {equivalent} (std {})",
        sd[1]
    );
    assert!(sigma0 < 1.15, "sigma0 {sigma0} with the rig estimated");
    // The base keeps its calibrated direction within 3 sigma: the angle took the error.
    for a in 1..3 {
        assert!(
            (rig.base[a] - s.rig.base_m[a]).abs() < 3.0 * sd[3 + a],
            "base {a}: {rig:?}"
        );
    }
    // With the rig held at the calibration the points take the offset as depth.
    let (_, _, _, _, _, fixed) = solve_with_right_error(&s, &s.rig, false, None, shift);
    assert!(
        fixed > 2.0 * rms,
        "point RMS {fixed} m with the rig fixed, {rms} m estimated"
    );
}

#[test]
fn right_focal_error_is_absorbed_by_the_self_calibration() {
    // The right camera's calibrated focal length is 0.6 % short (the two cameras'
    // calibration errors of 0.3 % with opposite signs). No relative orientation
    // explains a scale between the images: the base's y and z components bend to
    // absorb it. With the self-calibration the right focal length takes it and the
    // base stays where it is.
    let s = scene(92, 5, 300, 0.0);
    let mut start = s.rig;
    start.right.focal_mm = 8.0 * (1.0 - 0.006);
    let held = InteriorSigmas {
        principal_point_mm: [1e-4, 0.01],
        focal_mm: [1e-4, 0.08],
    };
    let (rig, sd, intr, isd, sigma0, _) =
        solve_with_right_error(&s, &start, true, Some(held), |xy| xy);
    let df = 8.0 * 0.006;
    assert!(
        (intr[5] - df).abs() < 3.0 * isd[5] && (intr[5] - df).abs() < 0.05 * df,
        "right focal correction {} mm (std {}), truth {df}",
        intr[5],
        isd[5]
    );
    assert!(sigma0 < 1.15, "sigma0 {sigma0}");
    let truth = RigParams::from_rig(&s.rig).to_array();
    let est = rig.to_array();
    for i in 0..6 {
        assert!(
            (est[i] - truth[i]).abs() < 4.0 * sd[i],
            "rig {i}: {est:?} vs {truth:?} (std {sd:?})"
        );
    }
    // Without it the base moves by many of its own sigmas and sigma0 grows.
    let (bent, bsd, _, _, s0, _) = solve_with_right_error(&s, &start, true, None, |xy| xy);
    let off = (1..3)
        .map(|a| (bent.base[a] - s.rig.base_m[a]).abs() / bsd[3 + a])
        .fold(0.0, f64::max);
    assert!(
        off > 5.0 || s0 > 1.5 * sigma0,
        "base {bent:?} ({off} sigma), sigma0 {s0}"
    );
}

/// What a window over the whole scene found with the calibration `start`: held (and
/// tested, then corrected once when `correct`) or, without `hold`, simply fixed.
struct HeldRun {
    poses: Vec<Pose>,
    /// Test statistic before and after the correction (0 when not tested).
    statistic: [f64; 2],
    /// RMS displacement of the newest epoch's observations by the first correction, px.
    effect_px: f64,
    dof: usize,
    /// RMS error of the points against the truth, metres.
    rms: f64,
    rig: RigParams,
    interior: InteriorCorrections,
}

fn held_run(s: &Scene, start: &Rig, hold: bool, correct: bool) -> HeldRun {
    let cfg = AdjustConfig {
        window: s.poses.len(),
        max_points: s.points.len(),
        max_observations: s.obs.len(),
        estimate_rig: hold,
        self_calibration: hold.then_some(InteriorSigmas {
            principal_point_mm: [1e-4, 2.0 * PIXEL_MM],
            focal_mm: [1e-4, 0.01 * 8.0],
        }),
        hold_calibration: hold,
        robust: Robust::None,
        sigmas: loose_rig_prior(),
        ..AdjustConfig::default()
    };
    let mut mem = arena_for(&cfg);
    let mut arena = Arena::new(&mut mem);
    let mut w = Window::new(cfg, start, &mut arena).unwrap();
    let ids = fill_whole_scene(&mut w, s, |xy| xy);
    let mut r = w.solve().unwrap();
    let mut statistic = [0.0; 2];
    let mut dof = 0;
    let mut effect_px = 0.0;
    if hold {
        let t = w.calibration_test(r.sigma0).unwrap();
        statistic[0] = t.statistic;
        dof = t.dof;
        effect_px = w.correction_effect(&t) / PIXEL_MM;
        if correct {
            w.correct_calibration(&t);
            r = w.solve().unwrap();
            statistic[1] = w.calibration_test(r.sigma0).unwrap().statistic;
        }
    }
    assert!(r.converged, "{r:?}");
    HeldRun {
        poses: (0..w.n_epochs())
            .map(|i| w.epoch_pose(i).unwrap())
            .collect(),
        statistic,
        effect_px,
        dof,
        rms: point_rms(&w, &ids, s),
        rig: w.rig(),
        interior: w.interior(),
    }
}

#[test]
fn a_held_calibration_leaves_the_poses_of_a_fixed_one() {
    let s = scene(93, 5, 300, 0.0);
    let fixed = held_run(&s, &s.rig, false, false);
    let held = held_run(&s, &s.rig, true, false);
    for (a, b) in fixed.poses.iter().zip(&held.poses) {
        let (pa, pb) = (a.to_params(), b.to_params());
        for i in 0..6 {
            assert!((pa[i] - pb[i]).abs() < 1e-9, "{pa:?} vs {pb:?}");
        }
    }
    // A right calibration: the score test stays below its 0.1 % critical value.
    let critical = crate::adjust::quality::chi2_quantile(0.999, held.dof as f64);
    assert_eq!(held.dof, 12);
    assert!(
        held.statistic[0] < critical,
        "statistic {} >= {critical} on the true calibration",
        held.statistic[0]
    );
    // What a correction would do to the observations: noise-level (0.3 px noise).
    assert!(held.effect_px < 0.05, "effect {} px", held.effect_px);
}

#[test]
fn a_wrong_calibration_fails_the_test_and_its_correction_recovers_the_points() {
    // The calibration has the right camera's principal point 1 px off in x and 0.6 %
    // off in focal length, and the rig's phi 0.05 deg off: the observations come from
    // the true rig.
    let s = scene(94, 5, 300, 0.0);
    let mut wrong = s.rig;
    wrong.right.principal_point_mm[0] += PIXEL_MM;
    wrong.right.focal_mm *= 1.006;
    wrong.relative_angles[1] += 0.05f64.to_radians();
    let truth = held_run(&s, &s.rig, false, false);
    let held = held_run(&s, &wrong, true, true);
    let critical = crate::adjust::quality::chi2_quantile(0.999, held.dof as f64);
    assert!(
        held.statistic[0] > 10.0 * critical,
        "statistic {} against {critical}",
        held.statistic[0]
    );
    // Its correction moves the observations by about the error it removes (a pixel of
    // principal point, 0.6 % of focal length, 0.05 deg: between 1 and 3 px).
    assert!(
        held.effect_px > 1.0 && held.effect_px < 3.0,
        "effect {} px",
        held.effect_px
    );
    // One correction takes the calibration to where the test passes...
    assert!(
        held.statistic[1] < critical,
        "after the correction: {} against {critical}",
        held.statistic[1]
    );
    // ... and the right focal length to the truth within 0.05 %.
    let df = held.interior[5] - (s.rig.right.focal_mm - wrong.right.focal_mm);
    assert!(df.abs() < 5e-4 * 8.0, "focal correction off by {df} mm");
    let uncorrected = held_run(&s, &wrong, true, false);
    assert!(
        held.rms < 0.5 * uncorrected.rms && held.rms < 1.5 * truth.rms,
        "point RMS {} m corrected, {} m held wrong, {} m with the truth",
        held.rms,
        uncorrected.rms,
        truth.rms
    );
    assert!(held.rig.angles[1] != wrong.relative_angles[1]);
}
