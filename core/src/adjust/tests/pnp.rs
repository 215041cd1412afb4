//! P3P and the RANSAC resection.
use super::*;

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
