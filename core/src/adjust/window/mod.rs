//! The sliding-window bundle adjuster.
//!
//! Unknowns: the left camera's attitude, as a small turn in the object frame
//! ([`super::attitude`]: the angles' corrections are singular where a vehicle heads
//! a quarter turn from the datum), and its centre `(X, Y, Z)`, of every epoch in the
//! window; optionally the relative orientation of the rig `(omega, phi, kappa, bx, by,
//! bz)` with a prior; and the tie points. The
//! normal equations are built point by point: each point's 3x3 block `V` is
//! eliminated at once (Schur complement), so only the reduced camera system
//! `S = U - W V^-1 W^T` (at most `6 (N + 1)` square) is stored; it is damped
//! (Levenberg-Marquardt, Marquardt's diagonal scaling) and solved by Cholesky
//! in place; the point steps follow by back-substitution
//! `dp = V^-1 (b_p - W^T dc)`.
//!
//! Sliding (see docs/adjustment.md): the leaving epoch is *fixed*: its pose is
//! final and its observations leave the window. Its information is carried as a
//! prior on the new first epoch: that epoch's adjusted pose with the 6x6
//! marginal covariance of the last solution (from the inverse of the reduced
//! normal matrix). This keeps the datum and lets the uncertainty of the traverse
//! grow; it is not exact marginalisation (the correlations between the new first
//! epoch and the rest are dropped), which keeps the reduced system dense and
//! small and never fills in tie points.
//!
//! All storage comes from the [`Arena`], sized by [`AdjustConfig::budget`].

use super::attitude;
use super::cholesky;
use super::constraints::{base_length, distance, pose_prior_residual, prior_residual, smoothness};
use super::geometry::{
    corrected_focal, project_epoch, project_xy, project_xy_with, right_rotation,
    shift_principal_point, with_interior, EpochRotations, InteriorCorrections, Partials, Rotations,
};
use super::propagation::{propagate, rigid_transport_turn, standard_deviations};
use super::quality::ChiSquareTest;
use super::weighting::{
    cauchy_factor, median_by_rank, CHI2_2_MEDIAN, MIN_SNOOPING_SCALE, SEED_REWEIGHT,
};
use crate::budget::{slice_bytes, Arena, ComponentKind, MemoryBudget, OutOfMemory};
use crate::camera::{Camera, RelativeOrientation};
use crate::camera::{Pose, Rig};
use bytemuck::{Pod, Zeroable};
use nalgebra::{Matrix3, Vector3};

mod build;
mod normal;
mod quality;
mod results;
mod slide;
mod solve;
#[cfg(test)]
mod tests;

/// Standard deviations of the weighted constraints. A value `<= 0` switches
/// the constraint off (the datum cannot be switched off).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConstraintSigmas {
    /// Datum: attitude of the first epoch, radians.
    pub datum_angle_rad: f64,
    /// Datum: position of the first epoch, metres.
    pub datum_position_m: f64,
    /// Prior on the relative angles when the rig is estimated, radians.
    pub rig_angle_rad: f64,
    /// Prior on the base vector when the rig is estimated, metres.
    pub rig_base_m: f64,
    /// Base length constraint (seed 000 eq. 44), metres.
    pub base_length_m: f64,
    /// Motion smoothness: change of velocity between consecutive intervals, m/s.
    pub velocity_change_mps: f64,
}

impl ConstraintSigmas {
    /// The information (6x6, row-major) of the datum's pose prior: the first epoch's,
    /// and any first epoch's that has no carried covariance.
    fn datum_information(&self) -> [f64; 36] {
        let mut info = [0.0; 36];
        for i in 0..6 {
            let sig = if i < 3 {
                self.datum_angle_rad
            } else {
                self.datum_position_m
            };
            info[i * 6 + i] = 1.0 / (sig * sig);
        }
        info
    }
}

impl Default for ConstraintSigmas {
    fn default() -> Self {
        ConstraintSigmas {
            datum_angle_rad: 1e-6,
            datum_position_m: 1e-6,
            rig_angle_rad: 1e-3,
            rig_base_m: 1e-3,
            base_length_m: 0.0,
            velocity_change_mps: 0.0,
        }
    }
}

