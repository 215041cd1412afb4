//! Configuration of the whole traverse and its memory budget.
use crate::adjust::{
    AdjustConfig, ConstraintSigmas, Correspondence, InteriorSigmas, ResectionConfig, Robust,
};
use crate::budget::{slice_bytes, ComponentKind, MemoryBudget};
/// Lives with the rig it qualifies, so the wire format can carry it without the traverse.
pub use crate::camera::CalibrationPrecision;
use crate::camera::{Pose, Rig};
use crate::features::FeatureSet;
use crate::matching::{MatchConfig, RefineConfig, StereoGeometry};
use crate::sift::SiftConfig;

use super::area::AreaTie;
use super::defaults::*;
use super::patches::Patches;
use super::{Refined, TrackPoint};

/// Fewest inliers of a relocalization's resection (on the previous stereo pair's points
/// found again without the motion prior) for its pose to start the adjustment. The pose
/// is only the adjustment's initial value, and with fewer tie points than
/// `min_tie_points` the epoch stays flagged and tied to its prediction: 8 consistent
/// points (two more than the resection's six unknowns need) are a better start than a
/// constant-velocity prediction that misses a hand-held rig's wobble by 2.5 deg. Demanding
/// `min_tie_points` (12) here left the prediction standing at such epochs, and on
/// 320x240 `handheld` (seeds 1 and 3 of 3) the adjustment then settled on a roll
/// 1.3 deg off that no later epoch corrected.
pub const RELOCALIZATION_MIN_INLIERS: usize = 8;

/// Largest image distance (pixels) between a previous keypoint's ray, turned by the
/// rotation from the temporal matches, and its current keypoint: beyond it the point
/// is near enough for the step's parallax to show, or a wrong match (`traverse::turn`).
pub const TURN_THRESHOLD_PX: f64 = 3.0;
/// The rotation from the temporal matches replaces the prediction's only when it
/// explains at least this many times as many matches.
pub const TURN_MIN_GAIN: usize = 2;
/// RANSAC samples of that rotation (pairs of matches).
pub const TURN_SAMPLES: u32 = 64;

/// Tie points per epoch at most (the spreading keeps the best spread ones).
pub const MAX_TIE_POINTS: usize = 400;
/// SIFT pending candidates per image column, over [`PENDING_SCALE`]: 1152 at 640 px,
/// 576 at 320 px (`docs/configuration.md`, "Capacities"). The rendered streets' poses
/// came out the same to the byte as with 2048 and 1024 (`bench/traverse/README.md`,
/// "Observation weights from the correlation peak"): no candidate waits beyond these
/// there. The bytes saved pay for the right positions' precision at 320x240.
pub const PENDING_PER_COLUMN: usize = 9;
pub const PENDING_SCALE: usize = 5;
/// Fewest SIFT pending candidates, whatever the width.
pub const MIN_PENDING: usize = 256;
/// Epipolar tolerance of the stereo search when the rig is estimated, pixels: the
/// calibration it starts from may be off by a pixel on each camera.
pub const RIG_ESTIMATION_TOLERANCE_PX: f32 = 3.0;
/// The left (reference) camera's calibration sigmas are these times the right one's:
/// its interior is held at the calibration (see `TraverseConfig::interior_sigmas`).
pub const REFERENCE_CAMERA_FACTOR: f64 = 0.01;

