//! The compact matcher shared by stereo and temporal matching (LIBVISO2-style):
//! for every query keypoint, the target keypoints inside its search region (found
//! through the [`Grid`]) are compared by descriptor distance; best and second best
//! are kept on both sides, so the mutual check and both ratio tests need no second pass
//! over the descriptors. Mutual best implies one-to-one.

use super::config::NONE;
use super::distance::{distance_bounded, passes_ratio};
use super::grid::Grid;
use crate::features::{Descriptor, Keypoint};
use bytemuck::{Pod, Zeroable};

/// Best and second-best squared descriptor distance seen by one keypoint.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct Best {
    /// Index of the best candidate, [`NONE`] when none was seen.
    pub idx: u32,
    pub d1: u32,
    pub d2: u32,
}

impl Best {
    pub const EMPTY: Best = Best {
        idx: NONE,
        d1: u32::MAX,
        d2: u32::MAX,
    };

    #[inline]
    fn offer(&mut self, idx: u32, d: u32) {
        if d < self.d1 {
            self.d2 = self.d1;
            self.d1 = d;
            self.idx = idx;
        } else if d < self.d2 {
            self.d2 = d;
        }
    }
}

/// Keypoints and descriptors of one image.
#[derive(Debug, Clone, Copy)]
pub struct Features<'k> {
    pub keypoints: &'k [Keypoint],
    pub descriptors: &'k [Descriptor],
}

impl<'k> Features<'k> {
    pub fn new(keypoints: &'k [Keypoint], descriptors: &'k [Descriptor]) -> Self {
        Features {
            keypoints,
            descriptors,
        }
    }

    /// Number of usable features (the shorter slice, capped by `cap`).
    pub fn usable(&self, cap: usize) -> usize {
        self.keypoints.len().min(self.descriptors.len()).min(cap)
    }
}

/// Where the target keypoints of one query may lie.
pub trait SearchRegion {
    /// Per-query data computed once (line coefficients, window centre ...).
    type Query;
    /// The rectangle to scan in the grid and the query data; `None` skips the query.
    fn prepare(&self, qi: usize, q: &Keypoint) -> Option<([f32; 4], Self::Query)>;
    /// The exact test of one candidate.
    fn contains(&self, query: &Self::Query, ti: usize, t: &Keypoint) -> bool;
}

/// What one matching pass did, and how many candidates each test removed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PairStats {
    /// Query keypoints considered.
    pub queries: u32,
    /// Descriptor comparisons (the cost).
    pub comparisons: u32,
    /// Queries whose candidate list hit `max_candidates`.
    pub truncated: u32,
    /// Queries with no candidate in their region.
    pub no_candidate: u32,
    /// Best candidate farther than `max_distance`.
    pub too_far: u32,
    /// Failed the ratio test on the query side.
    pub ambiguous: u32,
    /// Not the target's best (mutual check) or ambiguous on the target side.
    pub not_mutual: u32,
    /// Matches kept.
    pub matches: u32,
}

/// Matching parameters of one pass.
#[derive(Debug, Clone, Copy)]
pub struct PassParams {
    pub ratio: f32,
    pub max_distance: u32,
    pub max_candidates: usize,
}

/// Matches `query` into `target` (indexed by `grid`). On return `out[qi]` is the
/// matched target index or [`NONE`], and `qbest[qi].d1` its distance.
/// `qbest`, `tbest` and `out` must hold at least as many entries as the features used.
#[allow(clippy::too_many_arguments)]
pub fn match_pass<R: SearchRegion>(
    region: &R,
    query: Features<'_>,
    target: Features<'_>,
    nq: usize,
    grid: &Grid<'_>,
    params: PassParams,
    qbest: &mut [Best],
    tbest: &mut [Best],
    out: &mut [u32],
) -> PairStats {
    let mut stats = PairStats::default();
    let nq = nq.min(qbest.len()).min(out.len());
    let nt = target
        .keypoints
        .len()
        .min(target.descriptors.len())
        .min(tbest.len());
    qbest[..nq].fill(Best::EMPTY);
    tbest[..nt].fill(Best::EMPTY);
    out[..nq].fill(NONE);
    let queries = query
        .keypoints
        .iter()
        .zip(query.descriptors)
        .zip(qbest.iter_mut());
    for (qi, ((q, qdesc), slot)) in queries.enumerate().take(nq) {
        let Some((rect, qd)) = region.prepare(qi, q) else {
            continue;
        };
        stats.queries += 1;
        let mut seen = 0usize;
        let mut best = Best::EMPTY;
        grid.query(rect[0], rect[1], rect[2], rect[3], |ti| {
            let ti = ti as usize;
            if ti >= nt || !region.contains(&qd, ti, &target.keypoints[ti]) {
                return true;
            }
            if seen == params.max_candidates {
                stats.truncated += 1;
                return false;
            }
            seen += 1;
            // Values above both second-bests matter to neither side: stop summing there.
            let limit = best.d2.max(tbest[ti].d2);
            let d = distance_bounded(qdesc, &target.descriptors[ti], limit);
            stats.comparisons += 1;
            best.offer(ti as u32, d);
            tbest[ti].offer(qi as u32, d);
            true
        });
        *slot = best;
        if seen == 0 {
            stats.no_candidate += 1;
        }
    }
    for (qi, &b) in qbest[..nq].iter().enumerate() {
        if b.idx == NONE {
            continue;
        }
        if b.d1 > params.max_distance {
            stats.too_far += 1;
        } else if !passes_ratio(b.d1, b.d2, params.ratio) {
            stats.ambiguous += 1;
        } else {
            let t = tbest[b.idx as usize];
            if t.idx != qi as u32 || !passes_ratio(t.d1, t.d2, params.ratio) {
                stats.not_mutual += 1;
            } else {
                out[qi] = b.idx;
                stats.matches += 1;
            }
        }
    }
    stats
}
