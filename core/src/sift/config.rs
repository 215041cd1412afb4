//! Configuration of the reduced SIFT extractor and the geometry derived from it:
//! kernel radii, pipeline delays and ring depths, and the memory budget.

use crate::budget::{slice_bytes, ComponentKind, MemoryBudget};
use crate::features::{Descriptor, Keypoint};

use super::pending::Pending;

/// Most Gaussian levels per octave (`levels + 3`).
pub const MAX_LEVELS: usize = 8;
/// Largest Gaussian kernel radius (taps on each side of the centre).
pub const MAX_RADIUS: usize = 24;
/// Descriptor spatial bins along each axis.
pub const DESC_BINS: usize = 4;
/// Descriptor orientation bins.
pub const DESC_ORI_BINS: usize = 8;
/// Most samples of the descriptor grid along one axis (buffers are sized for it). The
/// grid spreads [`SiftConfig::descriptor_grid`] samples uniformly over bins -1..4
/// (trilinear interpolation spills into the outer bins as in Lowe's descriptor).
pub const DESC_GRID: usize = 20;
/// Keypoints are not detected closer than this to the octave border.
pub const BORDER: usize = 5;
/// Rows the refinement may move plus the neighbour row it reads.
pub const REFINE_ROWS: usize = 2;
/// Fractional bits of the Gaussian levels: grey levels are stored times 64 in i16.
pub const FRAC_BITS: u32 = 6;
/// Fractional bits of the Q14 kernel taps.
pub const KERNEL_BITS: u32 = 14;

/// Configuration of the extractor. All capacities are explicit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SiftConfig {
    /// Largest image width accepted (buffers are sized for it).
    pub max_width: usize,
    /// Largest image height accepted.
    pub max_height: usize,
    /// Octaves at most (fewer when the image becomes too small).
    pub octaves: usize,
    /// Detection levels per octave (Lowe's `s`, OpenCV's nOctaveLayers).
    pub levels: usize,
    /// Blur of the first level of each octave, in octave pixels.
    pub sigma0: f32,
    /// Blur assumed in the input image.
    pub input_sigma: f32,
    /// Contrast threshold on |DoG| in grey levels / 255, divided by `levels` as in OpenCV.
    pub contrast_threshold: f32,
    /// Edge threshold: largest ratio of principal curvatures.
    pub edge_threshold: f32,
    /// Keypoints kept per image at most.
    pub max_keypoints: usize,
    /// Columns of the spreading grid.
    pub grid_cols: usize,
    /// Rows of the spreading grid.
    pub grid_rows: usize,
    /// Upright mode: no orientation histogram, every orientation is 0.
    pub upright: bool,
    /// Refined candidates waiting for their descriptor rows at most.
    pub pending_capacity: usize,
    /// Secondary orientation peaks at least this fraction of the highest.
    pub peak_ratio: f32,
    /// An extra octave at input resolution with half the blur (`sigma0 / 2`), run before
    /// octave 0: the fine scales OpenCV reaches by doubling the image, at a quarter of the
    /// cost of doubling. Requires `input_sigma < sigma0 / 2`.
    pub fine_octave: bool,
    /// Gradient operator of orientations and descriptors in the regular octaves.
    pub gradient: Gradient,
    /// Gradient operator of orientations and descriptors in the fine octave, whose levels
    /// are blurred by only 0.8-1.6 pixels, where central differences bend directions most.
    pub fine_gradient: Gradient,
    /// Orientation votes split between the two nearest histogram bins (instead of all to
    /// the nearest, as Lowe and OpenCV): small keypoints have few samples in their window,
    /// and rounding each vote makes the peak jump between bins.
    pub soft_orientation: bool,
    /// Descriptor samples along each axis of the grid over bins -1..4: a multiple of 4 in
    /// 4..=20 (20: 4 samples per bin; 8: 1.6 per bin, 6x fewer samples).
    pub descriptor_grid: usize,
    /// Orientation windows are sampled every other pixel from this octave-relative scale
    /// up (the level is blurred by sigma, so a 2-pixel step loses little).
    pub orientation_stride_sigma: f32,
    /// Radius of the orientation window in keypoint sigmas (Lowe, OpenCV: 4.5, three
    /// sigmas of the 1.5-sigma Gaussian weight); at most 4.5, which the rings are sized for.
    pub orientation_radius: f32,
}

pub use super::levels::Gradient;