/// Everything the traverse needs before the first frame: the rig, the datum, the
/// stages' configurations and capacities.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraverseConfig {
    pub rig: Rig,
    /// Pose of the left camera at epoch 0: the datum.
    pub datum: Pose,
    pub sift: SiftConfig,
    pub matching: MatchConfig,
    pub adjust: AdjustConfig,
    pub resection: ResectionConfig,
    /// Standard deviation of an image measurement, pixels (weights of the adjustment).
    pub sigma_px: f64,
    /// Weight each right-image observation by the precision of its stereo correlation
    /// peak, relative to `sigma_px` (see `solve::observation_sigma_px`); `false`
    /// weights every observation with `sigma_px`, as the seeds' procedures do.
    pub peak_weights: bool,
    /// Fewer tie points than this and the epoch is flagged and tied to its prediction.
    pub min_tie_points: usize,
    /// Smallest ray angle of a new tie point, radians.
    pub min_ray_angle_rad: f64,
    /// New tie points farther than this from the camera are not added, metres.
    pub max_depth_m: f64,
    /// Prior standard deviations (the attitude's turn about the object axes, rad;
    /// positions m) tying an epoch that the images do not determine (lost track) to its
    /// motion prediction.
    pub prediction_sigmas: [f64; 6],
    /// Refine each tie point's current left position against the previous epoch's
    /// template (needs `matching.refine`; see `traverse::patches`).
    pub temporal_refine: bool,
    /// Most tie points per epoch found by area matching: the previous epoch's stereo
    /// points that no descriptor quad continued, looked for around their predicted
    /// positions (needs `temporal_refine`; see `traverse::area`); 0 turns it off.
    pub max_area_ties: usize,
    /// A tie point's template is carried on from its anchor epoch while the point
    /// appears at most this many times larger or smaller; 1 re-takes it at every
    /// epoch (see `traverse::patches`).
    pub max_anchor_scale: f32,
    /// The calibration's stated precision: the prior of its test and correction.
    pub calibration_precision: CalibrationPrecision,
    /// Test the calibration against the observations and correct it where they call
    /// for it (see [`CalibrationCheck`]); `None` holds the calibration as given (or
    /// estimates it freely with [`TraverseConfig::with_rig_estimation`]).
    pub calibration_check: Option<CalibrationCheck>,
}

/// The calibration check of the default configuration: the rig's relative orientation
/// and the interior orientation take part in the adjustment held at the calibration,
/// so a good calibration never moves; after each epoch's adjustment a score test
/// ([`crate::adjust::Window::calibration_test`]) asks whether freeing them would
/// lower `vTPv` significantly, and only then the correction it gives is applied.
/// Before the first matching, a stereo pair a pixel or more off its epipolar lines is
/// corrected too (`EPIPOLAR_OFFSET_MIN_PX`). A corrected calibration is estimated in
/// every adjustment from then on. After `epochs` epochs the calibration, held or
/// estimated, is kept as it is for the rest of the traverse and its blocks leave the
/// adjustment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationCheck {
    /// Epochs over which a calibration is tested before it is accepted as it is.
    pub epochs: u32,
    /// Significance level of the test (probability of correcting a good calibration
    /// at one epoch).
    pub level: f64,
    /// Smallest correction applied: the RMS displacement (pixels) that the mean of the
    /// steps asked at every test so far causes on the newest epoch's observations
    /// ([`crate::adjust::Window::correction_effect`]).
    pub min_effect_px: f64,
    /// Consecutive epochs that must reject the calibration before it is corrected: a
    /// wrong calibration is rejected at every epoch, a right one only now and then.
    pub persistence: u32,
    /// Consecutive rejections after which the calibration is corrected even though the
    /// correction moves the newest epoch's observations by less than `min_effect_px`.
    pub sustained: u32,
    /// Smallest correction (pixels, as `min_effect_px`) a rejection must ask for to
    /// count towards `sustained`.
    pub sustained_min_effect_px: f64,
}

