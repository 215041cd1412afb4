//! The epoch in the adjustment: its tie points as observations (new points by
//! intersection), the window's solution and the slide.
use super::*;
use crate::adjust::{right_camera_covariance, standard_deviations};

impl Traverse<'_> {
    /// Initial values, window update and adjustment; true when the epoch was adjusted.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn adjust_epoch(
        &mut self,
        k: u32,
        (time_s, aux): (f64, AuxObservations),
        prediction: &Pose,
        (left, right): (&ImageView, &ImageView),
        out: &mut EpochOutput,
        clock: &impl Clock,
        t_start: u64,
    ) -> bool {
        let first = self.window.n_epochs() == 0 && self.history[1].is_none();
        let dropped_before = self.window.dropped();
        let mut resected = if first { None } else { self.resect() };
        if !first && resected.is_none() {
            resected = self.relocalize();
            if resected.is_some() {
                out.flags |= flags::RELOCALIZED;
            }
        }
        // Without a resection the prediction stands, its rotation corrected from the
        // temporal matches when they tell it and the templates agree (`area_prefers`,
        // below); an epoch flagged below is tied to it.
        let mut guess = *prediction;
        if !first && resected.is_none() {
            out.flags |= flags::NO_RESECTION;
            if let Some(pose) = self.rotation_from_matches(prediction) {
                out.flags |= flags::ROTATION_FROM_MATCHES;
                guess = pose;
            }
        }
        let mut initial = match resected {
            Some(pose) => pose,
            None if first => self.cfg.datum,
            None => guess,
        };
        let ta = clock.now_us();
        self.track_by_area(left, right, (&initial, resected.is_some()));
        let hypotheses = (&initial, prediction);
        if out.flags & flags::ROTATION_FROM_MATCHES != 0
            && self.area_prefers(left, right, hypotheses)
        {
            out.flags &= !flags::ROTATION_FROM_MATCHES;
            (initial, guess) = (*prediction, *prediction);
        }
        let area_us = elapsed(ta, clock.now_us());
        out.times.matching_us = out.times.matching_us.saturating_add(area_us);
        out.tie_points += self.n_area as u32;
        if self.window.n_epochs() >= self.cfg.adjust.window && self.slide().is_err() {
            out.flags |= flags::SOLVE_FAILED;
            return false;
        }
        let Ok(id) = self.window.add_epoch(&initial, time_s) else {
            out.flags |= flags::SOLVE_FAILED;
            return false;
        };
        self.window_inputs[self.window.n_epochs() - 1] = k;
        // Invalid auxiliary values (NaN, sigma <= 0) are refused by the window and ignored.
        let count = aux.odometer.map(|(d, s)| (d, s * s));
        if let (Some((d0, v0)), Some((d1, v1))) = (self.odometer_count, count) {
            let _ = self.window.set_odometer(id, d1 - d0, libm::sqrt(v1 - v0));
        }
        self.odometer_count = count;
        if let Some(g) = aux.gnss {
            let _ = self
                .window
                .set_gnss_antenna(id, g.position_m, g.sigma_m, g.lever_arm_m);
        }
        if !first && (out.tie_points as usize) < self.cfg.min_tie_points {
            out.flags |= flags::FEW_TIE_POINTS;
            // Continuity from the motion prediction; errors here only mean a NaN pose.
            let _ = self
                .window
                .set_pose_prior(id, &guess, self.cfg.prediction_sigmas);
        }
        out.new_points = self.add_tie_points(id);
        let t3 = clock.now_us();
        out.times.initial_us = elapsed(t_start, t3).saturating_sub(area_us);
        out.left = initial;
        out.right = self.right_of(&initial);
        let adjusted = first || self.solve(id, prediction, out);
        if adjusted {
            out.step_m = self.step_from_previous(k);
        }
        out.times.adjust_us = elapsed(t3, clock.now_us());
        self.prev_window_epoch = Some(id);
        // The window counts its refusals since the start: this epoch's are the increase.
        let (dp, dobs) = self.window.dropped();
        out.dropped = (dp + dobs - dropped_before.0 - dropped_before.1) as u32;
        if out.dropped > 0 {
            out.flags |= flags::CAPACITY;
        }
        out.observations = self.window.observations().len() as u32;
        out.points = self.window.point_ids().count() as u32;
        adjusted
    }

    /// The newest window epoch's centre minus the previous one's, when that is input
    /// epoch `k - 1`: a step between epochs of one adjustment.
    fn step_from_previous(&self, k: u32) -> Option<[f64; 3]> {
        let n = self.window.n_epochs();
        if n < 2 || self.window_inputs[n - 2] != k.wrapping_sub(1) {
            return None;
        }
        let (a, b) = (
            self.window.epoch_pose(n - 2)?,
            self.window.epoch_pose(n - 1)?,
        );
        Some([0, 1, 2].map(|i| b.centre[i] - a.centre[i]))
    }

    /// Drops the oldest window epoch (its pose is final) and keeps the slot map in step.
    fn slide(&mut self) -> Result<Pose, AdjustError> {
        let pose = self.window.slide()?;
        let n = self.window.n_epochs();
        self.window_inputs.copy_within(1..=n, 0);
        Ok(pose)
    }

    /// Adds the epoch's tie points: observations of known points, new points by
    /// intersection from the previous epoch. Returns the number of new points.
    fn add_tie_points(&mut self, id: u32) -> u32 {
        let Some(prev_id) = self.prev_window_epoch else {
            return 0;
        };
        let Some(prev_slot) = self.window.n_epochs().checked_sub(2) else {
            return 0;
        };
        let Some(prev_left) = self.window.epoch_pose(prev_slot) else {
            return 0;
        };
        let prev = [prev_left, self.right_of(&prev_left)];
        let rig = self.rig_now();
        let mut new_points = 0;
        for (k, tie) in self.matcher.tie_points().enumerate() {
            // Two tracks whose templates led to one spot observe one image point: the
            // later one is left out (two window points on one observation would both
            // take it, and their right observations would contradict each other).
            let twin = self
                .matcher
                .tie_points()
                .take(k)
                .any(|t| same_spot(t.cur.left, tie.cur.left));
            if twin {
                continue;
            }
            // A track whose point left the window keeps its identity but gets no new
            // point: one track, one point, as the reports key points by track.
            if has_dead_point(self.track_points, &self.window, &tie) {
                continue;
            }
            let point = match known_point(self.track_points, &self.window, &tie) {
                Some(p) => p,
                None => {
                    let at = (prev_id, &prev);
                    let obs = tie.prev.px();
                    let geometry = (&self.cfg, &rig);
                    let Some(p) = new_point(geometry, &mut self.window, at, obs, tie.track_id)
                    else {
                        continue;
                    };
                    if let Some(e) = self.track_points.get_mut(tie.slot as usize) {
                        *e = TrackPoint {
                            track_id: tie.track_id,
                            point: p,
                        };
                    }
                    new_points += 1;
                    p
                }
            };
            let obs = tie.cur.px();
            add_stereo_observations(&self.cfg, &mut self.window, id, point, obs, tie.track_id);
        }
        new_points + self.add_area_ties(id, (prev_id, &prev))
    }

    /// Adjusts the window; on failure ties the new epoch to its prediction and tries once more.
    fn solve(&mut self, id: u32, prediction: &Pose, out: &mut EpochOutput) -> bool {
        let mut result = self.window.solve();
        if let Err(e) = result {
            self.last_solve_error = Some(e);
            out.flags |= flags::SOLVE_FAILED;
            self.hold_estimated_calibration();
            let _ = self
                .window
                .set_pose_prior(id, prediction, self.cfg.prediction_sigmas);
            result = self.window.solve();
        }
        let Ok(mut rep) = result else { return false };
        // A rejected calibration is corrected and freed: the window is adjusted again,
        // the calibration with it (held again if that fails).
        if self.check_calibration(rep.sigma0) {
            out.flags |= flags::CALIBRATION_CORRECTED;
            let mut again = self.window.solve();
            if again.is_err() && self.hold_estimated_calibration() {
                again = self.window.solve();
            }
            match again {
                Ok(r) => rep = r,
                Err(e) => {
                    self.last_solve_error = Some(e);
                    out.flags |= flags::SOLVE_FAILED;
                    return false;
                }
            }
        }
        let last = self.window.n_epochs() - 1;
        if let Some(pose) = self.window.epoch_pose(last) {
            out.left = pose;
            out.right = self.right_of(&pose);
        }
        let cov = self.window.epoch_absolute_covariance(last);
        out.std = cov.map(|c| standard_deviations(&c));
        out.right_std = cov.map(|c| {
            standard_deviations(&right_camera_covariance(&out.left, &self.window.rig(), &c))
        });
        out.relative_std_m = self
            .window
            .epoch_relative_std(last)
            .map(|s| [s[3], s[4], s[5]]);
        out.sigma0 = rep.sigma0;
        out.chi2_passed = rep.chi2.passed;
        out.redundancy = rep.redundancy as u32;
        out.iterations = rep.iterations as u32;
        out.flagged_observations = rep.flagged as u32;
        out.rms_px = self.rms_px();
        // Only the upper tail flags: sigma0 above its bound means blunders or a model
        // error; below it, the a-priori sigma was merely pessimistic.
        if rep.chi2.statistic > rep.chi2.upper {
            out.flags |= flags::CHI2;
        }
        true
    }

    /// RMS image residual of the window's unflagged observations, pixels.
    fn rms_px(&self) -> f64 {
        let px = self.cfg.rig.left.pixel_size_mm;
        let (mut sum, mut n) = (0.0, 0usize);
        let residuals = self.window.residuals();
        for (o, r) in self.window.observations().iter().zip(residuals) {
            if o.is_flagged() {
                continue;
            }
            if let Some([vx, vy]) = r {
                sum += (vx / px[0]) * (vx / px[0]) + (vy / px[1]) * (vy / px[1]);
                n += 1;
            }
        }
        if n == 0 {
            0.0
        } else {
            libm::sqrt(sum / n as f64)
        }
    }
}

