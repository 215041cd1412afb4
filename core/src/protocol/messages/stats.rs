//! The firmware's statistics after each epoch: stage timings, memory, capacities, stack
//! and link counters.
use super::*;

/// Pipeline stages timed in [`Stats`].
pub mod stage {
    pub const ASSEMBLE: usize = 0;
    pub const SIFT_LEFT: usize = 1;
    pub const SIFT_RIGHT: usize = 2;
    pub const STEREO_MATCH: usize = 3;
    pub const TEMPORAL_MATCH: usize = 4;
    pub const INITIAL_VALUES: usize = 5;
    pub const ADJUST: usize = 6;
    pub const TOTAL: usize = 7;
    pub const COUNT: usize = 8;
    pub const NAMES: [&str; COUNT] = [
        "assemble",
        "sift_left",
        "sift_right",
        "stereo_match",
        "temporal_match",
        "initial_values",
        "adjust",
        "total",
    ];
}

/// Link counters of one side.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LinkCounters {
    pub packets_ok: u32,
    pub crc_errors: u32,
    pub framing_errors: u32,
    pub oversized: u32,
    pub unexpected: u32,
    pub duplicates: u32,
    pub gaps: u32,
    pub retransmissions: u32,
}

impl LinkCounters {
    fn emit(&self, w: &mut Writer) -> Result<(), EncodeError> {
        w.u32s(&[
            self.packets_ok,
            self.crc_errors,
            self.framing_errors,
            self.oversized,
        ])?;
        w.u32s(&[
            self.unexpected,
            self.duplicates,
            self.gaps,
            self.retransmissions,
        ])
    }
    fn parse(r: &mut Reader) -> Result<Self, ParseError> {
        let [packets_ok, crc_errors, framing_errors, oversized, unexpected, duplicates, gaps, retransmissions] =
            r.u32s::<8>()?;
        Ok(LinkCounters {
            packets_ok,
            crc_errors,
            framing_errors,
            oversized,
            unexpected,
            duplicates,
            gaps,
            retransmissions,
        })
    }
}

/// Firmware -> host: timings and memory after an epoch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stats {
    pub epoch: u32,
    /// Microseconds per [`stage`].
    pub timings_us: [u32; stage::COUNT],
    pub memory_predicted: u32,
    /// Measured high-water mark of the working storage.
    pub memory_high_water: u32,
    pub memory_capacity: u32,
    pub epochs_ok: u32,
    pub epochs_lost: u32,
    /// The firmware's receive side and its retransmissions.
    pub link: LinkCounters,
    /// Each [`capacity`]'s highest use so far against what is reserved (zero for a
    /// processor without it).
    pub capacities: [CapacityUse; capacity::COUNT],
    /// The stack's high-water mark, on a target that paints its stack.
    pub stack: Option<StackUse>,
}

/// The capacities whose peak use the firmware reports, in [`Stats::capacities`].
pub mod capacity {
    /// Keypoints of one image (the larger of left and right).
    pub const KEYPOINTS: usize = 0;
    /// Left-right matches of an epoch.
    pub const STEREO_MATCHES: usize = 1;
    /// Live tracks.
    pub const TRACKS: usize = 2;
    /// Tie points linking an epoch to the previous one.
    pub const TIE_POINTS: usize = 3;
    /// Tie points in the adjustment window.
    pub const WINDOW_POINTS: usize = 4;
    /// Image observations in the adjustment window.
    pub const WINDOW_OBSERVATIONS: usize = 5;
    /// Image patches kept for area tracking.
    pub const PATCHES: usize = 6;
    pub const COUNT: usize = 7;
    pub const NAMES: [&str; COUNT] = [
        "keypoints_per_image",
        "stereo_matches",
        "tracks",
        "tie_points",
        "window_points",
        "window_observations",
        "patches",
    ];
}

/// The highest use of a capacity against the items reserved for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CapacityUse {
    pub peak: u32,
    pub reserved: u32,
}

impl CapacityUse {
    /// Raises the peak to `used` if higher.
    pub fn record(&mut self, used: usize) {
        self.peak = self.peak.max(used.min(u32::MAX as usize) as u32);
    }
}

/// The stack's high-water mark, bytes, against the bytes reserved for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StackUse {
    pub used: u32,
    pub reserved: u32,
}

repr!(
    Stats,
    Stats,
    |r| {
        Ok(Stats {
            epoch: r.u32()?,
            timings_us: r.u32s()?,
            memory_predicted: r.u32()?,
            memory_high_water: r.u32()?,
            memory_capacity: r.u32()?,
            epochs_ok: r.u32()?,
            epochs_lost: r.u32()?,
            link: LinkCounters::parse(&mut r)?,
            capacities: {
                let mut c = [CapacityUse::default(); capacity::COUNT];
                for u in c.iter_mut() {
                    *u = CapacityUse {
                        peak: r.u32()?,
                        reserved: r.u32()?,
                    };
                }
                c
            },
            stack: match r.u8()? {
                0 => None,
                1 => Some(StackUse {
                    used: r.u32()?,
                    reserved: r.u32()?,
                }),
                _ => return Err(ParseError::Invalid("stats stack presence")),
            },
        })
    },
    |s, w| {
        w.u32(s.epoch)?;
        w.u32s(&s.timings_us)?;
        w.u32s(&[
            s.memory_predicted,
            s.memory_high_water,
            s.memory_capacity,
            s.epochs_ok,
            s.epochs_lost,
        ])?;
        s.link.emit(&mut w)?;
        for c in &s.capacities {
            w.u32s(&[c.peak, c.reserved])?;
        }
        match s.stack {
            None => w.u8(0)?,
            Some(st) => {
                w.u8(1)?;
                w.u32s(&[st.used, st.reserved])?;
            }
        }
    }
);