/// Epochs over which the calibration is tested ([`CalibrationCheck::epochs`]).
pub const CALIBRATION_CHECK_EPOCHS: u32 = 30;
/// Significance level of the calibration test ([`CalibrationCheck::level`]).
pub const CALIBRATION_CHECK_LEVEL: f64 = 1e-3;
/// Smallest correction the calibration check applies ([`CalibrationCheck::min_effect_px`]).
pub const CALIBRATION_MIN_EFFECT_PX: f64 = 0.1;
/// Consecutive rejections before a correction ([`CalibrationCheck::persistence`]).
pub const CALIBRATION_PERSISTENCE: u32 = 2;
/// Consecutive rejections before a correction of any size
/// ([`CalibrationCheck::sustained`]): twice the longest run of rejections of a perfect
/// calibration on the benchmark's rendered streets (4, `seed2014`; 31 runs).
pub const CALIBRATION_SUSTAINED_REJECTIONS: u32 = 8;
/// Smallest correction a rejection asks for to count towards the sustained rule
/// ([`CalibrationCheck::sustained_min_effect_px`]). The disparity offset the rule is
/// for (`curves-real` seed 10, 0.09 px) asked for 0.060 to 0.069 px at its eight
/// rejections; the rig of the hand-held walk, which the data describe exactly, 0.015
/// to 0.022 px at the eight it reached with least-squares temporal matching, whose
/// precision makes such small systematic errors significant. Between the two.
pub const CALIBRATION_SUSTAINED_MIN_EFFECT_PX: f64 = 0.04;
/// How much wider than the stereo band the band is in which the calibration check
/// measures the pairs' offset from their epipolar lines, pixels.
pub const EPIPOLAR_PROBE_WIDEN_PX: f32 = 3.0;
/// Fewest matches that offset is measured from.
pub const EPIPOLAR_PROBE_MATCHES: usize = 30;
/// Smallest offset from the epipolar lines the check corrects, pixels.
pub const EPIPOLAR_OFFSET_MIN_PX: f64 = 1.0;
/// The lines' normal must be this close to the image's vertical (the lines within
/// 25 deg of the rows) for the offset to be corrected on the vertical principal point.
pub const EPIPOLAR_ROWS_MIN_NORMAL: f64 = 0.9;
/// Smallest a-posteriori sigma0 the calibration test divides by.
pub const CALIBRATION_TEST_MIN_SIGMA0: f64 = 0.05;

impl Default for CalibrationCheck {
    fn default() -> Self {
        CalibrationCheck {
            epochs: CALIBRATION_CHECK_EPOCHS,
            level: CALIBRATION_CHECK_LEVEL,
            min_effect_px: CALIBRATION_MIN_EFFECT_PX,
            persistence: CALIBRATION_PERSISTENCE,
            sustained: CALIBRATION_SUSTAINED_REJECTIONS,
            sustained_min_effect_px: CALIBRATION_SUSTAINED_MIN_EFFECT_PX,
        }
    }
}

/// Shortest window with the rig estimated ([`TraverseConfig::with_rig_estimation`]).
pub const RIG_ESTIMATION_WINDOW: usize = 8;

