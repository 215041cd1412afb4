//! The traverse behind the protocol loop: maps a `Configure` message to a
//! [`TraverseConfig`], carves the traverse from the firmware's arena and answers
//! every epoch with its orientation, precision, counts and stage timings.
//! On request it reports the tie points and image observations that became
//! final (their epoch is the next to leave the window), see [`TraverseProcessor`].
use crate::processor::{
    BuildError, Clock, EpochInput, EpochOutput, EpochProcessor, ProcessorFactory,
};
use phototraverse_core::budget::{Arena, MemoryBudget};
use phototraverse_core::camera::Pose;
use phototraverse_core::matching::StereoGeometry;
use phototraverse_core::protocol::messages::{
    processor_kind, stage, status, Configure, EpochResult, PointObservation, PointRecord, Points,
    RigEstimate, AUX_GNSS, AUX_ODOMETER,
};
use phototraverse_core::traverse::{
    flags, AuxObservations, EpochStatus, Traverse, TraverseConfig, TraverseError, WindowObservation,
};

/// Builds the traverse for a configuration.
pub struct TraverseFactory;

/// The traverse as an [`EpochProcessor`].
///
/// Tie point reports: once the window is full, its oldest epoch leaves at the
/// next slide, so its observations (measured pixel, final residual) and the
/// points whose last observation is in it are final after the adjustment that
/// just ran. They are reported once each, epoch by epoch, in answer to the
/// host's requests; a flush (end of the sequence) reports every epoch left.
pub struct TraverseProcessor<'a> {
    traverse: Traverse<'a>,
    report: ReportCursor,
}

/// Where the tie point report stands.
#[derive(Debug, Clone, Copy, Default)]
struct ReportCursor {
    /// Last input epoch whose observations and final points were reported.
    reported: Option<u32>,
    /// Reporting the points of the current epoch (after its observations).
    points_phase: bool,
    /// Next window observation index to look at.
    next: usize,
    /// A flush was asked: every epoch in the window is final.
    flushing: bool,
}

/// The traverse configuration a `Configure` message asks for.
pub fn traverse_config(c: &Configure) -> Result<TraverseConfig, BuildError> {
    let rig = c.rig;
    rig.validate()
        .map_err(|_| BuildError::Invalid("rig: focal, format or values"))?;
    if rig.left.width_px != rig.right.width_px || rig.left.height_px != rig.right.height_px {
        return Err(BuildError::Invalid(
            "rig: left and right image sizes differ",
        ));
    }
    if rig.base_length() <= 0.0 {
        return Err(BuildError::Invalid("rig: zero base"));
    }
    let p = &c.pipeline;
    let t = &c.traverse;
    if !t.datum.iter().all(|v| v.is_finite()) {
        return Err(BuildError::Invalid("datum: value not finite"));
    }
    if !(t.sigma_px > 0.0 && t.sigma_px.is_finite()) {
        return Err(BuildError::Invalid("image sigma must be positive"));
    }
    let datum = Pose::from_params(&t.datum);
    let mut cfg = TraverseConfig::for_rig(rig, datum);
    cfg.sigma_px = t.sigma_px;
    let n = p.keypoints_per_image.clamp(1, 100_000) as usize;
    cfg.sift.max_keypoints = n;
    cfg.matching.max_keypoints = n;
    cfg.sift.octaves = p.octaves.max(1) as usize;
    cfg.sift.levels = p.scales_per_octave.max(1) as usize;
    cfg.sift.contrast_threshold = p.contrast_threshold;
    cfg.sift.fine_octave = p.fine_octave;
    cfg.sift.edge_threshold = p.edge_ratio;
    cfg.matching.ratio = p.match_ratio;
    if let StereoGeometry::Rectified {
        max_disparity_px, ..
    } = &mut cfg.matching.stereo
    {
        *max_disparity_px = p.max_disparity_px;
    }
    let window = (p.window_len as usize).max(2);
    cfg.adjust.window = window;
    cfg.matching.track_history = window;
    cfg.matching.max_tracks = (p.track_capacity as usize).max(1);
    if let Some(f) = p.fixed_epochs {
        cfg.adjust.fixed_epochs = f as usize;
    }
    // The mode's own settings (seed window lengths included) come last, then the
    // capacities that follow from the window.
    // A seed mode's window length wins over the rig estimation's minimum.
    if !t.calibration_precision.valid() {
        return Err(BuildError::Invalid(
            "calibration precision must be positive",
        ));
    }
    let mut cfg = cfg.with_calibration_precision(t.calibration_precision);
    if !t.check_calibration {
        cfg = cfg.with_calibration_check(None);
    }
    let mut cfg = cfg.with_rig_estimation(t.estimate_rig).with_mode(t.mode);
    cfg.fit_capacities();
    Ok(cfg)
}