/// Standard deviations of the interior orientation's calibration (the prior of the
/// self-calibration), index 0 left, 1 right.
///
/// Why: a differential focal length error between the cameras scales the right
/// image against the left (0.6 % is 1.4 px at the image's top and bottom), which no
/// relative orientation can take: left free, the base's y and z components absorb it
/// as a depth-dependent scale and the traverse drifts by several percent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InteriorSigmas {
    /// Principal point (both coordinates), mm.
    pub principal_point_mm: [f64; 2],
    /// Focal length, mm.
    pub focal_mm: [f64; 2],
}

impl InteriorSigmas {
    /// Diagonal information `[x0_L, y0_L, f_L, x0_R, y0_R, f_R]` (row-major 6x6).
    fn information(&self) -> [f64; 36] {
        let mut info = [0.0; 36];
        for cam in 0..2 {
            let sig = [
                self.principal_point_mm[cam],
                self.principal_point_mm[cam],
                self.focal_mm[cam],
            ];
            for (k, sg) in sig.iter().enumerate() {
                let i = 3 * cam + k;
                info[i * 6 + i] = 1.0 / (sg * sg);
            }
        }
        info
    }

    fn valid(&self) -> bool {
        self.principal_point_mm
            .iter()
            .chain(self.focal_mm.iter())
            .all(|s| *s > 0.0 && s.is_finite())
    }
}

/// Treatment of blunders.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Robust {
    /// Plain least squares.
    None,
    /// Default: Cauchy re-weighting on a median scale, then data snooping of
    /// `T = v^T Q_vv^-1 v` against `critical` (chi-square, 2 dof) until stable.
    Snooping { critical: f64 },
    /// Seed 000: after one adjustment, observations whose x residual exceeds
    /// `threshold_mm` (the pixel size) get weight 1e-5 (both coordinates; the
    /// new weight stays in the window) and the adjustment reruns once.
    SeedReweight { threshold_mm: f64 },
}

impl Robust {
    /// Snooping at the 0.1 % level: `chi2(0.999, 2) = 13.8155`.
    pub const fn snooping() -> Self {
        Robust::Snooping {
            critical: 13.815510557964274,
        }
    }
}

/// Which camera blocks a point's pass accumulates besides its own `V` and `b`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum CamBlocks {
    None,
    /// The cross blocks `W` only (back-substitution, point covariances).
    Cross,
    /// `W`, the camera blocks `U` and gradients `g` (the reduced system).
    Full,
}

/// Configuration of the adjustment: capacities, iterations, constraints.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdjustConfig {
    /// Epochs in the window (2 reproduces seed 000's four-image sequences).
    pub window: usize,
    pub max_points: usize,
    pub max_observations: usize,
    /// Levenberg-Marquardt iterations per least-squares solution.
    pub max_iterations: usize,
    /// Robust rounds (re-weighting and snooping rounds each).
    pub max_robust_rounds: usize,
    /// Estimate the relative orientation (with the prior of `sigmas`) or keep it fixed.
    pub estimate_rig: bool,
    /// Self-calibration: estimate corrections to both cameras' principal point and
    /// focal length (one set for the whole traverse, as the rig) with a prior of
    /// these sigmas around the calibration; `None` keeps the interior fixed.
    pub self_calibration: Option<InteriorSigmas>,
    pub sigmas: ConstraintSigmas,
    pub robust: Robust,
    /// Convergence: relative decrease of `vTPv` below this stops the iterations.
    pub tolerance: f64,
    /// Convergence on the step: a Gauss-Newton step that moves no camera angle by more
    /// than `[0]` (rad) and no camera centre by more than `[1]` (m) ends the iterations
    /// without another one to confirm it (the linearisation error left after a step
    /// is of the order of its square). Zero turns it off.
    pub step_tolerance: [f64; 2],
    /// Sliding-window mode of [`Robust::Snooping`]: exclusions found by earlier solves
    /// stay as the starting set (snooping may readmit them) and the Cauchy rounds are
    /// skipped, so an epoch only pays for the blunders its own observations bring.
    pub keep_exclusions: bool,
    /// Epochs that left the window whose observations still constrain the points
    /// (their poses held fixed), 0 drops a leaving epoch's observations with it.
    /// See [`Window::slide`].
    pub fixed_epochs: usize,
    /// With `fixed_epochs > 0`, the carried prior of the window's first epoch is its
    /// marginal covariance times this factor (>= 1: the covariance also holds the
    /// information of observations that stay in the window, so it counts them twice at
    /// factor 1). Without fixed epochs the prior is not inflated.
    pub carried_prior_inflation: f64,
    /// With `estimate_rig` or `self_calibration`: their blocks start held at the
    /// calibration (the poses are adjusted as with a fixed rig) and change only through
    /// [`Window::correct_calibration`], after [`Window::calibration_test`] (or another
    /// measure) found the observations call for it, or once [`Window::free_calibration`]
    /// lets every adjustment estimate them.
    pub hold_calibration: bool,
}

