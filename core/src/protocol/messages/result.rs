//! The firmware's answer for an epoch: status, pose with precision, flags, counts and the
//! processor's figures.
use super::*;
use core::ops::{BitOr, BitOrAssign};

/// Status of an epoch's result.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResultStatus {
    /// Oriented.
    Ok,
    /// Features extracted, no orientation (the firmware runs the feature processor).
    FeaturesOnly,
    /// Image statistics only (bring-up processor).
    StatsOnly,
    /// The epoch's frames could not be assembled (lost chunk, CRC): the epoch is lost.
    Lost,
    /// The processor failed on this epoch (see the Error message), or refused its frames.
    Failed,
    /// Oriented, but flagged (see the [`ResultFlags`]).
    Flagged,
    /// Not oriented from the images: the pose is the motion prediction.
    Predicted,
    /// A code this build does not know (a newer firmware's); never one of the codes
    /// above, which parse to their own variants. Kept rather than refused so a host
    /// can still report the epoch.
    Unknown(u8),
}

impl ResultStatus {
    const KNOWN: [ResultStatus; 7] = [
        ResultStatus::Ok,
        ResultStatus::FeaturesOnly,
        ResultStatus::StatsOnly,
        ResultStatus::Lost,
        ResultStatus::Failed,
        ResultStatus::Flagged,
        ResultStatus::Predicted,
    ];

    /// Wire code.
    pub const fn code(self) -> u8 {
        match self {
            ResultStatus::Ok => 0,
            ResultStatus::FeaturesOnly => 1,
            ResultStatus::StatsOnly => 2,
            ResultStatus::Lost => 3,
            ResultStatus::Failed => 4,
            ResultStatus::Flagged => 5,
            ResultStatus::Predicted => 6,
            ResultStatus::Unknown(code) => code,
        }
    }

    pub fn from_code(code: u8) -> Self {
        Self::KNOWN
            .into_iter()
            .find(|s| s.code() == code)
            .unwrap_or(ResultStatus::Unknown(code))
    }
}

/// What went wrong or was noteworthy at an epoch, one bit each. Bits this build
/// does not name (a newer firmware's) are kept as they came.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ResultFlags(pub u32);

impl ResultFlags {
    pub const NONE: ResultFlags = ResultFlags(0);
    /// Too few tie points to the previous epoch: the epoch leans on its prediction.
    pub const FEW_TIE_POINTS: ResultFlags = ResultFlags(1 << 0);
    /// Continuity was lost (a frame from another place, a large jump): too few
    /// descriptor matches and too few tie points carried the epoch.
    pub const LOST: ResultFlags = ResultFlags(1 << 1);
    /// An image has no usable keypoints (textureless, dark, saturated).
    pub const NO_FEATURES: ResultFlags = ResultFlags(1 << 2);
    /// No stereo match at this epoch.
    pub const NO_STEREO: ResultFlags = ResultFlags(1 << 3);
    /// The frames repeat the previous epoch's: the previous pose is repeated.
    pub const REPEATED: ResultFlags = ResultFlags(1 << 4);
    /// The global chi-square test of the adjustment failed (upper tail).
    pub const CHI2: ResultFlags = ResultFlags(1 << 5);
    /// The adjustment failed (singular, no redundancy).
    pub const SOLVE_FAILED: ResultFlags = ResultFlags(1 << 6);
    /// The frames were refused (size, capacity): the epoch was skipped.
    pub const BAD_IMAGE: ResultFlags = ResultFlags(1 << 7);
    /// A capacity was reached (points or observations dropped).
    pub const CAPACITY: ResultFlags = ResultFlags(1 << 8);
    /// Informational: the resection failed and the motion prediction started the adjustment.
    pub const NO_RESECTION: ResultFlags = ResultFlags(1 << 9);
    /// Informational: the camera was found again by a resection on the previous stereo
    /// pair's points that the temporal matching found again (`docs/protocol.md`).
    pub const RELOCALIZED: ResultFlags = ResultFlags(1 << 10);
    /// Informational: the calibration check found the calibration significantly wrong
    /// and corrected it (the rig's relative orientation and the interior orientation).
    pub const CALIBRATION_CORRECTED: ResultFlags = ResultFlags(1 << 11);
    /// Informational: no resection posed the camera; its rotation came from the
    /// temporal matches, its position from the prediction.
    pub const ROTATION_FROM_MATCHES: ResultFlags = ResultFlags(1 << 12);

    pub const fn bits(self) -> u32 {
        self.0
    }

    /// Whether every bit of `other` is set.
    pub const fn contains(self, other: ResultFlags) -> bool {
        self.0 & other.0 == other.0
    }

    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }
}