impl Default for SiftConfig {
    fn default() -> Self {
        SiftConfig {
            max_width: 640,
            max_height: 480,
            octaves: 6,
            levels: 3,
            sigma0: 1.6,
            input_sigma: 0.5,
            contrast_threshold: 0.04,
            edge_threshold: 10.0,
            max_keypoints: 1000,
            grid_cols: 8,
            grid_rows: 6,
            upright: false,
            pending_capacity: 2048,
            peak_ratio: 0.8,
            fine_octave: false,
            gradient: Gradient::Central,
            fine_gradient: Gradient::Central,
            soft_orientation: false,
            descriptor_grid: DESC_GRID,
            orientation_stride_sigma: 3.0,
            orientation_radius: 4.5,
        }
    }
}

/// Why a configuration or an extraction was refused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SiftError {
    /// A configuration value is out of its range (the field is named).
    BadConfig(&'static str),
    /// The image does not fit the configured capacity or is malformed.
    Image(crate::image::ImageError),
    /// The arena holds less than the budget predicts.
    OutOfMemory(crate::budget::OutOfMemory),
}

impl core::fmt::Display for SiftError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            SiftError::BadConfig(field) => write!(f, "bad SIFT configuration: {field}"),
            SiftError::Image(e) => write!(f, "{e}"),
            SiftError::OutOfMemory(e) => write!(f, "{e}"),
        }
    }
}

impl From<crate::budget::OutOfMemory> for SiftError {
    fn from(e: crate::budget::OutOfMemory) -> Self {
        SiftError::OutOfMemory(e)
    }
}

impl From<crate::image::ImageError> for SiftError {
    fn from(e: crate::image::ImageError) -> Self {
        SiftError::Image(e)
    }
}

/// Everything derived from a configuration: kernel radii, delays, ring depths.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// Gaussian levels per octave (`levels + 3`).
    pub n: usize,
    /// Blur of level 0 in octave pixels.
    pub sigma0: f32,
    /// Incremental blur of each level (level 0: from the octave source).
    pub sigma_inc: [f32; MAX_LEVELS],
    /// Kernel radius of each level.
    pub radius: [usize; MAX_LEVELS],
    /// Rows by which level k lags the pipeline clock.
    pub delay: [usize; MAX_LEVELS],
    /// Rows each Gaussian ring holds.
    pub depth: [usize; MAX_LEVELS],
    /// First row of each level's Gaussian ring in the shared ring buffer.
    pub gring_row0: [usize; MAX_LEVELS],
    /// Rows of all Gaussian rings.
    pub gring_rows: usize,
    /// Rows a keypoint waits for its descriptor neighbourhood (and reaches back).
    pub margin: usize,
    /// Cells of the spreading grid.
    pub cells: usize,
}

impl SiftConfig {
    /// Checks every field against its range.
    pub fn validate(&self) -> Result<(), SiftError> {
        let finite_pos = |v: f32| v.is_finite() && v > 0.0;
        if self.max_width < 1 || self.max_height < 1 {
            return Err(SiftError::BadConfig("max_width/max_height must be >= 1"));
        }
        if self.max_width > 16384 || self.max_height > 16384 {
            return Err(SiftError::BadConfig(
                "max_width/max_height must be <= 16384",
            ));
        }
        if self.octaves < 1 || self.octaves > 12 {
            return Err(SiftError::BadConfig("octaves must be in 1..=12"));
        }
        if self.levels < 1 || self.levels + 3 > MAX_LEVELS {
            return Err(SiftError::BadConfig("levels must be in 1..=5"));
        }
        if !finite_pos(self.sigma0) || self.sigma0 > 3.0 {
            return Err(SiftError::BadConfig("sigma0 must be in (0, 3]"));
        }
        if !(self.input_sigma.is_finite()
            && self.input_sigma >= 0.0
            && self.input_sigma < self.sigma0)
        {
            return Err(SiftError::BadConfig("input_sigma must be in [0, sigma0)"));
        }
        if !(self.contrast_threshold.is_finite() && self.contrast_threshold >= 0.0) {
            return Err(SiftError::BadConfig("contrast_threshold must be >= 0"));
        }
        if !finite_pos(self.edge_threshold) {
            return Err(SiftError::BadConfig("edge_threshold must be > 0"));
        }
        if self.max_keypoints < 1 || self.max_keypoints > 65535 * 4 {
            return Err(SiftError::BadConfig("max_keypoints must be in 1..=262140"));
        }
        if self.grid_cols < 1 || self.grid_rows < 1 || self.grid_cols * self.grid_rows > 4096 {
            return Err(SiftError::BadConfig("grid must have 1..=4096 cells"));
        }
        if self.pending_capacity < 1 {
            return Err(SiftError::BadConfig("pending_capacity must be >= 1"));
        }
        if !(self.peak_ratio.is_finite() && self.peak_ratio > 0.0 && self.peak_ratio <= 1.0) {
            return Err(SiftError::BadConfig("peak_ratio must be in (0, 1]"));
        }
        if self.descriptor_grid < 4
            || self.descriptor_grid > DESC_GRID
            || !self.descriptor_grid.is_multiple_of(4)
        {
            return Err(SiftError::BadConfig(
                "descriptor_grid must be a multiple of 4 in 4..=20",
            ));
        }
        if !(self.orientation_stride_sigma.is_finite() && self.orientation_stride_sigma > 0.0) {
            return Err(SiftError::BadConfig("orientation_stride_sigma must be > 0"));
        }
        if !(self.orientation_radius >= 1.0 && self.orientation_radius <= 4.5) {
            return Err(SiftError::BadConfig(
                "orientation_radius must be in [1, 4.5]",
            ));
        }
        if self.fine_octave && self.input_sigma >= self.sigma0 * 0.5 {
            return Err(SiftError::BadConfig(
                "fine_octave needs input_sigma < sigma0 / 2",
            ));
        }
        let g = self.geometry_unchecked(self.sigma0);
        if g.radius[..g.n].iter().any(|&r| r > MAX_RADIUS) {
            return Err(SiftError::BadConfig(
                "sigma0/levels give a kernel wider than MAX_RADIUS",
            ));
        }
        Ok(())
    }

