//! Plain records of a run, serialised as `report.json`.
use phototraverse_core::adjust::quality::ChiSquareTest;
use phototraverse_core::camera::Pose;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Exterior orientation of one image with its standard deviations.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CameraEop {
    pub omega_deg: f64,
    pub phi_deg: f64,
    pub kappa_deg: f64,
    /// Perspective centre, metres, object frame.
    pub x: f64,
    pub y: f64,
    pub z: f64,
    /// Standard deviations of omega, phi, kappa (deg) and X, Y, Z (m); `None` when not estimated.
    pub sigma: Option<[f64; 6]>,
}

/// Standard deviations (three angles in radians, three lengths in metres) with the
/// angles in degrees, as the reports print them.
pub fn sigmas_in_degrees(s: [f64; 6]) -> [f64; 6] {
    [
        s[0].to_degrees(),
        s[1].to_degrees(),
        s[2].to_degrees(),
        s[3],
        s[4],
        s[5],
    ]
}

impl CameraEop {
    pub fn from_pose(pose: &Pose, sigma_rad_m: Option<[f64; 6]>) -> Self {
        let sigma = sigma_rad_m.map(sigmas_in_degrees);
        CameraEop {
            omega_deg: pose.omega.to_degrees(),
            phi_deg: pose.phi.to_degrees(),
            kappa_deg: pose.kappa.to_degrees(),
            x: pose.centre[0],
            y: pose.centre[1],
            z: pose.centre[2],
            sigma,
        }
    }

    pub fn to_pose(&self) -> Pose {
        Pose::from_degrees(
            self.omega_deg,
            self.phi_deg,
            self.kappa_deg,
            [self.x, self.y, self.z],
        )
    }
}

/// How an epoch was solved.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EpochStatus {
    /// Adjusted, tests passed.
    Ok,
    /// Adjusted, but a quality check failed (chi-square, few tie points); kept, flagged.
    Flagged,
    /// Not solved: the pose is the motion prediction.
    Predicted,
    /// The frames never arrived complete (link loss); the pose is the prediction.
    Lost,
}

impl EpochStatus {
    pub fn is_flagged(self) -> bool {
        self != EpochStatus::Ok
    }
}

/// One epoch of the traverse.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpochRecord {
    pub epoch: usize,
    pub time: Option<f64>,
    pub status: EpochStatus,
    /// Why the epoch is flagged, in words.
    pub note: Option<String>,
    pub left: CameraEop,
    pub right: CameraEop,
    pub sigma0: Option<f64>,
    /// The window adjustment's global test passed: the statistic within its bounds, as
    /// the run's quality summary counts it.
    pub chi2_passed: Option<bool>,
    /// That test: statistic, degrees of freedom, bounds and outcome.
    #[serde(default)]
    pub chi2: Option<EpochChi2>,
    pub observations: usize,
    pub tie_points: usize,
    /// Keypoints of the left and right image, and their stereo matches.
    #[serde(default)]
    pub keypoints: [u32; 2],
    #[serde(default)]
    pub stereo_matches: u32,
    /// Milliseconds per stage (features, matching, adjustment, link, ...).
    pub stage_ms: BTreeMap<String, f64>,
    /// The GNSS fix sent with the epoch, and the adjusted position's residual to it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gnss: Option<GnssRecord>,
    /// The odometer's count sent with the epoch (distance since its first reading), m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub odometer_count_m: Option<f64>,
    /// Velocity of the left perspective centre ([`super::velocity`]).
    #[serde(default)]
    pub velocity: Option<VelocityRecord>,
    /// Standard deviations of the left centre X, Y, Z relative to the recent past (the
    /// poses that left the window held exact), m: what a difference of neighbouring
    /// epochs is uncertain by; `left.sigma` is with respect to the datum.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relative_sd_m: Option<[f64; 3]>,
    /// The left centre's displacement from the previous epoch's (m), both from this
    /// epoch's window adjustment: the images' step (`crate::smoothing`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step_m: Option<[f64; 3]>,
    /// The left centre as the firmware output it, when the smoothing over the GNSS fixes
    /// moved it (`left` is then the smoothed one), m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub realtime_centre_m: Option<[f64; 3]>,
}

