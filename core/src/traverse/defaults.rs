//! The pipeline's defaults, in one table: the core's traverse (`TraverseConfig::for_rig`),
//! the configuration message (`Pipeline::default`), the CLI's settings and the firmware all
//! start from these. Each says its value and why.

/// Reduced-SIFT keypoints kept per image (the strongest, spread over a grid): at 640x480
/// enough for a few hundred stereo matches on a street, within the matcher's budget.
pub const TRAVERSE_KEYPOINTS: usize = 1000;

/// Scale-space octaves of the traverse: four reach keypoints of sigma 25 px at 640x480,
/// far beyond what stays matchable between epochs.
pub const TRAVERSE_OCTAVES: usize = 4;

/// Difference-of-Gaussian levels per octave: Lowe's 3, where repeatability peaks.
pub const TRAVERSE_SCALES: usize = 3;

/// DoG contrast threshold of the traverse (grey levels / 255): lower than SIFT's
/// usual 0.04, for the area tracks it feeds (docs/configuration.md).
pub const TRAVERSE_CONTRAST: f32 = 0.015;

/// Largest ratio of principal curvatures of a kept extremum: Lowe's 10 (edges rejected).
pub const TRAVERSE_EDGE_RATIO: f32 = 10.0;

/// Descriptor samples per axis in the traverse ([`SiftConfig::descriptor_grid`](crate::sift::SiftConfig::descriptor_grid)).
pub const TRAVERSE_DESCRIPTOR_GRID: usize = 12;

/// Nearest-neighbour distance ratio of a descriptor match: Lowe's 0.8.
pub const TRAVERSE_MATCH_RATIO: f32 = 0.8;

/// Largest stereo disparity searched, as a fraction of the image width: with a 90-degree
/// horizontal field of view (focal length w/2) half the width reaches points one base
/// length away, nearer than a vehicle's cameras see the street.
pub const TRAVERSE_DISPARITY_FRACTION: f32 = 0.5;

/// Live tracks at most: more than the tie points of an epoch (at most
/// `MAX_TIE_POINTS`) plus those a window keeps alive.
pub const TRAVERSE_TRACKS: usize = 600;

/// Epochs in the traverse's adjustment window: with the tie points carried on by area
/// matching, longer windows cost in proportion and gave no better drift on the rendered
/// streets (docs/traverse.md, "Window length").
pub const TRAVERSE_WINDOW: usize = 3;

/// Epochs that left the window whose observations still constrain their points
/// ([`AdjustConfig::fixed_epochs`](crate::adjust::AdjustConfig::fixed_epochs)).
pub const TRAVERSE_FIXED_EPOCHS: usize = 8;

/// Inflation of the carried prior of the window's first epoch
/// ([`AdjustConfig::carried_prior_inflation`](crate::adjust::AdjustConfig::carried_prior_inflation)).
pub const TRAVERSE_PRIOR_INFLATION: f64 = 1000.0;

/// Motion smoothness of the traverse: sigma of the change of velocity between
/// consecutive steps, in the camera's frame, m/s. 2 m/s per 0.1 s step (the rendered
/// streets' 10 Hz): 0.5 held the speed too tightly where it changes (`curves@320` went
/// from 0.29 to 0.89 % drift), 1.0 still lost more epochs on `drive@320`
/// (bench/traverse/README.md).
pub const TRAVERSE_VELOCITY_SIGMA: f64 = 2.0;

/// A-priori standard deviation of an image measurement, pixels: the unit of the image
/// weights and of the global test (the robust steps test on the residuals' median
/// scale instead). The reduced SIFT on rendered streets delivers 0.1 to 0.15 px (sigma0
/// 0.2 to 0.3 a posteriori), so the test reads "below the lower bound". The value stays:
/// the reported precision is floored at its a-priori value in these units, which covers
/// the errors a traverse accumulates, and the constraints' weights were tuned against
/// it (docs/adjustment.md, Quality).
pub const TRAVERSE_SIGMA_PX: f64 = 0.5;

// The model of a right-image observation's sigma from its stereo correlation peak
// (`solve::observation_sigma_px`): `sqrt(FLOOR^2 + (GAIN x peak)^2)` pixels, scaled so
// that `TRAVERSE_SIGMA_PX` stands for an observation modelled at `TYPICAL_PEAK_SIGMA_PX`.
// Fitted to the disparity errors of rendered streets against their depth maps
// (`bench/traverse/README.md`, "Observation weights from the correlation peak").

/// What the sharpest peaks still err by, pixels: the model's floor.
pub const PEAK_SIGMA_FLOOR_PX: f64 = 0.05;
/// What the peak's own figure underestimates the error by. A gain of 4 with a floor of
/// 0.04 px (weights spread 25-fold, both images weighted) did worse on three scenes of
/// five.
pub const PEAK_SIGMA_GAIN: f64 = 2.0;
/// The modelled sigma (pixels) of an observation that `TRAVERSE_SIGMA_PX` stands for:
/// about the median, so the weights' level stays where the constraints were tuned.
pub const TYPICAL_PEAK_SIGMA_PX: f64 = 0.08;
