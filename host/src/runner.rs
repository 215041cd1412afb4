//! `phototraverse run`: a dataset streamed through the emulated rig link to the
//! firmware, which runs the core traverse; the answers become `poses.txt`,
//! `eop.csv`, `points.ply`, `efoto/` (E-Foto's point import), `colmap/` (a COLMAP
//! text model), `report.json` and `report.html` in the output directory. After each result the host pulls
//! the tie points and observations that became final (protocol `Points`), and
//! at the end asks the firmware to flush its window.
//!
//! `poses.txt` is written line by line as results arrive, so whatever stops a
//! run (a corrupt image is skipped, a dead firmware ends it) leaves the poses of
//! the epochs processed so far on disk.
use crate::dataset::{aiding, Dataset};
use crate::eval::{evaluate, Evaluation};
use crate::link::LinkOptions;
use crate::mcu::{TargetImage, TargetReport};
use crate::pipeline::PipelineSettings;
use crate::poses::{format_pose, KittiPose};
use crate::report::colmap;
use crate::report::{
    efoto_image_index, velocities, write_efoto, write_eop_csv, write_html, write_ply, CameraEop,
    CapacityLine, EpochChi2, EpochRecord, EpochStatus, GnssRecord, MemoryLine, QualitySummary,
    RigReport, RunReport, TieCollector,
};
use crate::session::{EpochFrames, Session, SessionOptions};
use crate::smoothing;
use anyhow::{Context, Result};
use phototraverse_core::adjust::quality::ChiSquareTest;
use phototraverse_core::budget::{Component, ComponentKind, MemoryBudget, Stage};
use phototraverse_core::camera::{kitti_from_pose, pose_from_kitti, Pose, Rig};
use phototraverse_core::protocol::messages::{
    self, stage, Aux, ConfigAccepted, EpochResult, ResultFlags, AUX_GNSS, AUX_ODOMETER,
};
use phototraverse_core::traverse::motion::constant_velocity;
use phototraverse_firmware_sim::{configuration_budget, TraverseFactory};
use std::io::Write;
use std::path::Path;

/// How to run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    pub link: LinkOptions,
    pub settings: PipelineSettings,
    /// Process only the first epochs.
    pub max_epochs: Option<usize>,
    /// Draw a progress bar (on a terminal).
    pub progress: bool,
}

/// What a run produced.
#[derive(Debug, Clone)]
pub struct RunOutcome {
    pub report: RunReport,
    pub evaluation: Option<Evaluation>,
    /// Median firmware processing time per epoch, milliseconds.
    pub median_epoch_ms: f64,
    /// Epochs whose images could not be read (skipped, pose predicted).
    pub unreadable: Vec<usize>,
    /// Tie points written to `points.ply`.
    pub tie_points: usize,
    /// Median of the points' position standard deviation (sqrt(sX² + sY² + sZ²)), metres.
    pub median_point_sigma_m: f64,
}