    /// Blur (octave pixels) of level `k` of an octave whose level 0 has `sigma0`.
    pub fn level_sigma(&self, sigma0: f32, k: f32) -> f32 {
        sigma0 * libm::exp2f(k / self.levels as f32)
    }

    /// Geometry of the regular octaves (`sigma0`).
    pub fn geometry(&self) -> Result<Geometry, SiftError> {
        self.validate()?;
        Ok(self.geometry_unchecked(self.sigma0))
    }

    /// Geometry of the fine octave (`sigma0 / 2`, input resolution); it needs fewer rows
    /// than [`SiftConfig::geometry`] everywhere, so it runs in the same buffers.
    pub fn fine_geometry(&self) -> Result<Geometry, SiftError> {
        self.validate()?;
        Ok(self.geometry_unchecked(self.sigma0 * 0.5))
    }

    fn geometry_unchecked(&self, s0: f32) -> Geometry {
        let n = (self.levels + 3).min(MAX_LEVELS);
        let mut g = Geometry {
            n,
            sigma0: s0,
            sigma_inc: [0.0; MAX_LEVELS],
            radius: [0; MAX_LEVELS],
            delay: [0; MAX_LEVELS],
            depth: [0; MAX_LEVELS],
            gring_row0: [0; MAX_LEVELS],
            gring_rows: 0,
            margin: 0,
            cells: self.grid_cols * self.grid_rows,
        };
        // Level 0 of octave 0 blurs the input from input_sigma to sigma0; octaves > 0 start from
        // level `levels` of the previous octave decimated, which already has sigma0 in its pixels,
        // so their level 0 is a copy (radius 0).
        g.sigma0 = s0;
        g.sigma_inc[0] = libm::sqrtf((s0 * s0 - self.input_sigma * self.input_sigma).max(0.0));
        for k in 1..n {
            let a = self.level_sigma(s0, k as f32 - 1.0);
            let b = self.level_sigma(s0, k as f32);
            g.sigma_inc[k] = libm::sqrtf(b * b - a * a);
        }
        for k in 0..n {
            g.radius[k] = kernel_radius(g.sigma_inc[k]);
        }
        // Level 0 reads a random-access source, so it runs without delay.
        for k in 1..n {
            g.delay[k] = g.delay[k - 1] + g.radius[k];
        }
        // Descriptor reach in octave pixels: half diagonal of the sampling window
        // ((bins + 1) / 2 bins of 3 sigma) plus refinement shift, gradient and rounding.
        // Largest octave-relative scale a kept keypoint can have (refined layer < levels + 0.5).
        g.margin = self.reach_rows(s0, self.levels);
        let last = n - 1;
        let mut row = 0;
        for k in 0..n {
            let lag = g.delay[last] - g.delay[k];
            let depth = if k >= 1 && k <= self.levels {
                // Orientation and descriptor rows: back to r_proc minus the reach of the
                // largest keypoint this level describes (keypoints of refined layer in
                // [k - 0.5, k + 0.5) sample level k), ahead to the newest row produced.
                // Keypoints are described `margin` rows after detection whatever their level.
                g.margin + self.reach_rows(s0, k) + REFINE_ROWS + lag + 1
            } else {
                // Difference of Gaussians around the detection row only.
                2 * REFINE_ROWS + lag + 1
            };
            // Level k+1 is blurred vertically from this ring: it must also hold the
            // kernel's rows around the row being produced.
            let source = if k + 1 < n {
                2 * g.radius[k + 1] + 1
            } else {
                0
            };
            g.depth[k] = depth.max(source);
            g.gring_row0[k] = row;
            row += g.depth[k];
        }
        g.gring_rows = row;
        g
    }

