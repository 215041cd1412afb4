//! Matching configuration, its memory budget and the shared small types.

use crate::budget::{slice_bytes, Arena, ComponentKind, MemoryBudget, OutOfMemory};
use crate::camera::Rig;

/// "No index": an unmatched keypoint, a free track slot.
pub const NONE: u32 = u32::MAX;

/// Most samples along an epipolar segment when bounding its search region (general rig).
pub const EPIPOLAR_SAMPLES: usize = 9;

/// Largest NCC template half-size (a 15 x 15 template).
pub const MAX_REFINE_HALF: usize = 7;
/// Largest NCC search radius (a 9 x 9 grid of positions).
pub const MAX_REFINE_RADIUS: usize = 4;

/// Where a right keypoint may lie given a left one.
// The rig variant is larger, but the configuration is copied once per matcher.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StereoGeometry {
    /// A rectified pair: same row within a tolerance, `x_left - x_right` in a disparity range.
    Rectified {
        row_tolerance_px: f32,
        min_disparity_px: f32,
        max_disparity_px: f32,
    },
    /// A calibrated general rig: within `tolerance_px` of the epipolar curve (worked out
    /// in corrected photo-coordinates, so distortion bends the curve in pixels) and between
    /// the projections of `min_depth_m` and `max_depth_m` (may be infinite) along the ray.
    Rig {
        rig: Rig,
        tolerance_px: f32,
        min_depth_m: f64,
        max_depth_m: f64,
    },
}

/// Area-based sub-pixel refinement of stereo matches (normalised cross-correlation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefineConfig {
    /// Template half-size in pixels (4 gives a 9 x 9 template), at most `MAX_REFINE_HALF`.
    pub half_window: u8,
    /// Search radius in whole pixels around the matched position, at most `MAX_REFINE_RADIUS`.
    pub search_radius: u8,
    /// Smallest NCC peak accepted; below it the match is rejected as unreliable.
    pub min_ncc: f32,
    /// Search along the row only and put the right point on the left point's row
    /// (rectified pairs, where the row is known exactly).
    pub rows_only: bool,
    /// Left-right check: the right template, correlated back into the left image, must
    /// land within this many pixels of the left point (0 disables the check). Rejects
    /// matches whose templates straddle an occlusion edge.
    pub back_check_px: f32,
}

impl Default for RefineConfig {
    fn default() -> Self {
        RefineConfig {
            half_window: 4,
            search_radius: 2,
            min_ncc: 0.8,
            rows_only: true,
            back_check_px: 0.5,
        }
    }
}

/// Everything the matcher needs to know before it runs; capacities size the arena.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MatchConfig {
    /// Keypoints per image (more are ignored and counted).
    pub max_keypoints: usize,
    /// Image format (all four images of an epoch share it).
    pub image_width: u32,
    pub image_height: u32,
    /// Side of a spatial-grid bucket, pixels.
    pub cell_px: u32,
    /// Lowe's ratio on descriptor distances (not squared), e.g. 0.8.
    pub ratio: f32,
    /// Largest squared u8 descriptor distance of an accepted match.
    pub max_distance: u32,
    /// Most candidates compared per query keypoint: the documented constant that bounds
    /// the cost at `max_keypoints * max_candidates` distances per image pair.
    pub max_candidates: usize,
    /// Stereo search region.
    pub stereo: StereoGeometry,
    /// Half-size of the temporal search window around a predicted position, pixels.
    pub temporal_window_px: f32,
    /// Half-size of the fallback window around the previous position, pixels.
    pub fallback_window_px: f32,
    /// Fewer guided temporal matches than this (per side) triggers the fallback search.
    pub min_temporal_matches: usize,
    /// Spreading grid over the left image (Von Gruber regions).
    pub spread_cols: u16,
    pub spread_rows: u16,
    /// Most tie points (quads) kept per epoch.
    pub max_tie_points: usize,
    /// Track capacity and observations kept per track (the adjustment window).
    pub max_tracks: usize,
    pub track_history: usize,
    /// Optional sub-pixel refinement of stereo matches (needs the images).
    pub refine: Option<RefineConfig>,
    /// Rigid-motion consistency of the quads (needs the rig at each epoch).
    pub motion_check: Option<super::motion::MotionCheckConfig>,
}

impl MatchConfig {
    /// Defaults for a rectified pair of the given size.
    pub fn rectified(width: u32, height: u32, max_keypoints: usize, max_disparity_px: f32) -> Self {
        MatchConfig {
            max_keypoints,
            image_width: width,
            image_height: height,
            cell_px: 16,
            ratio: 0.8,
            max_distance: 120_000,
            max_candidates: 64,
            stereo: StereoGeometry::Rectified {
                row_tolerance_px: 2.0,
                min_disparity_px: 0.0,
                max_disparity_px,
            },
            temporal_window_px: 12.0,
            fallback_window_px: 80.0,
            min_temporal_matches: 20,
            spread_cols: 4,
            spread_rows: 3,
            max_tie_points: max_keypoints,
            max_tracks: max_keypoints,
            track_history: 8,
            refine: None,
            motion_check: Some(super::motion::MotionCheckConfig::default()),
        }
    }