/// The window point of a tie point's track, if the track already has one and the
/// window still holds it (a freed point's slot may hold another track's point).
pub(super) fn known_point(map: &[TrackPoint], window: &Window, tie: &TiePoint) -> Option<u32> {
    let e = map.get(tie.slot as usize)?;
    (e.track_id == tie.track_id && e.point != u32::MAX)
        .then_some(e.point)
        .filter(|&p| window.point_tag(p) == Some(tie.track_id))
}

/// An image observation of `point` at pixel `px` whose correlation gave it the
/// precision `sigma` (pixels; x, y; zero: not correlated), weighted by
/// [`observation_sigma_px`].
fn observation(
    cfg: &TraverseConfig,
    (epoch, camera): (u32, Camera),
    point: u32,
    (px, sigma): ([f32; 2], [f32; 2]),
    tag: u32,
) -> Observation {
    let interior = cfg.rig.interior(camera);
    let xy = interior.pixel_to_corrected(px[0] as f64, px[1] as f64);
    let [sx, sy] = interior.pixel_size_mm;
    let [wx, wy] = sigma.map(|s| observation_sigma_px(cfg.sigma_px, s));
    let weight = [1.0 / (wx * sx * wx * sx), 1.0 / (wy * sy * wy * sy)];
    let mut o = Observation::new(epoch, camera, point, xy, weight);
    o.tag = tag;
    o
}

