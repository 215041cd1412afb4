//! Keypoints and descriptors: the data the extractor (`sift`) hands to `matching`.

use bytemuck::{Pod, Zeroable};

/// One scale-space keypoint.
///
/// Position in the pixel convention of [`crate::image`]: `(0, 0)` is the centre
/// of the top-left pixel, x right (column), y down (row).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct Keypoint {
    /// Column, pixels.
    pub x: f32,
    /// Row, pixels.
    pub y: f32,
    /// Scale: Gaussian sigma in pixels of the input image.
    pub sigma: f32,
    /// Orientation in radians, measured from +x towards +y (image rows down), in `[0, 2 pi)`.
    pub orientation: f32,
    /// Absolute DoG response at the refined extremum (grey levels / 255); ranks keypoints.
    pub response: f32,
    /// Octave (0 = input resolution).
    pub octave: u16,
    /// Region of the spreading grid the keypoint belongs to.
    pub cell: u16,
}

/// A SIFT descriptor: 4x4 spatial cells x 8 orientation bins, quantised to u8.
pub type Descriptor = [u8; 128];

use crate::budget::{slice_bytes, Arena, ComponentKind, MemoryBudget, OutOfMemory};

/// Keypoints with their descriptors in caller storage, with an explicit capacity.
///
/// Slot `i` of [`FeatureSet::keypoints`] pairs with slot `i` of
/// [`FeatureSet::descriptors`]. `dropped` counts candidates that did not fit.
pub struct FeatureSet<'a> {
    keypoints: &'a mut [Keypoint],
    descriptors: &'a mut [Descriptor],
    len: usize,
    /// Candidates refused or evicted because the set was full.
    pub dropped: usize,
}

impl<'a> FeatureSet<'a> {
    /// Predicted bytes of a set of `capacity` features (two arena slices).
    pub fn budget(
        capacity: usize,
        budget: &mut MemoryBudget,
        kp_name: &'static str,
        desc_name: &'static str,
    ) {
        budget.add(
            kp_name,
            ComponentKind::Storage,
            slice_bytes::<Keypoint>(capacity),
        );
        budget.add(
            desc_name,
            ComponentKind::Storage,
            slice_bytes::<Descriptor>(capacity),
        );
    }

    /// Carves storage for `capacity` features.
    pub fn new(arena: &mut Arena<'a>, capacity: usize) -> Result<Self, OutOfMemory> {
        let keypoints = arena.alloc_slice::<Keypoint>(capacity)?;
        let descriptors = arena.alloc_slice::<Descriptor>(capacity)?;
        Ok(FeatureSet {
            keypoints,
            descriptors,
            len: 0,
            dropped: 0,
        })
    }

    /// A set over storage the caller already holds (capacity: the shorter slice).
    pub fn from_slices(keypoints: &'a mut [Keypoint], descriptors: &'a mut [Descriptor]) -> Self {
        FeatureSet {
            keypoints,
            descriptors,
            len: 0,
            dropped: 0,
        }
    }

    pub fn capacity(&self) -> usize {
        self.keypoints.len().min(self.descriptors.len())
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn clear(&mut self) {
        self.len = 0;
        self.dropped = 0;
    }

    pub fn keypoints(&self) -> &[Keypoint] {
        &self.keypoints[..self.len]
    }

    pub fn descriptors(&self) -> &[Descriptor] {
        &self.descriptors[..self.len]
    }

    /// Appends a feature; returns false (and counts it dropped) when full.
    pub fn push(&mut self, kp: Keypoint, desc: &Descriptor) -> bool {
        if self.len >= self.capacity() {
            self.dropped += 1;
            return false;
        }
        self.keypoints[self.len] = kp;
        self.descriptors[self.len] = *desc;
        self.len += 1;
        true
    }

    /// Grows the set by one slot (which the caller fills) and returns its index.
    pub(crate) fn grow(&mut self) -> Option<usize> {
        if self.len >= self.capacity() {
            return None;
        }
        self.len += 1;
        Some(self.len - 1)
    }

    /// Mutable access to one stored slot.
    pub(crate) fn slot_mut(&mut self, i: usize) -> Option<(&mut Keypoint, &mut Descriptor)> {
        if i >= self.len {
            return None;
        }
        Some((&mut self.keypoints[i], &mut self.descriptors[i]))
    }

    /// Sorts the features in place by `key` (ascending), keeping pairs together (heapsort:
    /// no allocation, deterministic).
    pub fn sort_by_key(&mut self, key: impl Fn(&Keypoint) -> (i64, i64)) {
        let n = self.len;
        let swap = |s: &mut Self, a: usize, b: usize| {
            s.keypoints.swap(a, b);
            s.descriptors.swap(a, b);
        };
        let sift_down = |s: &mut Self, mut root: usize, end: usize| loop {
            let mut child = 2 * root + 1;
            if child >= end {
                break;
            }
            if child + 1 < end && key(&s.keypoints[child + 1]) > key(&s.keypoints[child]) {
                child += 1;
            }
            if key(&s.keypoints[root]) >= key(&s.keypoints[child]) {
                break;
            }
            swap(s, root, child);
            root = child;
        };
        for start in (0..n / 2).rev() {
            sift_down(self, start, n);
        }
        for end in (1..n).rev() {
            swap(self, 0, end);
            sift_down(self, 0, end);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn set_counts_drops_and_sorts_pairs() {
        let mut storage = [0u8; 4096];
        let mut arena = Arena::new(&mut storage);
        let mut set = FeatureSet::new(&mut arena, 4).unwrap();
        for i in 0..6 {
            let kp = Keypoint {
                x: (5 - i) as f32,
                ..Default::default()
            };
            set.push(kp, &[i as u8; 128]);
        }
        assert_eq!((set.len(), set.dropped), (4, 2));
        set.sort_by_key(|k| (k.x as i64, 0));
        let xs: [f32; 4] = core::array::from_fn(|i| set.keypoints()[i].x);
        assert_eq!(xs, [2.0, 3.0, 4.0, 5.0]);
        assert_eq!(set.descriptors()[0][0], 3);
        assert_eq!(set.descriptors()[3][5], 0);
    }
}
