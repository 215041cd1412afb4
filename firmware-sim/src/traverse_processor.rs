//! The traverse behind the protocol loop: maps a `Configure` message to a
//! [`TraverseConfig`], carves the traverse from the firmware's arena and answers
//! every epoch with its orientation, precision, counts, flags, adjustment figures
//! and stage timings. The wire has its own modes, statuses and flag bits; this is
//! where they meet the traverse's.
//! On request it reports the tie points and image observations that became
//! final (their epoch is the next to leave the window), see [`TraverseProcessor`].
use crate::processor::{
    BuildError, Clock, EpochInput, EpochOutput, EpochProcessor, ProcessorFactory,
};
use phototraverse_core::budget::{Arena, MemoryBudget};
use phototraverse_core::camera::Pose;
use phototraverse_core::matching::StereoGeometry;
use phototraverse_core::protocol::messages::{
    capacity, processor_kind, stage, AdjustMode, Adjustment, CapacityUse, Configure, Counts,
    EpochResult, Figures, PointObservation, PointRecord, Points, ResultFlags, ResultStatus,
    RigEstimate, AUX_GNSS, AUX_ODOMETER,
};
use phototraverse_core::sift::SiftError;
use phototraverse_core::traverse::{
    self, flags, AuxObservations, GnssFix, Traverse, TraverseConfig, TraverseError, TraverseMode,
    WindowObservation,
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
    /// The highest use of each reported capacity so far.
    peaks: [CapacityUse; capacity::COUNT],
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

/// The traverse's mode for the wire's.
pub fn traverse_mode(mode: AdjustMode) -> TraverseMode {
    match mode {
        AdjustMode::Window => TraverseMode::Window,
        AdjustMode::Seed2014 => TraverseMode::Seed2014,
        AdjustMode::Seed2006 => TraverseMode::Seed2006,
    }
}

/// Every traverse flag and the wire's bit for it.
const FLAGS: [(u32, ResultFlags); 13] = [
    (flags::FEW_TIE_POINTS, ResultFlags::FEW_TIE_POINTS),
    (flags::LOST, ResultFlags::LOST),
    (flags::NO_FEATURES, ResultFlags::NO_FEATURES),
    (flags::NO_STEREO, ResultFlags::NO_STEREO),
    (flags::REPEATED, ResultFlags::REPEATED),
    (flags::CHI2, ResultFlags::CHI2),
    (flags::SOLVE_FAILED, ResultFlags::SOLVE_FAILED),
    (flags::BAD_IMAGE, ResultFlags::BAD_IMAGE),
    (flags::CAPACITY, ResultFlags::CAPACITY),
    (flags::NO_RESECTION, ResultFlags::NO_RESECTION),
    (flags::RELOCALIZED, ResultFlags::RELOCALIZED),
    (
        flags::CALIBRATION_CORRECTED,
        ResultFlags::CALIBRATION_CORRECTED,
    ),
    (
        flags::ROTATION_FROM_MATCHES,
        ResultFlags::ROTATION_FROM_MATCHES,
    ),
];

/// The wire's flags for the traverse's.
pub fn result_flags(traverse_flags: u32) -> ResultFlags {
    FLAGS
        .iter()
        .filter(|(t, _)| traverse_flags & t != 0)
        .fold(ResultFlags::NONE, |acc, (_, r)| acc | *r)
}

/// The Result of an epoch's traverse output (the rig block apart).
pub fn epoch_result(epoch: u32, out: &traverse::EpochOutput) -> EpochResult {
    let status = match out.status {
        traverse::EpochStatus::Ok => ResultStatus::Ok,
        traverse::EpochStatus::Flagged => ResultStatus::Flagged,
        traverse::EpochStatus::Predicted => ResultStatus::Predicted,
        traverse::EpochStatus::Rejected => ResultStatus::Failed,
    };
    // Only an adjusted epoch (Ok or Flagged) has figures of its own; the others'
    // would be zeros that read like a perfect fit.
    let adjusted = matches!(status, ResultStatus::Ok | ResultStatus::Flagged);
    let figures = if adjusted {
        Figures::Adjustment(Adjustment {
            sigma0: out.sigma0,
            rms_px: out.rms_px,
            // The global test's statistic vTPv, which sigma0^2 is over the redundancy.
            chi2: out.sigma0 * out.sigma0 * out.redundancy as f64,
            redundancy: out.redundancy,
            relative_sd_m: out.relative_std_m.map_or([0.0; 3], |s| s.map(|v| v as f32)),
            step_m: out.step_m.map(|s| s.map(|v| v as f32)),
        })
    } else {
        Figures::None
    };
    EpochResult {
        epoch,
        status,
        pose: out.left.to_params(),
        sigma: out.std.map_or([0.0; 6], |s| s.map(|v| v as f32)),
        right_sigma: out.right_std.map_or([0.0; 6], |s| s.map(|v| v as f32)),
        flags: result_flags(out.flags),
        counts: Counts {
            keypoints: out.keypoints,
            stereo_matches: out.stereo_matches,
            tie_points: out.tie_points,
            window_points: out.points,
            observations: out.observations,
            new_points: out.new_points,
            dropped: out.dropped,
        },
        figures,
        rig: None,
    }
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
    // The settings' ranges were checked by `Configure::validate`; what follows are
    // the rig's, which the settings do not carry.
    let p = &c.pipeline;
    let t = &c.traverse;
    let datum = Pose::from_params(&t.datum);
    let mut cfg = TraverseConfig::for_rig(rig, datum);
    cfg.sigma_px = t.sigma_px;
    let n = p.keypoints_per_image as usize;
    cfg.sift.max_keypoints = n;
    cfg.matching.max_keypoints = n;
    cfg.sift.octaves = p.octaves as usize;
    cfg.sift.levels = p.scales_per_octave as usize;
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
    let window = p.window_len as usize;
    cfg.adjust.window = window;
    cfg.matching.track_history = window;
    cfg.matching.max_tracks = p.track_capacity as usize;
    if let Some(f) = p.fixed_epochs {
        cfg.adjust.fixed_epochs = f as usize;
    }
    // The mode's own settings (seed window lengths included) come last, then the
    // capacities that follow from the window.
    // A seed mode's window length wins over the rig estimation's minimum.
    let mut cfg = cfg.with_calibration_precision(t.calibration_precision);
    if !t.check_calibration {
        cfg = cfg.with_calibration_check(None);
    }
    let mut cfg = cfg
        .with_rig_estimation(t.estimate_rig)
        .with_mode(traverse_mode(t.mode));
    cfg.fit_capacities();
    Ok(cfg)
}

fn build_error(e: TraverseError) -> BuildError {
    match e {
        TraverseError::OutOfMemory(m) => BuildError::OutOfMemory(m),
        TraverseError::Config(what) => BuildError::Invalid(what),
        TraverseError::Sift(SiftError::BadConfig(field)) => BuildError::Invalid(field),
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
            .map_err(|e| build_error(TraverseError::Sift(e)))
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
            peaks: [CapacityUse::default(); capacity::COUNT],
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
        gnss: (a.flags & AUX_GNSS != 0).then_some(GnssFix {
            position_m: a.gnss_m,
            sigma_m: sigma,
            lever_arm_m: a.gnss_lever_arm_m,
        }),
    }
}

impl TraverseProcessor<'_> {
    /// Raises the capacity peaks to this epoch's use.
    fn record_peaks(&mut self, out: &traverse::EpochOutput) {
        let cfg = self.traverse.config();
        let report = self.traverse.match_report();
        let (patches, patch_capacity) = self.traverse.patches_in_use().unwrap_or((0, 0));
        let uses = [
            (
                out.keypoints[0].max(out.keypoints[1]) as usize,
                cfg.sift.max_keypoints,
            ),
            (out.stereo_matches as usize, cfg.matching.max_keypoints),
            (report.tracks.live as usize, cfg.matching.max_tracks),
            (out.tie_points as usize, cfg.matching.max_tie_points),
            (out.points as usize, cfg.adjust.max_points),
            (out.observations as usize, cfg.adjust.max_observations),
            (patches, patch_capacity),
        ];
        for (peak, (used, reserved)) in self.peaks.iter_mut().zip(uses) {
            peak.record(used);
            peak.reserved = reserved.min(u32::MAX as usize) as u32;
        }
    }
}

