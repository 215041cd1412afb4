//! Spatial grid index over keypoint positions (a counting sort into square buckets),
//! so each query visits only the buckets its search rectangle overlaps.

use super::config::{carve, MatchError};
use crate::budget::Arena;
use crate::features::Keypoint;

/// Keypoint indices bucketed by position; rebuilt for each image searched.
pub struct Grid<'a> {
    cols: usize,
    rows: usize,
    cell: f32,
    /// `start[c]..start[c + 1]` are the entries of bucket `c` in `items`.
    start: &'a mut [u32],
    items: &'a mut [u32],
    len: usize,
}

impl<'a> Grid<'a> {
    pub fn new(
        arena: &mut Arena<'a>,
        cols: usize,
        rows: usize,
        cell_px: u32,
        capacity: usize,
    ) -> Result<Self, MatchError> {
        let start = carve::<u32>(arena, cols * rows + 1)?;
        let items = carve::<u32>(arena, capacity)?;
        Ok(Grid {
            cols,
            rows,
            cell: cell_px.max(1) as f32,
            start,
            items,
            len: 0,
        })
    }

    fn bucket_of(&self, x: f32, y: f32) -> Option<usize> {
        if !(x.is_finite() && y.is_finite()) {
            return None;
        }
        let c = ((x / self.cell).max(0.0) as usize).min(self.cols - 1);
        let r = ((y / self.cell).max(0.0) as usize).min(self.rows - 1);
        Some(r * self.cols + c)
    }

    /// Indexes the first `capacity` keypoints; returns how many were left out
    /// (beyond capacity or with non-finite coordinates).
    pub fn build(&mut self, keypoints: &[Keypoint]) -> usize {
        let n = keypoints.len().min(self.items.len());
        self.start.fill(0);
        let mut skipped = keypoints.len() - n;
        for kp in &keypoints[..n] {
            match self.bucket_of(kp.x, kp.y) {
                Some(b) => self.start[b + 1] += 1,
                None => skipped += 1,
            }
        }
        for b in 1..self.start.len() {
            self.start[b] += self.start[b - 1];
        }
        // Place with a moving cursor per bucket (start[b] walks to the bucket's end) ...
        for (i, kp) in keypoints[..n].iter().enumerate() {
            if let Some(b) = self.bucket_of(kp.x, kp.y) {
                let at = self.start[b] as usize;
                self.items[at] = i as u32;
                self.start[b] += 1;
            }
        }
        // ... then shift the ends back into starts.
        for b in (1..self.start.len()).rev() {
            self.start[b] = self.start[b - 1];
        }
        self.start[0] = 0;
        self.len = self.start[self.start.len() - 1] as usize;
        skipped
    }

    /// Number of indexed keypoints.
    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.len
    }

    /// Calls `f` with every indexed keypoint whose bucket overlaps the rectangle
    /// `[x0, x1] x [y0, y1]` (the caller checks the exact region) until `f` returns false.
    pub fn query(&self, x0: f32, y0: f32, x1: f32, y1: f32, mut f: impl FnMut(u32) -> bool) {
        if !(x0 <= x1 && y0 <= y1) {
            return;
        }
        // Clamping handles infinite bounds; out-of-image keypoints sit in the border buckets.
        let lim_x = self.cols as f32 * self.cell - 1.0;
        let lim_y = self.rows as f32 * self.cell - 1.0;
        let (Some(a), Some(b)) = (
            self.bucket_of(x0.clamp(0.0, lim_x), y0.clamp(0.0, lim_y)),
            self.bucket_of(x1.clamp(0.0, lim_x), y1.clamp(0.0, lim_y)),
        ) else {
            return;
        };
        let (c0, r0) = (a % self.cols, a / self.cols);
        let (c1, r1) = (b % self.cols, b / self.cols);
        for r in r0..=r1 {
            let row = r * self.cols;
            let from = self.start[row + c0] as usize;
            let to = self.start[row + c1 + 1] as usize;
            for &i in &self.items[from..to] {
                if !f(i) {
                    return;
                }
            }
        }
    }
}
