//! The sliding-window bundle adjuster.
//!
//! Unknowns: the left camera's `(omega, phi, kappa, X, Y, Z)` of every epoch in
//! the window, optionally the relative orientation of the rig
//! `(omega, phi, kappa, bx, by, bz)` with a prior, and the tie points. The
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

use super::cholesky;
use super::constraints::{base_length, distance, prior_residual, smoothness};
use super::geometry::{
    corrected_focal, project_epoch, project_xy, project_xy_with, right_rotation,
    shift_principal_point, with_interior, Camera, EpochRotations, InteriorCorrections, Partials,
    RigParams, Rotations,
};
use super::quality::ChiSquareTest;
use super::weighting::{cauchy_factor, median_by_rank, CHI2_2_MEDIAN, SEED_REWEIGHT};
use crate::budget::{slice_bytes, Arena, ComponentKind, MemoryBudget, OutOfMemory};
use crate::camera::{Pose, Rig};
use bytemuck::{Pod, Zeroable};
use nalgebra::{Matrix3, Vector3};

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
    /// [`Window::correct_calibration`], after [`Window::calibration_test`] found the
    /// observations call for it.
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
    prior_info: [f64; 36],
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
    /// Covariance of `params` with respect to the datum ([`Window::epoch_absolute_covariance`]).
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
    rig: RigParams,
    rig_prior: RigParams,
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

impl<'a> Window<'a> {
    /// An empty window for `rig`, carving its buffers from `arena`.
    pub fn new(cfg: AdjustConfig, rig: &Rig, arena: &mut Arena<'a>) -> Result<Self, AdjustError> {
        cfg.validate()?;
        if rig.validate().is_err() || !(rig.base_length() > 1e-9) {
            return Err(AdjustError::ZeroBase);
        }
        let nc = cfg.cam_capacity();
        let (p, o, w) = (cfg.max_points, cfg.max_observations, cfg.window);
        let epochs = arena.alloc_slice::<EpochSlot>(w)?;
        let fixed = arena.alloc_slice::<FixedSlot>(cfg.fixed_epochs)?;
        let points = arena.alloc_slice::<PointSlot>(p)?;
        let obs = arena.alloc_slice::<Observation>(o)?;
        let point_start = arena.alloc_slice::<u32>(p + 1)?;
        let obs_order = arena.alloc_slice::<u32>(o)?;
        let reduced = arena.alloc_slice::<f64>(nc * nc)?;
        let rhs = arena.alloc_slice::<f64>(nc)?;
        let saved_cam = arena.alloc_slice::<f64>(nc)?;
        let saved_points = arena.alloc_slice::<f64>(3 * p)?;
        let scratch = arena.alloc_slice::<BlockScratch>(w + cfg.extra_blocks())?;
        let touched = arena.alloc_slice::<u32>(w + cfg.extra_blocks())?;
        let residuals = arena.alloc_slice::<f64>(o)?;
        let r = RigParams::from_rig(rig);
        Ok(Window {
            cfg,
            rig: r,
            rig_prior: r,
            rig_prior_info: calibration_info(&cfg.sigmas),
            nominal_base: rig.base_length(),
            focal: [rig.left.focal_mm, rig.right.focal_mm],
            rig_std: [0.0; 6],
            rig_cov: [0.0; 36],
            rig_cov_valid: false,
            cov_s02: 1.0,
            rig_rot: Rotations::new(r.angles[0], r.angles[1], r.angles[2]),
            interior: [0.0; 6],
            interior_prior: [0.0; 6],
            interior_prior_info: cfg.self_calibration.map_or([0.0; 36], |c| c.information()),
            interior_std: [0.0; 6],
            interior_cov: [0.0; 36],
            origin: [0.0; 3],
            epochs,
            n_epochs: 0,
            fixed,
            n_fixed: 0,
            first_id: 0,
            points,
            n_point_slots: 0,
            obs,
            n_obs: 0,
            point_start,
            obs_order,
            indexed: None,
            reduced,
            rhs,
            saved_cam,
            saved_points,
            scratch,
            touched,
            residuals,
            dropped_points: 0,
            dropped_observations: 0,
            singular_epoch: None,
            calibration_active: true,
            calibration_held: cfg.hold_calibration,
            testing_calibration: false,
        })
    }

    pub fn config(&self) -> &AdjustConfig {
        &self.cfg
    }

    /// Sets the nominal base length used by the base-length constraint (defaults to `|b|`).
    pub fn set_base_length(&mut self, metres: f64) {
        self.nominal_base = metres;
    }

    // ----- building the window -----

    /// Adds an epoch with the approximate pose of its left camera (object
    /// coordinates) and its time (seconds). The first epoch of an empty window
    /// carries the datum. Returns the epoch id.
    pub fn add_epoch(&mut self, left: &Pose, time_s: f64) -> Result<u32, AdjustError> {
        let params = left.to_params();
        if !params.iter().all(|v| v.is_finite()) || !time_s.is_finite() {
            return Err(AdjustError::NotFinite);
        }
        if self.n_epochs >= self.cfg.window {
            return Err(AdjustError::WindowFull);
        }
        if self.n_epochs == 0 {
            self.origin = left.centre;
        }
        let mut local = params;
        for a in 0..3 {
            local[3 + a] -= self.origin[a];
        }
        let id = self.first_id + self.n_epochs as u32;
        let mut slot = EpochSlot::zeroed();
        slot.params = local;
        slot.time = time_s;
        slot.id = id;
        if self.n_epochs == 0 {
            let s = &self.cfg.sigmas;
            let mut info = [0.0; 36];
            for i in 0..6 {
                let sig = if i < 3 {
                    s.datum_angle_rad
                } else {
                    s.datum_position_m
                };
                info[i * 6 + i] = 1.0 / (sig * sig);
            }
            slot.prior = local;
            slot.prior_info = info;
            slot.flags |= EP_PRIOR;
        }
        self.epochs[self.n_epochs] = slot;
        self.n_epochs += 1;
        Ok(id)
    }

    fn slot_of(&self, epoch: u32) -> Option<usize> {
        let s = epoch.checked_sub(self.first_id)? as usize;
        (s < self.n_epochs).then_some(s)
    }

    /// The window slot or the fixed slot of an epoch id.
    fn locate(&self, epoch: u32) -> Option<At> {
        if let Some(s) = self.slot_of(epoch) {
            return Some(At::Window(s));
        }
        let back = self.first_id.checked_sub(epoch)? as usize;
        (back >= 1 && back <= self.n_fixed).then(|| At::Fixed(self.n_fixed - back))
    }

    /// Cached rotations and local centre of the pose at `at`.
    fn pose_parts(&self, at: At) -> (EpochRotations<'_>, [f64; 3]) {
        let (rot, right, p) = match at {
            At::Window(s) => {
                let e = &self.epochs[s];
                (&e.rot, &e.right, &e.params)
            }
            At::Fixed(s) => {
                let e = &self.fixed[s];
                (&e.rot, &e.right, &e.params)
            }
        };
        let rot = EpochRotations {
            left: rot,
            rel: &self.rig_rot,
            right,
        };
        (rot, [p[3], p[4], p[5]])
    }

    /// Local parameters of the pose at `at`.
    fn params_at(&self, at: At) -> [f64; 6] {
        match at {
            At::Window(s) => self.epochs[s].params,
            At::Fixed(s) => self.fixed[s].params,
        }
    }

    /// A prior on an epoch's pose (object coordinates) with standard
    /// deviations (angles rad, positions m); replaces any earlier prior.
    pub fn set_pose_prior(
        &mut self,
        epoch: u32,
        pose: &Pose,
        sigmas: [f64; 6],
    ) -> Result<(), AdjustError> {
        let slot = self.slot_of(epoch).ok_or(AdjustError::Unknown)?;
        let mut p = pose.to_params();
        if !p.iter().chain(sigmas.iter()).all(|v| v.is_finite()) || sigmas.iter().any(|s| *s <= 0.0)
        {
            return Err(AdjustError::NotFinite);
        }
        for a in 0..3 {
            p[3 + a] -= self.origin[a];
        }
        let e = &mut self.epochs[slot];
        e.prior = p;
        e.prior_info = [0.0; 36];
        for i in 0..6 {
            e.prior_info[i * 6 + i] = 1.0 / (sigmas[i] * sigmas[i]);
        }
        e.flags |= EP_PRIOR;
        Ok(())
    }

    /// A GNSS position of the epoch's left perspective centre with its sigma (m).
    pub fn set_gnss(
        &mut self,
        epoch: u32,
        position: [f64; 3],
        sigma_m: f64,
    ) -> Result<(), AdjustError> {
        self.set_gnss_antenna(epoch, position, sigma_m, [0.0; 3])
    }

    /// A GNSS position of an antenna at `lever_arm` from the epoch's left perspective
    /// centre (left camera frame: x right, y up, z backwards, m) with its sigma (m): the
    /// constraint `C + M^T lever_arm = G`.
    pub fn set_gnss_antenna(
        &mut self,
        epoch: u32,
        position: [f64; 3],
        sigma_m: f64,
        lever_arm: [f64; 3],
    ) -> Result<(), AdjustError> {
        let slot = self.slot_of(epoch).ok_or(AdjustError::Unknown)?;
        let finite = |v: &[f64; 3]| v.iter().all(|x| x.is_finite());
        if !finite(&position) || !finite(&lever_arm) || !(sigma_m > 0.0) || !sigma_m.is_finite() {
            return Err(AdjustError::NotFinite);
        }
        let e = &mut self.epochs[slot];
        e.gnss = [
            position[0] - self.origin[0],
            position[1] - self.origin[1],
            position[2] - self.origin[2],
        ];
        e.gnss_sigma = sigma_m;
        e.gnss_lever = lever_arm;
        e.flags |= EP_GNSS;
        // A fix, not the past held exact, anchors the window from now on
        // ([`Self::slide`]): the first fix after an outage pulls at once.
        self.release_fixed();
        Ok(())
    }

    /// An odometer distance (m) from the previous epoch to this one with its sigma.
    pub fn set_odometer(
        &mut self,
        epoch: u32,
        distance_m: f64,
        sigma_m: f64,
    ) -> Result<(), AdjustError> {
        let slot = self.slot_of(epoch).ok_or(AdjustError::Unknown)?;
        if !distance_m.is_finite() || !(sigma_m > 0.0) || !sigma_m.is_finite() {
            return Err(AdjustError::NotFinite);
        }
        let e = &mut self.epochs[slot];
        e.odometer = distance_m;
        e.odometer_sigma = sigma_m;
        e.flags |= EP_ODOMETER;
        Ok(())
    }

    /// Adds a tie point at its approximate object coordinates; returns its index.
    pub fn add_point(&mut self, xyz: [f64; 3]) -> Result<u32, AdjustError> {
        if !xyz.iter().all(|v| v.is_finite()) {
            return Err(AdjustError::NotFinite);
        }
        let slot = match self.points[..self.n_point_slots]
            .iter()
            .position(|p| p.flags & PT_USED == 0)
        {
            Some(s) => s,
            None if self.n_point_slots < self.points.len() => {
                self.n_point_slots += 1;
                self.n_point_slots - 1
            }
            None => {
                self.dropped_points += 1;
                return Err(AdjustError::CapacityFull);
            }
        };
        let mut p = PointSlot::zeroed();
        p.xyz = [
            xyz[0] - self.origin[0],
            xyz[1] - self.origin[1],
            xyz[2] - self.origin[2],
        ];
        p.flags = PT_USED;
        p.tag = NO_TAG;
        self.points[slot] = p;
        self.indexed = None;
        Ok(slot as u32)
    }

    /// Makes a point a control point: its coordinates are observed with `sigma_m`.
    pub fn set_point_prior(
        &mut self,
        point: u32,
        xyz: [f64; 3],
        sigma_m: f64,
    ) -> Result<(), AdjustError> {
        let p = self.point_slot(point)?;
        if !xyz.iter().all(|v| v.is_finite()) || !(sigma_m > 0.0) || !sigma_m.is_finite() {
            return Err(AdjustError::NotFinite);
        }
        let o = self.origin;
        let s = &mut self.points[p];
        s.prior = [xyz[0] - o[0], xyz[1] - o[1], xyz[2] - o[2]];
        s.prior_sigma = sigma_m;
        s.flags |= PT_PRIOR;
        Ok(())
    }

    /// Tag of a live point's first observation, `None` when the point is not in use
    /// or not observed yet.
    pub fn point_tag(&self, point: u32) -> Option<u32> {
        let p = self.point_slot(point).ok()?;
        let t = self.points[p].tag;
        (t != NO_TAG).then_some(t)
    }