impl Default for AdjustConfig {
    fn default() -> Self {
        AdjustConfig {
            window: 8,
            max_points: 500,
            max_observations: 4000,
            max_iterations: 50,
            max_robust_rounds: 8,
            estimate_rig: false,
            self_calibration: None,
            sigmas: ConstraintSigmas::default(),
            robust: Robust::snooping(),
            tolerance: 1e-12,
            step_tolerance: [0.0; 2],
            keep_exclusions: false,
            fixed_epochs: 0,
            carried_prior_inflation: 1.0,
            hold_calibration: false,
        }
    }
}

/// What the observations of the window say about the calibration (the rig's relative
/// orientation and the interior orientation) held at its current value: the score test
/// of the held parameters (see [`Window::calibration_test`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CalibrationTest {
    /// `g^T N^-1 g / sigma0^2`: the decrease of `vTPv` (in units of the a-posteriori
    /// variance) that freeing the calibration would bring, chi-square with `dof`
    /// degrees of freedom when the calibration is right.
    pub statistic: f64,
    pub dof: usize,
    /// The correction a free adjustment would make (one Gauss-Newton step): the rig's
    /// `[omega, phi, kappa, bx, by, bz]` and the interior `[x0_L, y0_L, f_L, x0_R, y0_R, f_R]` (mm).
    pub rig: [f64; 6],
    pub interior: InteriorCorrections,
}

/// Why the adjustment refused or failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AdjustError {
    OutOfMemory(OutOfMemory),
    /// A configuration value is out of range (window < 1, zero capacities).
    InvalidConfig,
    /// The rig has a zero base or non-finite values.
    ZeroBase,
    /// A value given to the window is NaN or infinite, or a weight is not positive.
    NotFinite,
    /// The window already holds `window` epochs: slide first.
    WindowFull,
    /// Point or observation capacity reached (the item was dropped and counted).
    CapacityFull,
    /// Epoch id or point index not in the window.
    Unknown,
    /// Fewer than two epochs to slide, or nothing to adjust.
    TooFewEpochs,
    /// Not enough observations: the redundancy is not positive.
    NoRedundancy,
    /// The reduced normal matrix is singular: the epoch (slot) whose
    /// parameters are undetermined (points on a line, too few points, no datum).
    Singular {
        epoch: usize,
    },
}

impl From<OutOfMemory> for AdjustError {
    fn from(e: OutOfMemory) -> Self {
        AdjustError::OutOfMemory(e)
    }
}

impl core::fmt::Display for AdjustError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            AdjustError::OutOfMemory(e) => write!(f, "{e}"),
            AdjustError::InvalidConfig => f.write_str("invalid adjustment configuration"),
            AdjustError::ZeroBase => f.write_str("rig base is zero or not finite"),
            AdjustError::NotFinite => f.write_str("value is not finite or weight not positive"),
            AdjustError::WindowFull => f.write_str("window is full: slide first"),
            AdjustError::CapacityFull => f.write_str("point or observation capacity reached"),
            AdjustError::Unknown => f.write_str("unknown epoch or point"),
            AdjustError::TooFewEpochs => f.write_str("too few epochs"),
            AdjustError::NoRedundancy => f.write_str("no redundancy: too few observations"),
            AdjustError::Singular { epoch } => {
                write!(
                    f,
                    "normal matrix singular: epoch slot {epoch} is undetermined"
                )
            }
        }
    }
}