impl TraverseConfig {
    /// Defaults for a rig and image size: 1000 keypoints per image at contrast 0.015,
    /// a 3-epoch window, tie points carried on by area matching, robust weighting,
    /// base-length and smoothness constraints switched on.
    pub fn for_rig(rig: Rig, datum: Pose) -> Self {
        let (w, h) = (rig.left.width_px, rig.left.height_px);
        let max_keypoints = TRAVERSE_KEYPOINTS;
        let sift = SiftConfig {
            max_width: w as usize,
            max_height: h as usize,
            max_keypoints,
            octaves: TRAVERSE_OCTAVES,
            contrast_threshold: TRAVERSE_CONTRAST,
            levels: TRAVERSE_SCALES,
            edge_threshold: TRAVERSE_EDGE_RATIO,
            // Descriptors only pair the features; positions come from the NCC refinement.
            // 12 x 12 gradient samples instead of 20 x 20 cost 2.4x less per descriptor
            // and gave the same drift on the rendered streets (docs/traverse.md, Speed).
            descriptor_grid: TRAVERSE_DESCRIPTOR_GRID,
            ..SiftConfig::default()
        };
        let mut matching =
            MatchConfig::rectified(w, h, max_keypoints, w as f32 * TRAVERSE_DISPARITY_FRACTION);
        matching.ratio = TRAVERSE_MATCH_RATIO;
        let ideal = rig.relative_angles == [0.0; 3]
            && rig.base_m[1] == 0.0
            && rig.base_m[2] == 0.0
            && rig.left == rig.right
            && rig.left.is_distortion_free();
        if !ideal {
            matching.stereo = StereoGeometry::Rig {
                rig,
                tolerance_px: 2.0,
                min_depth_m: 1.0,
                max_depth_m: f64::INFINITY,
            };
        }
        matching.refine = Some(RefineConfig {
            rows_only: matches!(matching.stereo, StereoGeometry::Rectified { .. }),
            ..RefineConfig::default()
        });
        matching.max_tie_points = MAX_TIE_POINTS;
        matching.max_tracks = TRAVERSE_TRACKS;
        let window = TRAVERSE_WINDOW;
        matching.track_history = window;
        let adjust = AdjustConfig {
            window,
            // Set from the window and the tie points by `fit_capacities` below.
            max_points: 1,
            max_observations: 1,
            max_iterations: 20,
            // One snooping round after the Cauchy re-weighting: the window re-adjusts
            // every epoch, so a blunder missed now is tested again at the next epoch.
            max_robust_rounds: 1,
            estimate_rig: false,
            sigmas: ConstraintSigmas {
                base_length_m: 1e-4,
                velocity_change_mps: TRAVERSE_VELOCITY_SIGMA,
                ..ConstraintSigmas::default()
            },
            // Each epoch starts from the last solution: a relative decrease of 1e-6
            // moves the poses by far less than their sigma.
            tolerance: 1e-6,
            // A step below 0.1 mrad and 1 mm leaves a linearisation error of the order
            // of 1e-8: no confirming iteration is needed.
            step_tolerance: [1e-4, 1e-3],
            keep_exclusions: true,
            fixed_epochs: TRAVERSE_FIXED_EPOCHS,
            carried_prior_inflation: TRAVERSE_PRIOR_INFLATION,
            ..AdjustConfig::default()
        };
        let mut cfg = TraverseConfig {
            rig,
            datum,
            sift,
            matching,
            adjust,
            resection: ResectionConfig::default(),
            sigma_px: TRAVERSE_SIGMA_PX,
            peak_weights: true,
            min_tie_points: 12,
            min_ray_angle_rad: 0.05f64.to_radians(),
            // Far points carry the attitude; only points at practically infinite
            // distance (where the ray angle test already refuses them) are left out.
            max_depth_m: 1000.0,
            // 1.7 deg: the constant-rate prediction of the attitude is off by a degree at
            // the onset of a turn or on a wobbling hand-held rig, and a tighter prior held
            // such epochs at the wrong attitude (320x240 `handheld`: 0.0213 -> 0.0085
            // deg/m; `drive` 0.64 -> 0.40 %; `curves` 0.32 -> 0.37 %).
            prediction_sigmas: [0.03, 0.03, 0.03, 0.3, 0.3, 0.3],
            temporal_refine: true,
            max_area_ties: usize::MAX,
            max_anchor_scale: super::patches::MAX_ANCHOR_SCALE,
            calibration_precision: CalibrationPrecision::UNSTATED,
            calibration_check: None,
        };
        cfg.fit_capacities();
        cfg.with_calibration_check(Some(CalibrationCheck::default()))
    }

    /// Derives the capacities that follow from the configured image size, keypoints,
    /// tracks and window, so a small configuration is really small. Call it again after
    /// changing any of `sift.max_width`, `sift.max_keypoints`, `matching.max_tracks`,
    /// `matching.max_keypoints` or `adjust.window`.
    ///
    /// - tie points per epoch (found by descriptors and by area together): at most
    ///   `MAX_TIE_POINTS`, the tracks and the keypoints;
    /// - window points: each epoch creates at most one point per tie point, and a point
    ///   lives while one of its observations is in the window: `tie points x window`;
    /// - window observations: an epoch holds two per tie point (left and right) plus two
    ///   per point intersected from it at the next epoch: `4 x tie points x window`.
    ///   With these bounds the window never drops an observation;
    /// - SIFT candidates waiting for their descriptor rows: a band of rows as wide as the
    ///   image, so proportional to the width (`PENDING_PER_COLUMN`).
    pub fn fit_capacities(&mut self) {
        let m = &mut self.matching;
        m.max_tie_points = MAX_TIE_POINTS.min(m.max_tracks).min(m.max_keypoints).max(1);
        let t = m.max_tie_points;
        let w = self.adjust.window.max(1);
        self.adjust.max_points = t.saturating_mul(w);
        // Observations of the epochs that left the window: two per tie point each.
        let fixed = t.saturating_mul(self.adjust.fixed_epochs).saturating_mul(2);
        self.adjust.max_observations = t.saturating_mul(w).saturating_mul(4).saturating_add(fixed);
        self.sift.pending_capacity = self
            .sift
            .max_width
            .saturating_mul(PENDING_PER_COLUMN)
            .div_ceil(PENDING_SCALE)
            .max(MIN_PENDING);
    }