/// Runs `ds` into `out` (created if needed).
pub fn run_dataset(ds: &Dataset, out: &Path, opts: &RunOptions) -> Result<RunOutcome> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let configure = opts
        .settings
        .configure_for(&ds.rig, &ds.datum, &ds.precision);
    let image = opts.link.target_image(&configure)?;
    let transport = opts
        .link
        .open_with_image(image.as_ref())
        .context("cannot open the link to the firmware")?;
    let mut session = Session::open(transport, SessionOptions::from_link(&opts.link))
        .context("the firmware did not answer the hello")?;
    let accepted = session.configure(&configure)?;
    let mut run = Run::new(ds, out, opts, accepted)?;
    run.target_image = image;
    let n = opts.max_epochs.map_or(ds.len(), |m| m.min(ds.len()));
    let bar = progress_bar(n as u64, opts.progress);
    let mut failure = None;
    let started = std::time::Instant::now();
    for i in 0..n {
        if crate::interrupt::requested() {
            // The epochs done are finished as at the sequence's end: their last results
            // and tie points are waited for, and every output is written.
            run.report.interrupted = true;
            break;
        }
        if let Err(e) = run.epoch(&mut session, i) {
            failure = Some(e.context(format!("epoch {i} ({})", ds.epochs[i].name)));
            break;
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    if failure.is_none() {
        if let Err(e) = session.finish() {
            failure = Some(anyhow::Error::new(e).context("waiting for the last results"));
        }
    }
    if failure.is_none() {
        // The sequence ended: the points and observations still in the window are final.
        match session.pull_points(true) {
            Ok(msgs) => msgs.iter().for_each(|m| run.ties.absorb(m)),
            Err(e) => {
                failure = Some(anyhow::Error::new(e).context("flushing the tie points"));
            }
        }
    }
    if !run.report.epochs.is_empty() {
        let ms = started.elapsed().as_secs_f64() * 1e3;
        run.report.wall_ms_per_epoch = Some(ms / run.report.epochs.len() as f64);
    }
    let link = session.link_stats();
    run.report.link = serde_json::to_value(&link).ok();
    let outcome = run.finish(&session)?;
    match failure {
        Some(e) => Err(e.context(format!(
            "run stopped; the outputs of the {} epochs processed are in {} (link: {})",
            outcome.report.epochs.len(),
            out.display(),
            link.summary()
        ))),
        None => Ok(outcome),
    }
}

fn progress_bar(n: u64, show: bool) -> indicatif::ProgressBar {
    use std::io::IsTerminal;
    if !show || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(n);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{spinner} epoch {pos}/{len} [{bar:40}] {per_sec} eta {eta}",
    ) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

/// State of one run.
struct Run<'d> {
    ds: &'d Dataset,
    out: &'d Path,
    poses_file: std::io::BufWriter<std::fs::File>,
    report: RunReport,
    kitti: Vec<KittiPose>,
    epoch_ms: Vec<f64>,
    unreadable: Vec<usize>,
    accepted: ConfigAccepted,
    settings: PipelineSettings,
    /// The datum of epoch 0: the poses written and the ground truth are relative to it.
    datum: Pose,
    /// The rig the right cameras are placed with: the calibration, or the last estimate.
    rig: Rig,
    /// Two-sided global test of each adjusted epoch (from sigma0 and the redundancy).
    chi2: Vec<ChiSquareTest>,
    /// Tie points and observations reported by the firmware.
    ties: TieCollector,
    /// The part and image of a run on an emulated microcontroller.
    target_image: Option<TargetImage>,
}

impl<'d> Run<'d> {
    fn new(
        ds: &'d Dataset,
        out: &'d Path,
        opts: &RunOptions,
        accepted: ConfigAccepted,
    ) -> Result<Self> {
        let path = out.join("poses.txt");
        let file = std::fs::File::create(&path)
            .with_context(|| format!("cannot create {}", path.display()))?;
        let report = RunReport {
            dataset: ds.dir.display().to_string(),
            mode: opts.settings.mode.name().into(),
            image_width: ds.rig.left.width_px,
            image_height: ds.rig.left.height_px,
            ..Default::default()
        };
        Ok(Run {
            ds,
            out,
            poses_file: std::io::BufWriter::new(file),
            report,
            kitti: Vec::new(),
            epoch_ms: Vec::new(),
            unreadable: Vec::new(),
            accepted,
            settings: opts.settings,
            datum: opts.settings.datum_for(&ds.datum),
            rig: ds.rig,
            chi2: Vec::new(),
            ties: TieCollector::default(),
            target_image: None,
        })
    }

    /// The GNSS fix and the odometer's count at epoch `i`, when the dataset has them
    /// ([`aiding`]).
    fn aux_of(&self, i: usize, time: f64) -> Option<Aux> {
        let outage = aiding::within(&self.ds.gnss_outages, time);
        let gnss = aiding::gnss_at(&self.ds.gnss, time).filter(|_| !outage);
        let odometer = aiding::odometer_at(&self.ds.odometer, time);
        if gnss.is_none() && odometer.is_none() {
            return None;
        }
        let (odometer_m, odometer_sigma_m) = odometer.unwrap_or_default();
        let (gnss_m, sigma) = gnss.unwrap_or_default();
        Some(Aux {
            epoch: i as u32,
            flags: gnss.map_or(0, |_| AUX_GNSS) | odometer.map_or(0, |_| AUX_ODOMETER),
            odometer_m,
            odometer_sigma_m,
            gnss_m,
            gnss_sigma_m: [sigma; 3],
            gnss_lever_arm_m: self.ds.gnss_setup.lever_arm_m,
        })
    }