/// The a-priori sigma (pixels) of a right-image observation on one axis whose stereo
/// correlation peak put its precision at `peak_sigma` pixels
/// ([`crate::matching::refine::Peak`]), zero when no correlation measured it.
///
/// Why: a disparity's error follows the texture it was matched on. Measured against
/// rendered truth (`bench/traverse/README.md`, "Observation weights from the
/// correlation peak"), the disparity errors of the fifth of the matches with the
/// sharpest peaks were a quarter of those of the fifth with the flattest ones, and most
/// of the tails the robust weighting has to catch are in the latter. The peak's own
/// figure accounts for the noise and the texture; [`defaults::PEAK_SIGMA_FLOOR_PX`]
/// for what it cannot see (interpolation, the template's change of shape), and
/// [`defaults::PEAK_SIGMA_GAIN`] for its optimism. `sigma_px` is the sigma of an
/// observation of [`defaults::TYPICAL_PEAK_SIGMA_PX`]'s modelled precision, and of
/// every position no correlation measured (a keypoint's own).
///
/// The left image's observations keep `sigma_px`: weighted by their temporal peaks
/// too, the per-step errors fell further on calibrated rigs, but the window then
/// balanced the images worse against what else it holds (a calibration corrected
/// from the first epochs, GNSS fixes before an outage): `bench/traverse/README.md`.
/// Weighted by least-squares matching's own precision (`left-weights.patch` there),
/// the rotation drift fell, not the translation drift, and both balances got worse
/// again: a track's errors are correlated, which a weight per observation does not see.
pub(super) fn observation_sigma_px(sigma_px: f64, peak_sigma: f32) -> f64 {
    use super::defaults::{PEAK_SIGMA_FLOOR_PX, PEAK_SIGMA_GAIN, TYPICAL_PEAK_SIGMA_PX};
    if !(peak_sigma > 0.0 && peak_sigma.is_finite()) {
        return sigma_px;
    }
    let s = PEAK_SIGMA_GAIN * peak_sigma as f64;
    let modelled = libm::sqrt(PEAK_SIGMA_FLOOR_PX * PEAK_SIGMA_FLOOR_PX + s * s);
    sigma_px * modelled / TYPICAL_PEAK_SIGMA_PX
}

