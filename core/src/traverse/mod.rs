//! The traverse: the per-epoch state machine that joins the stages.
//!
//! Each epoch (one synchronised stereo pair): reduced SIFT on both images ->
//! stereo and temporal matching (quad tie points, tracks) -> initial values
//! (robust resection on tie points already in object space, else the
//! constant-velocity prediction; new tie points by intersection from the
//! previous, adjusted epoch) -> incremental bundle adjustment of the sliding
//! window -> [`EpochOutput`].
//!
//! An epoch the images do not determine (few tie points, lost continuity) is
//! still added to the window, tied to its motion prediction by a weighted
//! prior, so the traverse goes on with continuity and the epoch is flagged.
//! Frames that cannot be processed at all (wrong size) are rejected without
//! touching the state: nothing computed before is lost.
//!
//! Memory: every buffer is carved from the arena at construction
//! ([`TraverseConfig::budget`] predicts it); processing allocates nothing.

mod area;
pub mod config;
pub mod motion;
pub mod output;
pub mod patches;
pub mod turn;

#[cfg(test)]
mod tests;

pub use config::{CalibrationCheck, CalibrationPrecision, TraverseConfig, TraverseMode};
pub use output::{flags, EpochOutput, EpochStatus, StageTimes};

use crate::adjust::geometry::camera_pose;
use crate::adjust::quality::chi2_quantile;
use crate::adjust::{
    intersect, resect, AdjustError, Camera, Correspondence, Observation, Ray, Window,
};
use crate::budget::{Arena, OutOfMemory};
use crate::camera::{angles_from_rotation, Pose};
use crate::features::FeatureSet;
use crate::image::ImageView;
use crate::matching::refine::{
    correlate, magnify_template, recentre, refine_checked, TEMPLATE_LEN,
};
use crate::matching::{
    relative_motion, EpochStatus as MatchStatus, Features, MatchError, Matcher, StereoFeatures,
    TiePoint,
};
use crate::sift::{Sift, SiftError};
use area::AreaTie;
use bytemuck::{Pod, Zeroable};
use motion::predict;
use nalgebra::Vector3;
use patches::{PatchInfo, Patches};

/// Microsecond time source for the per-stage timings (the DWT cycle counter on a
/// Cortex-M, `Instant` on the host). [`NoClock`] reports zeros.
pub trait Clock {
    fn now_us(&self) -> u64;
}

/// A clock that always reads zero (timings off).
pub struct NoClock;

impl Clock for NoClock {
    fn now_us(&self) -> u64 {
        0
    }
}

/// Which window point a track's tie point became.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct TrackPoint {
    pub track_id: u32,
    pub point: u32,
}

/// A tie point's refined current positions, waiting to be written to its track.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct Refined {
    pub slot: u32,
    /// The template (patch store index) the position was found with.
    pub entry: u32,
    pub left: [f32; 2],
    pub right: [f32; 2],
}

const NO_POINT: TrackPoint = TrackPoint {
    track_id: u32::MAX,
    point: u32::MAX,
};

/// Why the traverse could not be built.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TraverseError {
    Sift(SiftError),
    Match(MatchError),
    Adjust(AdjustError),
    OutOfMemory(OutOfMemory),
    /// The configuration is inconsistent (the field is named).
    Config(&'static str),
}

impl From<SiftError> for TraverseError {
    fn from(e: SiftError) -> Self {
        TraverseError::Sift(e)
    }
}
impl From<MatchError> for TraverseError {
    fn from(e: MatchError) -> Self {
        TraverseError::Match(e)
    }
}
impl From<AdjustError> for TraverseError {
    fn from(e: AdjustError) -> Self {
        TraverseError::Adjust(e)
    }
}
impl From<OutOfMemory> for TraverseError {
    fn from(e: OutOfMemory) -> Self {
        TraverseError::OutOfMemory(e)
    }
}

impl core::fmt::Display for TraverseError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            TraverseError::Sift(e) => write!(f, "feature extractor: {e:?}"),
            TraverseError::Match(e) => write!(f, "matcher: {e:?}"),
            TraverseError::Adjust(e) => write!(f, "adjustment: {e}"),
            TraverseError::OutOfMemory(e) => write!(f, "{e}"),
            TraverseError::Config(field) => write!(f, "inconsistent configuration: {field}"),
        }
    }
}

/// Auxiliary observations of an epoch, when the vehicle has them.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AuxObservations {
    /// The odometer's count at the epoch: the distance travelled since it started and
    /// its sigma, metres. The window takes the leg from the previous epoch it holds, so
    /// an epoch that never entered it (a refused image, a repeated frame) costs no leg.
    pub odometer: Option<(f64, f64)>,
    /// A GNSS fix.
    pub gnss: Option<GnssFix>,
}

/// A GNSS fix of an epoch: the antenna's position, its offset from the left camera.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GnssFix {
    /// The antenna's position (object frame) and the sigma of each coordinate, m.
    pub position_m: [f64; 3],
    pub sigma_m: f64,
    /// The antenna seen from the left perspective centre in the left camera's frame
    /// (x right, y up, z backwards), m; zero: the fix is the perspective centre's.
    pub lever_arm_m: [f64; 3],
}