impl EpochProcessor for TraverseProcessor<'_> {
    fn capacities(&self) -> [CapacityUse; capacity::COUNT] {
        self.peaks
    }

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
        self.record_peaks(&out);
        let mut result = epoch_result(input.epoch, &out);
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
    use phototraverse_core::camera::CalibrationPrecision;
    use phototraverse_core::camera::{Interior, Rig};
    use phototraverse_core::protocol::messages::{
        ImageStats, Pipeline, Repr, SiftCounts, TraverseSettings, CONFIG_VERSION,
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
            mode: AdjustMode::Seed2014,
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
            mode: AdjustMode::Seed2006,
            ..t
        }))
        .unwrap();
        assert_eq!(s.adjust.window, 7);
        assert!(s.adjust.sigmas.velocity_change_mps > 0.0);
        // Out-of-range settings are the Configure's own check (the same on the host).
        let bad = TraverseSettings { sigma_px: 0.0, ..t };
        assert_eq!(configure(bad).validate().unwrap_err().field, "sigma_px");
        let nan = TraverseSettings {
            datum: [f64::NAN; 6],
            ..t
        };
        assert_eq!(configure(nan).validate().unwrap_err().field, "datum");
    }

    #[test]
    fn every_traverse_flag_has_its_own_wire_bit() {
        let mut traverse_bits = 0;
        let mut wire = ResultFlags::NONE;
        for (t, r) in FLAGS {
            assert_eq!(t.count_ones(), 1);
            assert_eq!(r.bits().count_ones(), 1);
            assert_eq!(traverse_bits & t, 0, "traverse flag {t:#x} twice");
            assert!(!wire.contains(r), "wire flag {r:?} twice");
            traverse_bits |= t;
            wire |= r;
            assert_eq!(result_flags(t), r);
        }
        assert_eq!(traverse_bits & flags::FLAGGING, flags::FLAGGING);
        assert_eq!(result_flags(traverse_bits), wire);
        assert_eq!(result_flags(0), ResultFlags::NONE);
    }

    #[test]
    fn the_result_names_what_the_traverse_counted() {
        let out = traverse::EpochOutput {
            status: traverse::EpochStatus::Flagged,
            flags: flags::FEW_TIE_POINTS | flags::CAPACITY,
            std: Some([1e-4; 6]),
            sigma0: 0.8,
            redundancy: 500,
            relative_std_m: Some([0.01; 3]),
            keypoints: [900, 880],
            stereo_matches: 400,
            tie_points: 30,
            new_points: 12,
            observations: 1000,
            points: 250,
            dropped: 1,
            rms_px: 0.4,
            ..Default::default()
        };
        let r = epoch_result(7, &out);
        assert_eq!(r.status, ResultStatus::Flagged);
        assert_eq!(r.flags, ResultFlags::FEW_TIE_POINTS | ResultFlags::CAPACITY);
        assert_eq!(
            r.counts,
            Counts {
                keypoints: [900, 880],
                stereo_matches: 400,
                tie_points: 30,
                window_points: 250,
                observations: 1000,
                new_points: 12,
                dropped: 1,
            }
        );
        let a = r.adjustment().unwrap();
        assert_eq!((a.sigma0, a.rms_px, a.redundancy), (0.8, 0.4, 500));
        assert!((a.chi2 - 0.64 * 500.0).abs() < 1e-9);
        for (status, wire) in [
            (traverse::EpochStatus::Predicted, ResultStatus::Predicted),
            (traverse::EpochStatus::Rejected, ResultStatus::Failed),
        ] {
            let r = epoch_result(7, &traverse::EpochOutput { status, ..out });
            assert_eq!(r.status, wire);
            assert_eq!(r.figures, Figures::None, "{status:?}: not adjusted");
        }
    }

    #[test]
    fn the_largest_result_fits_a_transmit_slot() {
        let rig = Some(RigEstimate {
            params: [1.0; 6],
            std: [1.0; 6],
        });
        let blocks = [
            Figures::None,
            Figures::Adjustment(Adjustment {
                sigma0: 1.0,
                rms_px: 1.0,
                chi2: 1.0,
                redundancy: u32::MAX,
                relative_sd_m: [1.0; 3],
                step_m: Some([1.0; 3]),
            }),
            Figures::Sift(SiftCounts {
                extrema: [u32::MAX; 2],
                refined: [u32::MAX; 2],
            }),
            Figures::ImageStats(ImageStats {
                mean: [255.0; 2],
                gradient_energy: [510.0; 2],
                median: [255; 2],
            }),
        ];
        let mut buf = [0u8; 1024];
        let largest = blocks
            .into_iter()
            .map(|figures| {
                let r = EpochResult {
                    flags: ResultFlags(u32::MAX),
                    figures,
                    rig,
                    ..EpochResult::empty(u32::MAX, ResultStatus::Flagged)
                };
                r.emit(&mut buf).unwrap()
            })
            .max()
            .unwrap();
        assert!(largest <= crate::link::TX_MAX_PAYLOAD, "{largest} bytes");
    }
}