    /// Rows the orientation and descriptor windows of a keypoint described on level `k`
    /// reach from its row (refined layer below `k + 0.5`), plus refinement and rounding.
    fn reach_rows(&self, s0: f32, k: usize) -> usize {
        let max_sigma = self.level_sigma(s0, k as f32 + 0.5);
        let reach = 3.0 * max_sigma * (DESC_BINS as f32 + 1.0) * 0.5 * 1.4143;
        let ori_reach = 4.5 * max_sigma;
        libm::ceilf(reach.max(ori_reach)) as usize + 3
    }

    /// Adds the extractor's components: its working buffers ([`Self::working_budget`])
    /// and the keypoint storage of one image (`Storage`), all named `sift.*`.
    pub fn budget(&self, budget: &mut MemoryBudget) -> Result<(), SiftError> {
        self.working_budget(budget)?;
        budget.add(
            "sift.keypoints",
            ComponentKind::Storage,
            slice_bytes::<Keypoint>(self.max_keypoints),
        );
        budget.add(
            "sift.descriptors",
            ComponentKind::Storage,
            slice_bytes::<Descriptor>(self.max_keypoints),
        );
        Ok(())
    }

    /// Adds what [`Sift::new`](super::Sift::new) carves: the working buffers
    /// (`Working`), named `sift.*`. A pipeline that keeps several images' features
    /// adds their storage itself.
    pub fn working_budget(&self, budget: &mut MemoryBudget) -> Result<(), SiftError> {
        let g = self.geometry()?;
        let w = self.max_width;
        let h = self.max_height;
        budget.add(
            "sift.kernels",
            ComponentKind::Working,
            slice_bytes::<i32>(kernel_len(&g)),
        );
        budget.add(
            "sift.gauss_rings",
            ComponentKind::Working,
            slice_bytes::<i16>(g.gring_rows * w),
        );
        budget.add(
            "sift.dog_rows",
            ComponentKind::Working,
            slice_bytes::<i16>(dog_len(&g, w)),
        );
        let (a, b) = base_lens(w, h, self.octaves);
        budget.add(
            "sift.octave_bases",
            ComponentKind::Working,
            slice_bytes::<i16>(a) + slice_bytes::<i16>(b),
        );
        budget.add(
            "sift.row_scratch",
            ComponentKind::Working,
            slice_bytes::<i16>(w + 2 * MAX_RADIUS) + slice_bytes::<i16>(w) + slice_bytes::<i32>(w),
        );
        budget.add(
            "sift.pending",
            ComponentKind::Working,
            slice_bytes::<Pending>(self.pending_capacity),
        );
        budget.add(
            "sift.cells",
            ComponentKind::Working,
            slice_bytes::<u32>(g.cells),
        );
        budget.add(
            "sift.desc_weights",
            ComponentKind::Working,
            slice_bytes::<f32>(DESC_GRID * DESC_GRID),
        );
        Ok(())
    }
}

/// Radius of a truncated Gaussian kernel: 3 sigma, at least 1 when there is any blur.
pub fn kernel_radius(sigma: f32) -> usize {
    if sigma < 0.05 {
        0
    } else {
        (libm::ceilf(3.0 * sigma) as usize).max(1)
    }
}

/// Kernel taps stored per level (centre and one side: the kernels are symmetric).
pub const KERNEL_STRIDE: usize = MAX_RADIUS + 1;

/// Kernels of the regular octaves, then of the fine octave.
pub(crate) fn kernel_len(g: &Geometry) -> usize {
    2 * g.n * KERNEL_STRIDE
}

/// Three rows of every DoG layer: rows r-1, r, r+1 around the detection row.
pub(crate) fn dog_len(g: &Geometry, w: usize) -> usize {
    (g.n - 1) * 3 * w
}

/// Sizes of the two alternating octave bases: octave 1 (w/2 x h/2) and octave 2 (w/4 x h/4);
/// octave 3 reuses the first, octave 4 the second, and so on. Only the octaves configured
/// get one: a single octave needs no base, two octaves only the first.
pub(crate) fn base_lens(w: usize, h: usize, octaves: usize) -> (usize, usize) {
    let a = if octaves >= 2 { (w / 2) * (h / 2) } else { 0 };
    let b = if octaves >= 3 { (w / 4) * (h / 4) } else { 0 };
    (a, b)
}
