//! Keeping the strongest keypoints spread over a grid of image regions (seed 004's
//! Von Gruber regions): when the set is full, a new keypoint takes the slot of the
//! weakest keypoint of the most populated cell, or is dropped if it would be that one.
//!
//! The decision is made before the descriptor is computed, so rejected candidates
//! cost no descriptor.

use crate::features::FeatureSet;

/// Where a new keypoint goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Admit {
    /// Into slot `i` (a new slot, or one whose previous keypoint is evicted).
    Slot(usize),
    /// Not kept.
    Drop,
}

/// Decides where a keypoint of `cell` with `response` goes; updates the cell counts.
pub fn admit(
    set: &mut FeatureSet,
    cap: usize,
    counts: &mut [u32],
    cell: usize,
    response: f32,
) -> Admit {
    let cell = cell.min(counts.len().saturating_sub(1));
    if counts.is_empty() {
        return Admit::Drop;
    }
    if set.len() < cap {
        if let Some(i) = set.grow() {
            counts[cell] += 1;
            return Admit::Slot(i);
        }
    }
    // The fullest cell, counting the newcomer in its own cell; ties keep its own cell.
    let own = counts[cell] + 1;
    let mut target = cell;
    let mut most = own;
    for (i, &n) in counts.iter().enumerate() {
        if n > most {
            most = n;
            target = i;
        }
    }
    let weakest = weakest_in(set, target).or_else(|| weakest_in_all(set));
    let Some((slot, victim_response, victim_cell)) = weakest else {
        set.dropped += 1;
        return Admit::Drop;
    };
    if target == cell && victim_response >= response {
        set.dropped += 1;
        return Admit::Drop;
    }
    // Evicting from a fuller cell spreads the set even at the cost of response.
    counts[victim_cell as usize] = counts[victim_cell as usize].saturating_sub(1);
    counts[cell] += 1;
    set.dropped += 1;
    Admit::Slot(slot)
}

fn weakest_in(set: &FeatureSet, cell: usize) -> Option<(usize, f32, u16)> {
    let mut best: Option<(usize, f32, u16)> = None;
    for (i, k) in set.keypoints().iter().enumerate() {
        if k.cell as usize == cell && best.is_none_or(|b| k.response < b.1) {
            best = Some((i, k.response, k.cell));
        }
    }
    best
}

fn weakest_in_all(set: &FeatureSet) -> Option<(usize, f32, u16)> {
    let mut best: Option<(usize, f32, u16)> = None;
    for (i, k) in set.keypoints().iter().enumerate() {
        if best.is_none_or(|b| k.response < b.1) {
            best = Some((i, k.response, k.cell));
        }
    }
    best
}