    fn point_slot(&self, point: u32) -> Result<usize, AdjustError> {
        let p = point as usize;
        if p < self.n_point_slots && self.points[p].flags & PT_USED != 0 {
            Ok(p)
        } else {
            Err(AdjustError::Unknown)
        }
    }

    /// Adds an observation; returns its index.
    pub fn add_observation(&mut self, mut o: Observation) -> Result<usize, AdjustError> {
        let valid = o.xy.iter().all(|v| v.is_finite())
            && o.weight.iter().all(|w| w.is_finite() && *w > 0.0)
            && o.camera <= 1;
        if !valid {
            return Err(AdjustError::NotFinite);
        }
        self.slot_of(o.epoch).ok_or(AdjustError::Unknown)?;
        let p = self.point_slot(o.point)?;
        if self.n_obs >= self.obs.len() {
            self.dropped_observations += 1;
            return Err(AdjustError::CapacityFull);
        }
        o.factor = 1.0;
        o.flags = 0;
        self.obs[self.n_obs] = o;
        self.n_obs += 1;
        self.indexed = None;
        self.points[p].nobs += 1;
        if self.points[p].tag == NO_TAG {
            self.points[p].tag = o.tag;
        }
        Ok(self.n_obs - 1)
    }

    // ----- accessors -----

    pub fn n_epochs(&self) -> usize {
        self.n_epochs
    }

    /// Id of the epoch in slot `i` (0 = oldest).
    pub fn epoch_id(&self, i: usize) -> Option<u32> {
        (i < self.n_epochs).then(|| self.epochs[i].id)
    }

    /// Adjusted (or current) pose of the left camera of slot `i`, object coordinates.
    pub fn epoch_pose(&self, i: usize) -> Option<Pose> {
        if i >= self.n_epochs {
            return None;
        }
        let mut p = self.epochs[i].params;
        for a in 0..3 {
            p[3 + a] += self.origin[a];
        }
        Some(Pose::from_params(&p))
    }

    /// Standard deviations of slot `i` (omega, phi, kappa rad; X, Y, Z m) from the last solution.
    pub fn epoch_std(&self, i: usize) -> Option<[f64; 6]> {
        if i >= self.n_epochs || self.epochs[i].flags & EP_COV == 0 {
            return None;
        }
        let c = &self.epochs[i].cov;
        let mut s = [0.0; 6];
        for (k, sk) in s.iter_mut().enumerate() {
            *sk = libm::sqrt(c[k * 6 + k].max(0.0));
        }
        Some(s)
    }

    /// 6x6 covariance of slot `i` with respect to the datum (row-major, sigma0^2
    /// scaled). The window's own covariance ([`Self::epoch_covariance`]) holds the
    /// fixed epochs exact, so it is the precision relative to the poses that left; the
    /// newest fixed epoch's absolute covariance, carried rigidly to the epoch (its
    /// rotation error turns the epoch's offset from it), adds what they were uncertain
    /// by. Each fixed epoch keeps the absolute covariance it left with, so the
    /// uncertainty of a traverse without fixes accumulates step by step, as it should.
    pub fn epoch_absolute_covariance(&self, i: usize) -> Option<[f64; 36]> {
        let cov = self.epoch_covariance(i)?;
        Some(self.plus_anchor(i, cov))
    }

    /// `cov` (of slot `i`, relative to the fixed epochs) plus the newest fixed epoch's
    /// absolute covariance carried rigidly to the slot: `cov + J C_a J^T`.
    fn plus_anchor(&self, i: usize, mut cov: [f64; 36]) -> [f64; 36] {
        let Some(anchor) = self.n_fixed.checked_sub(1).map(|a| &self.fixed[a]) else {
            return cov;
        };
        let j = rigid_transport(&anchor.params, &self.epochs[i].params);
        let mut jc = [0.0; 36];
        for r in 0..6 {
            for c in 0..6 {
                jc[r * 6 + c] = (0..6).map(|k| j[r * 6 + k] * anchor.cov[k * 6 + c]).sum();
            }
        }
        for r in 0..6 {
            for c in 0..6 {
                cov[r * 6 + c] += (0..6).map(|k| jc[r * 6 + k] * j[c * 6 + k]).sum::<f64>();
            }
        }
        cov
    }

    /// The absolute covariance a leaving (oldest) epoch keeps as a fixed epoch: its
    /// window covariance at no less than its a-priori value (sigma0 = 1), plus the
    /// anchor's. The a-posteriori scale comes from residuals that do not see the errors
    /// a traverse accumulates, which are correlated from epoch to epoch (the same points
    /// on the same surfaces), so below 1 it would make the accumulated precision
    /// optimistic. Only the step's own part is scaled: the anchor's was, at its slide
    /// (scaling the sum compounded the scale at every slide).
    fn leaving_covariance(&self) -> Option<[f64; 36]> {
        let k = self.apriori_floor();
        let cov = self.epoch_covariance(0)?.map(|v| v * k);
        Some(self.plus_anchor(0, cov))
    }

    /// The factor that raises the last solution's covariances to no less than their
    /// a-priori value: `1 / sigma0^2` when sigma0 is below 1, else 1.
    fn apriori_floor(&self) -> f64 {
        if self.cov_s02 > 0.0 && self.cov_s02 < 1.0 {
            1.0 / self.cov_s02
        } else {
            1.0
        }
    }

    /// Standard deviations of slot `i` relative to the recent past (the fixed epochs held
    /// exact), at no less than their a-priori value, as a fixed epoch keeps them
    /// ([`Self::leaving_covariance`]): what a difference of neighbouring epochs is
    /// uncertain by.
    pub fn epoch_relative_std(&self, i: usize) -> Option<[f64; 6]> {
        let k = libm::sqrt(self.apriori_floor());
        Some(self.epoch_std(i)?.map(|v| v * k))
    }

    /// Standard deviations of slot `i` with respect to the datum (omega, phi, kappa
    /// rad; X, Y, Z m): [`Self::epoch_absolute_covariance`].
    pub fn epoch_absolute_std(&self, i: usize) -> Option<[f64; 6]> {
        let c = self.epoch_absolute_covariance(i)?;
        Some(core::array::from_fn(|k| libm::sqrt(c[k * 6 + k].max(0.0))))
    }

    /// 6x6 covariance (row-major) of slot `i` from the last solution (sigma0^2 scaled).
    pub fn epoch_covariance(&self, i: usize) -> Option<[f64; 36]> {
        (i < self.n_epochs && self.epochs[i].flags & EP_COV != 0).then(|| self.epochs[i].cov)
    }

    /// Adjusted point in object coordinates; `None` when unknown or excluded.
    pub fn point(&self, point: u32) -> Option<[f64; 3]> {
        let p = self.point_slot(point).ok()?;
        let s = &self.points[p];
        if s.flags & PT_EXCLUDED != 0 {
            return None;
        }
        Some([
            s.xyz[0] + self.origin[0],
            s.xyz[1] + self.origin[1],
            s.xyz[2] + self.origin[2],
        ])
    }

    /// Standard deviations of a point, metres.
    pub fn point_std(&self, point: u32) -> Option<[f64; 3]> {
        let p = self.point_slot(point).ok()?;
        (self.points[p].flags & PT_EXCLUDED == 0).then(|| self.points[p].std)
    }

    /// Whether a point was left out of the last solution.
    pub fn point_excluded(&self, point: u32) -> bool {
        self.point_slot(point)
            .map(|p| self.points[p].flags & PT_EXCLUDED != 0)
            .unwrap_or(true)
    }

    pub fn rig(&self) -> RigParams {
        self.rig
    }

    /// Standard deviations of the rig parameters (zero when fixed).
    pub fn rig_std(&self) -> [f64; 6] {
        self.rig_std
    }

    /// Interior orientation corrections `[x0_L, y0_L, f_L, x0_R, y0_R, f_R]` (mm)
    /// found by the self-calibration (zero without it).
    pub fn interior(&self) -> InteriorCorrections {
        self.interior
    }

    /// Standard deviations of [`Self::interior`] (zero without self-calibration).
    pub fn interior_std(&self) -> [f64; 6] {
        self.interior_std
    }

    pub fn observations(&self) -> &[Observation] {
        &self.obs[..self.n_obs]
    }

    /// Indices (into [`Window::observations`]) of point slot `p`'s observations, from
    /// the index of the last adjustment; `None` when observations came or went since.
    pub fn point_observations(&self, p: u32) -> Option<&[u32]> {
        let p = p as usize;
        if !self.indexed.is_some_and(|np| p < np) {
            return None;
        }
        let (s0, s1) = (
            self.point_start[p] as usize,
            self.point_start[p + 1] as usize,
        );
        self.obs_order.get(s0..s1)
    }

    /// Observations flagged as blunders, with their indices.
    pub fn flagged(&self) -> impl Iterator<Item = (usize, &Observation)> {
        self.observations()
            .iter()
            .enumerate()
            .filter(|(_, o)| o.is_flagged())
    }

    /// Residuals `observed - computed` (mm) of an observation at the current state.
    pub fn residual(&self, index: usize) -> Option<[f64; 2]> {
        let o = self.obs.get(index).filter(|_| index < self.n_obs)?;
        let at = self.locate(o.epoch)?;
        let p = self.params_at(at);
        let ml = crate::camera::rotation(p[0], p[1], p[2]);
        self.residual_with(o, &ml, &p, &self.rig_rotation())
    }