/// Observations of `point` in both images of window epoch `id`.
pub(super) fn add_stereo_observations(
    cfg: &TraverseConfig,
    window: &mut Window,
    id: u32,
    point: u32,
    obs: StereoPx,
    tag: u32,
) {
    // The left observations are not weighted by their temporal peaks (see
    // `observation_sigma_px`), nor any in the seed modes: they pass "not measured".
    let right_sigma = if cfg.peak_weights {
        obs.right_sigma
    } else {
        [0.0; 2]
    };
    for (cam, px) in [
        (Camera::Left, (obs.left, [0.0; 2])),
        (Camera::Right, (obs.right, right_sigma)),
    ] {
        let _ = window.add_observation(observation(cfg, (id, cam), point, px, tag));
    }
}

/// Intersects a point from a stereo observation (`left` and `right` pixels) of the
/// epoch with left and right poses `poses` through the cameras of `rig` (the rig as
/// adjusted, [`Traverse::rig_now`]); `None` when the rays barely intersect or the point
/// is behind the camera or beyond `max_depth_m`.
pub(super) fn intersect_pair(
    cfg: &TraverseConfig,
    rig: &Rig,
    poses: &[Pose; 2],
    left: [f32; 2],
    right: [f32; 2],
) -> Option<[f64; 3]> {
    let ray = |pose: &Pose, interior: &crate::camera::Interior, px: [f32; 2]| Ray {
        pose: *pose,
        focal_mm: interior.focal_mm,
        xy: interior.pixel_to_corrected(px[0] as f64, px[1] as f64),
    };
    let rays = [
        ray(&poses[0], &rig.left, left),
        ray(&poses[1], &rig.right, right),
    ];
    let x = intersect(&rays, cfg.min_ray_angle_rad).ok()?;
    let depth = -poses[0].to_camera(&x.point)[2];
    (depth > 0.0 && depth <= cfg.max_depth_m).then_some(x.point)
}

/// Intersects a new tie point from its stereo observation `obs` at the previous epoch
/// (`at`: its window epoch id and its left and right poses) through `rig` (the rig as
/// adjusted) and adds it with those two observations, tagged `tag`.
pub(super) fn new_point(
    (cfg, rig): (&TraverseConfig, &Rig),
    window: &mut Window,
    at: (u32, &[Pose; 2]),
    obs: StereoPx,
    tag: u32,
) -> Option<u32> {
    let (prev_id, poses) = at;
    let xyz = intersect_pair(cfg, rig, poses, obs.left, obs.right)?;
    let point = window.add_point(xyz).ok()?;
    add_stereo_observations(cfg, window, prev_id, point, obs, tag);
    Some(point)
}

#[cfg(test)]
mod tests {
    use super::observation_sigma_px;
    use crate::traverse::defaults::{PEAK_SIGMA_FLOOR_PX, PEAK_SIGMA_GAIN, TYPICAL_PEAK_SIGMA_PX};

    #[test]
    fn an_observation_sigma_follows_its_peak_from_the_floor_up() {
        let base = 0.5;
        // Not measured, or nonsense: the configured sigma.
        for s in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert_eq!(observation_sigma_px(base, s), base, "{s}");
        }
        // A peak modelled at the typical precision gets the configured sigma.
        let floor2 = PEAK_SIGMA_FLOOR_PX * PEAK_SIGMA_FLOOR_PX;
        let typical =
            (TYPICAL_PEAK_SIGMA_PX * TYPICAL_PEAK_SIGMA_PX - floor2).sqrt() / PEAK_SIGMA_GAIN;
        assert!((observation_sigma_px(base, typical as f32) - base).abs() < 1e-6);
        // The sharpest peak is held at the floor; flatter ones weigh less and less.
        let sharpest = observation_sigma_px(base, 1e-9);
        assert!((sharpest - base * PEAK_SIGMA_FLOOR_PX / TYPICAL_PEAK_SIGMA_PX).abs() < 1e-9);
        let mut last = sharpest;
        for s in [0.005f32, 0.01, 0.02, 0.05, 0.2] {
            let now = observation_sigma_px(base, s);
            assert!(now > last && now.is_finite(), "{s}: {now} after {last}");
            last = now;
        }
    }
}
