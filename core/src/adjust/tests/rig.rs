//! The rig in the adjustment: estimated, perturbed, self-calibrated, held and corrected.
use super::*;

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
        max_observations: s.observations.len(),
        estimate_rig: true,
        sigmas: loose_rig_prior(),
        ..AdjustConfig::default()
    };
    let mut mem = arena_for(&cfg);
    let mut arena = Arena::new(&mut mem);
    let mut w = Window::new(cfg, &start, &mut arena).unwrap();
    w.set_base_length(s.rig.base_length());
    let truth = RelativeOrientation::from_rig(&s.rig).to_array();
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
        for o in &s.observations {
            let (e, c, p, xy) = (&o.epoch, &o.camera, &o.point, &o.xy);
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
            let cam = *c;
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
    for o in &s.observations {
        let (e, c, p, xy) = (&o.epoch, &o.camera, &o.point, &o.xy);
        let (cam, xy) = if *c == Camera::Left {
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
) -> (
    RelativeOrientation,
    [f64; 6],
    InteriorCorrections,
    [f64; 6],
    f64,
    f64,
) {
    let cfg = AdjustConfig {
        window: s.poses.len(),
        max_points: s.points.len(),
        max_observations: s.observations.len(),
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
    let rp = RelativeOrientation::from_rig(&s.rig);
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
    let truth = RelativeOrientation::from_rig(&s.rig).to_array();
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
    rig: RelativeOrientation,
    interior: InteriorCorrections,
}

fn held_run(s: &Scene, start: &Rig, hold: bool, correct: bool) -> HeldRun {
    let cfg = AdjustConfig {
        window: s.poses.len(),
        max_points: s.points.len(),
        max_observations: s.observations.len(),
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