    /// Sends epoch `i`, waits for its result and records it.
    fn epoch<T: crate::link::Transport>(
        &mut self,
        session: &mut Session<T>,
        i: usize,
    ) -> Result<()> {
        let time = self.ds.time_of(i);
        let record = match self.ds.load_pair(i) {
            Ok((left, right)) => {
                let timestamp_us = (time * 1e6).max(0.0) as u64;
                let mut frames = EpochFrames::gray8(i as u32, timestamp_us, &left, &right);
                let aux = self.aux_of(i, time);
                frames.aux = aux;
                session.send_epoch(&frames)?;
                let e = i as u32;
                // Statistics follow the result of every epoch the firmware processed.
                session.wait_for("the epoch's result", |s| {
                    s.result(e)
                        .is_some_and(|r| s.stats(e).is_some() || no_pose_came_back(r))
                })?;
                let result = *session.result(e).context("result vanished")?;
                self.note_rig_and_test(&result);
                let pulled = std::time::Instant::now();
                for m in session.pull_points(false)? {
                    self.ties.absorb(&m);
                }
                let report_ms = pulled.elapsed().as_secs_f64() * 1e3;
                if let Some(st) = session.stats(e) {
                    self.epoch_ms
                        .push(st.timings_us[stage::TOTAL] as f64 / 1000.0);
                }
                let mut rec = self.record(i, time, &result, session.stats(e).map(|s| s.timings_us));
                // Host-side round trips of the tie point report (firmware work and link).
                rec.stage_ms.insert("points_report".into(), report_ms);
                note_aux(&mut rec, aux);
                rec
            }
            Err(err) => {
                eprintln!("phototraverse: warning: epoch {i}: {err}; its pose is predicted");
                self.unreadable.push(i);
                self.predicted(i, time, format!("unreadable image: {err}"))
            }
        };
        self.push(record)
    }

    fn push(&mut self, record: EpochRecord) -> Result<()> {
        let k = kitti_from_pose(&self.datum, &record.left.to_pose());
        writeln!(self.poses_file, "{}", format_pose(&k))?;
        self.poses_file.flush()?;
        self.kitti.push(k);
        self.report.epochs.push(record);
        Ok(())
    }

    /// The constant-velocity prediction of epoch `i` from the last two records.
    fn prediction(&self, time: f64) -> Pose {
        let e = &self.report.epochs;
        match e.len() {
            0 => self.datum,
            1 => e[0].left.to_pose(),
            n => {
                // Every record carries its time (`time_of`): index seconds without times.txt.
                let (a, b) = (&e[n - 2], &e[n - 1]);
                let (ta, tb) = (a.time.unwrap_or_default(), b.time.unwrap_or_default());
                constant_velocity((&a.left.to_pose(), ta), (&b.left.to_pose(), tb), time)
            }
        }
    }

    fn predicted(&self, i: usize, time: f64, note: String) -> EpochRecord {
        let left = self.prediction(time);
        let right = self.rig.right_pose(&left);
        let eop = |p: &Pose| CameraEop::from_pose(p, None);
        EpochRecord {
            note: Some(note),
            ..EpochRecord::posed(
                i,
                Some(time),
                EpochStatus::Predicted,
                (eop(&left), eop(&right)),
            )
        }
    }

    fn record(
        &self,
        i: usize,
        time: f64,
        r: &EpochResult,
        timings: Option<[u32; 8]>,
    ) -> EpochRecord {
        let status = match r.status {
            messages::ResultStatus::Ok => EpochStatus::Ok,
            messages::ResultStatus::Flagged => EpochStatus::Flagged,
            messages::ResultStatus::Predicted => EpochStatus::Predicted,
            messages::ResultStatus::Lost => EpochStatus::Lost,
            _ => EpochStatus::Predicted,
        };
        if no_pose_came_back(r) {
            // The host predicts it.
            let mut rec = self.predicted(i, time, "frames lost on the link".into());
            rec.status = status;
            return rec;
        }
        let left = Pose::from_params(&r.pose);
        let right = self.rig.right_pose(&left);
        let sigma = |s: [f32; 6]| (s != [0.0; 6]).then(|| s.map(f64::from));
        let stage_ms = timings
            .map(|t| {
                stage::NAMES
                    .iter()
                    .zip(t)
                    .filter(|(_, us)| *us > 0)
                    .map(|(n, us)| (n.to_string(), us as f64 / 1000.0))
                    .collect()
            })
            .unwrap_or_default();
        let test = epoch_test(r);
        EpochRecord {
            epoch: i,
            time: Some(time),
            status,
            note: flag_note(r.flags),
            left: CameraEop::from_pose(&left, sigma(r.sigma)),
            right: CameraEop::from_pose(&right, sigma(r.right_sigma)),
            sigma0: r.adjustment().map(|a| a.sigma0).filter(|s| *s > 0.0),
            chi2_passed: test.map(|t| t.passed),
            chi2: test.map(EpochChi2::from),
            observations: r.counts.observations as usize,
            tie_points: r.counts.tie_points as usize,
            keypoints: r.counts.keypoints,
            stereo_matches: r.counts.stereo_matches,
            stage_ms,
            gnss: None,
            odometer_count_m: None,
            velocity: None,
            relative_sd_m: r
                .adjustment()
                .map(|a| a.relative_sd_m.map(f64::from))
                .filter(|s| s.iter().any(|v| *v > 0.0)),
            step_m: r
                .adjustment()
                .and_then(|a| a.step_m)
                .map(|s| s.map(f64::from)),
            realtime_centre_m: None,
        }
    }

