//! Per-epoch processing behind a small trait, so the traverse plugs in without
//! touching the protocol loop. The firmware builds one processor per
//! configuration from its arena and calls it on every complete stereo epoch.
use phototraverse_core::budget::{Arena, ComponentKind, MemoryBudget, OutOfMemory, Stage};
use phototraverse_core::features::FeatureSet;
use phototraverse_core::image::ImageView;
use phototraverse_core::protocol::messages::{
    self, capacity, processor_kind, stage, Aux, CapacityUse, Configure, EpochResult, Figures,
    Points, ResultStatus, SiftCounts,
};
use phototraverse_core::sift::{Sift, SiftConfig, SiftError};

/// The microsecond clock of the core (the board's timer; `std::time::Instant` on the host).
pub use phototraverse_core::traverse::{Clock, NoClock};

/// One complete stereo epoch.
pub struct EpochInput<'i> {
    pub epoch: u32,
    pub left: ImageView<'i>,
    pub right: ImageView<'i>,
    pub timestamps_us: [u64; 2],
    /// Auxiliary observations sent for this epoch, if any.
    pub aux: Option<Aux>,
}

/// What a processor answers for an epoch.
pub struct EpochOutput {
    pub result: EpochResult,
    /// Microseconds per [`stage`] (the firmware fills `ASSEMBLE` and `TOTAL`).
    pub timings_us: [u32; stage::COUNT],
}

/// The per-epoch work.
pub trait EpochProcessor {
    fn process(&mut self, input: &EpochInput, clock: &dyn Clock) -> EpochOutput;

    /// The frame size (width, height in pixels) the processor was configured for, per
    /// camera (0 left, 1 right); `None` takes any size up to the configured capacity.
    fn frame_size(&self, _camera: usize) -> Option<(u16, u16)> {
        None
    }

    /// Fills `msg` (within `max_payload` bytes) with the next records of the
    /// tie point report: points and observations that became final since the
    /// last report; `flush` (the sequence ended) makes the whole window final.
    /// Returns true when records remain for another message. Processors
    /// without tie points report none.
    fn points(&mut self, _flush: bool, _max_payload: usize, _msg: &mut Points) -> bool {
        false
    }

    /// The highest use of each [`capacity`] so far; zeros for what the processor lacks.
    fn capacities(&self) -> [CapacityUse; capacity::COUNT] {
        [CapacityUse::default(); capacity::COUNT]
    }
}

/// Why a processor could not be built for a configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BuildError {
    OutOfMemory(OutOfMemory),
    /// A configuration value the processor cannot use (named).
    Invalid(&'static str),
}

impl From<OutOfMemory> for BuildError {
    fn from(e: OutOfMemory) -> Self {
        BuildError::OutOfMemory(e)
    }
}

/// Builds processors: predicts their memory, then carves it from the arena.
pub trait ProcessorFactory {
    type Processor<'a>: EpochProcessor;
    /// [`processor_kind`] reported in the capabilities.
    const KIND: u8;
    /// Adds the processor's components for `config` to `budget`.
    fn budget(&self, config: &Configure, budget: &mut MemoryBudget) -> Result<(), BuildError>;
    fn build<'a>(
        &mut self,
        config: &Configure,
        arena: &mut Arena<'a>,
    ) -> Result<Self::Processor<'a>, BuildError>;
}

/// The feature processor: reduced SIFT on both images of every epoch, the
/// configured capacities from the pipeline fields.
pub struct SiftFactory;

/// SIFT parameters from the protocol's pipeline fields (0 keeps SIFT's default).
pub fn sift_config(config: &Configure) -> SiftConfig {
    let p = &config.pipeline;
    let d = SiftConfig::default();
    let or = |v: usize, dflt: usize| if v == 0 { dflt } else { v };
    let orf = |v: f32, dflt: f32| if v > 0.0 && v.is_finite() { v } else { dflt };
    SiftConfig {
        max_width: p.max_width as usize,
        max_height: p.max_height as usize,
        octaves: or(p.octaves as usize, d.octaves),
        levels: or(p.scales_per_octave as usize, d.levels),
        contrast_threshold: orf(p.contrast_threshold, d.contrast_threshold),
        edge_threshold: orf(p.edge_ratio, d.edge_threshold),
        max_keypoints: or(p.keypoints_per_image as usize, d.max_keypoints),
        ..d
    }
}

fn sift_error(e: SiftError) -> BuildError {
    match e {
        SiftError::OutOfMemory(m) => BuildError::OutOfMemory(m),
        SiftError::BadConfig(field) => BuildError::Invalid(field),
        SiftError::Image(_) => BuildError::Invalid("image capacity"),
    }
}

pub struct SiftProcessor<'a> {
    sift: Sift<'a>,
    features: [FeatureSet<'a>; 2],
}

impl SiftProcessor<'_> {
    /// Features of the last epoch: left, right.
    pub fn features(&self) -> &[FeatureSet<'_>; 2] {
        &self.features
    }
}

impl ProcessorFactory for SiftFactory {
    type Processor<'a> = SiftProcessor<'a>;
    const KIND: u8 = processor_kind::SIFT;