    /// [`Self::residual`] of every observation in order: the rotations computed once
    /// per epoch's run of observations rather than once per observation.
    pub fn residuals(&self) -> impl Iterator<Item = Option<[f64; 2]>> + '_ {
        let mr = self.rig_rotation();
        let mut last: Option<(u32, Matrix3<f64>, [f64; 6])> = None;
        self.obs[..self.n_obs].iter().map(move |o| {
            let (ml, p) = match last {
                Some((e, ml, p)) if e == o.epoch => (ml, p),
                _ => {
                    let p = self.params_at(self.locate(o.epoch)?);
                    let ml = crate::camera::rotation(p[0], p[1], p[2]);
                    last = Some((o.epoch, ml, p));
                    (ml, p)
                }
            };
            self.residual_with(o, &ml, &p, &mr)
        })
    }

    /// The rig's relative rotation `M` from its current angles.
    fn rig_rotation(&self) -> Matrix3<f64> {
        let a = self.rig.angles;
        crate::camera::rotation(a[0], a[1], a[2])
    }

    /// Residual of `o` with its epoch's rotation `ml` and parameters `p`, the rig's `mr`.
    fn residual_with(
        &self,
        o: &Observation,
        ml: &Matrix3<f64>,
        p: &[f64; 6],
        mr: &Matrix3<f64>,
    ) -> Option<[f64; 2]> {
        let cam = Camera::from_index(o.camera)?;
        let f = corrected_focal(self.focal, cam, &self.interior);
        let point = &self.points[o.point as usize].xyz;
        let centre = [p[3], p[4], p[5]];
        let xy = project_xy_with(ml, &centre, mr, &self.rig.base, cam, f, point)?;
        let xy = shift_principal_point(xy, cam, &self.interior);
        Some([o.xy[0] as f64 - xy[0], o.xy[1] as f64 - xy[1]])
    }

    /// Items refused because a capacity was full: (points, observations).
    pub fn dropped(&self) -> (usize, usize) {
        (self.dropped_points, self.dropped_observations)
    }

    /// Slot of the epoch found undetermined by the last failed solution.
    pub fn singular_epoch(&self) -> Option<usize> {
        self.singular_epoch
    }

    /// The window's local origin (object coordinates).
    pub fn origin(&self) -> [f64; 3] {
        self.origin
    }

    // ----- sliding -----

    /// Drops the oldest epoch (fixed at its current pose). With
    /// [`AdjustConfig::fixed_epochs`], its observations stay while their points are
    /// observed in the window, so a point keeps what every epoch of its track told
    /// about it (the poses that left are fixed: their observations constrain the
    /// points only), and the oldest fixed epoch's observations leave in its place;
    /// without, its observations leave with it. Points left without an observation
    /// in the window are freed, and the new oldest epoch gets its current pose and
    /// covariance as a prior. The origin moves to the new oldest epoch. Returns the
    /// dropped epoch's final pose.
    pub fn slide(&mut self) -> Result<Pose, AdjustError> {
        if self.n_epochs < 2 {
            return Err(AdjustError::TooFewEpochs);
        }
        let dropped = self.epoch_pose(0).ok_or(AdjustError::TooFewEpochs)?;
        let gone = self.epochs[0].id;
        // A GNSS fix, not the poses of the past held exact, anchors an aided window:
        // an epoch with a fix leaves without becoming a fixed epoch and releases those
        // there are, or the window could not follow the fixes (it would carry the
        // past's drift forward, the fixes pulling at it only by their weight).
        let aided = self.epochs[0].flags & EP_GNSS != 0;
        let had_fixed = self.n_fixed > 0;
        let cap = if aided { 0 } else { self.cfg.fixed_epochs };
        let expired = if cap == 0 {
            Some(gone)
        } else {
            let e = &self.epochs[0];
            let rot = Rotations::new(e.params[0], e.params[1], e.params[2]);
            let slot = FixedSlot {
                params: e.params,
                rot,
                right: right_rotation(&rot, &self.rig_rot),
                time: e.time,
                // Without a covariance of its own (its solve failed) it passes the
                // anchor's on: the accumulated uncertainty is not lost.
                cov: self
                    .leaving_covariance()
                    .unwrap_or_else(|| self.plus_anchor(0, [0.0; 36])),
            };
            let expired = (self.n_fixed == cap).then(|| gone.wrapping_sub(cap as u32));
            if self.n_fixed == cap {
                self.fixed.copy_within(1..cap, 0);
                self.n_fixed -= 1;
            }
            self.fixed[self.n_fixed] = slot;
            self.n_fixed += 1;
            expired
        };
        let release = aided && had_fixed;
        // What the past tells about the new first epoch, taken while the fixed epochs
        // that are about to go still anchor it.
        let released_info = if release {
            self.carried_information(1, true)
        } else {
            None
        };
        // Observations in the window per point, after this slide (point_start is
        // scratch until the next build_index).
        let np = self.n_point_slots;
        self.point_start[..np].fill(0);
        for o in &self.obs[..self.n_obs] {
            if o.epoch != gone && self.slot_of(o.epoch).is_some() {
                self.point_start[o.point as usize] += 1;
            }
        }
        self.retain_observations(|w, o| {
            let released = release && w.slot_of(o.epoch).is_none();
            Some(o.epoch) != expired && !released && w.point_start[o.point as usize] > 0
        });
        if release {
            self.n_fixed = 0;
        }
        // Prior of the new first epoch from its marginal covariance.
        let aided_info = if aided && released_info.is_none() {
            self.carried_information(1, false)
        } else {
            None
        };
        let next = &mut self.epochs[1];
        let mut info = [0.0; 36];
        let have = match released_info.or(aided_info) {
            // The window's only link to the epochs that left, at full strength.
            Some(carried) => {
                info = carried;
                true
            }
            None => {
                let have = next.flags & EP_COV != 0 && invert6(&next.cov, &mut info);
                if have && self.cfg.fixed_epochs > 0 {
                    // The marginal holds the fixed epochs' observations, which stay:
                    // weakened.
                    let k = 1.0 / self.cfg.carried_prior_inflation;
                    info.iter_mut().for_each(|v| *v *= k);
                }
                have
            }
        };
        if !have {
            let s = self.cfg.sigmas;
            for i in 0..6 {
                let sig = if i < 3 {
                    s.datum_angle_rad
                } else {
                    s.datum_position_m
                };
                info[i * 6 + i] = 1.0 / (sig * sig);
            }
        }
        next.prior = next.params;
        next.prior_info = info;
        next.flags |= EP_PRIOR;
        // Its odometer leg led to the dropped epoch.
        next.flags &= !EP_ODOMETER;
        self.carry_rig_prior();
        self.epochs.copy_within(1..self.n_epochs, 0);
        self.n_epochs -= 1;
        self.first_id += 1;
        let shift = [
            self.epochs[0].params[3],
            self.epochs[0].params[4],
            self.epochs[0].params[5],
        ];
        self.recentre(shift);
        Ok(dropped)
    }

    /// The rig is shared by every epoch: a slide keeps its value, and what the
    /// dropped epoch told about it stays in its prior. The marginal information
    /// `inv(Q_rig)` is the prior's plus the window's observations'; the dropped
    /// epoch's share is taken as `1/n` of the latter, so the prior grows by one
    /// epoch's worth per slide (carrying the whole marginal would count the
    /// remaining epochs' observations again at every slide and make the rig
    /// overconfident). Uses `Q` without sigma0, like the calibration prior.
    /// The interior orientation corrections are carried the same way.
    fn carry_rig_prior(&mut self) {
        if !self.rig_cov_valid {
            return;
        }
        let n = self.n_epochs.max(1) as f64;
        if self.cfg.estimate_rig {
            let mut prior = self.rig_prior.to_array();
            carry_prior(
                &self.rig.to_array(),
                &self.rig_cov,
                n,
                &mut prior,
                &mut self.rig_prior_info,
            );
            self.rig_prior = RigParams::from_array(&prior);
        }
        if self.cfg.self_calibration.is_some() {
            carry_prior(
                &self.interior,
                &self.interior_cov,
                n,
                &mut self.interior_prior,
                &mut self.interior_prior_info,
            );
        }
        self.rig_cov_valid = false;
    }

    /// Keeps the observations `keep` accepts, in order; a point left without one (and
    /// without a prior) is freed.
    fn retain_observations(&mut self, keep: impl Fn(&Self, &Observation) -> bool) {
        let mut k = 0;
        for i in 0..self.n_obs {
            let o = self.obs[i];
            if keep(self, &o) {
                self.obs[k] = o;
                k += 1;
            } else {
                let p = &mut self.points[o.point as usize];
                p.nobs = p.nobs.saturating_sub(1);
                if p.nobs == 0 && p.flags & PT_PRIOR == 0 {
                    p.flags = 0;
                }
            }
        }
        self.n_obs = k;
        self.indexed = None;
    }

    /// Lets go of the fixed epochs: their observations leave, and the window's link to
    /// the past is its first epoch's prior alone.
    fn release_fixed(&mut self) {
        if self.n_fixed == 0 {
            return;
        }
        // The first epoch's prior, weak while the fixed epochs anchored the window,
        // becomes what they told about it: its covariance with respect to the datum.
        if let Some(info) = self.carried_information(0, true) {
            let e = &mut self.epochs[0];
            e.prior = e.params;
            e.prior_info = info;
            e.flags |= EP_PRIOR;
        }
        self.retain_observations(|w, o| w.slot_of(o.epoch).is_some());
        self.n_fixed = 0;
    }

    /// The information of a prior carried on slot `i` when the window is anchored by
    /// fixes: the slot's covariance in the a-priori units of the fixes' weights (the
    /// solution's is `sigma0^2 Q`; the prior is `Q^-1`), with the newest fixed epoch's
    /// absolute covariance added when `with_anchor` (the fixed epochs are about to go),
    /// less the slot's own fix, which stays in the window (`J^T W J`; kept only if the
    /// rest is still positive definite). `None` without a covariance.
    fn carried_information(&self, i: usize, with_anchor: bool) -> Option<[f64; 36]> {
        let e = &self.epochs[i];
        if e.flags & EP_COV == 0 || !(self.cov_s02 > 0.0) {
            return None;
        }
        let mut cov = e.cov.map(|v| v / self.cov_s02);
        if with_anchor {
            cov = self.plus_anchor(i, cov);
        }
        let mut info = [0.0; 36];
        if !invert6(&cov, &mut info) {
            return None;
        }
        if e.flags & EP_GNSS != 0 {
            let w = 1.0 / (e.gnss_sigma * e.gnss_sigma);
            let (_, j) = gnss_residual(e);
            let mut less = info;
            for r in 0..6 {
                for c in 0..6 {
                    let jtj: f64 = (0..3).map(|a| j[a][r] * j[a][c]).sum();
                    less[r * 6 + c] -= w * jtj;
                }
            }
            let mut check = [0.0; 36];
            if invert6(&less, &mut check) {
                info = less;
            }
        }
        Some(info)
    }

    /// Moves the local origin by `shift` (local coordinates).
    fn recentre(&mut self, shift: [f64; 3]) {
        for a in 0..3 {
            self.origin[a] += shift[a];
        }
        for e in self.epochs[..self.n_epochs].iter_mut() {
            for a in 0..3 {
                e.params[3 + a] -= shift[a];
                e.prior[3 + a] -= shift[a];
                e.gnss[a] -= shift[a];
            }
        }
        for f in self.fixed[..self.n_fixed].iter_mut() {
            for a in 0..3 {
                f.params[3 + a] -= shift[a];
            }
        }
        for p in self.points[..self.n_point_slots].iter_mut() {
            for a in 0..3 {
                p.xyz[a] -= shift[a];
                p.prior[a] -= shift[a];
            }
        }
    }

    // ----- the solver -----

    fn rig_block(&self) -> Option<usize> {
        (self.cfg.estimate_rig && self.calibration_active).then_some(self.n_epochs)
    }

    /// Block of the interior orientation corrections: the last one.
    fn interior_block(&self) -> Option<usize> {
        self.cfg
            .self_calibration
            .filter(|_| self.calibration_active)
            .map(|_| self.n_epochs + self.rig_block().is_some() as usize)
    }

    fn n_cam(&self) -> usize {
        6 * (self.n_epochs
            + self.rig_block().is_some() as usize
            + self.interior_block().is_some() as usize)
    }

    /// The rig and interior blocks a build accumulates: none for a held calibration
    /// except in its score test, since [`Self::hold_blocks`] wipes them.
    fn built_blocks(&self) -> (Option<usize>, Option<usize>) {
        if self.calibration_held && !self.testing_calibration {
            (None, None)
        } else {
            (self.rig_block(), self.interior_block())
        }
    }

    /// With the calibration held, takes the rig and interior blocks out of the reduced
    /// system just built (unit diagonal, no coupling, zero right-hand side): the poses
    /// are solved as with a fixed calibration and the held blocks' step is zero.
    fn hold_blocks(&mut self) {
        if !self.calibration_held {
            return;
        }
        let nc = self.n_cam();
        let first = 6 * self.n_epochs;
        for r in first..nc {
            for c in 0..=r {
                self.reduced[r * nc + c] = 0.0;
            }
            self.reduced[r * nc + r] = 1.0;
            self.rhs[r] = 0.0;
        }
    }

    /// Scratch index of the rig's block (the epochs use their slot).
    fn rig_scratch(&self) -> usize {
        self.cfg.window
    }

    /// Scratch index of the interior orientation's block.
    fn interior_scratch(&self) -> usize {
        self.cfg.window + 1
    }

    /// Block of the reduced system for scratch index `sidx`.
    fn block_of(&self, sidx: usize) -> usize {
        if sidx < self.cfg.window {
            sidx
        } else if sidx == self.rig_scratch() {
            self.rig_block().unwrap_or(0)
        } else {
            self.interior_block().unwrap_or(0)
        }
    }

    /// Projection through the cached rotations of epoch `slot` and the rig, with the
    /// `partials` the caller uses. Inlined into its callers: returned from a call, the
    /// projection and its partials (350 bytes) were copied once per observation.
    #[inline(always)]
    fn project(
        &self,
        at: At,
        cam: Camera,
        xyz: &[f64; 3],
        partials: Partials,
    ) -> Result<super::geometry::RigProjection, crate::camera::CameraError> {
        let (rot, c) = self.pose_parts(at);
        let f = corrected_focal(self.focal, cam, &self.interior);
        let pr = project_epoch(&rot, &c, &self.rig.base, cam, f, xyz, partials)?;
        Ok(with_interior(pr, cam, f, &self.interior))
    }

    /// Recomputes the cached rotations after the parameters changed.
    fn refresh_rotations(&mut self) {
        let a = self.rig.angles;
        self.rig_rot = Rotations::new(a[0], a[1], a[2]);
        for e in self.epochs[..self.n_epochs].iter_mut() {
            e.rot = Rotations::new(e.params[0], e.params[1], e.params[2]);
            e.right = right_rotation(&e.rot, &self.rig_rot);
        }
        for e in self.fixed[..self.n_fixed].iter_mut() {
            e.right = right_rotation(&e.rot, &self.rig_rot);
        }
    }

    /// Groups the observations by point (counting sort).
    fn build_index(&mut self) {
        let np = self.n_point_slots;
        self.point_start[..np + 1].fill(0);
        for o in &self.obs[..self.n_obs] {
            self.point_start[o.point as usize + 1] += 1;
        }
        for p in 0..np {
            self.point_start[p + 1] += self.point_start[p];
        }
        // Fill using point_start as moving cursors, then restore.
        for i in 0..self.n_obs {
            let p = self.obs[i].point as usize;
            let at = self.point_start[p] as usize;
            self.obs_order[at] = i as u32;
            self.point_start[p] += 1;
        }
        for p in (1..=np).rev() {
            self.point_start[p] = self.point_start[p - 1];
        }
        self.point_start[0] = 0;
        self.indexed = Some(np);
    }

    /// Builds point `p`'s blocks from its observations with weight factors
    /// (`rig`/`scratch` filled for the touched camera blocks). Returns `None`
    /// when the point has no usable observation.
    fn point_blocks(&mut self, p: usize, cams: CamBlocks) -> (PointBlocks, f64, usize) {
        self.point_blocks_with(p, cams, false)
    }

    /// [`Self::point_blocks`]; `cams` says which camera blocks to accumulate; with
    /// `all` every observation counts with factor 1.
    fn point_blocks_with(
        &mut self,
        p: usize,
        cams: CamBlocks,
        all: bool,
    ) -> (PointBlocks, f64, usize) {
        let (want_cam, full) = (cams != CamBlocks::None, cams == CamBlocks::Full);
        let mut v = Matrix3::<f64>::zeros();
        let mut b = Vector3::<f64>::zeros();
        let mut cost = 0.0;
        let mut behind = 0;
        let mut used = 0;
        let mut touched = 0usize;
        let xyz = self.points[p].xyz;
        let (rig_block, interior_block) = self.built_blocks();
        let (s0, s1) = (
            self.point_start[p] as usize,
            self.point_start[p + 1] as usize,
        );
        for k in s0..s1 {
            let oi = self.obs_order[k] as usize;
            let mut o = self.obs[oi];
            if all {
                o.factor = 1.0;
            }
            if !(o.factor > 0.0) {
                continue;
            }
            let Some(at) = self.locate(o.epoch) else {
                continue;
            };
            let cam = if o.camera == 0 {
                Camera::Left
            } else {
                Camera::Right
            };
            // Camera blocks need the pose's partials (a window epoch) and the rig's
            // (a right observation with the rig in the system); the point's always.
            let on_rig = cam == Camera::Right && rig_block.is_some();
            let partials = match (want_cam, at, on_rig) {
                (false, _, _) => Partials::Point,
                (true, _, true) => Partials::PoseAndRig,
                (true, At::Window(_), false) => Partials::Pose,
                (true, At::Fixed(_), false) => Partials::Point,
            };
            let pr = match self.project(at, cam, &xyz, partials) {
                Ok(pr) => pr,
                Err(_) => {
                    self.obs[oi].flags |= Observation::BEHIND;
                    behind += 1;
                    continue;
                }
            };
            self.obs[oi].flags &= !Observation::BEHIND;
            used += 1;
            let r = [o.xy[0] as f64 - pr.xy[0], o.xy[1] as f64 - pr.xy[1]];
            let f = o.factor as f64;
            let wt = [o.weight[0] as f64 * f, o.weight[1] as f64 * f];
            for c in 0..2 {
                cost += wt[c] * r[c] * r[c];
                let jp = &pr.d_point[c];
                for i in 0..3 {
                    b[i] += wt[c] * jp[i] * r[c];
                    for j in 0..3 {
                        v[(i, j)] += wt[c] * jp[i] * jp[j];
                    }
                }
            }
            if !want_cam {
                continue;
            }
            // Camera blocks touched by this observation (scratch index, Jacobian):
            // its epoch (a fixed epoch's pose is not adjusted), the rig (right
            // camera), the interior orientation; the calibration is shared by all.
            let slot = match at {
                At::Window(slot) => Some(slot),
                At::Fixed(_) => None,
            };
            if slot.is_none() && !on_rig && interior_block.is_none() {
                continue;
            }
            let blocks = [
                slot.map(|slot| (slot, &pr.d_pose)),
                on_rig.then_some((self.rig_scratch(), &pr.d_rig)),
                interior_block.map(|_| (self.interior_scratch(), &pr.d_interior)),
            ];
            for (which, blk) in blocks.iter().enumerate() {
                let Some((sidx, jc)) = *blk else { continue };
                if !self.touched[..touched].contains(&(sidx as u32)) {
                    self.touched[touched] = sidx as u32;
                    touched += 1;
                    // Only the parts this pass accumulates (the scratch is 1 KiB a block).
                    let sc = &mut self.scratch[sidx];
                    sc.w = [0.0; 18];
                    if full {
                        sc.g = [0.0; 6];
                        sc.u = [0.0; 36];
                        if rig_block.is_some() {
                            sc.u_rig = [0.0; 36];
                        }
                        if interior_block.is_some() {
                            sc.u_interior = [0.0; 36];
                        }
                    }
                }
                let sc = &mut self.scratch[sidx];
                for c in 0..2 {
                    for i in 0..6 {
                        let wi = wt[c] * jc[c][i];
                        for j in 0..3 {
                            sc.w[i * 3 + j] += wi * pr.d_point[c][j];
                        }
                        if !full {
                            continue;
                        }
                        sc.g[i] += wi * r[c];
                        for j in 0..6 {
                            sc.u[i * 6 + j] += wi * jc[c][j];
                        }
                        // Cross blocks with the later blocks: epoch x rig, epoch x
                        // interior, rig x interior (J_this^T W J_other).
                        if which == 0 && on_rig {
                            for j in 0..6 {
                                sc.u_rig[i * 6 + j] += wi * pr.d_rig[c][j];
                            }
                        }
                        if which < 2 && interior_block.is_some() {
                            for j in 0..6 {
                                sc.u_interior[i * 6 + j] += wi * pr.d_interior[c][j];
                            }
                        }
                    }
                }
            }
        }
        let pt = &self.points[p];
        if pt.flags & PT_PRIOR != 0 {
            let wp = 1.0 / (pt.prior_sigma * pt.prior_sigma);
            for i in 0..3 {
                let r = pt.prior[i] - pt.xyz[i];
                v[(i, i)] += wp;
                b[i] += wp * r;
                cost += wp * r * r;
            }
        }
        (
            PointBlocks {
                v,
                b,
                used,
                touched,
            },
            cost,
            behind,
        )
    }

    /// Builds and solves the damped system and applies the step; on a
    /// singular system returns the slot of the undetermined epoch.
    fn step(&mut self, lambda: f64) -> Result<(), usize> {
        let nc = self.n_cam();
        let rig_block = self.rig_block();
        self.build(lambda);
        self.hold_blocks();
        for i in 0..nc {
            self.reduced[i * nc + i] *= 1.0 + lambda;
        }
        cholesky::factor(&mut self.reduced[..nc * nc], nc, cholesky::PIVOT_REL_TOL)
            .map_err(|e| e.row / 6)?;
        cholesky::solve(&self.reduced[..nc * nc], nc, &mut self.rhs[..nc]);
        self.back_substitute(lambda);
        for e in 0..self.n_epochs {
            for i in 0..6 {
                self.epochs[e].params[i] += self.rhs[6 * e + i];
            }
        }
        if let Some(rb) = rig_block {
            let mut r = self.rig.to_array();
            for (i, ri) in r.iter_mut().enumerate() {
                *ri += self.rhs[6 * rb + i];
            }
            self.rig = RigParams::from_array(&r);
        }
        if let Some(ib) = self.interior_block() {
            for i in 0..6 {
                self.interior[i] += self.rhs[6 * ib + i];
            }
        }
        Ok(())
    }

    /// The reduced camera system `S dc = rhs` (lower triangle, undamped
    /// camera diagonal, points damped by `lambda`) into `reduced` and `rhs`.
    fn build(&mut self, lambda: f64) {
        self.refresh_rotations();
        let nc = self.n_cam();
        let (rig_block, interior_block) = self.built_blocks();
        self.reduced[..nc * nc].fill(0.0);
        self.rhs[..nc].fill(0.0);
        for p in 0..self.n_point_slots {
            if self.points[p].flags & PT_USED == 0 {
                continue;
            }
            let (pb, _, _) = self.point_blocks(p, CamBlocks::Full);
            let Some(vinv) = self.usable_point(p, &pb, lambda) else {
                continue;
            };
            for ti in 0..pb.touched {
                let a = self.touched[ti] as usize;
                let ba = self.block_of(a);
                let later = [
                    rig_block.filter(|_| a < self.cfg.window),
                    interior_block.filter(|_| a != self.interior_scratch()),
                ];
                let sa = &self.scratch[a];
                // U, gradient, and the cross blocks with the rig and the interior.
                for i in 0..6 {
                    self.rhs[6 * ba + i] += sa.g[i];
                    for j in 0..6 {
                        self.reduced[(6 * ba + i) * nc + 6 * ba + j] += sa.u[i * 6 + j];
                    }
                }
                // Row (later block) param i, column (this block) param j: the
                // transpose of J_this^T W J_other. Both later blocks follow the epochs.
                for (later, cross) in later.into_iter().zip([&sa.u_rig, &sa.u_interior]) {
                    let Some(lb) = later else { continue };
                    for i in 0..6 {
                        for j in 0..6 {
                            self.reduced[(6 * lb + i) * nc + 6 * ba + j] += cross[j * 6 + i];
                        }
                    }
                }
                // W_a V^-1 (6x3), then -W_a V^-1 W_b^T for blocks b <= a, and -W_a V^-1 b.
                let wa = nalgebra::Matrix6x3::from_row_slice(&sa.w);
                let wav = wa * vinv;
                let g = wav * pb.b;
                for i in 0..6 {
                    self.rhs[6 * ba + i] -= g[i];
                }
                for tj in 0..pb.touched {
                    let bidx = self.touched[tj] as usize;
                    let bb = self.block_of(bidx);
                    if bb > ba {
                        continue;
                    }
                    let wb = nalgebra::Matrix6x3::from_row_slice(&self.scratch[bidx].w);
                    let m = wav * wb.transpose();
                    for i in 0..6 {
                        for j in 0..6 {
                            self.reduced[(6 * ba + i) * nc + 6 * bb + j] -= m[(i, j)];
                        }
                    }
                }
            }
        }
        self.add_constraints(true);
    }

    /// Point steps `dp = V^-1 (b_p - W^T dc)` with the camera step in `rhs`, applied.
    fn back_substitute(&mut self, lambda: f64) {
        for p in 0..self.n_point_slots {
            if self.points[p].flags & (PT_USED | PT_EXCLUDED) != PT_USED {
                continue;
            }
            // The point's step needs only its own blocks and the cross blocks W.
            let (pb, _, _) = self.point_blocks(p, CamBlocks::Cross);
            let Some(vinv) = self.usable_point(p, &pb, lambda) else {
                continue;
            };
            let mut rhs = pb.b;
            for ti in 0..pb.touched {
                let a = self.touched[ti] as usize;
                let ba = self.block_of(a);
                let wa = nalgebra::Matrix6x3::from_row_slice(&self.scratch[a].w);
                let dc = nalgebra::Vector6::from_column_slice(&self.rhs[6 * ba..6 * ba + 6]);
                rhs -= wa.transpose() * dc;
            }
            let dp = vinv * rhs;
            for i in 0..3 {
                self.points[p].xyz[i] += dp[i];
            }
        }
    }

    /// Decides which points take part (two rays or more, not at infinity)
    /// before an iteration sequence, so costs compare like with like. Returns the
    /// cost of that set, as [`Self::cost`] would: the pass has projected every
    /// observation already.
    fn classify_points(&mut self) -> f64 {
        self.refresh_rotations();
        let mut cost = 0.0;
        for p in 0..self.n_point_slots {
            if self.points[p].flags & PT_USED == 0 {
                continue;
            }
            self.points[p].flags &= !PT_EXCLUDED;
            let (pb, point_cost, _) = self.point_blocks(p, CamBlocks::None);
            let _ = self.usable_point(p, &pb, 0.0);
            if self.points[p].flags & PT_EXCLUDED == 0 {
                cost += point_cost;
            }
        }
        cost + self.add_constraints(false).0
    }

    /// Damped inverse of a point's `V`, or `None` (point excluded) when it has
    /// fewer than two rays or is at infinity.
    fn usable_point(&mut self, p: usize, pb: &PointBlocks, lambda: f64) -> Option<Matrix3<f64>> {
        let has_prior = self.points[p].flags & PT_PRIOR != 0;
        let ok_count = pb.used >= 2 || (has_prior && pb.used >= 1);
        let inv = if ok_count { sym3_inverse(&pb.v) } else { None };
        match inv {
            Some(_) => {
                self.points[p].flags &= !PT_EXCLUDED;
                let mut v = pb.v;
                for i in 0..3 {
                    v[(i, i)] *= 1.0 + lambda;
                }
                v.try_inverse()
            }
            None => {
                self.points[p].flags |= PT_EXCLUDED;
                None
            }
        }
    }

    /// A prior with full information `info` on the six parameters of camera block
    /// `block` whose residual (prior - estimate) is `r`: added to the reduced system
    /// when `normal`; returns its `vTPv`.
    fn block_prior(&mut self, normal: bool, block: usize, r: &[f64; 6], info: &[f64; 36]) -> f64 {
        let nc = self.n_cam();
        let mut cost = 0.0;
        for i in 0..6 {
            let mut ir = 0.0;
            for j in 0..6 {
                ir += info[i * 6 + j] * r[j];
                if normal {
                    self.reduced[(6 * block + i) * nc + 6 * block + j] += info[i * 6 + j];
                }
            }
            cost += r[i] * ir;
            if normal {
                self.rhs[6 * block + i] -= ir;
            }
        }
        cost
    }

    /// Adds the camera constraints to the reduced system (when `normal`) and
    /// returns their `vTPv` and equation count.
    fn add_constraints(&mut self, normal: bool) -> (f64, usize) {
        let mut cost = 0.0;
        let mut count = 0;
        let s = self.cfg.sigmas;
        // Pose priors (datum, carried prior) with full information.
        for e in 0..self.n_epochs {
            let ep = self.epochs[e];
            if ep.flags & EP_PRIOR == 0 {
                continue;
            }
            let r = prior_residual(&ep.params, &ep.prior);
            count += 6;
            cost += self.block_prior(normal, e, &r, &ep.prior_info);
        }
        // A held calibration is no unknown and its priors no equations: the global
        // test and its degrees of freedom are those of the fixed calibration.
        let counted = !self.calibration_held as usize;
        if let Some(rb) = self.rig_block() {
            let r = prior_residual(&self.rig.to_array(), &self.rig_prior.to_array());
            let info = self.rig_prior_info;
            cost += self.block_prior(normal, rb, &r, &info);
            count += 6 * counted;
            if s.base_length_m > 0.0 {
                let (e, g) = base_length(&self.rig.base, self.nominal_base);
                let w = 1.0 / (s.base_length_m * s.base_length_m);
                cost += self.row(
                    normal,
                    &[(6 * rb + 3, g[0]), (6 * rb + 4, g[1]), (6 * rb + 5, g[2])],
                    e,
                    w,
                );
                count += counted;
            }
        }
        if let Some(ib) = self.interior_block() {
            let r = prior_residual(&self.interior, &self.interior_prior);
            let info = self.interior_prior_info;
            cost += self.block_prior(normal, ib, &r, &info);
            count += 6 * counted;
        }
        for e in 0..self.n_epochs {
            let ep = self.epochs[e];
            let centres =
                |k: usize| -> [f64; 3] { [0, 1, 2].map(|a| self.epochs[k].params[3 + a]) };
            let (c1, c2) = (centres(e.saturating_sub(1)), centres(e));
            if ep.flags & EP_GNSS != 0 {
                let w = 1.0 / (ep.gnss_sigma * ep.gnss_sigma);
                let (r, j) = gnss_residual(&ep);
                for a in 0..3 {
                    // The centre's own column and the three angles (the other centre
                    // columns are zero).
                    let mut row = [(6 * e + 3 + a, j[a][3 + a]); 4];
                    for k in 0..3 {
                        row[k + 1] = (6 * e + k, j[a][k]);
                    }
                    cost += self.row(normal, &row, r[a], w);
                }
                count += 3;
            }
            if ep.flags & EP_ODOMETER != 0 && e > 0 {
                let (r, g) = distance(&c1, &c2, ep.odometer);
                let w = 1.0 / (ep.odometer_sigma * ep.odometer_sigma);
                let j = [
                    (6 * (e - 1) + 3, -g[0]),
                    (6 * (e - 1) + 4, -g[1]),
                    (6 * (e - 1) + 5, -g[2]),
                    (6 * e + 3, g[0]),
                    (6 * e + 4, g[1]),
                    (6 * e + 5, g[2]),
                ];
                cost += self.row(normal, &j, r, w);
                count += 1;
            }
            if s.velocity_change_mps > 0.0 {
                let (c, n) = self.add_smoothness(normal, e, s.velocity_change_mps);
                cost += c;
                count += n;
            }
        }
        (cost, count)
    }

    /// The motion smoothness ending at window slot `e`: its velocity against the
    /// velocity before it. The epochs before the window's first slot are the fixed
    /// slots, constants without a column: without them the chain broke at the
    /// window's trailing edge, and the first slot's step, tied by its marginal prior
    /// alone, jumped where the images determine the translation poorly (a straight
    /// past open ground, few and far tie points: 0.3 m errors on 2 m steps).
    fn add_smoothness(&mut self, normal: bool, e: usize, sigma_mps: f64) -> (f64, usize) {
        let i = self.n_fixed + e;
        if i < 2 {
            return (0.0, 0);
        }
        let nodes = [
            self.motion_node(i - 2),
            self.motion_node(i - 1),
            self.motion_node(i),
        ];
        let (dt0, dt1) = (nodes[1].1 - nodes[0].1, nodes[2].1 - nodes[1].1);
        if !(dt0 > 0.0 && dt1 > 0.0) {
            return (0.0, 0);
        }
        let (r, jac) = smoothness([&nodes[0].0, &nodes[1].0, &nodes[2].0], dt0, dt1);
        let w = 1.0 / (sigma_mps * sigma_mps);
        let mut cost = 0.0;
        for (ra, ja) in r.iter().zip(&jac) {
            // Slots ascend with the nodes, as `row` wants its indices.
            let mut j = [(0, 0.0); 18];
            let mut n = 0;
            for (k, node) in nodes.iter().enumerate() {
                if let Some(slot) = node.2 {
                    for q in 0..6 {
                        j[n] = (6 * slot + q, ja[6 * k + q]);
                        n += 1;
                    }
                }
            }
            cost += self.row(normal, &j[..n], *ra, w);
        }
        (cost, 3)
    }

    /// Parameters, time and window slot (`None`: fixed) of the `i`-th epoch counted
    /// from the oldest fixed slot.
    fn motion_node(&self, i: usize) -> ([f64; 6], f64, Option<usize>) {
        if i < self.n_fixed {
            let f = &self.fixed[i];
            (f.params, f.time, None)
        } else {
            let e = i - self.n_fixed;
            (self.epochs[e].params, self.epochs[e].time, Some(e))
        }
    }

    /// One scalar constraint `e` with sparse gradient `j` (ascending indices) and weight `w`.
    fn row(&mut self, normal: bool, j: &[(usize, f64)], e: f64, w: f64) -> f64 {
        if normal {
            let nc = self.n_cam();
            for &(a, ca) in j {
                self.rhs[a] -= w * ca * e;
                for &(b, cb) in j {
                    if b <= a {
                        self.reduced[a * nc + b] += w * ca * cb;
                    }
                }
            }
        }
        w * e * e
    }

    /// `vTPv` at the current state, constraints included.
    fn cost(&mut self) -> (f64, usize) {
        self.refresh_rotations();
        let mut cost = 0.0;
        let mut behind = 0;
        // Observation by observation, projections without Jacobians.
        for i in 0..self.n_obs {
            let o = self.obs[i];
            let pt = &self.points[o.point as usize];
            if !(o.factor > 0.0) || pt.flags & (PT_USED | PT_EXCLUDED) != PT_USED {
                continue;
            }
            let Some(at) = self.locate(o.epoch) else {
                continue;
            };
            let (rot, c) = self.pose_parts(at);
            let cam = if o.camera == 0 {
                Camera::Left
            } else {
                Camera::Right
            };
            let f = corrected_focal(self.focal, cam, &self.interior);
            match project_xy(rot.left, &c, &self.rig_rot, &self.rig.base, cam, f, &pt.xyz) {
                Some(xy) => {
                    let xy = shift_principal_point(xy, cam, &self.interior);
                    let r = [o.xy[0] as f64 - xy[0], o.xy[1] as f64 - xy[1]];
                    let w = o.weights();
                    cost += o.factor as f64 * (w[0] * r[0] * r[0] + w[1] * r[1] * r[1]);
                    self.obs[i].flags &= !Observation::BEHIND;
                }
                None => {
                    self.obs[i].flags |= Observation::BEHIND;
                    behind += 1;
                }
            }
        }
        for pt in &self.points[..self.n_point_slots] {
            if pt.flags & (PT_USED | PT_EXCLUDED | PT_PRIOR) == PT_USED | PT_PRIOR {
                let wp = 1.0 / (pt.prior_sigma * pt.prior_sigma);
                for a in 0..3 {
                    let r = pt.prior[a] - pt.xyz[a];
                    cost += wp * r * r;
                }
            }
        }
        (cost + self.add_constraints(false).0, behind)
    }

    fn save(&mut self) {
        let nc = self.n_cam();
        for e in 0..self.n_epochs {
            self.saved_cam[6 * e..6 * e + 6].copy_from_slice(&self.epochs[e].params);
        }
        if let Some(rb) = self.rig_block() {
            self.saved_cam[6 * rb..6 * rb + 6].copy_from_slice(&self.rig.to_array());
        }
        if let Some(ib) = self.interior_block() {
            self.saved_cam[6 * ib..6 * ib + 6].copy_from_slice(&self.interior);
        }
        let _ = nc;
        for p in 0..self.n_point_slots {
            self.saved_points[3 * p..3 * p + 3].copy_from_slice(&self.points[p].xyz);
        }
    }

    fn restore(&mut self) {
        for e in 0..self.n_epochs {
            self.epochs[e]
                .params
                .copy_from_slice(&self.saved_cam[6 * e..6 * e + 6]);
        }
        if let Some(rb) = self.rig_block() {
            let mut r = [0.0; 6];
            r.copy_from_slice(&self.saved_cam[6 * rb..6 * rb + 6]);
            self.rig = RigParams::from_array(&r);
        }
        if let Some(ib) = self.interior_block() {
            self.interior
                .copy_from_slice(&self.saved_cam[6 * ib..6 * ib + 6]);
        }
        for p in 0..self.n_point_slots {
            self.points[p]
                .xyz
                .copy_from_slice(&self.saved_points[3 * p..3 * p + 3]);
        }
    }

    /// Levenberg-Marquardt to convergence with the current weight factors.
    /// Returns (iterations, converged).
    fn least_squares(&mut self, max_iter: usize) -> Result<(usize, bool), AdjustError> {
        let mut cost = self.classify_points();
        let mut lambda = 1e-6;
        let mut iterations = 0;
        let mut converged = false;
        while iterations < max_iter {
            iterations += 1;
            self.save();
            match self.step(lambda) {
                Ok(()) => {}
                Err(slot) => {
                    self.restore();
                    lambda *= 100.0;
                    if lambda > 1e6 {
                        self.singular_epoch = Some(slot.min(self.n_epochs.saturating_sub(1)));
                        return Err(AdjustError::Singular { epoch: slot });
                    }
                    continue;
                }
            }
            let small_step = self.step_is_small();
            let (new_cost, _) = self.cost();
            if new_cost.is_finite() && new_cost <= cost {
                let decrease = cost - new_cost;
                cost = new_cost;
                lambda = (lambda * 0.1).max(1e-12);
                if small_step || decrease <= self.cfg.tolerance * cost.max(1e-300) {
                    converged = true;
                    break;
                }
            } else {
                self.restore();
                if new_cost.is_finite() && (new_cost - cost) <= 1e-13 * cost.max(1e-300) {
                    // No representable improvement left: at the minimum.
                    converged = true;
                    break;
                }
                lambda *= 10.0;
                if lambda > 1e10 {
                    converged = true;
                    break;
                }
            }
        }
        Ok((iterations, converged))
    }

    /// Whether the last step (camera part in `rhs`) is below `step_tolerance`.
    fn step_is_small(&self) -> bool {
        let [ta, tp] = self.cfg.step_tolerance;
        if !(ta > 0.0 && tp > 0.0) {
            return false;
        }
        self.rhs[..6 * self.n_epochs]
            .chunks_exact(6)
            .all(|d| d[..3].iter().all(|a| a.abs() <= ta) && d[3..].iter().all(|p| p.abs() <= tp))
    }

    /// Adjusts the window: least squares with the robust treatment of the
    /// configuration, then the quality figures and standard deviations.
    pub fn solve(&mut self) -> Result<Report, AdjustError> {
        if self.n_epochs == 0 {
            return Err(AdjustError::TooFewEpochs);
        }
        self.singular_epoch = None;
        self.build_index();
        let keep = self.cfg.keep_exclusions && matches!(self.cfg.robust, Robust::Snooping { .. });
        if !keep {
            for o in self.obs[..self.n_obs].iter_mut() {
                o.factor = 1.0;
                o.flags = 0;
            }
        }
        for p in self.points[..self.n_point_slots].iter_mut() {
            p.flags &= !PT_EXCLUDED;
        }
        let mut report = Report::default();
        let max_it = self.cfg.max_iterations;
        match self.cfg.robust {
            Robust::None => {
                let (it, conv) = self.least_squares(max_it)?;
                report.iterations += it;
                report.converged = conv;
            }
            Robust::SeedReweight { threshold_mm } => {
                let (it, _) = self.least_squares(max_it)?;
                report.iterations += it;
                for i in 0..self.n_obs {
                    if let Some(r) = self.residual(i) {
                        if r[0].abs() > threshold_mm {
                            let o = &mut self.obs[i];
                            o.weight = [SEED_REWEIGHT as f32; 2];
                            o.flags |= Observation::FLAGGED;
                        }
                    }
                }
                let (it, conv) = self.least_squares(max_it)?;
                report.iterations += it;
                report.converged = conv;
                report.robust_rounds = 1;
            }
            Robust::Snooping { critical } => {
                let (it, conv) = self.least_squares(max_it)?;
                report.iterations += it;
                report.converged = conv;
                if self.detection_passes()? {
                    // Accepted as is.
                } else if keep {
                    self.snoop_rounds(critical, 1, &mut report)?;
                } else {
                    self.identify(critical, &mut report)?;
                }
            }
        }
        self.quality(&mut report)?;
        Ok(report)
    }

    /// Identification: Cauchy re-weighting, then data snooping until stable.
    fn identify(&mut self, critical: f64, report: &mut Report) -> Result<(), AdjustError> {
        let max_it = self.cfg.max_iterations;
        {
            {
                // Cauchy re-weighting on a median scale: blunders lose their pull.
                for _ in 0..self.cfg.max_robust_rounds {
                    let (it, _) = self.least_squares(max_it.min(10))?;
                    report.iterations += it;
                    let change = self.cauchy_factors();
                    report.robust_rounds += 1;
                    if change < 0.01 {
                        break;
                    }
                }
                // Data snooping with full weights until the excluded set is stable.
                for o in self.obs[..self.n_obs].iter_mut() {
                    o.factor = 1.0;
                }
                self.snoop_rounds(critical, 0, report)?;
            }
        }
        Ok(())
    }

    /// Snooping from the current solution until the excluded set is stable, then
    /// a final solution for that set. `first_round` 1 skips the hysteresis-free start.
    fn snoop_rounds(
        &mut self,
        critical: f64,
        first_round: usize,
        report: &mut Report,
    ) -> Result<(), AdjustError> {
        let max_it = self.cfg.max_iterations;
        self.snoop(critical, first_round);
        let mut stable = false;
        for round in first_round + 1..=first_round + self.cfg.max_robust_rounds {
            let (it, conv) = self.least_squares(max_it)?;
            report.iterations += it;
            report.converged = conv;
            report.robust_rounds += 1;
            if !self.snoop(critical, round) {
                stable = true;
                break;
            }
        }
        if !stable {
            // Out of rounds: the solution must match the final set.
            let (it, conv) = self.least_squares(max_it)?;
            report.iterations += it;
            report.converged = conv;
        }
        Ok(())
    }

    /// Standardised 2-D residual `sqrt(v^T P v)` of every observation into `residuals`.
    fn normalised_residuals(&mut self) {
        for i in 0..self.n_obs {
            let w = self.obs[i].weights();
            self.residuals[i] = match self.residual(i) {
                Some(r) => libm::sqrt(w[0] * r[0] * r[0] + w[1] * r[1] * r[1]),
                None => f64::INFINITY,
            };
        }
    }

    /// Sets Cauchy factors from the residuals; returns the largest factor change.
    fn cauchy_factors(&mut self) -> f64 {
        self.normalised_residuals();
        let n = self.n_obs;
        // Median of t^2 over chi2_2's median: the robust variance factor.
        let res = &*self.residuals;
        let scale2 = (median_by_rank(n, |i| Some(res[i] * res[i])) / CHI2_2_MEDIAN).max(1e-30);
        let scale = libm::sqrt(scale2);
        let mut change: f64 = 0.0;
        for i in 0..n {
            let f = cauchy_factor(self.residuals[i] / scale, 2.385);
            change = change.max((f - self.obs[i].factor as f64).abs());
            self.obs[i].factor = f as f32;
        }
        change
    }

    /// Tests every observation with `T = v^T Q_vv^-1 v`, `Q_vv = P^-1 -+ J_p V^-1 J_p^T`
    /// (point part of the cofactor: the cameras are determined by many points),
    /// on the median scale; excludes those beyond `critical`. Returns whether
    /// the excluded set changed.
    fn snoop(&mut self, critical: f64, round: usize) -> bool {
        self.statistics();
        let scale2 = self.median_scale();
        self.apply_flags(critical, round, scale2)
    }

    /// Median of the accepted observations' `T` (in `residuals`) over chi2_2's median:
    /// 1 when the weights match the noise, and right also with the seed's weights
    /// whose scale is arbitrary. Selected in place (no copy of the residuals).
    fn median_scale(&self) -> f64 {
        let (res, obs) = (&*self.residuals, &*self.obs);
        let used = |i: usize| (obs[i].factor > 0.0 && res[i].is_finite()).then_some(res[i]);
        (median_by_rank(self.n_obs, used) / CHI2_2_MEDIAN).max(1e-30)
    }

    /// Detection (Baarda's DIA order): after plain least squares, the data are
    /// accepted without any exclusion when the global test passes and the
    /// largest `T` stays below the Bonferroni bound `-2 ln(0.05 / n)` (5 % for
    /// the whole set); otherwise the robust identification runs.
    fn detection_passes(&mut self) -> Result<bool, AdjustError> {
        let mut r = Report::default();
        self.global_test(&mut r)?;
        // Only the upper tail is evidence of blunders; a sigma0 below its bound says
        // the a-priori sigma was pessimistic, and identification would be wasted work.
        if r.chi2.statistic > r.chi2.upper {
            return Ok(false);
        }
        self.statistics();
        let scale2 = self.median_scale();
        let n = self.n_obs.max(1) as f64;
        let bound = -2.0 * libm::log(0.05 / n);
        let worst = self.residuals[..self.n_obs]
            .iter()
            .enumerate()
            .filter(|(i, _)| self.obs[*i].factor > 0.0)
            .fold(0.0f64, |m, (_, t)| m.max(*t));
        // On the median scale, as snooping: a pessimistic a-priori sigma must not
        // hide blunders that stand out of the actual noise.
        Ok(worst <= bound * scale2)
    }

    /// `T` of every observation into `residuals` (a-priori scale).
    fn statistics(&mut self) {
        self.refresh_rotations();
        for p in 0..self.n_point_slots {
            if self.points[p].flags & PT_USED == 0 {
                continue;
            }
            let (pb, _, _) = self.point_blocks(p, CamBlocks::None);
            let mut vinv = if pb.used >= 2 {
                sym3_inverse(&pb.v)
            } else {
                None
            };
            // A point left with fewer than two rays is re-tested as if all
            // its observations were in, so a wrongly excluded point can return.
            let all = vinv.is_none();
            if all {
                let (pb, _, _) = self.point_blocks_with(p, CamBlocks::None, true);
                vinv = if pb.used >= 2 {
                    sym3_inverse(&pb.v)
                } else {
                    None
                };
            }
            let (s0, s1) = (
                self.point_start[p] as usize,
                self.point_start[p + 1] as usize,
            );
            for k in s0..s1 {
                let oi = self.obs_order[k] as usize;
                self.residuals[oi] = self.statistic(oi, vinv.as_ref(), all);
            }
        }
    }

    /// Excludes/readmits observations from their `T` on the scale `scale2`;
    /// returns whether the excluded set changed.
    fn apply_flags(&mut self, critical: f64, round: usize, scale2: f64) -> bool {
        let n = self.n_obs;
        let mut changed = false;
        for i in 0..n {
            let t = self.residuals[i] / scale2;
            let was = self.obs[i].factor == 0.0;
            // Hysteresis from the third round: an excluded observation returns
            // only well inside the acceptance region, so the set cannot oscillate.
            let readmit = if round >= 3 { 0.5 * critical } else { critical };
            let out = if was {
                !(t <= readmit)
            } else {
                !(t <= critical)
            };
            if out != was {
                changed = true;
            }
            self.obs[i].factor = if out { 0.0 } else { 1.0 };
            if out {
                self.obs[i].flags |= Observation::FLAGGED;
            } else {
                self.obs[i].flags &= !Observation::FLAGGED;
            }
        }
        changed
    }

    /// `T` of observation `oi` (0 when untestable).
    fn statistic(&self, oi: usize, vinv: Option<&Matrix3<f64>>, all: bool) -> f64 {
        let o = &self.obs[oi];
        let Some(vinv) = vinv else { return 0.0 };
        let Some(at) = self.locate(o.epoch) else {
            return 0.0;
        };
        let cam = if o.camera == 0 {
            Camera::Left
        } else {
            Camera::Right
        };
        let xyz = self.points[o.point as usize].xyz;
        let Ok(pr) = self.project(at, cam, &xyz, Partials::Point) else {
            return f64::INFINITY;
        };
        let r = [o.xy[0] as f64 - pr.xy[0], o.xy[1] as f64 - pr.xy[1]];
        let j = nalgebra::Matrix2x3::new(
            pr.d_point[0][0],
            pr.d_point[0][1],
            pr.d_point[0][2],
            pr.d_point[1][0],
            pr.d_point[1][1],
            pr.d_point[1][2],
        );
        let jq = j * vinv * j.transpose();
        let sign = if o.factor > 0.0 || all { -1.0 } else { 1.0 };
        let ow = o.weights();
        let q = nalgebra::Matrix2::new(1.0 / ow[0], 0.0, 0.0, 1.0 / ow[1]) + jq * sign;
        // Untestable when the observation carries (almost) no redundancy.
        if !(q[(0, 0)] > 1e-3 / ow[0]) || !(q[(1, 1)] > 1e-3 / ow[1]) {
            return 0.0;
        }
        match q.try_inverse() {
            Some(qi) => {
                let v = nalgebra::Vector2::new(r[0], r[1]);
                (v.transpose() * qi * v)[0].max(0.0)
            }
            None => 0.0,
        }
    }

    /// sigma0, chi-square, redundancy, and standard deviations from the inverse
    /// of the undamped reduced normal matrix (scaled by sigma0^2).
    /// Counts, redundancy, sigma0 and the global chi-square test of the current
    /// solution into `report`; returns the variance factor.
    fn global_test(&mut self, report: &mut Report) -> Result<f64, AdjustError> {
        let nc = if self.calibration_held {
            6 * self.n_epochs
        } else {
            self.n_cam()
        };
        let (obs_cost, behind) = self.cost();
        let (_, n_constraints) = self.add_constraints(false);
        let mut n_obs = 0;
        let mut n_points = 0;
        let mut n_point_priors = 0;
        let mut excluded = 0;
        for p in 0..self.n_point_slots {
            let pt = self.points[p];
            if pt.flags & PT_USED == 0 {
                continue;
            }
            if pt.flags & PT_EXCLUDED != 0 {
                excluded += 1;
                continue;
            }
            n_points += 1;
            if pt.flags & PT_PRIOR != 0 {
                n_point_priors += 3;
            }
            let (s0, s1) = (
                self.point_start[p] as usize,
                self.point_start[p + 1] as usize,
            );
            for k in s0..s1 {
                let o = &self.obs[self.obs_order[k] as usize];
                if o.factor > 0.0
                    && o.flags & Observation::BEHIND == 0
                    && self.locate(o.epoch).is_some()
                {
                    n_obs += 1;
                }
            }
        }
        let equations = 2 * n_obs + n_constraints + n_point_priors;
        let unknowns = nc + 3 * n_points;
        report.observations = n_obs;
        report.constraints = n_constraints + n_point_priors;
        report.unknowns = unknowns;
        report.behind = behind;
        report.excluded_points = excluded;
        report.cost = obs_cost;
        report.flagged = self.obs[..self.n_obs]
            .iter()
            .filter(|o| o.is_flagged())
            .count();
        if equations <= unknowns {
            return Err(AdjustError::NoRedundancy);
        }
        let dof = equations - unknowns;
        report.redundancy = dof;
        let s02 = obs_cost / dof as f64;
        report.sigma0 = libm::sqrt(s02);
        report.chi2 = ChiSquareTest::new(obs_cost, dof);
        Ok(s02)
    }

    /// [`Self::global_test`], then the precisions: camera, rig and interior covariances
    /// and the points' standard deviations.
    fn quality(&mut self, report: &mut Report) -> Result<(), AdjustError> {
        let s02 = self.global_test(report)?;
        self.cov_s02 = s02;
        let nc = self.n_cam();
        let rig_block = self.rig_block();
        // Undamped reduced matrix, inverted in place: Q_cc.
        self.step_matrix_only()?;
        cholesky::invert_in_place(&mut self.reduced[..nc * nc], nc);
        self.clear_held_cofactors();
        for e in 0..self.n_epochs {
            let mut cov = [0.0; 36];
            for i in 0..6 {
                for j in 0..6 {
                    cov[i * 6 + j] = s02 * self.reduced[(6 * e + i) * nc + 6 * e + j];
                }
            }
            self.epochs[e].cov = cov;
            self.epochs[e].flags |= EP_COV;
        }
        if let Some(rb) = rig_block.filter(|_| !self.calibration_held) {
            for i in 0..6 {
                for j in 0..6 {
                    self.rig_cov[i * 6 + j] = self.reduced[(6 * rb + i) * nc + 6 * rb + j];
                }
                self.rig_std[i] = libm::sqrt((s02 * self.rig_cov[i * 6 + i]).max(0.0));
            }
        }
        if let Some(ib) = self.interior_block().filter(|_| !self.calibration_held) {
            for i in 0..6 {
                for j in 0..6 {
                    self.interior_cov[i * 6 + j] = self.reduced[(6 * ib + i) * nc + 6 * ib + j];
                }
                self.interior_std[i] = libm::sqrt((s02 * self.interior_cov[i * 6 + i]).max(0.0));
            }
        }
        // A held calibration has no estimate to carry across the slide.
        self.rig_cov_valid = !self.calibration_held;
        // Points: Q_pp = V^-1 + V^-1 W^T Q_cc W V^-1.
        for p in 0..self.n_point_slots {
            if self.points[p].flags & (PT_USED | PT_EXCLUDED) != PT_USED {
                continue;
            }
            let (pb, _, _) = self.point_blocks(p, CamBlocks::Cross);
            let Some(vinv) = sym3_inverse(&pb.v) else {
                continue;
            };
            let mut q = vinv;
            for ti in 0..pb.touched {
                let a = self.touched[ti] as usize;
                let ba = self.block_of(a);
                let ga = nalgebra::Matrix6x3::from_row_slice(&self.scratch[a].w) * vinv;
                for tj in 0..pb.touched {
                    let b = self.touched[tj] as usize;
                    let bb = self.block_of(b);
                    let gb = nalgebra::Matrix6x3::from_row_slice(&self.scratch[b].w) * vinv;
                    let qab = nalgebra::Matrix6::from_fn(|i, j| {
                        self.reduced[(6 * ba + i) * nc + 6 * bb + j]
                    });
                    q += ga.transpose() * qab * gb;
                }
            }
            for i in 0..3 {
                self.points[p].std[i] = libm::sqrt((s02 * q[(i, i)]).max(0.0));
            }
        }
        Ok(())
    }

    /// A held calibration is known, not estimated: its rows and columns of the inverted
    /// reduced matrix (the unit placeholders of [`Self::hold_blocks`]) add nothing to
    /// the points' cofactors.
    fn clear_held_cofactors(&mut self) {
        if !self.calibration_held {
            return;
        }
        let nc = self.n_cam();
        for r in 6 * self.n_epochs..nc {
            for c in 0..nc {
                self.reduced[r * nc + c] = 0.0;
                self.reduced[c * nc + r] = 0.0;
            }
        }
    }

    /// The score test of the held calibration at the current solution (call it after
    /// [`Self::solve`]; `sigma0` is that solution's a-posteriori standard deviation).
    ///
    /// Why a score test: it needs no adjustment with the calibration free, so a good
    /// calibration is never disturbed by its own estimation. At the held solution the
    /// poses' and points' gradient is zero, so the full system's step `d = N^-1 g` is
    /// the free adjustment's first step in the calibration and `d_c^T g_c` (the
    /// calibration's part) is `g_red^T N_red^-1 g_red`, the Schur complement's quadratic
    /// form: the statistic. The calibration priors are part of `N` and `g`, so a
    /// correction is weighed against the calibration's stated precision.
    pub fn calibration_test(&mut self, sigma0: f64) -> Result<CalibrationTest, AdjustError> {
        let first = 6 * self.n_epochs;
        let nc = self.n_cam();
        if !self.calibration_held || nc == first {
            return Err(AdjustError::InvalidConfig);
        }
        self.build_index();
        self.testing_calibration = true;
        self.build(0.0);
        self.testing_calibration = false;
        let mut g = [0.0; 12];
        g[..nc - first].copy_from_slice(&self.rhs[first..nc]);
        cholesky::factor(&mut self.reduced[..nc * nc], nc, cholesky::PIVOT_REL_TOL).map_err(
            |e| AdjustError::Singular {
                epoch: (e.row / 6).min(self.n_epochs.saturating_sub(1)),
            },
        )?;
        cholesky::solve(&self.reduced[..nc * nc], nc, &mut self.rhs[..nc]);
        let d = &self.rhs[first..nc];
        let score: f64 = d.iter().zip(&g).map(|(a, b)| a * b).sum();
        let s02 = (sigma0 * sigma0).max(1e-300);
        let mut test = CalibrationTest {
            statistic: score / s02,
            dof: nc - first,
            ..Default::default()
        };
        let mut at = first;
        if self.rig_block().is_some() {
            test.rig.copy_from_slice(&self.rhs[at..at + 6]);
            at += 6;
        }
        if self.interior_block().is_some() {
            test.interior.copy_from_slice(&self.rhs[at..at + 6]);
        }
        Ok(test)
    }

    /// How far the correction of `test` would move the observations of the window's
    /// newest epoch: the RMS displacement (mm, both cameras) of their projections
    /// with the corrected calibration against the held one. A correction the test
    /// finds significant may still be too small to matter: hundreds of points make a
    /// hundredth of a pixel of systematic matching error significant.
    pub fn correction_effect(&mut self, test: &CalibrationTest) -> f64 {
        let Some(last) = self.n_epochs.checked_sub(1) else {
            return 0.0;
        };
        self.refresh_rotations();
        let mut rig = self.rig.to_array();
        for (r, d) in rig.iter_mut().zip(test.rig) {
            *r += d;
        }
        let rig = RigParams::from_array(&rig);
        let rig_rot = Rotations::new(rig.angles[0], rig.angles[1], rig.angles[2]);
        let mut interior = self.interior;
        for (i, d) in interior.iter_mut().zip(test.interior) {
            *i += d;
        }
        let id = self.epochs[last].id;
        let (rot, c) = self.pose_parts(At::Window(last));
        let (mut sum, mut n) = (0.0, 0usize);
        for o in &self.obs[..self.n_obs] {
            let pt = &self.points[o.point as usize];
            if o.epoch != id || !(o.factor > 0.0) || pt.flags & PT_USED == 0 {
                continue;
            }
            let cam = if o.camera == 0 {
                Camera::Left
            } else {
                Camera::Right
            };
            let project = |rig: &RigParams, rig_rot: &Rotations, interior: &InteriorCorrections| {
                let f = corrected_focal(self.focal, cam, interior);
                project_xy(rot.left, &c, rig_rot, &rig.base, cam, f, &pt.xyz)
                    .map(|xy| shift_principal_point(xy, cam, interior))
            };
            let before = project(&self.rig, &self.rig_rot, &self.interior);
            let after = project(&rig, &rig_rot, &interior);
            if let (Some(a), Some(b)) = (before, after) {
                sum += (a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]);
                n += 1;
            }
        }
        if n == 0 {
            0.0
        } else {
            libm::sqrt(sum / n as f64)
        }
    }

    /// Applies the correction of a [`CalibrationTest`] to the held calibration; the
    /// next [`Self::solve`] adjusts the poses and points to it.
    pub fn correct_calibration(&mut self, test: &CalibrationTest) {
        let mut r = self.rig.to_array();
        for (ri, d) in r.iter_mut().zip(test.rig) {
            *ri += d;
        }
        self.rig = RigParams::from_array(&r);
        for (i, d) in self.interior.iter_mut().zip(test.interior) {
            *i += d;
        }
    }

    /// Takes the rig and interior blocks out of the adjustment for good, keeping their
    /// values: the calibration was tested long enough and needs no correction, and
    /// each solve saves their partial derivatives.
    pub fn drop_calibration(&mut self) {
        self.calibration_active = false;
        self.rig_cov_valid = false;
    }

    /// Whether the rig and interior blocks still take part (held or free).
    pub fn calibration_active(&self) -> bool {
        self.calibration_active && (self.cfg.estimate_rig || self.cfg.self_calibration.is_some())
    }

    /// Builds the undamped reduced matrix and factors it (for the covariance).
    fn step_matrix_only(&mut self) -> Result<(), AdjustError> {
        // The matrix of an undamped step, without the step.
        let nc = self.n_cam();
        self.build(0.0);
        self.hold_blocks();
        let res = cholesky::factor(&mut self.reduced[..nc * nc], nc, cholesky::PIVOT_REL_TOL)
            .map_err(|e| e.row / 6);
        res.map_err(|slot| {
            self.singular_epoch = Some(slot.min(self.n_epochs.saturating_sub(1)));
            AdjustError::Singular { epoch: slot }
        })
    }
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
/// Jacobian with respect to the pose (`[coordinate][omega, phi, kappa, X, Y, Z]`: the
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