    /// Keeps the estimated rig (right cameras, report) and the epoch's global test.
    fn note_rig_and_test(&mut self, r: &EpochResult) {
        if let Some(est) = &r.rig {
            let p = est.params.map(f64::from);
            self.rig.relative_angles = [p[0], p[1], p[2]];
            self.rig.base_m = [p[3], p[4], p[5]];
            let s = est.std.map(f64::from);
            let c = &self.ds.rig;
            self.report.rig = Some(RigReport {
                relative_angles_deg: [p[0], p[1], p[2]].map(f64::to_degrees),
                base_m: self.rig.base_m,
                std: crate::report::sigmas_in_degrees(s),
                calibration_angles_deg: c.relative_angles.map(f64::to_degrees),
                calibration_base_m: c.base_m,
            });
        }
        if let Some(t) = epoch_test(r) {
            self.chi2.push(t);
        }
    }

    /// sigma0 and chi-square counts over the adjusted epochs.
    fn quality(&self) -> Option<QualitySummary> {
        if self.chi2.is_empty() {
            return None;
        }
        let mut s0: Vec<f64> = self.report.epochs.iter().filter_map(|e| e.sigma0).collect();
        let max = s0.iter().copied().fold(0.0, f64::max);
        Some(QualitySummary {
            adjusted: self.chi2.len(),
            sigma0_median: median(&mut s0),
            sigma0_max: max,
            chi2_passed: self.chi2.iter().filter(|t| t.passed).count(),
            chi2_failed: self.chi2.iter().filter(|t| t.statistic > t.upper).count(),
            chi2_below: self.chi2.iter().filter(|t| t.statistic < t.lower).count(),
            apriori_sigma_px: self.settings.sigma_px,
        })
    }

    /// E-Foto image index and file name of every image of the epochs processed.
    /// The path of a dataset file relative to the dataset: distinct for the left and
    /// right images of an epoch (`image_0/000000.png`, `image_1/000000.png`).
    fn relative_name(&self, p: &Path) -> String {
        p.strip_prefix(&self.ds.dir)
            .unwrap_or(p)
            .to_string_lossy()
            .into_owned()
    }

    fn image_names(&self) -> Vec<(usize, String)> {
        self.report
            .epochs
            .iter()
            .filter_map(|r| self.ds.epochs.get(r.epoch).map(|e| (r.epoch, e)))
            .flat_map(|(i, e)| {
                [
                    (efoto_image_index(i, 0), self.relative_name(&e.left)),
                    (efoto_image_index(i, 1), self.relative_name(&e.right)),
                ]
            })
            .collect()
    }

    /// The images of the COLMAP model: both cameras of every epoch, named by their path
    /// in the dataset.
    fn model_images(&self) -> Vec<colmap::ModelImage> {
        self.report
            .epochs
            .iter()
            .filter_map(|r| self.ds.epochs.get(r.epoch).map(|e| (r, e)))
            .flat_map(|(r, e)| {
                [(0u8, &r.left, &e.left), (1, &r.right, &e.right)].map(|(camera, eop, file)| {
                    colmap::ModelImage {
                        id: efoto_image_index(r.epoch, camera) as u32,
                        camera,
                        name: self.relative_name(file),
                        pose: eop.to_pose(),
                    }
                })
            })
            .collect()
    }

