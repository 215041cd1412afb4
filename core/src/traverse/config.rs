//! Configuration of the whole traverse and its memory budget.
use crate::adjust::{AdjustConfig, ConstraintSigmas, Correspondence, ResectionConfig};
use crate::budget::{slice_bytes, ComponentKind, MemoryBudget};
use crate::camera::{Pose, Rig};
use crate::features::FeatureSet;
use crate::matching::{MatchConfig, RefineConfig, StereoGeometry};
use crate::sift::SiftConfig;

use super::patches::Patches;
use super::{Refined, TrackPoint};

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
    /// Refine each tie point's current left position against the previous epoch's
    /// template (needs `matching.refine`; see `traverse::patches`).
    pub temporal_refine: bool,
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
        matching.refine = Some(RefineConfig {
            rows_only: matches!(matching.stereo, StereoGeometry::Rectified { .. }),
            ..RefineConfig::default()
        });
        matching.max_tie_points = 400;
        matching.max_tracks = 600;
        let window = 8;
        matching.track_history = window;
        let adjust = AdjustConfig {
            window,
            max_points: 1500,
            max_observations: 12_000,
            max_iterations: 20,
            max_robust_rounds: 4,
            estimate_rig: false,
            sigmas: ConstraintSigmas {
                base_length_m: 1e-4,
                velocity_change_mps: 0.5,
                ..ConstraintSigmas::default()
            },
            // Each epoch starts from the last solution: a relative decrease of 1e-6
            // moves the poses by far less than their sigma.
            tolerance: 1e-6,
            keep_exclusions: true,
            ..AdjustConfig::default()
        };
        TraverseConfig {
            rig,
            datum,
            sift,
            matching,
            adjust,
            resection: ResectionConfig::default(),
            sigma_px: 0.5,
            min_tie_points: 12,
            min_ray_angle_rad: 0.05f64.to_radians(),
            // Far points carry the attitude; only points at practically infinite
            // distance (where the ray angle test already refuses them) are left out.
            max_depth_m: 1000.0,
            prediction_sigmas: [0.01, 0.01, 0.01, 0.3, 0.3, 0.3],
            temporal_refine: true,
        }
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
        if let Some((cap, half)) = self.patch_capacity() {
            Patches::budget(cap, half, budget);
            budget.add(
                "traverse.refined",
                ComponentKind::Working,
                slice_bytes::<Refined>(self.matching.max_tie_points),
            );
        }
        budget.add(
            "traverse.correspondences",
            ComponentKind::Working,
            slice_bytes::<Correspondence>(self.matching.max_tie_points),
        );
        Ok(())
    }

    /// Templates kept for the temporal refinement (capacity, half-size), if it is on.
    pub fn patch_capacity(&self) -> Option<(usize, usize)> {
        let r = self.matching.refine.as_ref()?;
        self.temporal_refine
            .then_some((self.matching.max_tie_points, r.half_window as usize))
    }

    /// Total bytes of the budget (frames excluded).
    pub fn total_bytes(&self) -> Result<usize, crate::sift::SiftError> {
        let mut b = MemoryBudget::new();
        self.budget(&mut b)?;
        Ok(b.total())
    }
}
