//! Internal checks: the assembled normal equations against numerical
//! gradients of `vTPv` (constraints and rig chain included).
extern crate std;
use super::*;
use crate::camera::Interior;
use std::vec;

/// Loose datum and a velocity constraint that every step pulls: the constraint
/// tests move the poses away from them to see each one's gradient.
fn sigmas() -> ConstraintSigmas {
    ConstraintSigmas {
        datum_angle_rad: 0.01,
        datum_position_m: 0.01,
        velocity_change_mps: 0.3,
        ..ConstraintSigmas::default()
    }
}

/// Without points the reduced system is the full one: `rhs = -1/2 grad vTPv`.
#[test]
fn constraint_normal_equations_match_numerical_gradient() {
    let cam = Interior::pinhole_px(1000, 800, 900.0);
    let mut rig = Rig::rectified(cam, 0.5);
    rig.relative_angles = [0.01, -0.02, 0.005];
    rig.base_m = [0.5, 0.01, -0.02];
    let cfg = AdjustConfig {
        window: 4,
        estimate_rig: true,
        self_calibration: Some(InteriorSigmas {
            principal_point_mm: [0.01, 0.02],
            focal_mm: [0.03, 0.04],
        }),
        sigmas: ConstraintSigmas {
            base_length_m: 0.002,
            ..sigmas()
        },
        ..AdjustConfig::default()
    };
    let mut mem = vec![0u8; 1 << 20];
    let mut arena = Arena::new(&mut mem);
    let mut w = Window::new(cfg, &rig, &mut arena).unwrap();
    w.set_base_length(0.49);
    for k in 0..4 {
        let pose = Pose::from_degrees(
            90.0 + k as f64,
            0.5 * k as f64,
            -0.3,
            [0.1 * k as f64, 1.1 * k as f64, 0.02],
        );
        let id = w
            .add_epoch(&pose, 0.5 * k as f64 + 0.01 * (k * k) as f64)
            .unwrap();
        w.set_gnss(id, [0.05, 1.0 * k as f64, 0.0], 0.3).unwrap();
        if k > 0 {
            w.set_odometer(id, 1.0, 0.05).unwrap();
        }
    }
    // Move away from the priors so every residual is non-zero.
    w.epochs[0].params[0] += 0.001;
    w.epochs[0].params[4] += 0.002;
    w.rig = RelativeOrientation::from_array(&[0.012, -0.018, 0.004, 0.51, 0.012, -0.019]);
    w.interior = [0.003, -0.002, 0.01, -0.004, 0.001, -0.02];
    assert_rhs_is_the_numerical_gradient(&mut w);
}

/// `rhs = -1/2 grad vTPv` of every camera, rig and interior parameter, by central
/// differences (a window without points).
fn assert_rhs_is_the_numerical_gradient(w: &mut Window) {
    w.build_index();
    w.build(0.0);
    let nc = w.n_cam();
    let rhs: std::vec::Vec<f64> = w.rhs[..nc].to_vec();
    for i in 0..nc {
        let h = 1e-6;
        let (blk, k) = (i / 6, i % 6);
        let val = |w: &mut Window, d: f64| {
            if blk < w.n_epochs && k < 3 {
                let mut turn = [0.0; 3];
                turn[k] = d;
                attitude::turn(&mut w.epochs[blk].params, turn);
            } else if blk < w.n_epochs {
                w.epochs[blk].params[k] += d;
            } else if Some(blk) == w.rig_block() {
                let mut r = w.rig.to_array();
                r[k] += d;
                w.rig = RelativeOrientation::from_array(&r);
            } else {
                w.interior[k] += d;
            }
        };
        val(w, h);
        let cp = w.cost().0;
        val(w, -2.0 * h);
        let cm = w.cost().0;
        val(w, h);
        let num = -(cp - cm) / (2.0 * h) / 2.0;
        let tol = 1e-5 * (1.0 + num.abs().max(rhs[i].abs()));
        assert!(
            (num - rhs[i]).abs() <= tol,
            "param {i}: analytic {} numeric {num}",
            rhs[i]
        );
    }
}