    /// Feature storage per image: the extractor's cap, bounded by what the matcher reads.
    pub fn features_per_image(&self) -> usize {
        self.sift.max_keypoints
    }

    /// The whole budget: frames excluded (the caller owns them), every stage included.
    pub fn budget(&self, budget: &mut MemoryBudget) -> Result<(), crate::sift::SiftError> {
        // The extractor's working buffers; its feature storage is the four sets below.
        self.sift.working_budget(budget)?;
        let n = self.features_per_image();
        FeatureSet::budget(
            n,
            budget,
            "features.keypoints.left.a",
            "features.descriptors.left.a",
        );
        FeatureSet::budget(
            n,
            budget,
            "features.keypoints.right.a",
            "features.descriptors.right.a",
        );
        FeatureSet::budget(
            n,
            budget,
            "features.keypoints.left.b",
            "features.descriptors.left.b",
        );
        FeatureSet::budget(
            n,
            budget,
            "features.keypoints.right.b",
            "features.descriptors.right.b",
        );
        self.matching.budget(budget);
        self.adjust.budget(budget);
        budget.add(
            "traverse.track_points",
            ComponentKind::Storage,
            slice_bytes::<TrackPoint>(self.matching.max_tracks),
        );
        if let Some((cap, half)) = self.patch_capacity() {
            Patches::budget(cap, half, budget);
            budget.add(
                "traverse.refined",
                ComponentKind::Working,
                slice_bytes::<Refined>(self.matching.max_tie_points),
            );
            budget.add(
                "traverse.area_ties",
                ComponentKind::Working,
                slice_bytes::<AreaTie>(self.area_capacity()),
            );
        }
        budget.add(
            "traverse.correspondences",
            ComponentKind::Working,
            slice_bytes::<Correspondence>(self.matching.max_tie_points),
        );
        budget.add(
            "traverse.window_inputs",
            ComponentKind::Storage,
            slice_bytes::<u32>(self.adjust.window),
        );
        Ok(())
    }

    /// Templates kept for the temporal refinement (capacity, half-size), if it is on.
    pub fn patch_capacity(&self) -> Option<(usize, usize)> {
        let r = self.matching.refine.as_ref()?;
        self.temporal_refine
            .then_some((self.matching.max_tie_points, r.half_window as usize))
    }

    /// Tie points found by area matching per epoch: at most one per template, none
    /// when area tracking is off.
    pub fn area_capacity(&self) -> usize {
        match self.patch_capacity() {
            Some((cap, _)) => cap.min(self.max_area_ties),
            None => 0,
        }
    }

    /// Total bytes of the budget (frames excluded).
    pub fn total_bytes(&self) -> Result<usize, crate::sift::SiftError> {
        let mut b = MemoryBudget::new();
        self.budget(&mut b)?;
        Ok(b.total())
    }
}

