//! Quad consistency (seed 000's "seen in all four images", LIBVISO2's circle match):
//! starting from a stereo match (left_{k-1}, right_{k-1}), the temporal match of each
//! side and the current stereo match must close the loop
//! `left_{k-1} -> left_k -> right_k <- right_{k-1} <- left_{k-1}`.

use super::config::NONE;
use bytemuck::{Pod, Zeroable};

/// One tie point candidate seen in the four images (keypoint indices).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct Quad {
    pub prev_left: u32,
    pub prev_right: u32,
    pub cur_left: u32,
    pub cur_right: u32,
    /// Sum of the four descriptor distances (lower is better).
    pub cost: u32,
    /// Track slot continued by this quad, or [`NONE`] for a new tie point.
    pub track: u32,
    /// Epochs the continued track has been seen (0 for a new one): longer tracks rank first.
    pub age: u32,
}

/// How many stereo matches of the previous epoch each loop check removed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct QuadStats {
    /// Stereo matches of the previous epoch (the loop starts).
    pub candidates: u32,
    /// No temporal match of the left keypoint.
    pub no_left_temporal: u32,
    /// No temporal match of the right keypoint.
    pub no_right_temporal: u32,
    /// The left keypoint's current match has no stereo match.
    pub no_current_stereo: u32,
    /// Current stereo match and right temporal match disagree: the loop does not close.
    pub loop_open: u32,
    /// Quads that closed.
    pub closed: u32,
    /// Closed quads that did not fit the quad buffer.
    pub overflow: u32,
    /// Closed quads inconsistent with the epoch's rigid motion (removed).
    pub motion_outliers: u32,
}

/// Distances of the matches that make up a quad (for the cost).
pub struct LoopDistances<'a> {
    pub prev_stereo: &'a [u32],
    pub left_temporal: &'a [u32],
    pub right_temporal: &'a [u32],
    pub cur_stereo: &'a [u32],
}

/// Closes the loops. `prev_stereo[i]`: right index of previous left `i`;
/// `left_temporal[i]`: current left index of previous left `i`; `right_temporal[j]`:
/// current right index of previous right `j`; `cur_stereo[a]`: current right index of
/// current left `a`. Writes the closed quads to `out` and returns their number.
pub fn close_loops(
    prev_stereo: &[u32],
    left_temporal: &[u32],
    right_temporal: &[u32],
    cur_stereo: &[u32],
    dist: &LoopDistances<'_>,
    out: &mut [Quad],
    stats: &mut QuadStats,
) -> usize {
    let get = |s: &[u32], i: u32| {
        if i == NONE {
            NONE
        } else {
            s.get(i as usize).copied().unwrap_or(NONE)
        }
    };
    let mut n = 0;
    for (i, &j) in prev_stereo.iter().enumerate() {
        if j == NONE {
            continue;
        }
        stats.candidates += 1;
        let a = get(left_temporal, i as u32);
        if a == NONE {
            stats.no_left_temporal += 1;
            continue;
        }
        let b = get(right_temporal, j);
        if b == NONE {
            stats.no_right_temporal += 1;
            continue;
        }
        let b2 = get(cur_stereo, a);
        if b2 == NONE {
            stats.no_current_stereo += 1;
            continue;
        }
        if b2 != b {
            stats.loop_open += 1;
            continue;
        }
        stats.closed += 1;
        if n == out.len() {
            stats.overflow += 1;
            continue;
        }
        let d = |s: &[u32], k: u32| s.get(k as usize).copied().unwrap_or(0);
        let cost = d(dist.prev_stereo, i as u32)
            .saturating_add(d(dist.left_temporal, i as u32))
            .saturating_add(d(dist.right_temporal, j))
            .saturating_add(d(dist.cur_stereo, a));
        out[n] = Quad {
            prev_left: i as u32,
            prev_right: j,
            cur_left: a,
            cur_right: b,
            cost,
            track: NONE,
            age: 0,
        };
        n += 1;
    }
    n
}