fn build_error(e: TraverseError) -> BuildError {
    match e {
        TraverseError::OutOfMemory(m) => BuildError::OutOfMemory(m),
        TraverseError::Config(what) => BuildError::Invalid(what),
        TraverseError::Sift(_) => BuildError::Invalid("feature extractor configuration"),
        TraverseError::Match(_) => BuildError::Invalid("matcher configuration"),
        TraverseError::Adjust(_) => BuildError::Invalid("adjustment configuration"),
    }
}

impl ProcessorFactory for TraverseFactory {
    type Processor<'a> = TraverseProcessor<'a>;
    const KIND: u8 = processor_kind::TRAVERSE;

    fn budget(&self, config: &Configure, budget: &mut MemoryBudget) -> Result<(), BuildError> {
        traverse_config(config)?
            .budget(budget)
            .map_err(|_| BuildError::Invalid("feature extractor configuration"))
    }

    fn build<'a>(
        &mut self,
        config: &Configure,
        arena: &mut Arena<'a>,
    ) -> Result<TraverseProcessor<'a>, BuildError> {
        let cfg = traverse_config(config)?;
        let traverse = Traverse::new(cfg, arena).map_err(build_error)?;
        Ok(TraverseProcessor {
            traverse,
            report: ReportCursor::default(),
        })
    }
}

/// A `&dyn Clock` as a sized clock for the traverse's generic timing.
struct ClockRef<'c>(&'c dyn Clock);

impl Clock for ClockRef<'_> {
    fn now_us(&self) -> u64 {
        self.0.now_us()
    }
}

fn aux_of(input: &EpochInput) -> AuxObservations {
    let Some(a) = input.aux else {
        return AuxObservations::default();
    };
    let sigma = (a.gnss_sigma_m[0] + a.gnss_sigma_m[1] + a.gnss_sigma_m[2]) / 3.0;
    AuxObservations {
        odometer: (a.flags & AUX_ODOMETER != 0).then_some((a.odometer_m, a.odometer_sigma_m)),
        gnss: (a.flags & AUX_GNSS != 0).then_some((a.gnss_m, sigma)),
    }
}

impl EpochProcessor for TraverseProcessor<'_> {
    fn frame_size(&self, camera: usize) -> Option<(u16, u16)> {
        let rig = &self.traverse.config().rig;
        let c = if camera == 0 { &rig.left } else { &rig.right };
        // The configuration refuses cameras wider or taller than a u16 frame field.
        Some((
            u16::try_from(c.width_px).ok()?,
            u16::try_from(c.height_px).ok()?,
        ))
    }

    fn points(&mut self, flush: bool, max_payload: usize, msg: &mut Points) -> bool {
        self.report.flushing |= flush;
        self.fill_points(max_payload, msg)
    }

    fn process(&mut self, input: &EpochInput, clock: &dyn Clock) -> EpochOutput {
        // A report not drained before the next epoch restarts on the new window.
        self.report = ReportCursor {
            reported: self.report.reported,
            ..Default::default()
        };
        let time_s = input.timestamps_us[0] as f64 * 1e-6;
        let out = self.traverse.process_with_aux(
            &input.left,
            &input.right,
            time_s,
            aux_of(input),
            &ClockRef(clock),
        );
        let code = match out.status {
            EpochStatus::Ok => status::OK,
            EpochStatus::Flagged => status::FLAGGED,
            EpochStatus::Predicted => status::PREDICTED,
            EpochStatus::Rejected => status::FAILED,
        };
        let mut result = EpochResult::empty(input.epoch, code);
        result.pose = out.left.to_params();
        result.sigma = out.std.unwrap_or([0.0; 6]);
        result.sigma0 = out.sigma0;
        result.counts.keypoints = out.keypoints;
        result.counts.stereo_matches = out.stereo_matches;
        result.counts.temporal_matches = out.tie_points;
        result.counts.tie_points = out.points;
        result.counts.observations = out.observations;
        result.counts.dropped = (out.flags & flags::CAPACITY != 0) as u32;
        result.extra = [
            out.flags as f64,
            out.rms_px,
            out.new_points as f64,
            out.redundancy as f64,
        ];
        // The rig as the adjustment has it, when it can differ from the calibration:
        // estimated freely, or corrected by the calibration check.
        let cfg = self.traverse.config();
        let free = cfg.adjust.estimate_rig && cfg.calibration_check.is_none();
        if free || self.traverse.calibration_corrections() > 0 {
            let (rig, std) = self.traverse.rig_estimate();
            result.rig = Some(RigEstimate {
                params: rig.to_array().map(|v| v as f32),
                std: std.map(|v| v as f32),
            });
        }
        let mut timings_us = [0u32; stage::COUNT];
        timings_us[stage::SIFT_LEFT] = out.times.sift_left_us;
        timings_us[stage::SIFT_RIGHT] = out.times.sift_right_us;
        timings_us[stage::STEREO_MATCH] = out.times.matching_us;
        timings_us[stage::INITIAL_VALUES] = out.times.initial_us;
        timings_us[stage::ADJUST] = out.times.adjust_us;
        EpochOutput { result, timings_us }
    }
}