/// One image measurement of a tie point, 36 bytes.
///
/// Stored in `f32`: photo-coordinates of a few millimetres keep about 5e-7 mm
/// (1e-4 pixel at 5 um pixels), far below any measurement noise; weights and the robust
/// factor need fewer digits still. Everything computed from them (residuals, normal
/// equations) is `f64`: read them through [`Observation::xy_mm`] and
/// [`Observation::weights`].
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct Observation {
    /// Corrected photo-coordinates `(xc, yc)`, mm.
    pub xy: [f32; 2],
    /// Weights `[p_x, p_y]`, `1/mm^2` for the sigma scheme.
    pub weight: [f32; 2],
    /// Robust factor set by the solver (1 = full weight, 0 = excluded).
    pub factor: f32,
    /// Point index (from [`Window::add_point`]).
    pub point: u32,
    /// Epoch id (from [`Window::add_epoch`]).
    pub epoch: u32,
    /// Caller's tag (track id, line number), carried untouched.
    pub tag: u32,
    /// 0 = left, 1 = right.
    pub camera: u8,
    /// [`Observation::FLAGGED`], [`Observation::BEHIND`].
    pub flags: u8,
    pub _pad: [u8; 2],
}

impl Observation {
    /// Flagged as a blunder (excluded, or down-weighted by the seed scheme).
    pub const FLAGGED: u8 = 1;
    /// Behind its camera at the last evaluation.
    pub const BEHIND: u8 = 2;

    pub fn new(epoch: u32, camera: Camera, point: u32, xy: [f64; 2], weight: [f64; 2]) -> Self {
        Observation {
            xy: [xy[0] as f32, xy[1] as f32],
            weight: [weight[0] as f32, weight[1] as f32],
            factor: 1.0,
            point,
            epoch,
            tag: 0,
            camera: camera as u8,
            flags: 0,
            _pad: [0; 2],
        }
    }

    /// Photo-coordinates, mm, widened for the computation.
    #[inline]
    pub fn xy_mm(&self) -> [f64; 2] {
        [self.xy[0] as f64, self.xy[1] as f64]
    }

    /// Weights `[p_x, p_y]` (without the robust factor), widened for the computation.
    #[inline]
    pub fn weights(&self) -> [f64; 2] {
        [self.weight[0] as f64, self.weight[1] as f64]
    }

    pub fn is_flagged(&self) -> bool {
        self.flags & Self::FLAGGED != 0
    }
}

#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct EpochSlot {
    params: [f64; 6],
    prior: [f64; 6],
    /// Information of the prior in the window's unknowns (turn and centre).
    prior_info: [f64; 36],
    /// Covariance of the last solution in the window's unknowns (turn and centre).
    cov: [f64; 36],
    gnss: [f64; 3],
    gnss_sigma: f64,
    /// The GNSS antenna in the left camera's frame ([`Window::set_gnss_antenna`]).
    gnss_lever: [f64; 3],
    odometer: f64,
    odometer_sigma: f64,
    time: f64,
    /// Cached rotation and derivatives of `params`.
    rot: Rotations,
    /// Cached right camera rotation ([`EpochRotations::right`]).
    right: [f64; 9],
    id: u32,
    flags: u32,
}

const EP_PRIOR: u32 = 1;
const EP_GNSS: u32 = 2;
const EP_ODOMETER: u32 = 4;
const EP_COV: u32 = 8;