impl EpochRecord {
    /// An epoch with its poses and nothing measured yet (no adjustment, no counts).
    pub fn posed(
        epoch: usize,
        time: Option<f64>,
        status: EpochStatus,
        (left, right): (CameraEop, CameraEop),
    ) -> Self {
        EpochRecord {
            epoch,
            time,
            status,
            note: None,
            left,
            right,
            sigma0: None,
            chi2_passed: None,
            chi2: None,
            observations: 0,
            tie_points: 0,
            keypoints: [0; 2],
            stereo_matches: 0,
            stage_ms: Default::default(),
            gnss: None,
            odometer_count_m: None,
            velocity: None,
            relative_sd_m: None,
            step_m: None,
            realtime_centre_m: None,
        }
    }
}

/// A GNSS fix an epoch was adjusted with.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GnssRecord {
    /// The fix (object frame, m) and its sigma per coordinate.
    pub position: [f64; 3],
    pub sigma_m: f64,
    /// Adjusted position minus the fix, m.
    pub residual_m: [f64; 3],
}

/// Velocity of an epoch's left perspective centre (object frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct VelocityRecord {
    /// m/s along X, Y, Z.
    pub v_m_s: [f64; 3],
    /// Speed, m/s, and its standard deviation (None without position sigmas).
    pub speed_m_s: f64,
    pub sd_speed_m_s: Option<f64>,
}

/// The global chi-square test of an epoch's window adjustment (95 %, two-sided).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpochChi2 {
    /// `vTPv` with the a-priori variance factor: `sigma0^2 * dof`.
    pub statistic: f64,
    pub dof: usize,
    pub lower: f64,
    pub upper: f64,
    /// `passed`, `above` (blunders or a model error: the epoch is flagged) or `below`
    /// (the a-priori image sigma is pessimistic).
    pub result: String,
}

impl From<ChiSquareTest> for EpochChi2 {
    fn from(t: ChiSquareTest) -> Self {
        let result = if t.passed {
            "passed"
        } else if t.statistic > t.upper {
            "above"
        } else {
            "below"
        };
        EpochChi2 {
            statistic: t.statistic,
            dof: t.dof,
            lower: t.lower,
            upper: t.upper,
            result: result.into(),
        }
    }
}

/// A measured position of a tie point in one image.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ImageMeasurement {
    pub epoch: usize,
    /// 0 = left, 1 = right.
    pub camera: u8,
    /// Pixel column and row, pixel-centre convention ((0, 0) = centre of the top-left pixel).
    pub col: f64,
    pub row: f64,
}

/// A tie point in object space with its image measurements.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TiePoint {
    pub id: u32,
    pub xyz: [f64; 3],
    pub sigma: Option<[f64; 3]>,
    pub measurements: Vec<ImageMeasurement>,
}

/// One line of the memory budget: predicted from the configuration, measured by the firmware.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct MemoryLine {
    pub name: String,
    pub kind: String,
    pub predicted_bytes: usize,
    pub measured_bytes: Option<usize>,
}

