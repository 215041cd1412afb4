//! Reduced SIFT over integer buffers.
//!
//! Scale space: each octave is streamed row by row. Level 0 is blurred from the
//! octave source (the input image, or level `levels` of the previous octave decimated
//! by two), every further level blurs the one below with a separable Q14 kernel, and
//! each level keeps only a ring of rows (see [`config::Geometry`]). The difference of
//! Gaussians is taken in i16 on three rows, extrema are searched one row behind the
//! slowest level, refined, and wait in a FIFO until the rows of their orientation and
//! descriptor neighbourhood are in the rings. Octaves run one after the other; the
//! decimated source of the next octave is the only quarter-size plane kept.
//!
//! Memory: working memory grows with the width (rings) plus a quarter-size plane for
//! the next octave; see [`SiftConfig::budget`]. Nothing is allocated.
//!
//! ```
//! use phototraverse_core::budget::{Arena, MemoryBudget};
//! use phototraverse_core::features::FeatureSet;
//! use phototraverse_core::image::ImageView;
//! use phototraverse_core::sift::{Sift, SiftConfig};
//!
//! let cfg = SiftConfig { max_width: 64, max_height: 48, max_keypoints: 50, ..SiftConfig::default() };
//! let mut budget = MemoryBudget::new();
//! cfg.budget(&mut budget).unwrap();
//! let mut storage = vec![0u8; budget.total()];
//! let mut arena = Arena::new(&mut storage);
//! let mut sift = Sift::new(cfg, &mut arena).unwrap();
//! let mut features = FeatureSet::new(&mut arena, cfg.max_keypoints).unwrap();
//! let pixels: Vec<u8> = (0..64 * 48).map(|i| if (i % 64 / 8 + i / 64 / 8) % 2 == 0 { 40 } else { 200 }).collect();
//! let image = ImageView::new(&pixels, 64, 48).unwrap();
//! let stats = sift.extract(&image, &mut features).unwrap();
//! assert_eq!(stats.kept, features.len());
//! assert!(arena.used() <= budget.total());
//! ```

pub(crate) mod config;
pub(crate) mod desc_samples;
pub(crate) mod descriptor;
pub(crate) mod extrema;
pub(crate) mod fastmath;
pub(crate) mod levels;
pub(crate) mod orientation;
pub(crate) mod pending;
pub(crate) mod scale_space;
pub(crate) mod select;

pub use config::{Geometry, Gradient, SiftConfig, SiftError};

use crate::budget::Arena;
use crate::features::{FeatureSet, Keypoint};
use crate::image::ImageView;
use config::{
    base_lens, dog_len, kernel_len, BORDER, DESC_GRID, KERNEL_STRIDE, MAX_RADIUS, REFINE_ROWS,
};
use extrema::{candidate_mask, is_extremum, prelim_threshold, refine, RefineParams, Refined};
use levels::Levels;
use orientation::{orientations, ORI_BINS};
use pending::{Pending, PendingQueue};
use scale_space::{blur_column, blur_column_u8, blur_row, clamp_row, make_kernel};
use select::{admit, Admit};

/// Counts of one extraction, stage by stage.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SiftStats {
    /// Octaves processed.
    pub octaves: usize,
    /// 3x3x3 extrema above the preliminary threshold.
    pub extrema: usize,
    /// Refinement did not converge or left the octave/layers/window.
    pub unstable: usize,
    /// Rejected by the contrast threshold.
    pub low_contrast: usize,
    /// Rejected by the edge (curvature ratio) threshold.
    pub edge: usize,
    /// Refined keypoint locations accepted.
    pub refined: usize,
    /// Refined locations dropped because the pending FIFO was full.
    pub pending_dropped: usize,
    /// Keypoints (orientations included) offered to the feature set.
    pub oriented: usize,
    /// Keypoints dropped or evicted by the capacity and the grid.
    pub dropped: usize,
    /// Features kept.
    pub kept: usize,
}

