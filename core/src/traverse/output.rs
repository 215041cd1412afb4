//! What the traverse reports for each epoch.
use crate::camera::Pose;

/// Reasons an epoch is flagged (bit set in [`EpochOutput::flags`]).
pub mod flags {
    /// Fewer tie points than `min_tie_points`: the epoch leans on its prediction.
    pub const FEW_TIE_POINTS: u32 = 1 << 0;
    /// Continuity was lost (a frame from another place, a large jump): the matcher
    /// found too few descriptor matches and fewer than `min_tie_points` tie points,
    /// area-matched ones included, carried the epoch.
    pub const LOST: u32 = 1 << 1;
    /// An image has no usable keypoints (textureless, dark, saturated).
    pub const NO_FEATURES: u32 = 1 << 2;
    /// No stereo match at this epoch.
    pub const NO_STEREO: u32 = 1 << 3;
    /// The frames repeat the previous epoch's: the previous pose is repeated.
    pub const REPEATED: u32 = 1 << 4;
    /// The global chi-square test of the adjustment failed.
    pub const CHI2: u32 = 1 << 5;
    /// The adjustment failed (singular, no redundancy): the pose is the initial value.
    pub const SOLVE_FAILED: u32 = 1 << 6;
    /// The image buffer was refused (size, capacity): the epoch was skipped.
    pub const BAD_IMAGE: u32 = 1 << 7;
    /// A capacity was reached (points or observations dropped).
    pub const CAPACITY: u32 = 1 << 8;
    /// Informational: the resection failed and the motion prediction started the adjustment.
    pub const NO_RESECTION: u32 = 1 << 9;
    /// Informational: the tie points did not resect the camera; it was found again by a
    /// resection on the previous stereo pair's points that the temporal matching found
    /// again, with or without the motion prior (in a small configuration, most epochs:
    /// docs/traverse.md, "Relocalization").
    pub const RELOCALIZED: u32 = 1 << 10;
    /// Informational: the calibration check found the calibration significantly wrong
    /// and corrected it (the rig's relative orientation and the interior orientation).
    pub const CALIBRATION_CORRECTED: u32 = 1 << 11;
    /// Informational: neither resection posed the camera; its rotation came from the
    /// temporal matches (`traverse::turn`), its position from the prediction. Kept only
    /// when the area matching found at least as many tie points from it as from the
    /// prediction (`Traverse::area_prefers`).
    pub const ROTATION_FROM_MATCHES: u32 = 1 << 12;

    /// Flags that make an epoch count as flagged (the informational ones do not).
    pub const FLAGGING: u32 = FEW_TIE_POINTS
        | LOST
        | NO_FEATURES
        | NO_STEREO
        | REPEATED
        | CHI2
        | SOLVE_FAILED
        | BAD_IMAGE;
}

/// How an epoch's pose was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(u8)]
pub enum EpochStatus {
    /// Adjusted, every check passed.
    #[default]
    Ok = 0,
    /// Adjusted, but flagged (see the flags).
    Flagged = 1,
    /// Not adjusted: the pose is the motion prediction.
    Predicted = 2,
    /// The frames were refused; the pose is the prediction and the state is unchanged.
    Rejected = 3,
}

impl EpochStatus {
    pub fn from_u8(v: u8) -> Option<Self> {
        match v {
            0 => Some(EpochStatus::Ok),
            1 => Some(EpochStatus::Flagged),
            2 => Some(EpochStatus::Predicted),
            3 => Some(EpochStatus::Rejected),
            _ => None,
        }
    }
}

/// Microseconds per stage of one epoch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StageTimes {
    pub sift_left_us: u32,
    pub sift_right_us: u32,
    /// Stereo and temporal matching, quads and tracks.
    pub matching_us: u32,
    pub initial_us: u32,
    pub adjust_us: u32,
    pub total_us: u32,
}

/// The result of one epoch.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EpochOutput {
    /// Input epoch index (0-based, counting every epoch given to the traverse).
    pub epoch: u32,
    pub status: EpochStatus,
    /// Bits of [`flags`].
    pub flags: u32,
    /// Left and right camera poses, object frame.
    pub left: Pose,
    pub right: Pose,
    /// Standard deviations of the left pose (omega, phi, kappa rad; X, Y, Z m) with
    /// respect to the datum ([`crate::adjust::Window::epoch_absolute_std`]).
    pub std: Option<[f64; 6]>,
    /// Standard deviations of the right pose, from the left pose's covariance carried
    /// through the rig's relative orientation
    /// ([`crate::adjust::right_camera_covariance`]).
    pub right_std: Option<[f64; 6]>,
    /// Standard deviations of the left perspective centre (X, Y, Z m) with the poses
    /// that left the window held exact: its precision relative to the recent past, what
    /// a velocity from neighbouring epochs is uncertain by.
    pub relative_std_m: Option<[f64; 3]>,
    /// The left perspective centre's displacement from the previous epoch's (m), both
    /// as adjusted in this epoch's window: the images' step, which fixes shift with the
    /// whole window and do not distort. `None` when the previous epoch is not in the
    /// window (the first epoch, an epoch after one that was not adjusted).
    pub step_m: Option<[f64; 3]>,
    /// A-posteriori sigma0 of the window adjustment (0 when not adjusted).
    pub sigma0: f64,
    pub chi2_passed: bool,
    /// Redundancy of the window adjustment.
    pub redundancy: u32,
    /// Keypoints of the left and right image.
    pub keypoints: [u32; 2],
    pub stereo_matches: u32,
    /// Tie points (quads) linking this epoch to the previous one.
    pub tie_points: u32,
    /// New tie points added to the window at this epoch.
    pub new_points: u32,
    /// Image observations in the window after this epoch.
    pub observations: u32,
    /// Points in the window after this epoch (descriptor and area tie points, the
    /// excluded ones included): the use of `AdjustConfig::max_points`.
    pub points: u32,
    /// Observations flagged as blunders in the last adjustment.
    pub flagged_observations: u32,
    /// Points and observations the window refused at this epoch, its capacity full.
    pub dropped: u32,
    /// RMS image residual of the window, pixels.
    pub rms_px: f64,
    pub iterations: u32,
    pub times: StageTimes,
}

impl EpochOutput {
    /// Sets the status from the flags and whether the epoch was adjusted.
    pub(crate) fn settle(&mut self, adjusted: bool) {
        self.status = if self.flags & flags::BAD_IMAGE != 0 {
            EpochStatus::Rejected
        } else if !adjusted {
            EpochStatus::Predicted
        } else if self.flags & flags::FLAGGING != 0 {
            EpochStatus::Flagged
        } else {
            EpochStatus::Ok
        };
    }
}