/// The smoothness reaches back over the window's edge to the fixed epochs
/// (constants), in the camera's frame: its equations count once per epoch from
/// the third counted from the oldest fixed one, and their gradient is exact.
#[test]
fn smoothness_spans_the_window_edge() {
    use core::f64::consts::FRAC_PI_2;
    let cam = Interior::pinhole_px(1000, 800, 900.0);
    let rig = Rig::rectified(cam, 0.5);
    let cfg = AdjustConfig {
        window: 3,
        fixed_epochs: 2,
        sigmas: sigmas(),
        ..AdjustConfig::default()
    };
    let mut mem = vec![0u8; 1 << 20];
    let mut arena = Arena::new(&mut mem);
    let mut w = Window::new(cfg, &rig, &mut arena).unwrap();
    // A turn of constant rate and speed: the smoothness holds exactly.
    let pose = |k: usize| {
        let heading = 0.1 * k as f64;
        let r = 20.0;
        let centre = [r * (1.0 - libm::cos(heading)), r * libm::sin(heading), 1.5];
        Pose::from_params(&[FRAC_PI_2, -heading, 0.0, centre[0], centre[1], centre[2]])
    };
    for k in 0..6 {
        if w.n_epochs == 3 {
            w.slide().unwrap();
        }
        w.add_epoch(&pose(k), 0.1 * k as f64).unwrap();
    }
    assert_eq!((w.n_fixed, w.n_epochs), (2, 3));
    w.build_index();
    let (cost, count) = w.add_constraints(false);
    // The carried prior (6) and three smoothness triples over 2 fixed + 3 window epochs.
    assert_eq!(count, 6 + 3 * 3);
    assert!(cost < 1e-16, "a steady turn costs {cost}");
    // Speed up the newest epoch and turn the first window epoch: every triple pulls.
    w.epochs[2].params[4] += 0.05;
    w.epochs[0].params[2] += 0.002;
    w.epochs[1].params[3] -= 0.01;
    assert_rhs_is_the_numerical_gradient(&mut w);
}

/// One Gauss-Newton step through the Schur complement (rig estimated,
/// constraints on) leaves a gradient of `vTPv` (by central differences over
/// every camera, rig and point parameter) orders of magnitude smaller: the
/// Jacobians, the elimination and the back-substitution agree.
#[test]
fn schur_step_zeroes_the_numerical_gradient() {
    use crate::adjust::tests::{load, scene};
    let s = scene(71, 3, 12, 0.0);
    let cfg = AdjustConfig {
        window: 3,
        max_points: 12,
        max_observations: s.observations.len(),
        estimate_rig: true,
        self_calibration: Some(InteriorSigmas {
            principal_point_mm: [0.02, 0.02],
            focal_mm: [0.05, 0.05],
        }),
        robust: Robust::None,
        sigmas: ConstraintSigmas {
            datum_angle_rad: 1e-3,
            datum_position_m: 1e-3,
            base_length_m: 0.01,
            velocity_change_mps: 1.0,
            ..ConstraintSigmas::default()
        },
        ..AdjustConfig::default()
    };
    let mut b = MemoryBudget::new();
    cfg.budget(&mut b);
    let mut mem = vec![0u8; b.total()];
    let mut arena = Arena::new(&mut mem);
    let (mut w, _) = load(&s, cfg, &mut arena, 72);
    w.set_gnss(2, s.poses[2].centre, 0.05).unwrap();
    w.build_index();
    // Start close to the optimum so one step is (nearly) the whole way.
    for _ in 0..3 {
        w.step(0.0).1.unwrap();
    }
    for e in 1..3 {
        w.epochs[e].params[0] += 2e-4;
        w.epochs[e].params[4] += 3e-3;
    }
    let mut r = w.rig.to_array();
    r[1] += 1e-4;
    r[3] += 2e-3;
    w.rig = RelativeOrientation::from_array(&r);
    w.interior[1] += 4e-4;
    w.interior[5] -= 2e-3;
    for p in 0..w.n_point_slots {
        w.points[p].xyz[1] += 5e-3;
    }
    let n_cam = w.n_cam();
    let n = n_cam + 3 * w.n_point_slots;
    let bump = |w: &mut Window, i: usize, d: f64| {
        if i < 6 * w.n_epochs {
            w.epochs[i / 6].params[i % 6] += d;
        } else if i < 6 * w.n_epochs + 6 {
            let mut r = w.rig.to_array();
            r[i - 6 * w.n_epochs] += d;
            w.rig = RelativeOrientation::from_array(&r);
        } else if i < n_cam {
            w.interior[i - 6 * w.n_epochs - 6] += d;
        } else {
            let k = i - n_cam;
            w.points[k / 3].xyz[k % 3] += d;
        }
    };
    let grad_norm = |w: &mut Window| numerical_gradient_norm(w, n, bump);
    let before = grad_norm(&mut w);
    w.step(0.0).1.unwrap();
    let after = grad_norm(&mut w);
    assert!(after < 1e-3 * before, "gradient {before} -> {after}");
}