#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct PointSlot {
    xyz: [f64; 3],
    std: [f64; 3],
    prior: [f64; 3],
    prior_sigma: f64,
    nobs: u32,
    flags: u32,
    /// Tag of the point's first observation ([`NO_TAG`] before it): a slot freed and
    /// re-used for another point gets another tag, so a caller holding the index of
    /// the freed point can tell (see [`Window::point_tag`]).
    tag: u32,
    _pad: u32,
}

/// No observation has tagged the point yet.
const NO_TAG: u32 = u32::MAX;

const PT_USED: u32 = 1;
const PT_PRIOR: u32 = 2;
const PT_EXCLUDED: u32 = 4;

/// A pose that left the window, kept fixed while its observations still count.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct FixedSlot {
    /// Local parameters (the window's origin), as the epoch left the window.
    params: [f64; 6],
    /// Cached rotation and derivatives of `params`.
    rot: Rotations,
    /// Cached right camera rotation ([`EpochRotations::right`]).
    right: [f64; 9],
    /// Time of the epoch, seconds (the motion smoothness across the window's edge).
    time: f64,
    /// Covariance with respect to the datum ([`Window::epoch_absolute_covariance`]), in
    /// the window's unknowns (turn and centre).
    cov: [f64; 36],
}

/// Where an observation's epoch is: a window slot (adjusted) or a fixed slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum At {
    Window(usize),
    Fixed(usize),
}

/// Per camera block scratch of one point: `W` (6x3), the block's own `U`
/// (6x6), its cross blocks with the rig and with the interior orientation
/// (6x6 each, `J_this^T P J_other`) and its gradient.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct BlockScratch {
    w: [f64; 18],
    u: [f64; 36],
    u_rig: [f64; 36],
    u_interior: [f64; 36],
    g: [f64; 6],
}

/// What one adjustment found.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Report {
    /// Levenberg-Marquardt iterations, all rounds.
    pub iterations: usize,
    /// The last least-squares solution met the tolerance.
    pub converged: bool,
    /// A-posteriori standard deviation of unit weight.
    pub sigma0: f64,
    /// Global chi-square test (two-sided, 95 %).
    pub chi2: ChiSquareTest,
    /// Redundancy `n + n_x - u`.
    pub redundancy: usize,
    /// Image observations used (each has two coordinates).
    pub observations: usize,
    /// Constraint equations.
    pub constraints: usize,
    /// Unknowns.
    pub unknowns: usize,
    /// Observations flagged as blunders.
    pub flagged: usize,
    /// Points left out (fewer than two rays, or at infinity).
    pub excluded_points: usize,
    /// Observations behind their camera at the solution.
    pub behind: usize,
    /// Robust rounds run.
    pub robust_rounds: usize,
    /// Final `vTPv`.
    pub cost: f64,
}

/// Result of building one point's blocks.
struct PointBlocks {
    v: Matrix3<f64>,
    b: Vector3<f64>,
    used: usize,
    touched: usize,
}

/// The sliding window: epochs, points, observations and the solver's buffers.
pub struct Window<'a> {
    cfg: AdjustConfig,
    rig: RelativeOrientation,
    rig_prior: RelativeOrientation,
    /// Information of the rig prior: the calibration sigmas at first, the
    /// marginal information of the estimate after a slide.
    rig_prior_info: [f64; 36],
    nominal_base: f64,
    focal: [f64; 2],
    rig_std: [f64; 6],
    /// Cofactor matrix `Q` of the rig at the last solution (valid when `rig_cov_valid`).
    rig_cov: [f64; 36],
    rig_cov_valid: bool,
    /// sigma0^2 of the solution the epochs' covariances come from (they are `s02 Q`).
    cov_s02: f64,
    rig_rot: Rotations,
    /// Interior orientation corrections (self-calibration), their prior and
    /// information, carried across slides like the rig's.
    interior: InteriorCorrections,
    interior_prior: InteriorCorrections,
    interior_prior_info: [f64; 36],
    interior_std: [f64; 6],
    interior_cov: [f64; 36],
    origin: [f64; 3],
    epochs: &'a mut [EpochSlot],
    n_epochs: usize,
    /// Epochs that left the window, oldest first: ids `first_id - n_fixed ..`.
    fixed: &'a mut [FixedSlot],
    n_fixed: usize,
    first_id: u32,
    points: &'a mut [PointSlot],
    n_point_slots: usize,
    obs: &'a mut [Observation],
    n_obs: usize,
    point_start: &'a mut [u32],
    obs_order: &'a mut [u32],
    /// Point slots that `point_start` / `obs_order` describe, while no observation
    /// came or went since [`Window::build_index`].
    indexed: Option<usize>,
    reduced: &'a mut [f64],
    rhs: &'a mut [f64],
    saved_cam: &'a mut [f64],
    saved_points: &'a mut [f64],
    scratch: &'a mut [BlockScratch],
    touched: &'a mut [u32],
    residuals: &'a mut [f64],
    dropped_points: usize,
    dropped_observations: usize,
    singular_epoch: Option<usize>,
    /// The rig and interior blocks take part in the adjustment (see [`Window::drop_calibration`]).
    calibration_active: bool,
    /// They are held at their values ([`AdjustConfig::hold_calibration`]).
    calibration_held: bool,
    /// The held calibration's blocks are being built for its score test: the only
    /// build that needs them (the others wipe them in [`Self::hold_blocks`]).
    testing_calibration: bool,
}

