//! Tracks: a tie point keeps one identity for as long as its quads keep closing.
//!
//! Fixed capacity: `max_tracks` slots, each with a ring of `history` observations
//! (the adjustment window). Continued tracks are served first; new tracks take free
//! slots in the order the spreading step ranked them (best of every region first), so
//! when the table is full the strongest, best-spread tie points are the ones kept and
//! the rest are counted in [`TrackStats::dropped`].

use super::config::{carve, MatchError, NONE};
use super::quad::Quad;
use crate::budget::Arena;
use bytemuck::{Pod, Zeroable};

/// One track slot.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct Track {
    /// Persistent identity ([`NONE`] for a free slot).
    pub id: u32,
    pub first_epoch: u32,
    pub last_epoch: u32,
    /// Epochs observed.
    pub length: u32,
}

impl Track {
    pub const FREE: Track = Track {
        id: NONE,
        first_epoch: 0,
        last_epoch: 0,
        length: 0,
    };

    pub fn is_live(&self) -> bool {
        self.id != NONE
    }
}

/// A track's stereo observation at one epoch (pixel positions, left and right).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct Observation {
    pub epoch: u32,
    pub left: [f32; 2],
    pub right: [f32; 2],
    /// Standard deviations (pixels; x, y) of `right` as its stereo correlation gave
    /// them ([`super::refine::Peak`]); zero where none measured it (a right
    /// keypoint's own position).
    pub right_sigma: [f32; 2],
}

/// One epoch's stereo positions of a point: left and right pixels, and the right
/// one's precision from its stereo correlation (pixels; x, y; zero: not measured).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct StereoPx {
    pub left: [f32; 2],
    pub right: [f32; 2],
    pub right_sigma: [f32; 2],
}

impl Observation {
    /// The observation's positions.
    pub fn px(&self) -> StereoPx {
        StereoPx {
            left: self.left,
            right: self.right,
            right_sigma: self.right_sigma,
        }
    }
}

/// What one update did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TrackStats {
    pub continued: u32,
    pub started: u32,
    /// Tracks not seen this epoch (their slots were freed).
    pub ended: u32,
    /// New tie points that found no free slot.
    pub dropped: u32,
    /// Live tracks after the update.
    pub live: u32,
}

/// The track table.
pub struct Tracks<'a> {
    slots: &'a mut [Track],
    obs: &'a mut [Observation],
    history: usize,
    next_id: u32,
    /// Sum of the lengths of ended tracks and their number (mean track length).
    ended_length: u64,
    ended_count: u64,
}

impl<'a> Tracks<'a> {
    pub fn new(arena: &mut Arena<'a>, capacity: usize, history: usize) -> Result<Self, MatchError> {
        let slots = carve::<Track>(arena, capacity)?;
        slots.fill(Track::FREE);
        let obs = carve::<Observation>(arena, capacity * history)?;
        Ok(Tracks {
            slots,
            obs,
            history,
            next_id: 0,
            ended_length: 0,
            ended_count: 0,
        })
    }

    pub fn slots(&self) -> &[Track] {
        self.slots
    }

    pub fn capacity(&self) -> usize {
        self.slots.len()
    }

    /// The observation of track slot `slot` at `epoch`, if it is still in the ring.
    pub fn observation(&self, slot: u32, epoch: u32) -> Option<Observation> {
        let t = self.slots.get(slot as usize)?;
        if !t.is_live() || epoch < t.first_epoch || epoch > t.last_epoch {
            return None;
        }
        let o = self.obs[slot as usize * self.history + epoch as usize % self.history];
        (o.epoch == epoch).then_some(o)
    }

    /// Replaces the observation of track `slot` at `o.epoch` (a later refinement of
    /// the same observation); false when the track has no observation there.
    pub fn set_observation(&mut self, slot: u32, o: Observation) -> bool {
        if self.observation(slot, o.epoch).is_none() {
            return false;
        }
        self.record(slot as usize, o);
        true
    }

    /// Mean length (epochs) over every track that ended so far and the live ones.
    pub fn mean_length(&self) -> f64 {
        let (mut sum, mut n) = (self.ended_length, self.ended_count);
        for t in self.slots.iter().filter(|t| t.is_live()) {
            sum += t.length as u64;
            n += 1;
        }
        if n == 0 {
            0.0
        } else {
            sum as f64 / n as f64
        }
    }

    fn record(&mut self, slot: usize, o: Observation) {
        self.obs[slot * self.history + o.epoch as usize % self.history] = o;
    }

    /// Applies the selected quads of `epoch` (`epoch >= 1`): continues the tracks the
    /// quads carry (`quad.track`), ends the others, then starts new tracks for the rest
    /// in order. `position(quad)` gives (previous, current) observations; each quad's
    /// `track` field is set to its slot, or [`NONE`] when it was dropped.
    pub fn update(
        &mut self,
        epoch: u32,
        quads: &mut [Quad],
        mut position: impl FnMut(&Quad) -> (Observation, Observation),
    ) -> TrackStats {
        let mut stats = TrackStats::default();
        let prev = epoch.wrapping_sub(1);
        for q in quads.iter_mut() {
            let slot = q.track as usize;
            if q.track == NONE
                || slot >= self.slots.len()
                || !self.slots[slot].is_live()
                || self.slots[slot].last_epoch != prev
            {
                q.track = NONE;
                continue;
            }
            let (_, cur) = position(q);
            let t = &mut self.slots[slot];
            t.last_epoch = epoch;
            t.length += 1;
            self.record(slot, cur);
            stats.continued += 1;
        }
        for t in self.slots.iter_mut() {
            if t.is_live() && t.last_epoch != epoch {
                self.ended_length += t.length as u64;
                self.ended_count += 1;
                *t = Track::FREE;
                stats.ended += 1;
            }
        }
        let mut cursor = 0usize;
        for q in quads.iter_mut() {
            if q.track != NONE {
                continue;
            }
            while cursor < self.slots.len() && self.slots[cursor].is_live() {
                cursor += 1;
            }
            if cursor == self.slots.len() {
                stats.dropped += 1;
                continue;
            }
            let (p, c) = position(q);
            self.slots[cursor] = Track {
                id: self.allocate_id(),
                first_epoch: prev,
                last_epoch: epoch,
                length: 2,
            };
            self.record(cursor, p);
            self.record(cursor, c);
            q.track = cursor as u32;
            stats.started += 1;
        }
        stats.live = self.slots.iter().filter(|t| t.is_live()).count() as u32;
        stats
    }

    /// A fresh identity: for a new track, and for a tie point followed outside the
    /// table (by area matching), so every tie point of the traverse keeps a distinct id.
    pub fn allocate_id(&mut self) -> u32 {
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1) % NONE;
        id
    }

    /// Ends every track (for example after a frame from another place broke the chain).
    pub fn clear(&mut self) {
        for t in self.slots.iter_mut().filter(|t| t.is_live()) {
            self.ended_length += t.length as u64;
            self.ended_count += 1;
            *t = Track::FREE;
        }
    }
}