/// Everything `report.json` holds.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RunReport {
    pub dataset: String,
    pub mode: String,
    pub image_width: u32,
    pub image_height: u32,
    pub epochs: Vec<EpochRecord>,
    pub memory: Vec<MemoryLine>,
    /// Image residuals of the last adjustment of each epoch, pixels (for the histogram).
    pub residuals_px: Vec<f32>,
    /// Ground-truth left camera centres, object frame, when the dataset has them.
    pub ground_truth: Option<Vec<[f64; 3]>>,
    /// Output of the evaluation against ground truth, when present.
    pub evaluation: Option<serde_json::Value>,
    /// Link statistics (bytes, retransmissions, errors).
    pub link: Option<serde_json::Value>,
    /// RMS reprojection error of the COLMAP model written (`colmap/`), pixels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colmap_rms_reprojection_px: Option<f64>,
    /// A signal (Ctrl-C, SIGTERM) stopped the run before the sequence's end: the outputs
    /// hold the epochs done.
    #[serde(default)]
    pub interrupted: bool,
    /// Wall time per epoch from the first frame sent to the last result received,
    /// ms: reading the images, the link, the firmware and the host together.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wall_ms_per_epoch: Option<f64>,
    /// The positions' smoothing over the GNSS fixes after the run, when there were fixes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub smoothing: Option<crate::smoothing::SmoothingSummary>,
    /// The rig as the adjustment had it at the last epoch, when it differs from the
    /// calibration: estimated (`--estimate-rig`, or by the calibration check after a
    /// correction: with the standard deviations of its last estimate).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rig: Option<RigReport>,
    /// sigma0 and the chi-square tests over all adjusted epochs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quality: Option<QualitySummary>,
    /// Each capacity's highest use during the run against what it reserves, as the
    /// firmware counted it.
    #[serde(default)]
    pub capacities: Vec<CapacityLine>,
    /// Sections, stack and instructions measured on the emulated microcontroller
    /// (`--link qemu`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<crate::mcu::TargetReport>,
}

/// The highest use of a capacity against the items it reserves.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CapacityLine {
    pub name: String,
    pub peak: u32,
    pub reserved: u32,
}

/// The estimated relative orientation and base, with the calibration it started from.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RigReport {
    /// Relative angles omega, phi, kappa (degrees), `M_R = Mrel M_L`.
    pub relative_angles_deg: [f64; 3],
    /// Base vector in the left camera frame (m).
    pub base_m: [f64; 3],
    /// Standard deviations: angles (degrees), base (m); zero when not available.
    pub std: [f64; 6],
    pub calibration_angles_deg: [f64; 3],
    pub calibration_base_m: [f64; 3],
}

/// Quality of the adjustments of a run: per-epoch sigma0 and chi-square test outcomes.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct QualitySummary {
    /// Epochs with an adjustment (sigma0 reported).
    pub adjusted: usize,
    pub sigma0_median: f64,
    pub sigma0_max: f64,
    /// Global test of each epoch's window adjustment: passed, failed (upper tail:
    /// the epoch is flagged) and below the lower bound (a-priori sigma pessimistic).
    pub chi2_passed: usize,
    pub chi2_failed: usize,
    pub chi2_below: usize,
    /// The a-priori image sigma the weights use, pixels: `sigma0` times it is about
    /// what the images delivered.
    #[serde(default)]
    pub apriori_sigma_px: f64,
}

impl QualitySummary {
    /// The image residuals' sigma the median sigma0 implies, pixels.
    pub fn delivered_sigma_px(&self) -> f64 {
        self.sigma0_median * self.apriori_sigma_px
    }

    /// What the counts of the global test mean, for people: "below" reads as a
    /// failure unless it says that the images did better than the weights assume.
    pub fn test_reading(&self) -> String {
        let mut s = format!(
            "global test over {} adjusted epochs: {} within the bounds, {} above (flagged), \
             {} below",
            self.adjusted, self.chi2_passed, self.chi2_failed, self.chi2_below
        );
        if self.chi2_below > 0 {
            s += &format!(
                " (below: the images delivered about {:.2} px against the a-priori {:.2} px, \
                 better than the weights assume, which stay pessimistic: docs/adjustment.md)",
                self.delivered_sigma_px(),
                self.apriori_sigma_px
            );
        }
        s
    }
}

impl RunReport {
    pub fn flagged_epochs(&self) -> usize {
        self.epochs.iter().filter(|e| e.status.is_flagged()).count()
    }
}