impl AdjustConfig {
    /// Parameter blocks besides the epochs: the rig's (always reserved) and the
    /// interior orientation's (with self-calibration).
    fn extra_blocks(&self) -> usize {
        1 + self.self_calibration.is_some() as usize
    }

    fn cam_capacity(&self) -> usize {
        6 * (self.window + self.extra_blocks())
    }

    /// Adds the adjustment's buffers ("adjust." prefix) to `budget`. Sizes
    /// saturate instead of overflowing, so an absurd configuration gives an
    /// absurd budget (and `Window::new` refuses it), never a panic.
    pub fn budget(&self, budget: &mut MemoryBudget) {
        let nc = 6usize.saturating_mul(self.window.saturating_add(self.extra_blocks()));
        let (p, o, w) = (self.max_points, self.max_observations, self.window);
        let p1 = p.saturating_add(1);
        let w1 = w.saturating_add(self.extra_blocks());
        budget.add(
            "adjust.epochs",
            ComponentKind::Storage,
            bytes::<EpochSlot>(w),
        );
        budget.add(
            "adjust.fixed_epochs",
            ComponentKind::Storage,
            bytes::<FixedSlot>(self.fixed_epochs),
        );
        budget.add(
            "adjust.points",
            ComponentKind::Storage,
            bytes::<PointSlot>(p),
        );
        budget.add(
            "adjust.observations",
            ComponentKind::Storage,
            bytes::<Observation>(o),
        );
        budget.add(
            "adjust.point_index",
            ComponentKind::Working,
            bytes::<u32>(p1).saturating_add(bytes::<u32>(o)),
        );
        budget.add(
            "adjust.reduced_normal",
            ComponentKind::Working,
            bytes::<f64>(nc.saturating_mul(nc)),
        );
        budget.add(
            "adjust.vectors",
            ComponentKind::Working,
            bytes::<f64>(nc)
                .saturating_mul(2)
                .saturating_add(bytes::<f64>(p.saturating_mul(3))),
        );
        budget.add(
            "adjust.point_scratch",
            ComponentKind::Working,
            bytes::<BlockScratch>(w1).saturating_add(bytes::<u32>(w1)),
        );
        budget.add("adjust.residuals", ComponentKind::Working, bytes::<f64>(o));
    }

    fn validate(&self) -> Result<(), AdjustError> {
        let s = &self.sigmas;
        let ok = self.window >= 1
            && self.window <= 4096
            && self.max_points >= 1
            && self.max_points < u32::MAX as usize
            && self.max_observations >= 1
            && self.max_observations < u32::MAX as usize
            && self.max_iterations >= 1
            && s.datum_angle_rad > 0.0
            && s.datum_position_m > 0.0
            && (!self.estimate_rig || (s.rig_angle_rad > 0.0 && s.rig_base_m > 0.0))
            && self.self_calibration.is_none_or(|c| c.valid())
            && self.tolerance.is_finite()
            && self.fixed_epochs <= 4096
            && self.carried_prior_inflation >= 1.0
            && self.carried_prior_inflation.is_finite();
        if ok {
            Ok(())
        } else {
            Err(AdjustError::InvalidConfig)
        }
    }
}