impl BitOr for ResultFlags {
    type Output = ResultFlags;
    fn bitor(self, rhs: ResultFlags) -> ResultFlags {
        ResultFlags(self.0 | rhs.0)
    }
}

impl BitOrAssign for ResultFlags {
    fn bitor_assign(&mut self, rhs: ResultFlags) {
        self.0 |= rhs.0;
    }
}

/// Counts of an epoch; a processor that does not produce an item sends 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counts {
    /// Keypoints of the left and right image.
    pub keypoints: [u32; 2],
    /// Left-right matches of the epoch.
    pub stereo_matches: u32,
    /// Tie points linking this epoch to the previous one (seen in both stereo pairs).
    pub tie_points: u32,
    /// Points in the adjustment window after this epoch (of descriptor and area tracks).
    pub window_points: u32,
    /// Image observations in the adjustment window after this epoch.
    pub observations: u32,
    /// Tie points this epoch added to the window.
    pub new_points: u32,
    /// Items dropped because a capacity was full.
    pub dropped: u32,
}

/// The adjustment of the window that ended with an epoch.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Adjustment {
    /// A-posteriori sigma0 (a-priori 1).
    pub sigma0: f64,
    /// RMS image residual of the window, pixels.
    pub rms_px: f64,
    /// Statistic of the global test, `vTPv` with the a-priori variance factor 1;
    /// chi-square with `redundancy` degrees of freedom.
    pub chi2: f64,
    /// Redundancy of the adjustment: the degrees of freedom of `chi2`.
    pub redundancy: u32,
    /// Standard deviations of the left perspective centre X, Y, Z (m) relative to the
    /// recent past (the poses that left the window held exact); 0: not estimated.
    pub relative_sd_m: [f32; 3],
    /// The left perspective centre's displacement from the previous epoch's (m), both
    /// as adjusted in this window: the images' step, undistorted by GNSS fixes, which
    /// move the window as a whole. `None` when the previous epoch is not in the window.
    /// `f32` keeps a few tenths of a micrometre on a step of metres.
    pub step_m: Option<[f32; 3]>,
}

/// What the feature extractor found in each image (left, right).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SiftCounts {
    /// 3x3x3 scale-space extrema above the preliminary contrast threshold.
    pub extrema: [u32; 2],
    /// Refined keypoint locations accepted (contrast and edge tests passed).
    pub refined: [u32; 2],
}

/// Statistics of each image (left, right), for checking that the frames arrived whole.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ImageStats {
    /// Mean grey value.
    pub mean: [f64; 2],
    /// Mean absolute gradient, `|dx| + |dy|` per pixel.
    pub gradient_energy: [f64; 2],
    /// Median grey value.
    pub median: [u8; 2],
}

/// The figures only one kind of processor produces. A processor answers an epoch
/// alone, so a Result carries one block at most; and the blocks together would
/// not fit the firmware's 256-byte transmit slot with the rig block.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Figures {
    #[default]
    None,
    Adjustment(Adjustment),
    Sift(SiftCounts),
    ImageStats(ImageStats),
}

/// Wire codes of the [`Figures`] kinds.
mod figures_kind {
    pub const NONE: u8 = 0;
    pub const ADJUSTMENT: u8 = 1;
    pub const SIFT: u8 = 2;
    pub const IMAGE_STATS: u8 = 3;
}

impl Figures {
    fn parse(r: &mut Reader) -> Result<Self, ParseError> {
        Ok(match r.u8()? {
            figures_kind::NONE => Figures::None,
            figures_kind::ADJUSTMENT => Figures::Adjustment(Adjustment {
                sigma0: r.f64()?,
                rms_px: r.f64()?,
                chi2: r.f64()?,
                redundancy: r.u32()?,
                relative_sd_m: r.f32s()?,
                step_m: match r.u8()? {
                    0 => None,
                    1 => Some(r.f32s()?),
                    _ => return Err(ParseError::Invalid("result step presence")),
                },
            }),
            figures_kind::SIFT => Figures::Sift(SiftCounts {
                extrema: r.u32s()?,
                refined: r.u32s()?,
            }),
            figures_kind::IMAGE_STATS => Figures::ImageStats(ImageStats {
                mean: r.f64s()?,
                gradient_energy: r.f64s()?,
                median: [r.u8()?, r.u8()?],
            }),
            _ => return Err(ParseError::Invalid("result figures kind")),
        })
    }