/// How the traverse adjusts: the project's sliding window or one of the seed
/// procedures (docs/configuration.md, "Traverse modes").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TraverseMode {
    /// The project's default: a sliding window of `TRAVERSE_WINDOW` (3) adjusted epochs
    /// (8 with the rig estimated) and the observations of `TRAVERSE_FIXED_EPOCHS` that
    /// left it, robust snooping, base-length and smoothness constraints.
    #[default]
    Window,
    /// Seed 000 (Lemes Neto 2014): four-image sequences (two epochs), base-length
    /// constraints on both pairs, plain least squares then one re-weighting of the
    /// observations whose x residual exceeds the pixel size (weight 1e-5).
    Seed2014,
    /// Seed 002 (Barbosa 2006) strategy 4: all bases of a 7-base traverse adjusted
    /// together, one base-length constraint per base (variance 0.001 m^2) and a
    /// velocity constraint between consecutive bases (0.5 m^2/s^2), plain least
    /// squares, at most 20 iterations.
    Seed2006,
}

impl TraverseMode {
    /// Lower-case name used on the command line and in reports.
    pub const fn name(self) -> &'static str {
        match self {
            TraverseMode::Window => "window",
            TraverseMode::Seed2014 => "seed2014",
            TraverseMode::Seed2006 => "seed2006",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        [
            TraverseMode::Window,
            TraverseMode::Seed2014,
            TraverseMode::Seed2006,
        ]
        .into_iter()
        .find(|m| m.name() == name)
    }
}

/// Seed 002 Table 14: base variance 0.001 m^2.
pub const SEED2006_BASE_SIGMA_M: f64 = 0.031_622_776_601_683_79;
/// Seed 002 Table 14 / Quadro 1: velocity variance 0.5 m^2/s^2.
pub const SEED2006_VELOCITY_SIGMA_MPS: f64 = core::f64::consts::FRAC_1_SQRT_2;
/// Seed 002: "the limit of 7 bases" adjusted together.
pub const SEED2006_BASES: usize = 7;
/// Seed 002 Table 14: at most 20 iterations.
pub const SEED2006_MAX_ITERATIONS: usize = 20;
/// Seed 000 Quadro 4: the first pair's parameters carry variance 1e-6 (sigma 1e-3).
pub const SEED2014_DATUM_SIGMA: f64 = 1e-3;
/// Seed 000 leaves the base-length variance unstated; 1 mm keeps the bar rigid
/// against the image observations without overriding them.
pub const SEED2014_BASE_SIGMA_M: f64 = 1e-3;

impl TraverseConfig {
    /// Switches on the free estimation of the rig's relative orientation and of the
    /// interior orientation in the adjustment (`off` leaves the configuration as it is:
    /// the default calibration check stays).
    ///
    /// Estimating the rig needs the vertical parallax the images really show: with
    /// a rectified calibration the matcher would put each right point on its left
    /// point's row (`rows_only`) and the rig's omega and kappa would only see the
    /// calibration back. So the stereo search goes through the general rig geometry
    /// (epipolar band of `RIG_ESTIMATION_TOLERANCE_PX`, wide enough for a pixel of
    /// principal-point error on each camera) and the refinement searches both axes.
    pub fn with_rig_estimation(mut self, on: bool) -> Self {
        if !on {
            return self;
        }
        self.calibration_check = None;
        self.adjust.estimate_rig = true;
        self.adjust.hold_calibration = false;
        self.adjust.self_calibration = Some(self.interior_sigmas());
        // The rig and interior blocks are shared by the window's epochs: in three
        // epochs they trade against the poses (singular solves on the realistic
        // `curves`), in eight they do not.
        if self.adjust.window < RIG_ESTIMATION_WINDOW {
            self.adjust.window = RIG_ESTIMATION_WINDOW;
            self.matching.track_history = RIG_ESTIMATION_WINDOW;
            self.fit_capacities();
        }
        self.matching.stereo = StereoGeometry::Rig {
            rig: self.rig,
            tolerance_px: RIG_ESTIMATION_TOLERANCE_PX,
            min_depth_m: 1.0,
            max_depth_m: f64::INFINITY,
        };
        if let Some(r) = &mut self.matching.refine {
            r.rows_only = false;
        }
        self
    }