/// The extractor: working buffers carved from an arena, reused for every image.
pub struct Sift<'a> {
    cfg: SiftConfig,
    /// Geometry of the regular octaves and of the fine octave.
    geo: Geometry,
    fine: Geometry,
    kernels: &'a mut [i32],
    grings: &'a mut [i16],
    dog: &'a mut [i16],
    base_a: &'a mut [i16],
    base_b: &'a mut [i16],
    pad: &'a mut [i16],
    tmp: &'a mut [i16],
    acc: &'a mut [i32],
    pending: PendingQueue<'a>,
    cells: &'a mut [u32],
    desc_weights: &'a mut [f32],
}

/// Where level 0 of an octave comes from.
#[derive(Clone, Copy)]
enum Source<'s> {
    Image(&'s ImageView<'s>),
    /// A decimated plane of `w * h` values, row stride `w`.
    Plane(&'s [i16]),
}

/// Per-octave constants.
#[derive(Clone, Copy)]
struct Octave {
    index: usize,
    w: usize,
    h: usize,
    /// Decimate level `levels` into the next octave's plane.
    decimate: bool,
    /// The fine octave (input resolution, half blur) rather than a regular one.
    fine: bool,
    /// Input image size (for the spreading grid).
    image_w: usize,
    image_h: usize,
}

impl<'a> Sift<'a> {
    /// Carves the working buffers the configuration's budget predicts (not the feature
    /// storage: see [`FeatureSet::new`]).
    pub fn new(cfg: SiftConfig, arena: &mut Arena<'a>) -> Result<Self, SiftError> {
        let geo = cfg.geometry()?;
        let fine = cfg.fine_geometry()?;
        if fine.gring_rows > geo.gring_rows || fine.n != geo.n {
            return Err(SiftError::BadConfig(
                "fine octave does not fit the regular rings",
            ));
        }
        let w = cfg.max_width;
        let kernels = arena.alloc_slice::<i32>(kernel_len(&geo))?;
        let grings = arena.alloc_slice::<i16>(geo.gring_rows * w)?;
        let dog = arena.alloc_slice::<i16>(dog_len(&geo, w))?;
        let (a, b) = base_lens(w, cfg.max_height, cfg.octaves);
        let base_a = arena.alloc_slice::<i16>(a)?;
        let base_b = arena.alloc_slice::<i16>(b)?;
        let pad = arena.alloc_slice::<i16>(w + 2 * MAX_RADIUS)?;
        let tmp = arena.alloc_slice::<i16>(w)?;
        let acc = arena.alloc_slice::<i32>(w)?;
        let pending = PendingQueue::new(arena.alloc_slice::<Pending>(cfg.pending_capacity)?);
        let cells = arena.alloc_slice::<u32>(geo.cells)?;
        let desc_weights = arena.alloc_slice::<f32>(DESC_GRID * DESC_GRID)?;
        for (i, g) in [&geo, &fine].into_iter().enumerate() {
            for k in 0..g.n {
                let at = (i * g.n + k) * KERNEL_STRIDE;
                make_kernel(g.sigma_inc[k], g.radius[k], &mut kernels[at..]);
            }
        }
        descriptor::fill_weights(desc_weights, cfg.descriptor_grid);
        Ok(Sift {
            cfg,
            geo,
            fine,
            kernels,
            grings,
            dog,
            base_a,
            base_b,
            pad,
            tmp,
            acc,
            pending,
            cells,
            desc_weights,
        })
    }

    pub fn config(&self) -> &SiftConfig {
        &self.cfg
    }

    pub fn geometry(&self) -> &Geometry {
        &self.geo
    }

    fn gradient(&self, oct: &Octave) -> Gradient {
        if oct.fine {
            self.cfg.fine_gradient
        } else {
            self.cfg.gradient
        }
    }

    fn geometry_of(&self, oct: &Octave) -> &Geometry {
        if oct.fine {
            &self.fine
        } else {
            &self.geo
        }
    }

