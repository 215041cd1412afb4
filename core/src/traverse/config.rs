//! Configuration of the whole traverse and its memory budget.
use crate::adjust::{AdjustConfig, ConstraintSigmas, Correspondence, ResectionConfig};
use crate::budget::{slice_bytes, ComponentKind, MemoryBudget};
use crate::camera::{Pose, Rig};
use crate::features::FeatureSet;
use crate::matching::{MatchConfig, StereoGeometry};
use crate::sift::SiftConfig;

use super::TrackPoint;

/// Tie points per epoch at most (the spreading keeps the best spread ones).
pub const MAX_TIE_POINTS: usize = 400;
/// SIFT pending candidates per image column, over [`PENDING_SCALE`]: 2048 at 640 px.
pub const PENDING_PER_COLUMN: usize = 16;
pub const PENDING_SCALE: usize = 5;
/// Fewest SIFT pending candidates, whatever the width.
pub const MIN_PENDING: usize = 256;

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
    /// Fewer tie points than this and the epoch is flagged and tied to its prediction.
    pub min_tie_points: usize,
    /// Smallest ray angle of a new tie point, radians.
    pub min_ray_angle_rad: f64,
    /// New tie points farther than this from the camera are not added, metres.
    pub max_depth_m: f64,
    /// Prior standard deviations (angles rad, positions m) tying an epoch that the images
    /// do not determine (lost track) to its motion prediction.
    pub prediction_sigmas: [f64; 6],
}

impl TraverseConfig {
    /// Defaults for a rig and image size: 1000 keypoints per image, an 8-epoch window,
    /// robust weighting, base-length and smoothness constraints switched on.
    pub fn for_rig(rig: Rig, datum: Pose) -> Self {
        let (w, h) = (rig.left.width_px, rig.left.height_px);
        let max_keypoints = 1000;
        let sift = SiftConfig {
            max_width: w as usize,
            max_height: h as usize,
            max_keypoints,
            ..SiftConfig::default()
        };
        let mut matching = MatchConfig::rectified(w, h, max_keypoints, w as f32 * 0.5);
        let ideal = rig.relative_angles == [0.0; 3]
            && rig.base_m[1] == 0.0
            && rig.base_m[2] == 0.0
            && rig.left == rig.right
            && rig.left.radial == [0.0; 2]
            && rig.left.decentering == [0.0; 2];
        if !ideal {
            matching.stereo = StereoGeometry::Rig {
                rig,
                tolerance_px: 2.0,
                min_depth_m: 1.0,
                max_depth_m: f64::INFINITY,
            };
        }
        matching.max_tie_points = MAX_TIE_POINTS;
        matching.max_tracks = 600;
        let window = 8;
        matching.track_history = window;
        let adjust = AdjustConfig {
            window,
            // Set from the window and the tie points by `fit_capacities` below.
            max_points: 1,
            max_observations: 1,
            max_iterations: 20,
            max_robust_rounds: 4,
            estimate_rig: false,
            sigmas: ConstraintSigmas {
                base_length_m: 1e-4,
                velocity_change_mps: 0.5,
                ..ConstraintSigmas::default()
            },
            tolerance: 1e-10,
            ..AdjustConfig::default()
        };
        let mut cfg = TraverseConfig {
            rig,
            datum,
            sift,
            matching,
            adjust,
            resection: ResectionConfig::default(),
            sigma_px: 0.5,
            min_tie_points: 12,
            min_ray_angle_rad: 0.05f64.to_radians(),
            max_depth_m: 200.0,
            prediction_sigmas: [0.01, 0.01, 0.01, 0.3, 0.3, 0.3],
        };
        cfg.fit_capacities();
        cfg
    }

    /// Derives the capacities that follow from the configured image size, keypoints,
    /// tracks and window, so a small configuration is really small. Call it again after
    /// changing any of `sift.max_width`, `sift.max_keypoints`, `matching.max_tracks`,
    /// `matching.max_keypoints` or `adjust.window`.
    ///
    /// - tie points per epoch: at most [`MAX_TIE_POINTS`], the tracks and the keypoints;
    /// - window points: each epoch creates at most one point per tie point, and a point
    ///   lives while one of its observations is in the window: `tie points x window`;
    /// - window observations: an epoch holds two per tie point (left and right) plus two
    ///   per point intersected from it at the next epoch: `4 x tie points x window`.
    ///   With these bounds the window never drops an observation;
    /// - SIFT candidates waiting for their descriptor rows: a band of rows as wide as the
    ///   image, so proportional to the width ([`PENDING_PER_COLUMN`]).
    pub fn fit_capacities(&mut self) {
        let m = &mut self.matching;
        m.max_tie_points = MAX_TIE_POINTS.min(m.max_tracks).min(m.max_keypoints).max(1);
        let t = m.max_tie_points;
        let w = self.adjust.window.max(1);
        self.adjust.max_points = t.saturating_mul(w);
        self.adjust.max_observations = t.saturating_mul(w).saturating_mul(4);
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
        let mut sift = MemoryBudget::new();
        self.sift.budget(&mut sift)?;
        for c in sift
            .components()
            .iter()
            .filter(|c| c.kind == ComponentKind::Working)
        {
            budget.add(c.name, c.kind, c.bytes);
        }
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
        budget.add(
            "traverse.correspondences",
            ComponentKind::Working,
            slice_bytes::<Correspondence>(self.matching.max_tie_points),
        );
        Ok(())
    }

    /// Total bytes of the budget (frames excluded).
    pub fn total_bytes(&self) -> Result<usize, crate::sift::SiftError> {
        let mut b = MemoryBudget::new();
        self.budget(&mut b)?;
        Ok(b.total())
    }
}