/// Norm of the numerical gradient of `vTPv` (central differences) over `n` parameters,
/// `bump(w, i, d)` moving parameter `i` by `d`.
fn numerical_gradient_norm(
    w: &mut Window,
    n: usize,
    bump: impl Fn(&mut Window, usize, f64),
) -> f64 {
    let h = 1e-7;
    let mut sum = 0.0;
    for i in 0..n {
        bump(w, i, h);
        let cp = w.cost().0;
        bump(w, i, -2.0 * h);
        let cm = w.cost().0;
        bump(w, i, h);
        let g = (cp - cm) / (2.0 * h);
        sum += g * g;
    }
    libm::sqrt(sum)
}

/// The GNSS residual's attitude derivatives (the lever arm turning with the camera)
/// against numerical differentiation, near the angles' singularity too.
#[test]
fn gnss_lever_arm_jacobian_matches_numeric() {
    let slot = |p: [f64; 6]| {
        let mut e: EpochSlot = bytemuck::Zeroable::zeroed();
        e.params = p;
        e.rot = Rotations::with_turn(p[0], p[1], p[2]);
        e.gnss = [1.0, 2.0, 3.0];
        e.gnss_lever = [0.3, 1.1, -0.7];
        e
    };
    // The default datum (omega 90 deg: the camera's y is the object's Z, its z the
    // object's -Y): an antenna 1.2 m up and 0.5 m behind the camera.
    let mut level = slot([core::f64::consts::FRAC_PI_2, 0.0, 0.0, 1.0, 2.0, 3.0]);
    level.gnss_lever = [0.0, 1.2, 0.5];
    let (r, _) = gnss_residual(&level);
    assert!(
        r[0].abs() < 1e-12 && (r[1] + 0.5).abs() < 1e-12 && (r[2] - 1.2).abs() < 1e-12,
        "{r:?}"
    );
    let p = [1.55, 0.2, -0.4, 1.0, 2.5, 2.0];
    // At zero lever the residual is the centre's offset from the fix.
    let mut plain = slot(p);
    plain.gnss_lever = [0.0; 3];
    assert_eq!(gnss_residual(&plain).0, [0.0, 0.5, -1.0]);
    let h = 1e-5;
    let near_90 = core::f64::consts::FRAC_PI_2 - 1e-4;
    for p in [p, [1.55, near_90, -0.4, 1.0, 2.5, 2.0]] {
        let (_, j) = gnss_residual(&slot(p));
        for k in 0..3 {
            let turned = |s: f64| {
                let (mut q, mut d) = (p, [0.0; 3]);
                d[k] = s;
                attitude::turn(&mut q, d);
                gnss_residual(&slot(q)).0
            };
            let (r1, r0) = (turned(h), turned(-h));
            for a in 0..3 {
                let numeric = (r1[a] - r0[a]) / (2.0 * h);
                assert!(
                    (numeric - j[a][k]).abs() < 1e-6,
                    "d r{a} / d turn {k}: {numeric} against {}",
                    j[a][k]
                );
            }
        }
    }
}

