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
mod calibration;
pub(crate) mod config;
pub mod defaults;
mod initial;
pub mod motion;
pub(crate) mod output;
pub(crate) mod patches;
mod refine;
mod solve;
pub(crate) mod turn;
mod window_view;

#[cfg(test)]
mod tests;

pub use config::{CalibrationCheck, CalibrationPrecision, TraverseConfig, TraverseMode};
pub use defaults::*;
pub use output::{flags, EpochOutput, EpochStatus, StageTimes};
pub use window_view::WindowObservation;

use crate::adjust::geometry::camera_pose;
use crate::adjust::quality::chi2_quantile;
use crate::adjust::{intersect, resect, AdjustError, Correspondence, Observation, Ray, Window};
use crate::budget::{Arena, OutOfMemory, Stage};
use crate::camera::{angles_from_rotation, Camera, Pose, Rig};
use crate::features::FeatureSet;
use crate::image::ImageView;
use crate::matching::refine::{
    magnify_template, refine_checked, sample_template, search_line, Correlator, LineSegment,
    TEMPLATE_LEN,
};
use crate::matching::{
    relative_motion, Features, MatchError, MatchOutcome as MatchStatus, Matcher, StereoFeatures,
    StereoGeometry, StereoPx, TiePoint,
};
use crate::sift::{Sift, SiftError};
use area::AreaTie;
use bytemuck::{Pod, Zeroable};
use motion::predict;
use nalgebra::Vector3;
use patches::{PatchInfo, Patches};
// The helpers the stages share, each in the file of its stage.
use refine::{has_dead_point, same_spot, template_at_scale};
use solve::{add_stereo_observations, intersect_pair, known_point, new_point};

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
    pub px: StereoPx,
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
    /// The calibration check's record of the tests since the calibration was last set.
    calibration_verdicts: calibration::Verdicts,
    /// The stereo pairs' offset from their epipolar lines has been measured
    /// (`Traverse::check_epipolar_offset`).
    epipolar_offset_checked: bool,
    /// The odometer count (distance, variance) of the newest window epoch, if it had one.
    odometer_count: Option<(f64, f64)>,
}

impl<'a> Traverse<'a> {
    /// Builds every stage from `arena` (size it with [`TraverseConfig::budget`]).
    pub fn new(cfg: TraverseConfig, arena: &mut Arena<'a>) -> Result<Self, TraverseError> {
        check_config(&cfg)?;
        arena.stage(Stage::Sift);
        let sift = Sift::new(cfg.sift, arena)?;
        let n = cfg.features_per_image();
        arena.stage(Stage::Features);
        let features = [
            [FeatureSet::new(arena, n)?, FeatureSet::new(arena, n)?],
            [FeatureSet::new(arena, n)?, FeatureSet::new(arena, n)?],
        ];
        arena.stage(Stage::Match);
        let matcher = Matcher::new(cfg.matching, arena)?;
        arena.stage(Stage::Adjust);
        let mut window = Window::new(cfg.adjust, &cfg.rig, arena)?;
        window.set_base_length(cfg.rig.base_length());
        arena.stage(Stage::Traverse);
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
            calibration_verdicts: Default::default(),
            epipolar_offset_checked: false,
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

    /// The rig as the adjustment has it (the calibration when it is not estimated)
    /// and the standard deviations of its last estimate (zero when never estimated).
    pub fn rig_estimate(&self) -> (crate::camera::RelativeOrientation, [f64; 6]) {
        (self.window.rig(), self.window.rig_std())
    }

    /// The rig as last adjusted: the calibration with the relative orientation and the
    /// interior corrections that the calibration check (or the free estimation) found.
    /// Every search and prediction in the images goes through it, so that a correction
    /// reaches the matching and not the adjustment alone (`docs/traverse.md`,
    /// Calibration check). The observations stay reduced with the calibration; the
    /// window adds its corrections to them.
    fn rig_now(&self) -> Rig {
        self.window.adjusted_rig(&self.cfg.rig)
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

        if self.check_epipolar_offset(fill) {
            out.flags |= flags::CALIBRATION_CORRECTED;
        }
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
        self.store_patches(fill, images, added);
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
        let cur = stereo_pair(&self.features[fill]);
        let prev = self
            .have_prev
            .then(|| stereo_pair(&self.features[1 - fill]));
        // A motion guide needs a velocity: two epochs behind.
        let motion = match self.history {
            [Some(_), Some(last)] => Some(relative_motion(&last.pose, prediction)),
            _ => None,
        };
        let images = Some((*left, *right));
        // Search and predict the right positions with the rig as last adjusted.
        let rig = self.rig_now();
        self.matcher.set_rig(&rig);
        self.matcher
            .process_epoch(cur, prev, images, motion.as_ref().map(|m| (&rig, m)))
    }

    /// Corrections the calibration check has applied so far.
    pub fn calibration_corrections(&self) -> u32 {
        self.calibration_corrections
    }
}

/// A left and a right image's features as a stereo pair.
fn stereo_pair<'k>([l, r]: &'k [FeatureSet<'_>; 2]) -> StereoFeatures<'k> {
    StereoFeatures {
        left: Features::new(l.keypoints(), l.descriptors()),
        right: Features::new(r.keypoints(), r.descriptors()),
    }
}

/// Two image positions closer than this (pixels, each axis) are one spot.
const SAME_SPOT_PX: f32 = 0.5;

/// Scale changes below this are left to the correlation (a template's extent changes
/// by less than a tenth of a pixel).
const SAME_SCALE: f32 = 0.02;

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