    fn grid_dims(&self) -> (usize, usize) {
        let cell = self.cell_px.max(1) as usize;
        let cols = (self.image_width as usize).div_ceil(cell).max(1);
        let rows = (self.image_height as usize).div_ceil(cell).max(1);
        (cols, rows)
    }

    /// Checks the values that would otherwise make the matcher meaningless.
    pub fn validate(&self) -> Result<(), MatchError> {
        let finite = [self.ratio, self.temporal_window_px, self.fallback_window_px]
            .iter()
            .all(|v| v.is_finite() && *v >= 0.0);
        let geometry_ok = match self.stereo {
            StereoGeometry::Rectified {
                row_tolerance_px,
                min_disparity_px,
                max_disparity_px,
            } => row_tolerance_px >= 0.0 && min_disparity_px <= max_disparity_px,
            StereoGeometry::Rig {
                rig,
                tolerance_px,
                min_depth_m,
                max_depth_m,
            } => {
                rig.validate().is_ok()
                    && tolerance_px >= 0.0
                    && min_depth_m > 0.0
                    && min_depth_m.is_finite()
                    && max_depth_m > min_depth_m
                    && rig.base_length() > 0.0
            }
        };
        let refine_ok = match self.refine {
            None => true,
            Some(r) => {
                (r.half_window as usize) <= MAX_REFINE_HALF
                    && r.half_window > 0
                    && (r.search_radius as usize) <= MAX_REFINE_RADIUS
                    && r.search_radius > 0
                    && r.min_ncc.is_finite()
                    && r.back_check_px.is_finite()
            }
        };
        if !finite || !geometry_ok || !refine_ok || self.ratio > 1.0 {
            return Err(MatchError::BadConfig);
        }
        if self.max_keypoints == 0
            || self.max_keypoints >= NONE as usize
            || self.image_width == 0
            || self.image_height == 0
            || self.max_candidates == 0
            || self.spread_cols == 0
            || self.spread_rows == 0
            || self.track_history < 2
            || self.max_tracks == 0
        {
            return Err(MatchError::BadConfig);
        }
        Ok(())
    }

    /// Adds the matcher's buffers (prefix `match.`) to a budget; [`super::Matcher::new`]
    /// carves exactly these from the arena.
    pub fn budget(&self, budget: &mut MemoryBudget) {
        let n = self.max_keypoints;
        let (gc, gr) = self.grid_dims();
        let w = ComponentKind::Working;
        let s = ComponentKind::Storage;
        budget.add(
            "match.grid",
            w,
            slice_bytes::<u32>(gc * gr + 1) + slice_bytes::<u32>(n),
        );
        budget.add("match.best", w, 2 * slice_bytes::<super::Best>(n));
        budget.add("match.corrected", w, slice_bytes::<[f32; 2]>(n));
        budget.add("match.temporal", w, 4 * slice_bytes::<u32>(n));
        budget.add("match.predictions", w, 2 * slice_bytes::<[f32; 2]>(n));
        budget.add(
            "match.motion",
            w,
            slice_bytes::<super::motion::QuadObs>(n)
                + slice_bytes::<[f64; 3]>(2 * n)
                + slice_bytes::<u8>(n),
        );
        budget.add(
            "match.quads",
            w,
            slice_bytes::<super::Quad>(n) + slice_bytes::<u32>(n),
        );
        budget.add(
            "match.stereo",
            s,
            2 * (3 * slice_bytes::<u32>(n) + 2 * slice_bytes::<[f32; 2]>(n)),
        );

        budget.add(
            "match.tracks",
            s,
            slice_bytes::<super::Track>(self.max_tracks),
        );
        budget.add(
            "match.observations",
            s,
            slice_bytes::<super::Observation>(self.max_tracks * self.track_history),
        );
    }

    /// Total predicted bytes of [`MatchConfig::budget`].
    pub fn predicted_bytes(&self) -> usize {
        let mut b = MemoryBudget::new();
        self.budget(&mut b);
        b.total_with_prefix("match.")
    }

    pub(crate) fn grid_shape(&self) -> (usize, usize) {
        self.grid_dims()
    }
}

/// Why the matcher refused to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MatchError {
    /// A configuration value is out of range.
    BadConfig,
    /// The arena cannot hold the configured buffers.
    OutOfMemory(OutOfMemory),
    /// Keypoint and descriptor slices differ in length.
    LengthMismatch,
    /// The previous epoch's features differ from those of the last call.
    PreviousMismatch,
}

impl From<OutOfMemory> for MatchError {
    fn from(e: OutOfMemory) -> Self {
        MatchError::OutOfMemory(e)
    }
}

impl core::fmt::Display for MatchError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            MatchError::BadConfig => f.write_str("matching configuration out of range"),
            MatchError::OutOfMemory(e) => write!(f, "matching: {e}"),
            MatchError::LengthMismatch => f.write_str("keypoints and descriptors differ in count"),
            MatchError::PreviousMismatch => {
                f.write_str("previous-epoch features differ from the last call's")
            }
        }
    }
}

/// Carves `n` values of `T` (helper to keep the constructor readable).
pub(crate) fn carve<'a, T: bytemuck::Pod>(
    arena: &mut Arena<'a>,
    n: usize,
) -> Result<&'a mut [T], MatchError> {
    Ok(arena.alloc_slice::<T>(n)?)
}