/// [`slice_bytes`] that saturates (at a sixteenth of the address space, so a
/// few saturated components still sum without overflow).
fn bytes<T>(n: usize) -> usize {
    let cap = usize::MAX / 16;
    if n > cap / core::mem::size_of::<T>().max(1) {
        cap
    } else {
        slice_bytes::<T>(n)
    }
}

fn sym3_inverse(v: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let tr = v[(0, 0)] + v[(1, 1)] + v[(2, 2)];
    let det = v.determinant();
    // det / trace^3 bounds lambda_min / lambda_max from below: a point seen
    // along (nearly) one direction, i.e. at infinity, fails it.
    if !(tr > 0.0) || !(det > 1e-10 * tr * tr * tr) {
        return None;
    }
    v.try_inverse()
}

/// Diagonal information of the rig's calibration prior (`sigmas.rig_*`).
fn calibration_info(s: &ConstraintSigmas) -> [f64; 36] {
    let mut info = [0.0; 36];
    for i in 0..6 {
        let sig = if i < 3 { s.rig_angle_rad } else { s.rig_base_m };
        info[i * 6 + i] = 1.0 / (sig * sig);
    }
    info
}

/// One slide's update of a shared block's prior (see `Window::carry_rig_prior`): the
/// information grows by `1/n` of what the window's observations added to it (from the
/// cofactor `cov` of the last solution), centred at the estimate `est`. Left
/// unchanged when a matrix is not positive definite.
fn carry_prior(
    est: &[f64; 6],
    cov: &[f64; 36],
    n: f64,
    prior: &mut [f64; 6],
    info: &mut [f64; 36],
) {
    let mut marginal = [0.0; 36];
    if !invert6(cov, &mut marginal) {
        return;
    }
    let mut next = *info;
    for (i, m) in next.iter_mut().zip(marginal) {
        *i += (m - *i) / n;
    }
    let mut check = [0.0; 36];
    if invert6(&next, &mut check) {
        *prior = *est;
        *info = next;
    }
}

/// The GNSS residual `C + M^T l - G` of an epoch (local coordinates) and its
/// Jacobian with respect to the pose (`[coordinate][turn x, y, z, X, Y, Z]`: the
/// lever arm's turn, then the identity). Uses the epoch's cached rotation.
fn gnss_residual(ep: &EpochSlot) -> ([f64; 3], [[f64; 6]; 3]) {
    let l = ep.gnss_lever;
    // Rotations hold M and its derivatives column-major: (M^T l)_a = sum_i M[i][a] l_i.
    let mt_l = |m: &[f64]| -> [f64; 3] {
        core::array::from_fn(|a| (0..3).map(|i| m[a * 3 + i] * l[i]).sum())
    };
    let rot = &ep.rot.0;
    let ml = mt_l(&rot[..9]);
    let r = core::array::from_fn(|a| ep.params[3 + a] + ml[a] - ep.gnss[a]);
    let mut j = [[0.0; 6]; 3];
    for k in 0..3 {
        let d = mt_l(&rot[9 * (k + 1)..9 * (k + 2)]);
        for a in 0..3 {
            j[a][k] = d[a];
        }
        j[k][3 + k] = 1.0;
    }
    (r, j)
}

/// Inverts a symmetric positive definite 6x6 (row-major); false when not SPD.
fn invert6(a: &[f64; 36], out: &mut [f64; 36]) -> bool {
    let mut m = *a;
    if cholesky::factor(&mut m, 6, cholesky::PIVOT_REL_TOL).is_err() {
        return false;
    }
    cholesky::invert_in_place(&mut m, 6);
    *out = m;
    out.iter().all(|v| v.is_finite())
}
