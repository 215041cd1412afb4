//! Spreading the tie points of an epoch over a grid of image regions (seed 004's Von
//! Gruber regions): candidates are ranked inside their region, then taken round-robin
//! (every region's best, then every region's second ...), so near (bottom rows) and
//! far (upper rows), left and right are all covered before any region gets more.

use super::quad::Quad;
use crate::features::Keypoint;

/// Cell of a position on a `cols x rows` grid over a `width x height` image.
pub fn region_of(x: f32, y: f32, width: u32, height: u32, cols: u16, rows: u16) -> u32 {
    let fx = if x.is_finite() {
        x / width.max(1) as f32
    } else {
        0.0
    };
    let fy = if y.is_finite() {
        y / height.max(1) as f32
    } else {
        0.0
    };
    let c = ((fx * cols as f32).max(0.0) as u32).min(cols as u32 - 1);
    let r = ((fy * rows as f32).max(0.0) as u32).min(rows as u32 - 1);
    r * cols as u32 + c
}

/// Priority inside a region: continued (older) tracks first, then lower match cost.
fn priority(q: &Quad) -> u64 {
    ((u32::MAX - q.age) as u64) << 32 | q.cost as u64
}

/// Reorders `quads` so the first `keep` are the spread selection (round-robin over the
/// regions by priority) and returns `keep = min(len, max)`. `ranks` is scratch of at
/// least `quads.len()` entries.
pub fn spread(
    quads: &mut [Quad],
    cur_left: &[Keypoint],
    size: (u32, u32),
    grid: (u16, u16),
    max: usize,
    ranks: &mut [u32],
) -> usize {
    let region = |q: &Quad| {
        cur_left
            .get(q.cur_left as usize)
            .map(|k| region_of(k.x, k.y, size.0, size.1, grid.0, grid.1))
            .unwrap_or(0)
    };
    quads.sort_unstable_by_key(|q| (region(q), priority(q)));
    // Rank of each quad inside its region.
    let mut prev_region = u32::MAX;
    let mut rank = 0u32;
    for (q, r) in quads.iter().zip(ranks.iter_mut()) {
        let reg = region(q);
        rank = if reg == prev_region { rank + 1 } else { 0 };
        prev_region = reg;
        *r = rank;
    }
    // Round-robin order: by rank inside the region, then by priority.
    let n = quads.len().min(ranks.len());
    sort_by_rank(&mut quads[..n], &mut ranks[..n]);
    quads.len().min(max)
}

/// Sorts `quads` by `(ranks, priority)` keeping `ranks` aligned (heap sort, in place, no alloc).
fn sort_by_rank(quads: &mut [Quad], ranks: &mut [u32]) {
    let key = |q: &Quad, r: u32| ((r as u128) << 64) | priority(q) as u128;
    let n = quads.len();
    let sift = |quads: &mut [Quad], ranks: &mut [u32], mut root: usize, end: usize| loop {
        let mut child = 2 * root + 1;
        if child >= end {
            break;
        }
        if child + 1 < end
            && key(&quads[child + 1], ranks[child + 1]) > key(&quads[child], ranks[child])
        {
            child += 1;
        }
        if key(&quads[root], ranks[root]) >= key(&quads[child], ranks[child]) {
            break;
        }
        quads.swap(root, child);
        ranks.swap(root, child);
        root = child;
    };
    for start in (0..n / 2).rev() {
        sift(quads, ranks, start, n);
    }
    for end in (1..n).rev() {
        quads.swap(0, end);
        ranks.swap(0, end);
        sift(quads, ranks, 0, end);
    }
}
