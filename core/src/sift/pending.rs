//! Refined keypoint candidates waiting until the rows of their orientation and
//! descriptor neighbourhood have entered the Gaussian rings (a bounded FIFO).

use bytemuck::{Pod, Zeroable};

/// A refined candidate in octave coordinates.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct Pending {
    /// Column, octave pixels.
    pub x: f32,
    /// Row, octave pixels.
    pub y: f32,
    /// Refined layer (continuous, in `[0.5, levels + 0.5)`).
    pub layer: f32,
    /// |DoG| at the refined extremum, grey levels / 255.
    pub response: f32,
    /// Detection row: the candidate is processed once this row is `margin` rows old.
    pub row: i32,
    /// Gaussian level whose image the orientation and descriptor sample.
    pub level: u32,
}

/// A fixed-capacity FIFO over caller storage.
pub struct PendingQueue<'a> {
    slots: &'a mut [Pending],
    head: usize,
    len: usize,
}

impl<'a> PendingQueue<'a> {
    pub fn new(slots: &'a mut [Pending]) -> Self {
        PendingQueue {
            slots,
            head: 0,
            len: 0,
        }
    }

    pub fn clear(&mut self) {
        self.head = 0;
        self.len = 0;
    }

    #[cfg(test)]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Appends; returns false (and keeps nothing) when full.
    pub fn push(&mut self, p: Pending) -> bool {
        let cap = self.slots.len();
        if self.len >= cap {
            return false;
        }
        let i = (self.head + self.len) % cap;
        self.slots[i] = p;
        self.len += 1;
        true
    }

    /// Oldest entry, if any.
    pub fn front(&self) -> Option<Pending> {
        if self.len == 0 {
            None
        } else {
            Some(self.slots[self.head])
        }
    }

    pub fn pop(&mut self) -> Option<Pending> {
        let p = self.front()?;
        self.head = (self.head + 1) % self.slots.len();
        self.len -= 1;
        Some(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fifo_wraps_and_refuses_when_full() {
        let mut store = [Pending::default(); 3];
        let mut q = PendingQueue::new(&mut store);
        for i in 0..3 {
            assert!(q.push(Pending {
                row: i,
                ..Default::default()
            }));
        }
        assert!(!q.push(Pending {
            row: 9,
            ..Default::default()
        }));
        assert_eq!(q.pop().unwrap().row, 0);
        assert!(q.push(Pending {
            row: 3,
            ..Default::default()
        }));
        let rows: [i32; 3] = core::array::from_fn(|_| q.pop().unwrap().row);
        assert_eq!(rows, [1, 2, 3]);
        assert!(q.is_empty() && q.pop().is_none());
    }
}