impl TraverseProcessor<'_> {
    /// The next epoch to report: the oldest unreported window epoch, when the
    /// window is full (it leaves at the next slide) or a flush was asked.
    fn target(&self) -> Option<u32> {
        let mut epochs = self.traverse.window_epochs().map(|e| e.0);
        let oldest = epochs.next()?;
        let full = self.traverse.window_epochs().count() >= self.traverse.config().adjust.window;
        let after = |e: u32| !matches!(self.report.reported, Some(r) if e <= r);
        if self.report.flushing {
            core::iter::once(oldest).chain(epochs).find(|e| after(*e))
        } else {
            (full && after(oldest)).then_some(oldest)
        }
    }

    /// Whether observation `i` (of `o`) is the first of its point in its epoch,
    /// and whether the point has no observation in a later epoch (it is final).
    /// The point's own observations come from the window's index (a few per point);
    /// scanning them all per observation would cost the square of their number.
    fn first_and_final(&self, i: usize, o: &WindowObservation) -> (bool, bool) {
        let (mut first, mut last) = (true, true);
        let all = 0..self.traverse.window_observation_count() as u32;
        let own = self.traverse.window_point_observations(o.point);
        let candidates = own.into_iter().flatten().copied();
        let scan = own.is_none().then_some(all).into_iter().flatten();
        for j in candidates.chain(scan) {
            let j = j as usize;
            let Some(q) = self.traverse.window_observation(j) else {
                continue;
            };
            if q.point != o.point {
                continue;
            }
            first &= !(j < i && q.epoch == o.epoch);
            last &= q.epoch <= o.epoch;
            if !last {
                break;
            }
        }
        (first, last)
    }

    fn observation_record(&self, i: usize, o: &WindowObservation) -> PointObservation {
        let (px, residual) = self
            .traverse
            .window_observation_pixels(i)
            .unwrap_or(([f64::NAN; 2], None));
        let mut flags = 0;
        if o.flagged {
            flags |= PointObservation::FLAGGED;
        }
        if residual.is_none() {
            flags |= PointObservation::NO_RESIDUAL;
        }
        let r = residual.unwrap_or([0.0; 2]);
        PointObservation {
            track: o.track_id,
            epoch: o.epoch,
            camera: o.camera,
            flags,
            col: px[0] as f32,
            row: px[1] as f32,
            residual_px: [r[0] as f32, r[1] as f32],
        }
    }

    /// Fills `msg` from the cursor on; true when it is full and records remain.
    fn fill_points(&mut self, max_payload: usize, msg: &mut Points) -> bool {
        while let Some(epoch) = self.target() {
            let n = self.traverse.window_observation_count();
            while self.report.next < n {
                let i = self.report.next;
                let Some(o) = self
                    .traverse
                    .window_observation(i)
                    .filter(|o| o.epoch == epoch)
                else {
                    self.report.next += 1;
                    continue;
                };
                // A record that does not fit even an empty message (a payload limit
                // below one record) is skipped, so every request makes progress.
                let empty = msg.n_points == 0 && msg.n_obs == 0;
                if !self.report.points_phase {
                    if !msg.push_observation(self.observation_record(i, &o), max_payload) && !empty
                    {
                        return true;
                    }
                } else if let (true, true) = self.first_and_final(i, &o) {
                    if let Some((xyz, std)) = self.traverse.window_point(o.point) {
                        let s = std.unwrap_or([0.0; 3]);
                        let rec = PointRecord {
                            track: o.track_id,
                            xyz,
                            std: [s[0] as f32, s[1] as f32, s[2] as f32],
                        };
                        if !msg.push_point(rec, max_payload) && !empty {
                            return true;
                        }
                    }
                }
                self.report.next += 1;
            }
            if self.report.points_phase {
                self.report = ReportCursor {
                    reported: Some(epoch),
                    flushing: self.report.flushing,
                    ..Default::default()
                };
            } else {
                self.report.points_phase = true;
                self.report.next = 0;
            }
        }
        self.report.flushing = false;
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use phototraverse_core::adjust::Robust;
    use phototraverse_core::camera::{Interior, Rig};
    use phototraverse_core::protocol::messages::{
        CalibrationPrecision, Pipeline, Repr, TraverseMode, TraverseSettings, CONFIG_VERSION,
    };

    fn configure(traverse: TraverseSettings) -> Configure {
        let rig = Rig::rectified(Interior::pinhole_px(320, 240, 300.0), 0.4);
        Configure {
            version: CONFIG_VERSION,
            rig,
            pipeline: Pipeline {
                max_width: 320,
                max_height: 240,
                window_len: 8,
                ..Pipeline::default()
            },
            traverse,
        }
    }

    #[test]
    fn configure_v2_fields_reach_the_traverse_config() {
        let d = traverse_config(&configure(TraverseSettings::default())).unwrap();
        assert_eq!(d.adjust.window, 8);
        // The calibration check: rig and interior blocks held at the calibration.
        assert!(d.calibration_check.is_some() && d.adjust.hold_calibration);
        assert!(d.adjust.estimate_rig && d.adjust.self_calibration.is_some());
        assert_eq!(d.datum, Pose::from_degrees(90.0, 0.0, 0.0, [0.0; 3]));
        assert_eq!(d.sigma_px, 0.5);
        let t = TraverseSettings {
            mode: TraverseMode::Seed2014,
            estimate_rig: true,
            sigma_px: 0.3,
            datum: [1.5, 0.01, 0.02, 5.0, 6.0, 1.2],
            ..TraverseSettings::default()
        };
        let c = traverse_config(&configure(t)).unwrap();
        assert_eq!(c.adjust.window, 2);
        assert!(matches!(c.adjust.robust, Robust::SeedReweight { .. }));
        // Free estimation replaces the check.
        assert!(c.adjust.estimate_rig && !c.adjust.hold_calibration);
        assert!(c.calibration_check.is_none());
        // v4: the stated precision becomes the prior; the hold flag ends the check.
        let precision = CalibrationPrecision {
            principal_point_px: 0.5,
            focal: 0.002,
            angles_rad: 2e-4,
            base_m: 5e-4,
        };
        let p = traverse_config(&configure(TraverseSettings {
            calibration_precision: precision,
            ..TraverseSettings::default()
        }))
        .unwrap();
        assert_eq!(p.adjust.sigmas.rig_angle_rad, 2e-4);
        assert_eq!(p.adjust.sigmas.rig_base_m, 5e-4);
        let focal = p.rig.right.focal_mm;
        let sc = p.adjust.self_calibration.unwrap();
        assert!((sc.focal_mm[1] - 0.002 * focal).abs() < 1e-15);
        let held = traverse_config(&configure(TraverseSettings {
            check_calibration: false,
            ..TraverseSettings::default()
        }))
        .unwrap();
        assert!(held.calibration_check.is_none() && !held.adjust.estimate_rig);
        assert!(held.adjust.self_calibration.is_none());
        assert_eq!(c.sigma_px, 0.3);
        assert_eq!(c.datum.to_params(), t.datum);
        let s = traverse_config(&configure(TraverseSettings {
            mode: TraverseMode::Seed2006,
            ..t
        }))
        .unwrap();
        assert_eq!(s.adjust.window, 7);
        assert!(s.adjust.sigmas.velocity_change_mps > 0.0);
        let bad = TraverseSettings { sigma_px: 0.0, ..t };
        assert!(traverse_config(&configure(bad)).is_err());
        let nan = TraverseSettings {
            datum: [f64::NAN; 6],
            ..t
        };
        assert!(traverse_config(&configure(nan)).is_err());
    }

    #[test]
    fn a_result_with_the_rig_fits_a_transmit_slot() {
        let mut r = EpochResult::empty(u32::MAX, status::FLAGGED);
        r.rig = Some(RigEstimate {
            params: [1.0; 6],
            std: [1.0; 6],
        });
        let mut buf = [0u8; 1024];
        let n = r.emit(&mut buf).unwrap();
        assert!(n <= crate::link::TX_MAX_PAYLOAD, "{n} bytes");
    }
}