/// Jacobian (6x6, row-major) of the pose `to` with respect to the pose `from` when both
/// move as one rigid body with `from`: a small rotation `d` (object frame) of `from`
/// turns `to` by the same `d` and moves its centre by `d x (C_to - C_from)`. In the
/// parameters (omega, phi, kappa, X, Y, Z): angles `E_to^-1 E_from`, centre
/// `-[C_to - C_from]x E_from` and the identity, with `E` the angles' rotation vector.
fn rigid_transport(from: &[f64; 6], to: &[f64; 6]) -> [f64; 36] {
    let e_from = angle_rates(from);
    let e_to_inv = angle_rates(to)
        .try_inverse()
        .unwrap_or_else(Matrix3::identity);
    let a = e_to_inv * e_from;
    let d = Vector3::new(to[3] - from[3], to[4] - from[4], to[5] - from[5]);
    let lever = -d.cross_matrix() * e_from;
    let mut j = [0.0; 36];
    for r in 0..3 {
        for c in 0..3 {
            j[r * 6 + c] = a[(r, c)];
            j[(r + 3) * 6 + c] = lever[(r, c)];
        }
        j[(r + 3) * 6 + r + 3] = 1.0;
    }
    j
}

/// `E` of the angles in `p`: column `i` is the object-frame rotation vector of a unit
/// change of angle `i` (`dR R^T = [E da]x`, `R = M^T` camera to object).
fn angle_rates(p: &[f64; 6]) -> Matrix3<f64> {
    let (m, d) = crate::camera::rotation_with_derivatives(p[0], p[1], p[2]);
    let mut e = Matrix3::zeros();
    for (i, di) in d.iter().enumerate() {
        let s = di.transpose() * m;
        e[(0, i)] = s[(2, 1)];
        e[(1, i)] = s[(0, 2)];
        e[(2, i)] = s[(1, 0)];
    }
    e
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

#[cfg(test)]
mod tests {
    //! Internal checks: the assembled normal equations against numerical
    //! gradients of `vTPv` (constraints and rig chain included).
    extern crate std;
    use super::*;
    use crate::camera::Interior;
    use std::vec;

    /// Loose datum and a velocity constraint that every step pulls: the constraint
    /// tests move the poses away from them to see each one's gradient.
    fn sigmas() -> ConstraintSigmas {
        ConstraintSigmas {
            datum_angle_rad: 0.01,
            datum_position_m: 0.01,
            velocity_change_mps: 0.3,
            ..ConstraintSigmas::default()
        }
    }

    /// Without points the reduced system is the full one: `rhs = -1/2 grad vTPv`.
    #[test]
    fn constraint_normal_equations_match_numerical_gradient() {
        let cam = Interior::pinhole_px(1000, 800, 900.0);
        let mut rig = Rig::rectified(cam, 0.5);
        rig.relative_angles = [0.01, -0.02, 0.005];
        rig.base_m = [0.5, 0.01, -0.02];
        let cfg = AdjustConfig {
            window: 4,
            estimate_rig: true,
            self_calibration: Some(InteriorSigmas {
                principal_point_mm: [0.01, 0.02],
                focal_mm: [0.03, 0.04],
            }),
            sigmas: ConstraintSigmas {
                base_length_m: 0.002,
                ..sigmas()
            },
            ..AdjustConfig::default()
        };
        let mut mem = vec![0u8; 1 << 20];
        let mut arena = Arena::new(&mut mem);
        let mut w = Window::new(cfg, &rig, &mut arena).unwrap();
        w.set_base_length(0.49);
        for k in 0..4 {
            let pose = Pose::from_degrees(
                90.0 + k as f64,
                0.5 * k as f64,
                -0.3,
                [0.1 * k as f64, 1.1 * k as f64, 0.02],
            );
            let id = w
                .add_epoch(&pose, 0.5 * k as f64 + 0.01 * (k * k) as f64)
                .unwrap();
            w.set_gnss(id, [0.05, 1.0 * k as f64, 0.0], 0.3).unwrap();
            if k > 0 {
                w.set_odometer(id, 1.0, 0.05).unwrap();
            }
        }
        // Move away from the priors so every residual is non-zero.
        w.epochs[0].params[0] += 0.001;
        w.epochs[0].params[4] += 0.002;
        w.rig = RigParams::from_array(&[0.012, -0.018, 0.004, 0.51, 0.012, -0.019]);
        w.interior = [0.003, -0.002, 0.01, -0.004, 0.001, -0.02];
        assert_rhs_is_the_numerical_gradient(&mut w);
    }

    /// `rhs = -1/2 grad vTPv` of every camera, rig and interior parameter, by central
    /// differences (a window without points).
    fn assert_rhs_is_the_numerical_gradient(w: &mut Window) {
        w.build_index();
        w.build(0.0);
        let nc = w.n_cam();
        let rhs: std::vec::Vec<f64> = w.rhs[..nc].to_vec();
        for i in 0..nc {
            let h = 1e-6;
            let (blk, k) = (i / 6, i % 6);
            let val = |w: &mut Window, d: f64| {
                if blk < w.n_epochs {
                    w.epochs[blk].params[k] += d;
                } else if Some(blk) == w.rig_block() {
                    let mut r = w.rig.to_array();
                    r[k] += d;
                    w.rig = RigParams::from_array(&r);
                } else {
                    w.interior[k] += d;
                }
            };
            val(w, h);
            let cp = w.cost().0;
            val(w, -2.0 * h);
            let cm = w.cost().0;
            val(w, h);
            let num = -(cp - cm) / (2.0 * h) / 2.0;
            let tol = 1e-5 * (1.0 + num.abs().max(rhs[i].abs()));
            assert!(
                (num - rhs[i]).abs() <= tol,
                "param {i}: analytic {} numeric {num}",
                rhs[i]
            );
        }
    }

    /// The smoothness reaches back over the window's edge to the fixed epochs
    /// (constants), in the camera's frame: its equations count once per epoch from
    /// the third counted from the oldest fixed one, and their gradient is exact.
    #[test]
    fn smoothness_spans_the_window_edge() {
        use core::f64::consts::FRAC_PI_2;
        let cam = Interior::pinhole_px(1000, 800, 900.0);
        let rig = Rig::rectified(cam, 0.5);
        let cfg = AdjustConfig {
            window: 3,
            fixed_epochs: 2,
            sigmas: sigmas(),
            ..AdjustConfig::default()
        };
        let mut mem = vec![0u8; 1 << 20];
        let mut arena = Arena::new(&mut mem);
        let mut w = Window::new(cfg, &rig, &mut arena).unwrap();
        // A turn of constant rate and speed: the smoothness holds exactly.
        let pose = |k: usize| {
            let heading = 0.1 * k as f64;
            let r = 20.0;
            let centre = [r * (1.0 - libm::cos(heading)), r * libm::sin(heading), 1.5];
            Pose::from_params(&[FRAC_PI_2, -heading, 0.0, centre[0], centre[1], centre[2]])
        };
        for k in 0..6 {
            if w.n_epochs == 3 {
                w.slide().unwrap();
            }
            w.add_epoch(&pose(k), 0.1 * k as f64).unwrap();
        }
        assert_eq!((w.n_fixed, w.n_epochs), (2, 3));
        w.build_index();
        let (cost, count) = w.add_constraints(false);
        // The carried prior (6) and three smoothness triples over 2 fixed + 3 window epochs.
        assert_eq!(count, 6 + 3 * 3);
        assert!(cost < 1e-16, "a steady turn costs {cost}");
        // Speed up the newest epoch and turn the first window epoch: every triple pulls.
        w.epochs[2].params[4] += 0.05;
        w.epochs[0].params[2] += 0.002;
        w.epochs[1].params[3] -= 0.01;
        assert_rhs_is_the_numerical_gradient(&mut w);
    }

    /// One Gauss-Newton step through the Schur complement (rig estimated,
    /// constraints on) leaves a gradient of `vTPv` (by central differences over
    /// every camera, rig and point parameter) orders of magnitude smaller: the
    /// Jacobians, the elimination and the back-substitution agree.
    #[test]
    fn schur_step_zeroes_the_numerical_gradient() {
        use crate::adjust::tests::{load, scene};
        let s = scene(71, 3, 12, 0.0);
        let cfg = AdjustConfig {
            window: 3,
            max_points: 12,
            max_observations: s.obs.len(),
            estimate_rig: true,
            self_calibration: Some(InteriorSigmas {
                principal_point_mm: [0.02, 0.02],
                focal_mm: [0.05, 0.05],
            }),
            robust: Robust::None,
            sigmas: ConstraintSigmas {
                datum_angle_rad: 1e-3,
                datum_position_m: 1e-3,
                base_length_m: 0.01,
                velocity_change_mps: 1.0,
                ..ConstraintSigmas::default()
            },
            ..AdjustConfig::default()
        };
        let mut b = MemoryBudget::new();
        cfg.budget(&mut b);
        let mut mem = vec![0u8; b.total()];
        let mut arena = Arena::new(&mut mem);
        let (mut w, _) = load(&s, cfg, &mut arena, 72);
        w.set_gnss(2, s.poses[2].centre, 0.05).unwrap();
        w.build_index();
        let _ = w.classify_points();
        // Start close to the optimum so one step is (nearly) the whole way.
        for _ in 0..3 {
            w.step(0.0).unwrap();
        }
        for e in 1..3 {
            w.epochs[e].params[0] += 2e-4;
            w.epochs[e].params[4] += 3e-3;
        }
        let mut r = w.rig.to_array();
        r[1] += 1e-4;
        r[3] += 2e-3;
        w.rig = RigParams::from_array(&r);
        w.interior[1] += 4e-4;
        w.interior[5] -= 2e-3;
        for p in 0..w.n_point_slots {
            w.points[p].xyz[1] += 5e-3;
        }
        let grad_norm = |w: &mut Window| -> f64 {
            let mut sum = 0.0;
            let h = 1e-7;
            let n_cam = w.n_cam();
            for i in 0..n_cam + 3 * w.n_point_slots {
                let bump = |w: &mut Window, d: f64| {
                    if i < 6 * w.n_epochs {
                        w.epochs[i / 6].params[i % 6] += d;
                    } else if i < 6 * w.n_epochs + 6 {
                        let mut r = w.rig.to_array();
                        r[i - 6 * w.n_epochs] += d;
                        w.rig = RigParams::from_array(&r);
                    } else if i < n_cam {
                        w.interior[i - 6 * w.n_epochs - 6] += d;
                    } else {
                        let k = i - n_cam;
                        w.points[k / 3].xyz[k % 3] += d;
                    }
                };
                bump(w, h);
                let cp = w.cost().0;
                bump(w, -2.0 * h);
                let cm = w.cost().0;
                bump(w, h);
                let g = (cp - cm) / (2.0 * h);
                sum += g * g;
            }
            libm::sqrt(sum)
        };
        let before = grad_norm(&mut w);
        w.step(0.0).unwrap();
        let after = grad_norm(&mut w);
        assert!(after < 1e-3 * before, "gradient {before} -> {after}");
    }

    /// The rigid transport against moving both poses numerically: a small rotation
    /// about the first pose's centre (object frame) and a shift.
    #[test]
    fn rigid_transport_matches_a_rigid_motion_of_both_poses() {
        use crate::camera::{angles_from_rotation, rotation};
        let from = [1.62, 0.05, -0.1, 1.0, 2.0, 3.0];
        let to = [1.5, -0.02, 0.3, 5.0, 20.0, 1.0];
        let j = rigid_transport(&from, &to);
        let e_from = angle_rates(&from);
        let h = 1e-6;
        for axis in 0..6 {
            // The motion: a rotation vector (object frame) or a shift, size h.
            let mut d = Vector3::zeros();
            let mut shift = Vector3::zeros();
            if axis < 3 {
                d[axis] = h;
            } else {
                shift[axis - 3] = h;
            }
            let turn = nalgebra::Rotation3::new(d).into_inner();
            let moved = |p: &[f64; 6]| {
                let r = rotation(p[0], p[1], p[2]).transpose();
                let c = Vector3::new(p[3], p[4], p[5]) - Vector3::new(from[3], from[4], from[5]);
                let m = (turn * r).transpose();
                let a = angles_from_rotation(&m);
                let c = turn * c + Vector3::new(from[3], from[4], from[5]) + shift;
                [a[0], a[1], a[2], c[0], c[1], c[2]]
            };
            let (f2, t2) = (moved(&from), moved(&to));
            let df: [f64; 6] = core::array::from_fn(|k| f2[k] - from[k]);
            let dt: [f64; 6] = core::array::from_fn(|k| t2[k] - to[k]);
            // The angles' change of `from` is the rotation vector through E.
            let da = e_from.try_inverse().unwrap() * d;
            for k in 0..3 {
                assert!((df[k] - da[k]).abs() < 1e-9, "axis {axis}: E");
            }
            for r in 0..6 {
                let predicted: f64 = (0..6).map(|k| j[r * 6 + k] * df[k]).sum();
                assert!(
                    (predicted - dt[r]).abs() < 1e-3 * h,
                    "axis {axis}, row {r}: {predicted} against {}",
                    dt[r]
                );
            }
        }
    }

    /// The GNSS residual's angle derivatives (the lever arm turning with the camera)
    /// against numerical differentiation.
    #[test]
    fn gnss_lever_arm_jacobian_matches_numeric() {
        let slot = |p: [f64; 6]| {
            let mut e: EpochSlot = bytemuck::Zeroable::zeroed();
            e.params = p;
            e.rot = Rotations::new(p[0], p[1], p[2]);
            e.gnss = [1.0, 2.0, 3.0];
            e.gnss_lever = [0.3, 1.1, -0.7];
            e
        };
        // The default datum (omega 90 deg: the camera's y is the object's Z, its z the
        // object's -Y): an antenna 1.2 m up and 0.5 m behind the camera.
        let mut level = slot([core::f64::consts::FRAC_PI_2, 0.0, 0.0, 1.0, 2.0, 3.0]);
        level.gnss_lever = [0.0, 1.2, 0.5];
        let (r, _) = gnss_residual(&level);
        assert!(
            r[0].abs() < 1e-12 && (r[1] + 0.5).abs() < 1e-12 && (r[2] - 1.2).abs() < 1e-12,
            "{r:?}"
        );
        let p = [1.55, 0.2, -0.4, 1.0, 2.5, 2.0];
        let (r0, j) = gnss_residual(&slot(p));
        // At zero lever the residual is the centre's offset from the fix.
        let mut plain = slot(p);
        plain.gnss_lever = [0.0; 3];
        assert_eq!(gnss_residual(&plain).0, [0.0, 0.5, -1.0]);
        let h = 1e-7;
        for k in 0..3 {
            let mut q = p;
            q[k] += h;
            let (r1, _) = gnss_residual(&slot(q));
            for a in 0..3 {
                let numeric = (r1[a] - r0[a]) / h;
                assert!(
                    (numeric - j[a][k]).abs() < 1e-6,
                    "d r{a} / d angle {k}: {numeric} against {}",
                    j[a][k]
                );
            }
        }
    }
}