/// Defaults with room for the whole of the six-epoch, 300-point drive `s` in one window.
fn whole_drive(s: &crate::adjust::tests::Scene) -> AdjustConfig {
    AdjustConfig {
        window: 6,
        max_points: 300,
        max_observations: s.observations.len(),
        ..AdjustConfig::default()
    }
}

/// Snooping's first round after detection reads the statistics detection computed
/// for the same solution instead of computing them again: on a window with 2 %
/// blunders and a pessimistic a-priori sigma (the global test passes, as on the
/// traverse's windows; its kept exclusions and single round), the same exclusions and
/// the same poses, to the bit, as from statistics computed afresh.
#[test]
fn snooping_from_the_statistics_of_detection_is_snooping_from_fresh_ones() {
    use super::solve::Detection;
    use crate::adjust::tests::{arena_for, load_weighted, scene};
    let s = scene(11, 6, 300, 0.02);
    let cfg = AdjustConfig {
        max_robust_rounds: 1,
        keep_exclusions: true,
        ..whole_drive(&s)
    };
    let Robust::Snooping { critical } = cfg.robust else {
        panic!("the default is snooping");
    };
    let snooped = |fresh: bool| {
        let mut mem = arena_for(&cfg);
        let mut arena = Arena::new(&mut mem);
        let (mut w, _) = load_weighted(&s, cfg, &mut arena, 3, 1e-3);
        w.build_index();
        w.least_squares(cfg.max_iterations).unwrap();
        assert_eq!(w.detection().unwrap(), Detection::ObservationStandsOut);
        let mut report = Report::default();
        w.snoop_rounds(critical, 1, fresh, &mut report).unwrap();
        let poses: std::vec::Vec<Pose> = (0..6).map(|e| w.epoch_pose(e).unwrap()).collect();
        let flags: std::vec::Vec<bool> = w.observations().iter().map(|o| o.is_flagged()).collect();
        (poses, flags)
    };
    let (poses, flags) = snooped(true);
    let blunders = s.observations.iter().filter(|o| o.blunder).count();
    let n = flags.iter().filter(|&&f| f).count();
    assert!(n >= blunders, "{n} flagged, {blunders} blunders");
    assert_eq!((poses, flags), snooped(false));
}

/// The cost a build returns, where an iteration sequence starts, is the window's
/// cost at that state over the points that take part: a point left with a single
/// ray counts in neither.
#[test]
fn build_returns_the_cost_of_the_points_it_takes() {
    use crate::adjust::tests::{arena_for, load, scene};
    let s = scene(11, 6, 300, 0.0);
    let cfg = whole_drive(&s);
    let mut mem = arena_for(&cfg);
    let mut arena = Arena::new(&mut mem);
    let (mut w, ids) = load(&s, cfg, &mut arena, 3);
    let lone = ids[0];
    let rays = w.obs[..w.n_obs].iter().filter(|o| o.point == lone).count();
    assert!(rays >= 2, "point 0 has {rays} rays");
    for o in w.obs[..w.n_obs]
        .iter_mut()
        .filter(|o| o.point == lone)
        .skip(1)
    {
        o.factor = 0.0;
    }
    w.build_index();
    let built = w.build(1e-3);
    assert_ne!(w.points[lone as usize].flags & PT_EXCLUDED, 0);
    let (cost, _) = w.cost();
    assert!(cost > 0.0);
    assert!(
        (built - cost).abs() <= 1e-12 * cost,
        "built {built}, cost {cost}"
    );
}