    /// Extracts keypoints and descriptors of `image` into `out` (cleared first), keeping at
    /// most `min(max_keypoints, out.capacity())`, strongest first within each grid cell.
    pub fn extract(
        &mut self,
        image: &ImageView,
        out: &mut FeatureSet,
    ) -> Result<SiftStats, SiftError> {
        image.check_capacity(self.cfg.max_width, self.cfg.max_height)?;
        out.clear();
        self.cells.fill(0);
        self.pending.clear();
        let mut stats = SiftStats::default();
        let min_side = 2 * BORDER + 3;
        let (mut w, mut h) = (image.width(), image.height());
        // Octave o reads plane a when odd, b when even (o > 0) and writes the other.
        let a = core::mem::take(&mut self.base_a);
        let b = core::mem::take(&mut self.base_b);
        if self.cfg.fine_octave && w >= min_side && h >= min_side {
            let oct = Octave {
                index: 0,
                w,
                h,
                decimate: false,
                fine: true,
                image_w: w,
                image_h: h,
            };
            let mut none: [i16; 0] = [];
            self.run_octave(&oct, Source::Image(image), &mut none, out, &mut stats);
            stats.octaves += 1;
        }
        for o in 0..self.cfg.octaves {
            if w < min_side || h < min_side {
                break;
            }
            let decimate = o + 1 < self.cfg.octaves && w / 2 >= min_side && h / 2 >= min_side;
            let oct = Octave {
                index: o,
                w,
                h,
                decimate,
                fine: false,
                image_w: image.width(),
                image_h: image.height(),
            };
            let (src, dst): (Source, &mut [i16]) = if o == 0 {
                (Source::Image(image), &mut *a)
            } else if o % 2 == 1 {
                (Source::Plane(&a[..w * h]), &mut *b)
            } else {
                (Source::Plane(&b[..w * h]), &mut *a)
            };
            self.run_octave(&oct, src, dst, out, &mut stats);
            stats.octaves += 1;
            w /= 2;
            h /= 2;
        }
        self.base_a = a;
        self.base_b = b;
        stats.kept = out.len();
        stats.dropped = out.dropped;
        Ok(stats)
    }

    fn run_octave(
        &mut self,
        oct: &Octave,
        src: Source,
        dst: &mut [i16],
        out: &mut FeatureSet,
        stats: &mut SiftStats,
    ) {
        let g = *self.geometry_of(oct);
        let n = g.n;
        let last = n - 1;
        let h = oct.h as isize;
        let lag = g.delay[last] as isize;
        let margin = g.margin as isize;
        let t_end = h - 1 + lag + REFINE_ROWS as isize + margin;
        let thr = prelim_threshold(self.cfg.contrast_threshold, self.cfg.levels);
        let params = RefineParams {
            levels: self.cfg.levels,
            contrast: self.cfg.contrast_threshold,
            edge: self.cfg.edge_threshold,
        };
        for t in 0..=t_end {
            for k in 0..n {
                let r = t - g.delay[k] as isize;
                if r >= 0 && r < h {
                    self.produce(oct, src, k, r as usize, dst);
                }
            }
            let r_det = t - lag - REFINE_ROWS as isize;
            let q = r_det + 1;
            if q >= 0 && q < h {
                self.difference_row(oct, q as usize);
            }
            if r_det >= BORDER as isize && r_det < h - BORDER as isize {
                self.detect_row(oct, r_det as usize, thr, &params, stats);
            }
            let r_proc = r_det - margin;
            while let Some(p) = self.pending.front() {
                if p.row as isize > r_proc {
                    break;
                }
                self.pending.pop();
                self.describe_pending(oct, &p, out, stats);
            }
        }
    }