    fn memory_lines(&self, high_water: Option<u32>) -> Vec<MemoryLine> {
        // The firmware's own prediction: frames and traverse components.
        let mut budget = MemoryBudget::new();
        let configure =
            self.settings
                .configure_for(&self.ds.rig, &self.ds.datum, &self.ds.precision);
        let _ = configuration_budget(&TraverseFactory, &configure, &mut budget);
        let kind = |k: ComponentKind| format!("{k:?}").to_lowercase();
        let line = |c: &Component| MemoryLine {
            name: c.name.to_string(),
            kind: kind(c.kind),
            predicted_bytes: c.bytes,
            measured_bytes: None,
        };
        // Each stage's components, then the stage's total beside what its buffers
        // carved when the firmware built them.
        let mut lines = Vec::new();
        for (stage, carved) in Stage::ALL.into_iter().zip(self.accepted.carved_bytes) {
            let own: Vec<&Component> = budget
                .components()
                .iter()
                .filter(|c| Stage::of_component(c.name) == Some(stage))
                .collect();
            if own.is_empty() && carved == 0 {
                continue;
            }
            lines.extend(own.into_iter().map(line));
            lines.push(MemoryLine {
                name: format!("{} (stage)", stage.prefix()),
                kind: "stage".into(),
                predicted_bytes: budget.total_of_stage(stage),
                measured_bytes: Some(carved as usize),
            });
        }
        let unstaged = |c: &&Component| Stage::of_component(c.name).is_none();
        lines.extend(budget.components().iter().filter(unstaged).map(line));
        lines.push(MemoryLine {
            name: "total (firmware arena)".into(),
            kind: "all".into(),
            predicted_bytes: self.accepted.predicted_bytes as usize,
            measured_bytes: high_water.map(|h| h as usize),
        });
        lines
    }

    /// Smooths the positions over all the GNSS fixes ([`crate::smoothing`]) and
    /// rewrites `poses.txt`, which held the positions as the firmware gave them.
    fn smooth(&mut self) -> Result<()> {
        let rig = self.rig;
        let lever_arm = self.ds.gnss_setup.lever_arm_m;
        self.report.smoothing =
            smoothing::smooth_over_fixes(&mut self.report.epochs, lever_arm, &rig.relative());
        if self.report.smoothing.is_none() {
            return Ok(());
        }
        self.kitti = self
            .report
            .epochs
            .iter()
            .map(|e| kitti_from_pose(&self.datum, &e.left.to_pose()))
            .collect();
        let text: String = self.kitti.iter().map(|k| format_pose(k) + "\n").collect();
        // Written aside and renamed: an interruption leaves the firmware's poses whole.
        let (path, aside) = (self.out.join("poses.txt"), self.out.join("poses.txt.part"));
        std::fs::write(&aside, text)
            .with_context(|| format!("cannot write {}", aside.display()))?;
        std::fs::rename(&aside, &path).with_context(|| format!("cannot replace {}", path.display()))
    }

