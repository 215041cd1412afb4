//! Squared Euclidean distance between u8 descriptors with an early exit.
//!
//! The sum is taken in four blocks of 32 bytes; after each block the partial sum is
//! compared with the caller's limit (the current second-best distance), so most
//! non-matching candidates are dropped after a quarter or half of the descriptor.

use crate::features::Descriptor;

/// Bytes summed between two limit checks.
const BLOCK: usize = 32;

/// Squared L2 distance, or any value `> limit` as soon as the partial sum exceeds `limit`.
#[inline]
pub fn distance_bounded(a: &Descriptor, b: &Descriptor, limit: u32) -> u32 {
    let mut sum = 0u32;
    for (ca, cb) in a.chunks_exact(BLOCK).zip(b.chunks_exact(BLOCK)) {
        sum += block_ssd(ca, cb);
        if sum > limit {
            return sum;
        }
    }
    sum
}

/// Full squared L2 distance (max 128 * 255^2, fits in u32): the reference of the
/// bounded kernel's tests.
#[cfg(test)]
pub fn distance(a: &Descriptor, b: &Descriptor) -> u32 {
    distance_bounded(a, b, u32::MAX)
}

#[inline]
fn block_ssd(a: &[u8], b: &[u8]) -> u32 {
    // i32 lanes let the compiler vectorise the differences; 32 * 255^2 fits easily.
    let mut s = 0i32;
    for (&x, &y) in a.iter().zip(b.iter()) {
        let d = x as i32 - y as i32;
        s += d * d;
    }
    s as u32
}

/// Lowe's ratio test on squared distances: `sqrt(d1) < ratio * sqrt(d2)`.
/// Strict, so two equally good candidates (for example identical descriptors) fail.
#[inline]
pub fn passes_ratio(d1: u32, d2: u32, ratio: f32) -> bool {
    if d2 == u32::MAX {
        return true;
    }
    (d1 as f64) < (ratio as f64) * (ratio as f64) * (d2 as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_and_early_exit() {
        let mut a = [0u8; 128];
        let mut b = [0u8; 128];
        for i in 0..128 {
            a[i] = (i * 2) as u8;
            b[i] = (i * 2 + (i % 3)) as u8;
        }
        let full: u32 = (0..128).map(|i| ((i % 3) * (i % 3)) as u32).sum();
        assert_eq!(distance(&a, &b), full);
        assert_eq!(distance(&a, &a), 0);
        let far = [255u8; 128];
        let zero = [0u8; 128];
        assert_eq!(distance(&far, &zero), 128 * 255 * 255);
        // Early exit: first block already exceeds the limit, so only 32 bytes were summed.
        assert_eq!(distance_bounded(&far, &zero, 10), 32 * 255 * 255);
        // Under the limit: the exact value.
        assert_eq!(distance_bounded(&a, &b, full), full);
    }

    #[test]
    fn ratio_is_strict() {
        assert!(!passes_ratio(0, 0, 0.8));
        assert!(passes_ratio(5, u32::MAX, 0.8));
        assert!(passes_ratio(63, 100, 0.8));
        assert!(!passes_ratio(65, 100, 0.8));
    }
}