    /// Computes row `r` of level `k` into its Gaussian ring and feeds level `k + 1`.
    fn produce(&mut self, oct: &Octave, src: Source, k: usize, r: usize, dst: &mut [i16]) {
        let g = if oct.fine { &self.fine } else { &self.geo };
        let kb = if oct.fine { g.n } else { 0 };
        let stride = self.cfg.max_width;
        let (w, h) = (oct.w, oct.h);
        let gstart = (g.gring_row0[k] + r % g.depth[k]) * stride;
        if k == 0 {
            let taps = &self.kernels[kb * KERNEL_STRIDE..(kb + 1) * KERNEL_STRIDE];
            match src {
                Source::Image(img) => {
                    // Vertical pass from the u8 rows into `tmp`, then horizontal into the ring.
                    let rad = g.radius[0];
                    let tmp = &mut self.tmp[..w];
                    blur_column_u8(
                        |j| img.row(clamp_row(r, j, rad, h)),
                        taps,
                        rad,
                        self.acc,
                        tmp,
                    );
                    blur_row(
                        tmp,
                        taps,
                        rad,
                        self.pad,
                        self.acc,
                        &mut self.grings[gstart..gstart + w],
                    );
                }
                Source::Plane(p) => {
                    let s = &p[r * w..r * w + w];
                    self.grings[gstart..gstart + w].copy_from_slice(s);
                }
            }
        } else {
            // Vertical pass over the rows of level k-1 still in its ring (its depth covers
            // the kernel: see `SiftConfig::geometry`) into `tmp`, then horizontal into the
            // ring: no horizontal-pass rings.
            let rad = g.radius[k];
            let (row0, depth) = (g.gring_row0[k - 1], g.depth[k - 1]);
            let taps = &self.kernels[(kb + k) * KERNEL_STRIDE..(kb + k + 1) * KERNEL_STRIDE];
            let grings = &*self.grings;
            let rows = |j: usize| {
                let s = (row0 + clamp_row(r, j, rad, h) % depth) * stride;
                &grings[s..s + w]
            };
            let tmp = &mut self.tmp[..w];
            blur_column(rows, taps, rad, self.acc, tmp);
            blur_row(
                tmp,
                taps,
                rad,
                self.pad,
                self.acc,
                &mut self.grings[gstart..gstart + w],
            );
        }
        if k == self.cfg.levels && oct.decimate && r.is_multiple_of(2) && r / 2 < h / 2 {
            let (w2, r2) = (w / 2, r / 2);
            let row = &self.grings[gstart..gstart + w];
            if let Some(d) = dst.get_mut(r2 * w2..r2 * w2 + w2) {
                for (c, v) in d.iter_mut().enumerate() {
                    *v = row[2 * c];
                }
            }
        }
    }

    /// DoG rows of every layer at row `q` into the three-row ring.
    fn difference_row(&mut self, oct: &Octave, q: usize) {
        let g = if oct.fine { &self.fine } else { &self.geo };
        let stride = self.cfg.max_width;
        let w = oct.w;
        for l in 0..g.n - 1 {
            let a = (g.gring_row0[l] + q % g.depth[l]) * stride;
            let b = (g.gring_row0[l + 1] + q % g.depth[l + 1]) * stride;
            let d = (l * 3 + q % 3) * stride;
            let lo = &self.grings[a..a + w];
            let hi = &self.grings[b..b + w];
            for ((o, &x), &y) in self.dog[d..d + w].iter_mut().zip(lo).zip(hi) {
                *o = y.wrapping_sub(x);
            }
        }
    }