    fn finish<T: crate::link::Transport>(mut self, session: &Session<T>) -> Result<RunOutcome> {
        let last = self.report.epochs.len().checked_sub(1);
        let last_stats = last.and_then(|l| session.stats(l as u32));
        self.report.memory = self.memory_lines(last_stats.map(|s| s.memory_high_water));
        self.report.capacities = last_stats.map(capacity_lines).unwrap_or_default();
        if let Some(image) = &self.target_image {
            let stats: Vec<_> = session.all_stats().copied().collect();
            self.report.target = Some(TargetReport::new(image, &stats)?);
        }
        self.smooth()?;
        for (e, v) in velocities(&self.report.epochs).into_iter().enumerate() {
            self.report.epochs[e].velocity = v;
        }
        self.report.quality = self.quality();
        let mut evaluation = None;
        if let Some(gt) = &self.ds.ground_truth {
            let gt_part = &gt[..self.kitti.len().min(gt.len())];
            self.report.ground_truth = Some(
                gt_part
                    .iter()
                    .map(|k| pose_from_kitti(&self.datum, k).centre)
                    .collect(),
            );
            if let Ok(e) = evaluate(gt_part, &self.kitti) {
                self.report.evaluation = serde_json::to_value(&e).ok();
                evaluation = Some(e);
            }
        }
        write_eop_csv(&self.out.join("eop.csv"), &self.report)?;
        let points = self.ties.tie_points();
        self.report.residuals_px = self.ties.residuals_px();
        write_ply(&self.out.join("points.ply"), &points)?;
        write_efoto(&self.out.join("efoto"), &points, &self.image_names())?;
        let image_id = |epoch: usize, camera: u8| efoto_image_index(epoch, camera) as u32;
        let model = colmap::write_colmap(
            &self.out.join("colmap"),
            &self.rig,
            &self.model_images(),
            &points,
            image_id,
        )?;
        self.report.colmap_rms_reprojection_px = Some(model.rms_reprojection_px);
        let json = serde_json::to_string_pretty(&self.report)?;
        std::fs::write(self.out.join("report.json"), json + "\n")?;
        write_html(&self.out.join("report.html"), &self.report)?;
        Ok(RunOutcome {
            median_epoch_ms: median(&mut self.epoch_ms),
            tie_points: points.len(),
            median_point_sigma_m: median(
                &mut points
                    .iter()
                    .filter_map(|p| p.sigma)
                    .map(|s| (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt())
                    .collect::<Vec<f64>>(),
            ),
            report: self.report,
            evaluation,
            unreadable: self.unreadable,
        })
    }
}

/// What the epoch's Aux carried, with the adjusted antenna position's residual to the
/// fix (the centre plus the lever arm turned by the adjusted attitude).
fn note_aux(rec: &mut EpochRecord, aux: Option<Aux>) {
    let Some(a) = aux else { return };
    if a.flags & AUX_GNSS != 0 {
        let antenna = aiding::antenna_position(&rec.left.to_pose(), a.gnss_lever_arm_m);
        rec.gnss = Some(GnssRecord {
            position: a.gnss_m,
            sigma_m: a.gnss_sigma_m[0],
            residual_m: [0, 1, 2].map(|k| antenna[k] - a.gnss_m[k]),
        });
    }
    if a.flags & AUX_ODOMETER != 0 {
        rec.odometer_count_m = Some(a.odometer_m);
    }
}

/// The firmware's capacity peaks, by name; a processor without a capacity reports none.
fn capacity_lines(stats: &messages::Stats) -> Vec<CapacityLine> {
    stats
        .capacities
        .iter()
        .zip(messages::capacity::NAMES)
        .filter(|(c, _)| c.reserved > 0)
        .map(|(c, name)| CapacityLine {
            name: name.into(),
            peak: c.peak,
            reserved: c.reserved,
        })
        .collect()
}

/// The median of the run's figures (the upper one of an even count); 0 when empty.
pub(crate) fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// Whether the firmware sent no pose for the epoch (frames lost or refused).
fn no_pose_came_back(r: &EpochResult) -> bool {
    matches!(
        r.status,
        messages::ResultStatus::Lost | messages::ResultStatus::Failed
    )
}

/// The two-sided global test of an adjusted epoch's window.
fn epoch_test(r: &EpochResult) -> Option<ChiSquareTest> {
    let oriented = matches!(
        r.status,
        messages::ResultStatus::Ok | messages::ResultStatus::Flagged
    );
    r.adjustment()
        .filter(|a| oriented && a.sigma0 > 0.0 && a.redundancy >= 1)
        .map(|a| ChiSquareTest::new(a.chi2, a.redundancy as usize))
}

/// The flags of an epoch in words. The informational NO_RESECTION has no word: the
/// notes never carried it, and the reports stay comparable with earlier runs.
fn flag_note(f: ResultFlags) -> Option<String> {
    let names = [
        (ResultFlags::FEW_TIE_POINTS, "few tie points"),
        (ResultFlags::LOST, "continuity lost"),
        (ResultFlags::NO_FEATURES, "no features"),
        (ResultFlags::NO_STEREO, "no stereo matches"),
        (ResultFlags::REPEATED, "repeated frame"),
        (ResultFlags::CHI2, "chi-square test failed"),
        (ResultFlags::SOLVE_FAILED, "adjustment failed"),
        (ResultFlags::BAD_IMAGE, "image refused"),
        (ResultFlags::CAPACITY, "capacity reached"),
        (ResultFlags::RELOCALIZED, "relocalized"),
        (ResultFlags::ROTATION_FROM_MATCHES, "rotation from matches"),
        (ResultFlags::CALIBRATION_CORRECTED, "calibration corrected"),
    ];
    let words: Vec<&str> = names
        .iter()
        .filter(|(b, _)| f.contains(*b))
        .map(|(_, n)| *n)
        .collect();
    (!words.is_empty()).then(|| words.join(", "))
}