    /// Sets the calibration check ([`CalibrationCheck`]; `None` holds the calibration
    /// as given). The matching is left as it is: the check corrects what the
    /// observations show, and the free estimation ([`Self::with_rig_estimation`])
    /// replaces it.
    pub fn with_calibration_check(mut self, check: Option<CalibrationCheck>) -> Self {
        if self.calibration_check.is_none() && self.adjust.estimate_rig {
            // Free estimation: nothing to check.
            return self;
        }
        self.calibration_check = check;
        let on = check.is_some();
        self.adjust.estimate_rig = on;
        self.adjust.hold_calibration = on;
        self.adjust.self_calibration = on.then(|| self.interior_sigmas());
        self
    }

    /// Sets the calibration's stated precision (the prior of the check and of the free
    /// estimation).
    pub fn with_calibration_precision(mut self, p: CalibrationPrecision) -> Self {
        self.calibration_precision = p;
        self.adjust.sigmas.rig_angle_rad = p.angles_rad;
        self.adjust.sigmas.rig_base_m = p.base_m;
        if self.adjust.self_calibration.is_some() {
            self.adjust.self_calibration = Some(self.interior_sigmas());
        }
        self
    }

    /// Calibration sigmas of the self-calibration that goes with the rig estimation
    /// and the check: the stated precision, the left camera's times
    /// [`REFERENCE_CAMERA_FACTOR`].
    ///
    /// Why the left camera is held: it is the reference of the traverse. Its principal
    /// point trades against the attitude of every epoch (only the datum's fixed first
    /// attitude tells them apart) and its focal length, with the right one, is the
    /// common image scale, which a forward-moving rig hardly sees: left free, both
    /// wander within their prior (1.4 % on `curves`) and the drift follows. What the
    /// stereo geometry does determine is the right camera against the left one: its
    /// focal length through the vertical parallax growing with the row, its principal
    /// point (with the rig's angles) through the parallax offsets.
    fn interior_sigmas(&self) -> InteriorSigmas {
        let (l, r) = (&self.rig.left, &self.rig.right);
        let k = REFERENCE_CAMERA_FACTOR;
        let p = &self.calibration_precision;
        InteriorSigmas {
            principal_point_mm: [
                k * p.principal_point_px * l.pixel_size_mm[0],
                p.principal_point_px * r.pixel_size_mm[0],
            ],
            focal_mm: [k * p.focal * l.focal_mm, p.focal * r.focal_mm],
        }
    }

    /// The settings of `mode` applied to this configuration (capacities untouched
    /// except the window length and the track history that follows it).
    ///
    /// - `Window`: unchanged.
    /// - `Seed2014`: window 2 (four images), `Robust::SeedReweight` with the pixel
    ///   size as threshold (one re-run), base-length sigma 1 mm, no smoothness
    ///   constraint, datum sigmas 1e-3 (Quadro 4's variance 1e-6).
    /// - `Seed2006`: window 7 (bases), `Robust::None`, base-length sigma
    ///   sqrt(0.001) m, velocity-change sigma sqrt(0.5) m/s, at most 20 iterations.
    ///
    /// `estimate_rig` is orthogonal to the mode and left as it is; a seed mode's window
    /// replaces the longer one [`TraverseConfig::with_rig_estimation`] sets, so apply
    /// the mode after it.
    pub fn with_mode(mut self, mode: TraverseMode) -> Self {
        if mode == TraverseMode::Window {
            return self;
        }
        // The seeds' procedures drop a leaving epoch's observations with it, weight
        // every observation alike and hold the calibration as given (unless it is
        // estimated freely).
        self.adjust.fixed_epochs = 0;
        self.peak_weights = false;
        if self.calibration_check.is_some() {
            self = self.with_calibration_check(None);
        }
        let a = &mut self.adjust;
        match mode {
            TraverseMode::Window => {}
            TraverseMode::Seed2014 => {
                a.window = 2;
                a.robust = Robust::SeedReweight {
                    threshold_mm: self.rig.left.pixel_size_mm[0],
                };
                a.sigmas.base_length_m = SEED2014_BASE_SIGMA_M;
                a.sigmas.velocity_change_mps = 0.0;
                a.sigmas.datum_angle_rad = SEED2014_DATUM_SIGMA;
                a.sigmas.datum_position_m = SEED2014_DATUM_SIGMA;
            }
            TraverseMode::Seed2006 => {
                a.window = SEED2006_BASES;
                a.robust = Robust::None;
                a.sigmas.base_length_m = SEED2006_BASE_SIGMA_M;
                a.sigmas.velocity_change_mps = SEED2006_VELOCITY_SIGMA_MPS;
                a.max_iterations = SEED2006_MAX_ITERATIONS;
            }
        }
        self.matching.track_history = a.window;
        self
    }
}