    fn detect_row(
        &mut self,
        oct: &Octave,
        r: usize,
        thr: i32,
        params: &RefineParams,
        stats: &mut SiftStats,
    ) {
        let stride = self.cfg.max_width;
        let w = oct.w;
        let gradient = self.gradient(oct);
        let dog = &*self.dog;
        let lv = Levels {
            data: self.grings,
            stride,
            w,
            h: oct.h,
            geo: if oct.fine { &self.fine } else { &self.geo },
            gradient,
        };
        for l in 1..=self.cfg.levels {
            let row = |layer: usize, rr: usize| {
                let s = (layer * 3 + rr % 3) * stride;
                &dog[s..s + w]
            };
            let rows: [&[i16]; 9] = [
                row(l - 1, r - 1),
                row(l - 1, r),
                row(l - 1, r + 1),
                row(l, r - 1),
                row(l, r),
                row(l, r + 1),
                row(l + 1, r - 1),
                row(l + 1, r),
                row(l + 1, r + 1),
            ];
            let cur = rows[4];
            // Most samples are below the threshold: test 32 at a time (vectorises).
            let thr16 = thr.clamp(0, i16::MAX as i32) as i16;
            let (c0, c1) = (BORDER, w - BORDER);
            let mut start = c0;
            while start < c1 {
                let end = (start + 32).min(c1);
                // Candidates as a bit mask, then visited bit by bit.
                let mut mask = candidate_mask(cur, start, end - start, thr16);
                while mask != 0 {
                    let i = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let c = start + i;
                    let v = cur[c];
                    {
                        if (v as i32).abs() <= thr || !is_extremum(&rows, c, v) {
                            continue;
                        }
                        stats.extrema += 1;
                        match refine(&lv, params, c, r, l) {
                            Refined::Kept(p) => {
                                stats.refined += 1;
                                if !self.pending.push(p) {
                                    stats.pending_dropped += 1;
                                }
                            }
                            Refined::Unstable => stats.unstable += 1,
                            Refined::LowContrast => stats.low_contrast += 1,
                            Refined::Edge => stats.edge += 1,
                        }
                    }
                }
                start = end;
            }
        }
    }

    fn describe_pending(
        &mut self,
        oct: &Octave,
        p: &Pending,
        out: &mut FeatureSet,
        stats: &mut SiftStats,
    ) {
        let gradient = self.gradient(oct);
        let lv = Levels {
            data: self.grings,
            stride: self.cfg.max_width,
            w: oct.w,
            h: oct.h,
            geo: if oct.fine { &self.fine } else { &self.geo },
            gradient,
        };
        let k = (p.level as usize).clamp(1, self.cfg.levels);
        let sigma0 = if oct.fine {
            self.fine.sigma0
        } else {
            self.geo.sigma0
        };
        let sigma = self.cfg.level_sigma(sigma0, p.layer);
        let mut angles = [0f32; ORI_BINS];
        let count = if self.cfg.upright {
            1
        } else {
            orientations(&lv, k, p.x, p.y, sigma, &self.cfg, &mut angles)
        };
        let scale = (1u32 << oct.index) as f32;
        let x = p.x * scale;
        let y = p.y * scale;
        let cell = grid_cell(
            x,
            y,
            oct.image_w,
            oct.image_h,
            self.cfg.grid_cols,
            self.cfg.grid_rows,
        );
        let cap = self.cfg.max_keypoints.min(out.capacity());
        for &angle in &angles[..count] {
            stats.oriented += 1;
            let kp = Keypoint {
                x,
                y,
                sigma: sigma * scale,
                orientation: angle,
                response: p.response,
                octave: oct.index as u16,
                cell: cell as u16,
            };
            if let Admit::Slot(i) = admit(out, cap, self.cells, cell, p.response) {
                if let Some((ks, ds)) = out.slot_mut(i) {
                    *ks = kp;
                    descriptor::describe(
                        &lv,
                        self.cfg.descriptor_grid,
                        k,
                        p.x,
                        p.y,
                        sigma,
                        angle,
                        self.desc_weights,
                        ds,
                    );
                }
            }
        }
    }
}

/// Cell of the spreading grid holding input-image position (`x`, `y`).
pub fn grid_cell(x: f32, y: f32, w: usize, h: usize, cols: usize, rows: usize) -> usize {
    let cx = ((x + 0.5) * cols as f32 / w.max(1) as f32) as isize;
    let cy = ((y + 0.5) * rows as f32 / h.max(1) as f32) as isize;
    let cx = cx.clamp(0, cols as isize - 1) as usize;
    let cy = cy.clamp(0, rows as isize - 1) as usize;
    cy * cols + cx
}
