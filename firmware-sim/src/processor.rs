//! Per-epoch processing behind a small trait, so the traverse plugs in without
//! touching the protocol loop. The firmware builds one processor per
//! configuration from its arena and calls it on every complete stereo epoch.
use phototraverse_core::budget::{Arena, ComponentKind, MemoryBudget, OutOfMemory};
use phototraverse_core::image::ImageView;
use phototraverse_core::protocol::messages::{
    processor_kind, stage, status, Aux, Configure, EpochResult,
};

/// A monotonic microsecond clock (the board's timer; `std::time::Instant` on the host).
pub trait Clock {
    fn now_us(&self) -> u64;
}

/// A clock that always reads zero (timings reported as 0).
pub struct NoClock;

impl Clock for NoClock {
    fn now_us(&self) -> u64 {
        0
    }
}

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
    fn budget(&self, config: &Configure, budget: &mut MemoryBudget);
    fn build<'a>(
        &mut self,
        config: &Configure,
        arena: &mut Arena<'a>,
    ) -> Result<Self::Processor<'a>, BuildError>;
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

    fn budget(&self, _config: &Configure, budget: &mut MemoryBudget) {
        budget.add(
            "stats.histogram",
            ComponentKind::Working,
            phototraverse_core::budget::slice_bytes::<u32>(256),
        );
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
    fn measure(&mut self, img: &ImageView) -> [f64; 3] {
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
                median = v;
                break;
            }
        }
        [sum as f64 / n as f64, median as f64, grad as f64 / n as f64]
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
        let mut result = EpochResult::empty(input.epoch, status::STATS_ONLY);
        result.extra = [l[0], l[2], r[0], r[2]];
        result.sigma0 = (l[1] - r[1]).abs();
        EpochOutput { result, timings_us }
    }
}