#[cfg(test)]
mod mode_tests {
    use super::*;
    use crate::camera::Interior;

    fn base() -> TraverseConfig {
        let rig = Rig::rectified(Interior::pinhole_px(640, 480, 500.0), 0.4);
        TraverseConfig::for_rig(rig, Pose::from_degrees(90.0, 0.0, 0.0, [0.0; 3]))
    }

    #[test]
    fn window_mode_changes_nothing() {
        assert_eq!(base().with_mode(TraverseMode::Window), base());
    }

    #[test]
    fn seed2014_is_two_epochs_with_one_seed_reweighting() {
        let b = base();
        let c = b.with_mode(TraverseMode::Seed2014);
        assert_eq!(c.adjust.window, 2);
        assert_eq!(c.matching.track_history, 2);
        assert_eq!((b.adjust.fixed_epochs, c.adjust.fixed_epochs), (8, 0));
        assert_eq!(
            c.adjust.robust,
            Robust::SeedReweight {
                threshold_mm: b.rig.left.pixel_size_mm[0]
            }
        );
        assert_eq!(c.adjust.sigmas.base_length_m, 1e-3);
        assert_eq!(c.adjust.sigmas.velocity_change_mps, 0.0);
        // Quadro 4: variance 1e-6 on the first pair.
        assert_eq!(c.adjust.sigmas.datum_angle_rad.powi(2), 1e-6);
        assert_eq!(c.adjust.sigmas.datum_position_m.powi(2), 1e-6);
        // Capacities and the rest untouched.
        assert_eq!(c.adjust.max_points, b.adjust.max_points);
        // The seeds hold the calibration as given: no check.
        assert!(b.calibration_check.is_some() && b.adjust.estimate_rig);
        assert!(c.calibration_check.is_none() && !c.adjust.estimate_rig);
        assert_eq!((c.sift, c.sigma_px), (b.sift, b.sigma_px));
        // The seeds weight every observation alike.
        assert!(b.peak_weights && !c.peak_weights);
    }

    #[test]
    fn seed2006_is_seven_bases_with_base_and_velocity_constraints() {
        let b = base();
        let c = b.with_mode(TraverseMode::Seed2006);
        assert_eq!(c.adjust.window, 7);
        assert_eq!(c.matching.track_history, 7);
        assert_eq!(c.adjust.fixed_epochs, 0);
        assert!(!c.peak_weights);
        assert_eq!(c.adjust.robust, Robust::None);
        assert_eq!(c.adjust.max_iterations, 20);
        // Table 14: base variance 0.001 m^2, velocity variance 0.5 m^2/s^2.
        assert!((c.adjust.sigmas.base_length_m.powi(2) - 0.001).abs() < 1e-15);
        assert!((c.adjust.sigmas.velocity_change_mps.powi(2) - 0.5).abs() < 1e-15);
        assert_eq!(
            c.adjust.sigmas.datum_angle_rad,
            b.adjust.sigmas.datum_angle_rad
        );
        // A budget still exists for the longer history.
        assert!(c.total_bytes().unwrap() > 0);
    }

    #[test]
    fn mode_names_round_trip() {
        for m in [
            TraverseMode::Window,
            TraverseMode::Seed2014,
            TraverseMode::Seed2006,
        ] {
            assert_eq!(TraverseMode::from_name(m.name()), Some(m));
        }
        assert_eq!(TraverseMode::from_name("seed"), None);
    }
}