    fn budget(&self, config: &Configure, budget: &mut MemoryBudget) -> Result<(), BuildError> {
        let cfg = sift_config(config);
        cfg.working_budget(budget).map_err(sift_error)?;
        FeatureSet::budget(
            cfg.max_keypoints,
            budget,
            "features.keypoints_left",
            "features.descriptors_left",
        );
        FeatureSet::budget(
            cfg.max_keypoints,
            budget,
            "features.keypoints_right",
            "features.descriptors_right",
        );
        Ok(())
    }

    fn build<'a>(
        &mut self,
        config: &Configure,
        arena: &mut Arena<'a>,
    ) -> Result<SiftProcessor<'a>, BuildError> {
        let cfg = sift_config(config);
        arena.stage(Stage::Sift);
        let sift = Sift::new(cfg, arena).map_err(sift_error)?;
        arena.stage(Stage::Features);
        let left = FeatureSet::new(arena, cfg.max_keypoints)?;
        let right = FeatureSet::new(arena, cfg.max_keypoints)?;
        Ok(SiftProcessor {
            sift,
            features: [left, right],
        })
    }
}

impl EpochProcessor for SiftProcessor<'_> {
    fn process(&mut self, input: &EpochInput, clock: &dyn Clock) -> EpochOutput {
        let mut timings_us = [0u32; stage::COUNT];
        let mut result = EpochResult::empty(input.epoch, ResultStatus::FeaturesOnly);
        let mut sift = SiftCounts::default();
        let [fl, fr] = &mut self.features;
        for (k, (image, set, st)) in [
            (&input.left, fl, stage::SIFT_LEFT),
            (&input.right, fr, stage::SIFT_RIGHT),
        ]
        .into_iter()
        .enumerate()
        {
            let t0 = clock.now_us();
            match self.sift.extract(image, set) {
                Ok(stats) => {
                    result.counts.keypoints[k] = set.len() as u32;
                    result.counts.dropped += (stats.dropped + stats.pending_dropped) as u32;
                    sift.extrema[k] = stats.extrema as u32;
                    sift.refined[k] = stats.refined as u32;
                }
                Err(_) => result.status = ResultStatus::Failed,
            }
            timings_us[st] = clock.now_us().saturating_sub(t0) as u32;
        }
        result.figures = Figures::Sift(sift);
        EpochOutput { result, timings_us }
    }
}

/// Bring-up processor: real image statistics of both images (mean, median,
/// gradient energy), no features. Used until a feature processor is wired.
pub struct ImageStatsFactory;

pub struct ImageStats<'a> {
    histogram: &'a mut [u32],
}

impl ProcessorFactory for ImageStatsFactory {
    type Processor<'a> = ImageStats<'a>;
    const KIND: u8 = processor_kind::IMAGE_STATS;

    fn budget(&self, _config: &Configure, budget: &mut MemoryBudget) -> Result<(), BuildError> {
        budget.add(
            "firmware.histogram",
            ComponentKind::Working,
            phototraverse_core::budget::slice_bytes::<u32>(256),
        );
        Ok(())
    }

    fn build<'a>(
        &mut self,
        _config: &Configure,
        arena: &mut Arena<'a>,
    ) -> Result<ImageStats<'a>, BuildError> {
        Ok(ImageStats {
            histogram: arena.alloc_slice::<u32>(256)?,
        })
    }
}

impl ImageStats<'_> {
    /// Mean, median and mean absolute gradient (|dx| + |dy|) of one image.
    fn measure(&mut self, img: &ImageView) -> (f64, u8, f64) {
        self.histogram.fill(0);
        let (w, h) = (img.width(), img.height());
        let (mut sum, mut grad) = (0u64, 0u64);
        for r in 0..h {
            let row = img.row(r);
            let below = if r + 1 < h {
                Some(img.row(r + 1))
            } else {
                None
            };
            for c in 0..w {
                let v = row[c];
                self.histogram[v as usize] += 1;
                sum += v as u64;
                if c + 1 < w {
                    grad += (row[c + 1] as i32 - v as i32).unsigned_abs() as u64;
                }
                if let Some(b) = below {
                    grad += (b[c] as i32 - v as i32).unsigned_abs() as u64;
                }
            }
        }
        let n = (w * h).max(1) as u64;
        let mut acc = 0u64;
        let mut median = 0;
        for (v, &k) in self.histogram.iter().enumerate() {
            acc += k as u64;
            if 2 * acc >= n {
                // The histogram has one bin per grey value.
                median = v as u8;
                break;
            }
        }
        (sum as f64 / n as f64, median, grad as f64 / n as f64)
    }
}

impl EpochProcessor for ImageStats<'_> {
    fn process(&mut self, input: &EpochInput, clock: &dyn Clock) -> EpochOutput {
        let mut timings_us = [0u32; stage::COUNT];
        let t0 = clock.now_us();
        let l = self.measure(&input.left);
        let t1 = clock.now_us();
        let r = self.measure(&input.right);
        let t2 = clock.now_us();
        timings_us[stage::SIFT_LEFT] = (t1 - t0) as u32;
        timings_us[stage::SIFT_RIGHT] = (t2 - t1) as u32;
        let mut result = EpochResult::empty(input.epoch, ResultStatus::StatsOnly);
        result.figures = Figures::ImageStats(messages::ImageStats {
            mean: [l.0, r.0],
            gradient_energy: [l.2, r.2],
            median: [l.1, r.1],
        });
        EpochOutput { result, timings_us }
    }
}