/// A left pose with its time, for the motion prediction.
#[derive(Debug, Clone, Copy)]
struct Stamped {
    pose: Pose,
    time: f64,
}

/// The traverse state over a sequence.
pub struct Traverse<'a> {
    cfg: TraverseConfig,
    sift: Sift<'a>,
    /// Feature sets `[buffer][camera]`; `features[cur]` holds the last accepted epoch.
    features: [[FeatureSet<'a>; 2]; 2],
    cur: usize,
    matcher: Matcher<'a>,
    window: Window<'a>,
    track_points: &'a mut [TrackPoint],
    corr: &'a mut [Correspondence],
    /// Templates of the last accepted epoch's left image (temporal refinement).
    patches: Option<Patches<'a>>,
    refined: &'a mut [Refined],
    /// Tie points found by area matching at this epoch (`area`), the first `n_area`.
    area: &'a mut [AreaTie],
    n_area: usize,
    /// Tie points of this epoch found with their template (`refined`), the first `n_refined`.
    n_refined: usize,
    /// Input epoch index of each window slot (oldest first).
    window_inputs: &'a mut [u32],
    epochs: u32,
    have_prev: bool,
    /// The last two adjusted (or predicted) epochs.
    history: [Option<Stamped>; 2],
    /// Window epoch id of the last accepted epoch.
    prev_window_epoch: Option<u32>,
    /// The matcher's report of the last epoch (diagnostics).
    last_match: crate::matching::EpochReport,
    /// Why the last failed adjustment failed (diagnostics).
    last_solve_error: Option<AdjustError>,
    /// Corrections the calibration check applied so far.
    calibration_corrections: u32,
    /// Consecutive epochs whose calibration test rejected the calibration.
    calibration_rejections: u32,
    /// The odometer count (distance, variance) of the newest window epoch, if it had one.
    odometer_count: Option<(f64, f64)>,
}

impl<'a> Traverse<'a> {
    /// Builds every stage from `arena` (size it with [`TraverseConfig::budget`]).
    pub fn new(cfg: TraverseConfig, arena: &mut Arena<'a>) -> Result<Self, TraverseError> {
        check_config(&cfg)?;
        let sift = Sift::new(cfg.sift, arena)?;
        let n = cfg.features_per_image();
        let features = [
            [FeatureSet::new(arena, n)?, FeatureSet::new(arena, n)?],
            [FeatureSet::new(arena, n)?, FeatureSet::new(arena, n)?],
        ];
        let matcher = Matcher::new(cfg.matching, arena)?;
        let mut window = Window::new(cfg.adjust, &cfg.rig, arena)?;
        window.set_base_length(cfg.rig.base_length());
        let track_points = arena.alloc_slice::<TrackPoint>(cfg.matching.max_tracks)?;
        track_points.fill(NO_POINT);
        let (patches, refined, area) = match cfg.patch_capacity() {
            Some((cap, half)) => (
                Some(Patches::new(arena, cap, half)?),
                arena.alloc_slice::<Refined>(cfg.matching.max_tie_points)?,
                arena.alloc_slice::<AreaTie>(cfg.area_capacity())?,
            ),
            None => (None, Default::default(), Default::default()),
        };
        let corr = arena.alloc_slice::<Correspondence>(cfg.matching.max_tie_points)?;
        let window_inputs = arena.alloc_slice::<u32>(cfg.adjust.window)?;
        Ok(Traverse {
            cfg,
            sift,
            features,
            cur: 0,
            matcher,
            window,
            track_points,
            corr,
            patches,
            refined,
            area,
            n_area: 0,
            n_refined: 0,
            window_inputs,
            epochs: 0,
            have_prev: false,
            history: [None, None],
            prev_window_epoch: None,
            last_match: Default::default(),
            last_solve_error: None,
            calibration_corrections: 0,
            calibration_rejections: 0,
            odometer_count: None,
        })
    }

    /// What the matcher did at the last epoch (counts per step, for diagnostics).
    pub fn match_report(&self) -> &crate::matching::EpochReport {
        &self.last_match
    }

    /// Why the last adjustment that failed did so (diagnostics).
    pub fn last_solve_error(&self) -> Option<AdjustError> {
        self.last_solve_error
    }

    /// Image patches kept for area tracking and the store's capacity; `None` when
    /// area tracking is off.
    pub fn patches_in_use(&self) -> Option<(usize, usize)> {
        self.patches.as_ref().map(|p| (p.len(), p.capacity()))
    }

    pub fn config(&self) -> &TraverseConfig {
        &self.cfg
    }

    /// Epochs given to [`Traverse::process`] so far.
    pub fn epochs_seen(&self) -> u32 {
        self.epochs
    }

    /// The window's epochs, oldest first: input epoch index, left pose and its
    /// standard deviations from the last adjustment (refinements of earlier outputs).
    pub fn window_epochs(&self) -> impl Iterator<Item = (u32, Pose, Option<[f64; 6]>)> + '_ {
        (0..self.window.n_epochs()).filter_map(move |i| {
            Some((
                self.window_inputs[i],
                self.window.epoch_pose(i)?,
                self.window.epoch_absolute_std(i),
            ))
        })
    }

    /// The window's tie points with their standard deviations.
    pub fn window_points(&self) -> impl Iterator<Item = (u32, [f64; 3], Option<[f64; 3]>)> + '_ {
        self.track_points
            .iter()
            .filter(|t| t.point != u32::MAX)
            .filter_map(move |t| {
                Some((
                    t.track_id,
                    self.window.point(t.point)?,
                    self.window.point_std(t.point),
                ))
            })
    }

    /// The rig as the adjustment has it (the calibration when it is not estimated)
    /// and its standard deviations (zero when fixed).
    pub fn rig_estimate(&self) -> (crate::adjust::RigParams, [f64; 6]) {
        (self.window.rig(), self.window.rig_std())
    }

    /// Right camera pose for a left pose, with the rig as last adjusted.
    fn right_of(&self, left: &Pose) -> Pose {
        camera_pose(left, &self.window.rig(), Camera::Right)
    }

    /// Processes one synchronised stereo pair taken at `time_s`.
    pub fn process(
        &mut self,
        left: &ImageView,
        right: &ImageView,
        time_s: f64,
        clock: &impl Clock,
    ) -> EpochOutput {
        self.process_with_aux(left, right, time_s, AuxObservations::default(), clock)
    }

    /// [`Traverse::process`] with odometer and GNSS observations of the epoch, which
    /// enter the adjustment as weighted constraints (bridging a GNSS outage).
    pub fn process_with_aux(
        &mut self,
        left: &ImageView,
        right: &ImageView,
        time_s: f64,
        aux: AuxObservations,
        clock: &impl Clock,
    ) -> EpochOutput {
        let t0 = clock.now_us();
        let k = self.epochs;
        self.epochs = self.epochs.wrapping_add(1);
        let prediction = predict(&self.history, time_s).unwrap_or(self.cfg.datum);
        let mut out = EpochOutput {
            epoch: k,
            left: prediction,
            right: self.right_of(&prediction),
            ..EpochOutput::default()
        };

        let fill = 1 - self.cur;
        if !self.extract(fill, left, right, &mut out, clock) {
            out.settle(false);
            return self.finish(out, t0, clock);
        }
        let t1 = clock.now_us();

        let report = match self.match_epoch(fill, left, right, &prediction) {
            Ok(r) => r,
            Err(_) => {
                // The matcher refused the state (a programming error, not an input one):
                // start over from this epoch rather than stop the traverse.
                self.have_prev = false;
                out.flags |= flags::LOST;
                out.settle(false);
                return self.finish(out, t0, clock);
            }
        };
        self.n_refined = 0;
        if report.status != MatchStatus::RepeatedFrame {
            self.refine_temporal(left, right);
        }
        self.last_match = report;
        let t2 = clock.now_us();
        out.times.matching_us = elapsed(t1, t2);
        out.stereo_matches = report.stereo.pass.matches;
        out.tie_points = report.tie_points;
        if report.status == MatchStatus::RepeatedFrame {
            out.flags |= flags::REPEATED;
            if let Some(last) = self.history[1] {
                out.left = last.pose;
                out.right = self.right_of(&last.pose);
            }
            out.settle(false);
            return self.finish(out, t0, clock);
        }
        self.cur = fill;
        self.have_prev = true;
        out.flags |= match report.status {
            MatchStatus::NoKeypoints => flags::NO_FEATURES,
            MatchStatus::NoStereoMatches => flags::NO_STEREO,
            _ => 0,
        };

        let before = self.prev_window_epoch;
        let images = (left, right);
        let adjusted =
            self.adjust_epoch(k, (time_s, aux), &prediction, images, &mut out, clock, t2);
        // The matcher calls an epoch lost below its own (fallback) threshold of
        // descriptor matches; the traverse is lost only when too few tie points remain
        // to adjust it, those the templates found by area matching included (at
        // 320x240 the descriptors alone fell short at half the epochs of the rendered
        // streets that the area tie points carried well).
        if report.status == MatchStatus::Lost && (out.tie_points as usize) < self.cfg.min_tie_points
        {
            out.flags |= flags::LOST;
        }
        // The templates of this image serve the next epoch only if it is in the window.
        let added = self.prev_window_epoch.filter(|&e| Some(e) != before);
        self.store_patches(fill, left, added);
        out.settle(adjusted);
        self.history = [
            self.history[1],
            Some(Stamped {
                pose: out.left,
                time: time_s,
            }),
        ];
        self.finish(out, t0, clock)
    }

    fn finish(&self, mut out: EpochOutput, t0: u64, clock: &impl Clock) -> EpochOutput {
        out.times.total_us = elapsed(t0, clock.now_us());
        out
    }

    /// Extracts both images into buffer `fill`; false (and flags) when an image is refused.
    fn extract(
        &mut self,
        fill: usize,
        left: &ImageView,
        right: &ImageView,
        out: &mut EpochOutput,
        clock: &impl Clock,
    ) -> bool {
        let [fl, fr] = &mut self.features[fill];
        fl.clear();
        fr.clear();
        // Both images must have the rig's format: the calibration is for that size.
        let (w, h) = (
            self.cfg.rig.left.width_px as usize,
            self.cfg.rig.left.height_px as usize,
        );
        let sized = |v: &ImageView| v.width() == w && v.height() == h;
        let t0 = clock.now_us();
        let mut ok = sized(left) && sized(right) && self.sift.extract(left, fl).is_ok();
        let t1 = clock.now_us();
        ok = ok && self.sift.extract(right, fr).is_ok();
        out.times.sift_left_us = elapsed(t0, t1);
        out.times.sift_right_us = elapsed(t1, clock.now_us());
        out.keypoints = [fl.len() as u32, fr.len() as u32];
        if !ok {
            out.flags |= flags::BAD_IMAGE;
            // Leave the buffer empty: the previous epoch's features are in the other one.
            fl.clear();
            fr.clear();
        }
        ok
    }

    fn match_epoch(
        &mut self,
        fill: usize,
        left: &ImageView,
        right: &ImageView,
        prediction: &Pose,
    ) -> Result<crate::matching::EpochReport, MatchError> {
        fn view<'k>(f: &'k FeatureSet) -> Features<'k> {
            Features::new(f.keypoints(), f.descriptors())
        }
        let [cl, cr] = &self.features[fill];
        let cur = StereoFeatures {
            left: view(cl),
            right: view(cr),
        };
        let prev = self.have_prev.then(|| {
            let [pl, pr] = &self.features[1 - fill];
            StereoFeatures {
                left: view(pl),
                right: view(pr),
            }
        });
        // A motion guide needs a velocity: two epochs behind.
        let motion = match self.history {
            [Some(_), Some(last)] => Some(relative_motion(&last.pose, prediction)),
            _ => None,
        };
        let images = Some((*left, *right));
        // Predict the right positions with the rig as last adjusted (the calibration
        // when it is not estimated).
        let mut rig = self.cfg.rig;
        let r = self.window.rig();
        rig.relative_angles = r.angles;
        rig.base_m = r.base;
        self.matcher
            .process_epoch(cur, prev, images, motion.as_ref().map(|m| (&rig, m)))
    }

    /// Moves each tie point's current left position onto the spot its left template
    /// shows (magnified by the point's scale change since the template's anchor
    /// epoch), then re-refines the right position from there (see `patches`).
    fn refine_temporal(&mut self, left: &ImageView, right: &ImageView) {
        let (Some(patches), Some(rcfg)) = (&self.patches, self.cfg.matching.refine) else {
            return;
        };
        let h = rcfg.half_window as usize;
        let rad = rcfg.search_radius as usize;
        let mut tpl = [0f32; TEMPLATE_LEN];
        let mut n = 0;
        for tie in self.matcher.tie_points() {
            if n >= self.refined.len() {
                break;
            }
            let Some(entry) = patches.index_of(tie.prev.left) else {
                continue;
            };
            let now = stereo_depth(&self.cfg, &self.window, tie.cur.left, tie.cur.right);
            let scale = anchor_scale(patches.anchor_depth(entry), now);
            if !template_at_scale(patches, entry, scale, &mut tpl) {
                continue;
            }
            let Ok(found) = correlate(&tpl, h, left, tie.cur.left, (rad, rad), rcfg.min_ncc) else {
                continue;
            };
            let (l, _) = recentre(&tpl, h, left, found, (1, 1), rcfg.min_ncc);
            let Ok((r, _)) = refine_checked(left, right, l, tie.cur.right, &rcfg) else {
                continue;
            };
            self.refined[n] = Refined {
                slot: tie.slot,
                entry: entry as u32,
                left: l,
                right: r,
            };
            n += 1;
        }
        self.n_refined = n;
        for r in self.refined[..n].iter() {
            self.matcher.refine_tie_point(r.slot, r.left, r.right);
        }
    }

    /// Renews the templates the next epoch's tie points will start from (`epoch` is
    /// this image's window epoch): the tie points found with a template carry it on
    /// while their scale allows (see `patches`); the other tie points, those found by
    /// area and the other stereo matches' left keypoints get a new template, in that
    /// order of priority.
    fn store_patches(&mut self, fill: usize, left: &ImageView, epoch: Option<u32>) {
        let Some(patches) = &mut self.patches else {
            return;
        };
        patches.begin(epoch);
        if epoch.is_none() {
            return;
        }
        let limit = self.cfg.max_anchor_scale;
        let (cfg, window) = (&self.cfg, &self.window);
        let carry = |patches: &Patches, entry: usize, at: ([f32; 2], [f32; 2])| {
            let now = stereo_depth(cfg, window, at.0, at.1);
            let s = anchor_scale(patches.anchor_depth(entry), now);
            // A receding point would need a template larger than the anchor's.
            s <= limit && s >= 1.0 - SAME_SCALE
        };
        // The tie points' templates: first every carried one (their slots must not be
        // overwritten), then the new ones.
        for r in self.refined[..self.n_refined].iter() {
            let entry = r.entry as usize;
            let Some(tie) = self.matcher.tie_points().find(|t| t.slot == r.slot) else {
                continue;
            };
            if tie.cur.left != r.left || !carry(patches, entry, (r.left, r.right)) {
                continue;
            }
            let info = tie_info(self.track_points, window, &tie);
            patches.keep(entry, tie.cur.left, info);
        }
        for a in self.area[..self.n_area]
            .iter()
            .filter(|a| a.point != patches::NO_ID)
        {
            if carry(patches, a.entry as usize, (a.left, a.right)) {
                patches.keep(a.entry as usize, a.left, a.into());
            }
        }
        for tie in self.matcher.tie_points() {
            if patches.index_of(tie.cur.left).is_some() {
                continue;
            }
            let info = tie_info(self.track_points, window, &tie);
            let depth = stereo_depth(cfg, window, tie.cur.left, tie.cur.right);
            patches.push(left, tie.cur.left, info, depth);
        }
        for a in self.area[..self.n_area]
            .iter()
            .filter(|a| a.point != patches::NO_ID)
        {
            if patches.index_of(a.left).is_none() {
                let depth = stereo_depth(cfg, window, a.left, a.right);
                patches.push(left, a.left, a.into(), depth);
            }
        }
        let quads = self.matcher.quads();
        let kps = self.features[fill][0].keypoints();
        for m in self.matcher.stereo_matches(kps) {
            if !quads.iter().any(|q| q.cur_left == m.left) {
                let depth = stereo_depth(cfg, window, m.left_px, m.right_px);
                patches.push(left, m.left_px, PatchInfo::stereo(m.right_px), depth);
            }
        }
    }

    /// Initial values, window update and adjustment; true when the epoch was adjusted.
    #[allow(clippy::too_many_arguments)]
    fn adjust_epoch(
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
        // temporal matches when they tell it; an epoch flagged below is tied to it.
        let mut guess = *prediction;
        if !first && resected.is_none() {
            out.flags |= flags::NO_RESECTION;
            if let Some(pose) = self.rotation_from_matches(prediction) {
                out.flags |= flags::ROTATION_FROM_MATCHES;
                guess = pose;
            }
        }
        let initial = match resected {
            Some(pose) => pose,
            None if first => self.cfg.datum,
            None => guess,
        };
        let ta = clock.now_us();
        self.track_by_area(left, right, (&initial, resected.is_some()));
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
        out.points = self.window_points().count() as u32;
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

    /// Robust resection of the current left camera on tie points already in the window.
    fn resect(&mut self) -> Option<Pose> {
        let mut n = 0;
        for tie in self.matcher.tie_points() {
            if n >= self.corr.len() {
                break;
            }
            let Some(point) = known_point(self.track_points, &self.window, &tie) else {
                continue;
            };
            let Some(xyz) = self.window.point(point) else {
                continue;
            };
            let [c, r] = tie.cur.left;
            let xy = self.cfg.rig.left.pixel_to_corrected(c as f64, r as f64);
            self.corr[n] = Correspondence { point: xyz, xy };
            n += 1;
        }
        self.resect_on(n, self.cfg.min_tie_points)
    }

    /// Robust resection of the current left camera on the first `n` correspondences;
    /// a pose only with at least `min_inliers` inliers.
    fn resect_on(&self, n: usize, min_inliers: usize) -> Option<Pose> {
        let mut rcfg = self.cfg.resection;
        rcfg.threshold_mm = 3.0 * self.cfg.sigma_px * self.cfg.rig.left.pixel_size_mm[0];
        rcfg.min_inliers = min_inliers;
        let r = resect(&self.corr[..n], self.cfg.rig.left.focal_mm, &rcfg).ok()?;
        (r.inliers >= min_inliers).then_some(r.pose)
    }

    /// Resection of the current left camera on the previous stereo pair's points that
    /// the temporal matching found again, quads or not (`Matcher::temporal_stereo`):
    /// when the motion prediction was wrong (the onset of a turn, a jolt), the guided
    /// search closes few quads, but the fallback search still pairs many keypoints.
    /// The points are intersected from the previous window epoch's pose.
    fn relocalize(&mut self) -> Option<Pose> {
        let last = self.window.n_epochs().checked_sub(1)?;
        let prev_left = self.window.epoch_pose(last)?;
        let prev = [prev_left, self.right_of(&prev_left)];
        let cur = self.features[self.cur][0].keypoints();
        let prev_kps = self.features[1 - self.cur][0].keypoints();
        let mut n = 0;
        for (pl, pr, c) in self.matcher.temporal_stereo(prev_kps) {
            if n >= self.corr.len() {
                break;
            }
            let (Some(k), Some(xyz)) = (
                cur.get(c as usize),
                intersect_pair(&self.cfg, &prev, pl, pr),
            ) else {
                continue;
            };
            let xy = self.cfg.rig.left.pixel_to_corrected(k.x as f64, k.y as f64);
            self.corr[n] = Correspondence { point: xyz, xy };
            n += 1;
        }
        self.resect_on(n, config::RELOCALIZATION_MIN_INLIERS)
    }

    /// The prediction with its rotation found from the left temporal matches
    /// ([`turn::robust_rotation`]), when they agree on one: the previous left keypoints'
    /// rays from the previous window epoch's pose against the current keypoints' rays.
    fn rotation_from_matches(&mut self, prediction: &Pose) -> Option<Pose> {
        let last = self.window.n_epochs().checked_sub(1)?;
        let prev_pose = self.window.epoch_pose(last)?;
        let m_prev = prev_pose.rotation();
        let interior = self.cfg.rig.left;
        let f = interior.focal_mm;
        let cur = self.features[self.cur][0].keypoints();
        let prev_kps = self.features[1 - self.cur][0].keypoints();
        let mut n = 0;
        for (p, c) in self.matcher.temporal_left(prev_kps.len()) {
            if n >= self.corr.len() {
                break;
            }
            let (Some(q), Some(k)) = (prev_kps.get(p), cur.get(c as usize)) else {
                continue;
            };
            let [x, y] = interior.pixel_to_corrected(q.x as f64, q.y as f64);
            let ray = m_prev.transpose() * Vector3::new(x, y, -f).normalize();
            let xy = interior.pixel_to_corrected(k.x as f64, k.y as f64);
            self.corr[n] = Correspondence {
                point: [ray[0], ray[1], ray[2]],
                xy,
            };
            n += 1;
        }
        let px = 0.5 * (interior.pixel_size_mm[0] + interior.pixel_size_mm[1]);
        let tcfg = turn::TurnConfig {
            threshold_rad: config::TURN_THRESHOLD_PX * px / f,
            min_inliers: config::RELOCALIZATION_MIN_INLIERS,
            samples: config::TURN_SAMPLES,
        };
        let corr = &self.corr[..n];
        let (r, k) = turn::robust_rotation(corr, f, &tcfg)?;
        // Only a rotation that explains far more matches than the prediction's replaces
        // it: where a moving vehicle fills the image, its matches agree on a rotation of
        // their own, while the prediction's still explains the static scene.
        let k_pred = turn::inliers(corr, f, tcfg.threshold_rad, &prediction.rotation());
        if k < config::TURN_MIN_GAIN * k_pred {
            return None;
        }
        let [omega, phi, kappa] = angles_from_rotation(&r);
        Some(Pose {
            omega,
            phi,
            kappa,
            centre: prediction.centre,
        })
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
                    let obs = (tie.prev.left, tie.prev.right);
                    let Some(p) = new_point(&self.cfg, &mut self.window, at, obs, tie.track_id)
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
            let obs = (tie.cur.left, tie.cur.right);
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
            let _ = self
                .window
                .set_pose_prior(id, prediction, self.cfg.prediction_sigmas);
            result = self.window.solve();
        }
        let Ok(mut rep) = result else { return false };
        // A correction is one Gauss-Newton step of the freed calibration: repeated on
        // the re-adjusted window until the test accepts it.
        let mut steps = 0;
        while steps < config::CALIBRATION_STEPS && self.check_calibration(rep.sigma0, steps > 0) {
            steps += 1;
            out.flags |= flags::CALIBRATION_CORRECTED;
            match self.window.solve() {
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
        out.std = self.window.epoch_absolute_std(last);
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

    /// The calibration check ([`config::CalibrationCheck`]) after an adjustment whose
    /// a-posteriori sigma is `sigma0`: corrects the held calibration when the score
    /// test rejects it and the correction matters (returns true: the window must be
    /// adjusted again), and holds it as it is for good after `epochs` epochs.
    /// `again`: the calibration was just corrected at this epoch; a rejection now
    /// continues that correction without waiting for `persistence`.
    fn check_calibration(&mut self, sigma0: f64, again: bool) -> bool {
        let Some(check) = self.cfg.calibration_check else {
            return false;
        };
        if !self.window.calibration_active() {
            return false;
        }
        // A test that cannot be computed (a singular system) corrects nothing. The
        // floor keeps noise-free data (sigma0 near zero) from magnifying rounding
        // into a rejection; real matching stays well above it (0.17 to 0.35 on the
        // rendered streets).
        let sigma0 = sigma0.max(config::CALIBRATION_TEST_MIN_SIGMA0);
        if let Ok(test) = self.window.calibration_test(sigma0) {
            let critical = chi2_quantile(1.0 - check.level, test.dof as f64);
            let px = self.cfg.rig.right.pixel_size_mm[0];
            let rejected = test.statistic > critical
                && self.window.correction_effect(&test) > check.min_effect_px * px;
            self.calibration_rejections = if rejected {
                self.calibration_rejections + 1
            } else {
                0
            };
            if self.calibration_rejections >= check.persistence || (again && rejected) {
                self.window.correct_calibration(&test);
                self.calibration_corrections += 1;
                self.calibration_rejections = 0;
                return true;
            }
        }
        if self.epochs >= check.epochs && !again {
            self.window.drop_calibration();
        }
        false
    }

    /// Corrections the calibration check has applied so far.
    pub fn calibration_corrections(&self) -> u32 {
        self.calibration_corrections
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

/// What a tie point's template shows: its window point when its track has one.
fn tie_info(map: &[TrackPoint], window: &Window, tie: &TiePoint) -> PatchInfo {
    match known_point(map, window, tie) {
        Some(point) => PatchInfo {
            right: tie.cur.right,
            tag: tie.track_id,
            point,
        },
        None => PatchInfo::stereo(tie.cur.right),
    }
}

/// Whether a tie point's track had a window point that the window has since freed.
fn has_dead_point(map: &[TrackPoint], window: &Window, tie: &TiePoint) -> bool {
    map.get(tie.slot as usize).is_some_and(|e| {
        e.track_id == tie.track_id
            && e.point != u32::MAX
            && window.point_tag(e.point) != Some(tie.track_id)
    })
}

/// Two image positions closer than this (pixels, each axis) are one spot.
const SAME_SPOT_PX: f32 = 0.5;

fn same_spot(a: [f32; 2], b: [f32; 2]) -> bool {
    (a[0] - b[0]).abs() < SAME_SPOT_PX && (a[1] - b[1]).abs() < SAME_SPOT_PX
}

/// Depth (metres, along the left camera's axis) of a stereo observation, from the
/// rig as last adjusted; `None` when the rays barely intersect (a far point).
fn stereo_depth(
    cfg: &TraverseConfig,
    window: &Window,
    left: [f32; 2],
    right: [f32; 2],
) -> Option<f32> {
    let d = cfg.datum;
    let poses = [d, camera_pose(&d, &window.rig(), Camera::Right)];
    let x = intersect_pair(cfg, &poses, left, right)?;
    Some(-d.to_camera(&x)[2] as f32)
}

/// How many times larger a point appears now than at its template's anchor epoch,
/// from the two depths; 1 when either is unknown (a far point).
fn anchor_scale(anchor: Option<f32>, now: Option<f32>) -> f32 {
    match (anchor, now) {
        (Some(a), Some(n)) if n > 0.0 => a / n,
        _ => 1.0,
    }
}

/// Scale changes below this are left to the correlation (a template's extent changes
/// by less than a tenth of a pixel).
const SAME_SCALE: f32 = 0.02;

/// Template `entry` of the store as it appears `scale` times larger into `out`;
/// false when there is no such template or it would have to shrink.
fn template_at_scale(
    patches: &Patches,
    entry: usize,
    scale: f32,
    out: &mut [f32; TEMPLATE_LEN],
) -> bool {
    let mut anchor = [0f32; TEMPLATE_LEN];
    if !patches.template(entry, &mut anchor) {
        return false;
    }
    if (scale - 1.0).abs() < SAME_SCALE {
        *out = anchor;
        return true;
    }
    magnify_template(&anchor, patches.half(), scale, out)
}

/// The window point of a tie point's track, if the track already has one and the
/// window still holds it (a freed point's slot may hold another track's point).
fn known_point(map: &[TrackPoint], window: &Window, tie: &TiePoint) -> Option<u32> {
    let e = map.get(tie.slot as usize)?;
    (e.track_id == tie.track_id && e.point != u32::MAX)
        .then_some(e.point)
        .filter(|&p| window.point_tag(p) == Some(tie.track_id))
}

/// An image observation of `point` at pixel `px`, weighted by the configured sigma.
fn observation(
    cfg: &TraverseConfig,
    epoch: u32,
    camera: Camera,
    point: u32,
    px: [f32; 2],
    tag: u32,
) -> Observation {
    let interior = match camera {
        Camera::Left => &cfg.rig.left,
        Camera::Right => &cfg.rig.right,
    };
    let xy = interior.pixel_to_corrected(px[0] as f64, px[1] as f64);
    let s = cfg.sigma_px;
    let [sx, sy] = interior.pixel_size_mm;
    let weight = [1.0 / (s * sx * s * sx), 1.0 / (s * sy * s * sy)];
    let mut o = Observation::new(epoch, camera, point, xy, weight);
    o.tag = tag;
    o
}

/// Observations of `point` in both images of window epoch `id`.
fn add_stereo_observations(
    cfg: &TraverseConfig,
    window: &mut Window,
    id: u32,
    point: u32,
    (left, right): ([f32; 2], [f32; 2]),
    tag: u32,
) {
    for (cam, px) in [(Camera::Left, left), (Camera::Right, right)] {
        let _ = window.add_observation(observation(cfg, id, cam, point, px, tag));
    }
}

/// Intersects a point from a stereo observation (`left` and `right` pixels) of the
/// epoch with left and right poses `poses`; `None` when the rays barely intersect or
/// the point is behind the camera or beyond `max_depth_m`.
fn intersect_pair(
    cfg: &TraverseConfig,
    poses: &[Pose; 2],
    left: [f32; 2],
    right: [f32; 2],
) -> Option<[f64; 3]> {
    let rig = &cfg.rig;
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
/// (`at`: its window epoch id and its left and right poses) and adds it with those two
/// observations, tagged `tag`.
fn new_point(
    cfg: &TraverseConfig,
    window: &mut Window,
    at: (u32, &[Pose; 2]),
    obs: ([f32; 2], [f32; 2]),
    tag: u32,
) -> Option<u32> {
    let (prev_id, poses) = at;
    let xyz = intersect_pair(cfg, poses, obs.0, obs.1)?;
    let point = window.add_point(xyz).ok()?;
    add_stereo_observations(cfg, window, prev_id, point, obs, tag);
    Some(point)
}

fn elapsed(a: u64, b: u64) -> u32 {
    b.saturating_sub(a).min(u32::MAX as u64) as u32
}

/// True for a finite, strictly positive value (false for NaN).
fn positive(v: f64) -> bool {
    v > 0.0 && v.is_finite()
}

fn check_config(cfg: &TraverseConfig) -> Result<(), TraverseError> {
    let m = &cfg.matching;
    if m.image_width as usize != cfg.sift.max_width
        || m.image_height as usize != cfg.sift.max_height
    {
        return Err(TraverseError::Config(
            "matching image size differs from the extractor's",
        ));
    }
    if cfg.rig.left.width_px as usize != cfg.sift.max_width
        || cfg.rig.left.height_px as usize != cfg.sift.max_height
    {
        return Err(TraverseError::Config(
            "rig image size differs from the extractor's",
        ));
    }
    if cfg.adjust.window < 2 {
        return Err(TraverseError::Config("adjust.window must be at least 2"));
    }
    if !positive(cfg.sigma_px) || !positive(cfg.max_depth_m) {
        return Err(TraverseError::Config(
            "sigma_px and max_depth_m must be positive",
        ));
    }
    if !cfg.prediction_sigmas.iter().all(|s| positive(*s)) {
        return Err(TraverseError::Config("prediction_sigmas must be positive"));
    }
    Ok(())
}

// ----- Window observations for reports (tie point exports, residual histograms) -----

/// One image observation of the window in the input's terms (see
/// [`Traverse::window_observation`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WindowObservation {
    /// Track id of the tie point (the observation's tag).
    pub track_id: u32,
    /// Window point index, stable while the point is in the window.
    pub point: u32,
    /// Input epoch index.
    pub epoch: u32,
    /// 0 = left, 1 = right.
    pub camera: u8,
    /// Flagged as a blunder by the last adjustment.
    pub flagged: bool,
}

impl Traverse<'_> {
    /// Number of image observations in the window.
    pub fn window_observation_count(&self) -> usize {
        self.window.observations().len()
    }

    /// Indices of the window observations of `point` ([`WindowObservation::point`]) as
    /// of the last adjustment; `None` when the window changed since (scan instead).
    pub fn window_point_observations(&self, point: u32) -> Option<&[u32]> {
        self.window.point_observations(point)
    }

    /// Observation `i` of the window (storage order), cheap: no projection.
    pub fn window_observation(&self, i: usize) -> Option<WindowObservation> {
        let o = self.window.observations().get(i)?;
        let first = self.window.epoch_id(0)?;
        let slot = o.epoch.checked_sub(first)? as usize;
        let epoch = *self.window_inputs.get(slot)?;
        (slot < self.window.n_epochs()).then_some(WindowObservation {
            track_id: o.tag,
            point: o.point,
            epoch,
            camera: o.camera,
            flagged: o.is_flagged(),
        })
    }

    /// Measured pixel (column, row; pixel-centre convention) of observation `i`
    /// and its residual (observed - computed) in pixels at the last adjustment;
    /// no residual when its point is excluded or behind the camera.
    pub fn window_observation_pixels(&self, i: usize) -> Option<([f64; 2], Option<[f64; 2]>)> {
        let o = self.window.observations().get(i)?;
        let interior = if o.camera == 0 {
            &self.cfg.rig.left
        } else {
            &self.cfg.rig.right
        };
        let px = {
            let [x, y] = o.xy_mm();
            interior.corrected_to_pixel(x, y)
        }
        .ok()?;
        let [sx, sy] = interior.pixel_size_mm;
        let residual = (!self.window.point_excluded(o.point))
            .then(|| self.window.residual(i))
            .flatten()
            .map(|[vx, vy]| [vx / sx, vy / sy]);
        Some((px, residual))
    }

    /// Adjusted object coordinates of window point `point` and their standard deviations.
    pub fn window_point(&self, point: u32) -> Option<([f64; 3], Option<[f64; 3]>)> {
        Some((self.window.point(point)?, self.window.point_std(point)))
    }
}