    fn emit(&self, w: &mut Writer) -> Result<(), EncodeError> {
        match self {
            Figures::None => w.u8(figures_kind::NONE),
            Figures::Adjustment(a) => {
                w.u8(figures_kind::ADJUSTMENT)?;
                w.f64s(&[a.sigma0, a.rms_px, a.chi2])?;
                w.u32(a.redundancy)?;
                w.f32s(&a.relative_sd_m)?;
                match a.step_m {
                    None => w.u8(0),
                    Some(step) => {
                        w.u8(1)?;
                        w.f32s(&step)
                    }
                }
            }
            Figures::Sift(s) => {
                w.u8(figures_kind::SIFT)?;
                w.u32s(&s.extrema)?;
                w.u32s(&s.refined)
            }
            Figures::ImageStats(s) => {
                w.u8(figures_kind::IMAGE_STATS)?;
                w.f64s(&s.mean)?;
                w.f64s(&s.gradient_energy)?;
                w.bytes(&s.median)
            }
        }
    }
}

/// Firmware -> host: result of one epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpochResult {
    pub epoch: u32,
    pub status: ResultStatus,
    /// Left camera: omega, phi, kappa (rad), X, Y, Z (m).
    pub pose: [f64; 6],
    /// Standard deviations of `pose` (zero when not available). `f32`: seven
    /// significant digits of a precision are more than it is known to.
    pub sigma: [f32; 6],
    /// Standard deviations of the right camera's pose, in the same order (zero when
    /// not available).
    pub right_sigma: [f32; 6],
    pub flags: ResultFlags,
    pub counts: Counts,
    /// The processor's own figures.
    pub figures: Figures,
    /// Optional trailing block: the rig as estimated by the adjustment (sent only
    /// when it can differ from the calibration).
    pub rig: Option<RigEstimate>,
}

/// The relative orientation estimated with an epoch. `f32` on the wire keeps a
/// Result within a 256-byte transmit slot; the values are small (angles of a few
/// mrad, a base under a few metres), so `f32` keeps nanoradians and tens of nanometres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigEstimate {
    /// Relative angles omega, phi, kappa (rad) and base bx, by, bz (m), as in [`Rig`](crate::camera::Rig).
    pub params: [f32; 6],
    /// Their standard deviations (zero when not available).
    pub std: [f32; 6],
}

impl RigEstimate {
    fn parse(r: &mut Reader) -> Result<Self, ParseError> {
        Ok(RigEstimate {
            params: r.f32s()?,
            std: r.f32s()?,
        })
    }

    fn emit(&self, w: &mut Writer) -> Result<(), EncodeError> {
        w.f32s(&self.params)?;
        w.f32s(&self.std)
    }
}

impl EpochResult {
    pub fn empty(epoch: u32, status: ResultStatus) -> Self {
        EpochResult {
            epoch,
            status,
            pose: [0.0; 6],
            sigma: [0.0; 6],
            right_sigma: [0.0; 6],
            flags: ResultFlags::NONE,
            counts: Counts::default(),
            figures: Figures::None,
            rig: None,
        }
    }

    pub fn adjustment(&self) -> Option<&Adjustment> {
        match &self.figures {
            Figures::Adjustment(a) => Some(a),
            _ => None,
        }
    }

    pub fn sift(&self) -> Option<&SiftCounts> {
        match &self.figures {
            Figures::Sift(s) => Some(s),
            _ => None,
        }
    }

    pub fn image_stats(&self) -> Option<&ImageStats> {
        match &self.figures {
            Figures::ImageStats(s) => Some(s),
            _ => None,
        }
    }
}

repr!(
    EpochResult,
    Result,
    |r| {
        Ok(EpochResult {
            epoch: r.u32()?,
            status: ResultStatus::from_code(r.u8()?),
            pose: r.f64s()?,
            sigma: r.f32s()?,
            right_sigma: r.f32s()?,
            flags: ResultFlags(r.u32()?),
            counts: Counts {
                keypoints: r.u32s()?,
                stereo_matches: r.u32()?,
                tie_points: r.u32()?,
                window_points: r.u32()?,
                observations: r.u32()?,
                new_points: r.u32()?,
                dropped: r.u32()?,
            },
            figures: Figures::parse(&mut r)?,
            rig: if r.remaining() > 0 {
                Some(RigEstimate::parse(&mut r)?)
            } else {
                None
            },
        })
    },
    |s, w| {
        w.u32(s.epoch)?;
        w.u8(s.status.code())?;
        w.f64s(&s.pose)?;
        w.f32s(&s.sigma)?;
        w.f32s(&s.right_sigma)?;
        w.u32(s.flags.bits())?;
        let c = &s.counts;
        w.u32s(&c.keypoints)?;
        w.u32s(&[
            c.stereo_matches,
            c.tie_points,
            c.window_points,
            c.observations,
            c.new_points,
            c.dropped,
        ])?;
        s.figures.emit(&mut w)?;
        if let Some(rig) = &s.rig {
            rig.emit(&mut w)?;
        }
    }
);
