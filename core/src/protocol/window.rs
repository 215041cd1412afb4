//! Reliability: a go-back-N sender window that keeps encoded packets until
//! they are acknowledged, and the receiver's in-order sequencer. The receiver
//! needs no buffer beyond the decoder's: out-of-order packets are dropped and
//! recovered by retransmission, so a firmware pays only for its own window.

/// Most slots a window may have.
pub const MAX_WINDOW: usize = 64;

/// `a - b` in sequence space (u16 wrap-around), as a signed distance.
pub fn seq_diff(a: u16, b: u16) -> i16 {
    a.wrapping_sub(b) as i16
}

/// The sender's retransmission window over caller storage cut in equal slots.
pub struct TxWindow<'a> {
    storage: &'a mut [u8],
    slot_len: usize,
    slots: usize,
    lens: [u16; MAX_WINDOW],
    /// Sequence number of the oldest unacknowledged packet.
    base: u16,
    /// Slot of the oldest packet: the slots are a ring from here, so any slot count
    /// works across the sequence wrap (`seq % slots` would not: 65535 and 0 are
    /// consecutive packets but `65535 % 5 == 0 % 5`).
    head: usize,
    /// Packets held (unacknowledged).
    count: usize,
}

/// A packet could not be held.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WindowError {
    Full,
    /// The encoded packet is larger than a slot.
    TooLarge,
    /// The sequence number is not the next one after those held.
    OutOfSequence,
}

impl<'a> TxWindow<'a> {
    /// A window of `storage.len() / slot_len` slots (at most [`MAX_WINDOW`]).
    pub fn new(storage: &'a mut [u8], slot_len: usize) -> Self {
        let slots = storage
            .len()
            .checked_div(slot_len)
            .unwrap_or(0)
            .min(MAX_WINDOW);
        TxWindow {
            storage,
            slot_len,
            slots,
            lens: [0; MAX_WINDOW],
            base: 0,
            head: 0,
            count: 0,
        }
    }

    pub fn capacity(&self) -> usize {
        self.slots
    }

    pub fn len(&self) -> usize {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    pub fn is_full(&self) -> bool {
        self.count >= self.slots
    }

    /// Sequence number of the oldest packet held.
    pub fn base(&self) -> u16 {
        self.base
    }

    /// Forgets everything and restarts at `next_seq`.
    pub fn reset(&mut self, next_seq: u16) {
        self.base = next_seq;
        self.head = 0;
        self.count = 0;
    }

    /// The slot of the packet `k` places after the oldest (`k < slots`).
    fn slot_at(&self, k: usize) -> usize {
        (self.head + k) % self.slots
    }

    /// Holds the encoded packet `bytes` sent with sequence number `seq`.
    pub fn push(&mut self, seq: u16, bytes: &[u8]) -> Result<(), WindowError> {
        if self.is_full() {
            return Err(WindowError::Full);
        }
        if bytes.len() > self.slot_len {
            return Err(WindowError::TooLarge);
        }
        if seq != self.base.wrapping_add(self.count as u16) {
            return Err(WindowError::OutOfSequence);
        }
        let i = self.slot_at(self.count);
        let start = i * self.slot_len;
        self.storage[start..start + bytes.len()].copy_from_slice(bytes);
        self.lens[i] = bytes.len() as u16;
        self.count += 1;
        Ok(())
    }

    /// Releases every packet before `next_expected`; returns how many. Stale or
    /// bogus acknowledgements (outside the window) release nothing.
    pub fn ack(&mut self, next_expected: u16) -> usize {
        let d = seq_diff(next_expected, self.base);
        if d <= 0 || d as usize > self.count {
            return 0;
        }
        self.base = next_expected;
        self.head = self.slot_at(d as usize);
        self.count -= d as usize;
        d as usize
    }

    /// The held packets from `from` (or the oldest when `from` is older) in order.
    pub fn unacked_from(&self, from: u16) -> impl Iterator<Item = &[u8]> + '_ {
        let skip = seq_diff(from, self.base).clamp(0, self.count as i16) as usize;
        (skip..self.count).map(move |k| {
            let i = self.slot_at(k);
            let start = i * self.slot_len;
            &self.storage[start..start + self.lens[i] as usize]
        })
    }
}

/// What the receiver does with a sequenced packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Accept {
    /// The next one: deliver it.
    Deliver,
    /// Already delivered: drop it, acknowledge again.
    Duplicate,
    /// Something before it is missing: drop it; `nack` says whether to ask for
    /// a retransmission now (rate-limited).
    Gap { nack: bool },
}

/// The receiver's in-order sequencer with a rate-limited negative acknowledgement.
#[derive(Debug, Clone, Copy, Default)]
pub struct RxSequence {
    expected: u16,
    /// Packets dropped since the last nack for `expected`, or `None` when no nack is pending.
    since_nack: Option<u16>,
    /// Re-ask after this many further dropped packets (a lost retransmission).
    renack_after: u16,
}

impl RxSequence {
    pub fn new(renack_after: u16) -> Self {
        RxSequence {
            expected: 0,
            since_nack: None,
            renack_after: renack_after.max(1),
        }
    }

    pub fn expected(&self) -> u16 {
        self.expected
    }

    /// Restarts at `expected` (a new session).
    pub fn reset(&mut self, expected: u16) {
        self.expected = expected;
        self.since_nack = None;
    }

    pub fn accept(&mut self, seq: u16) -> Accept {
        let d = seq_diff(seq, self.expected);
        if d == 0 {
            self.expected = self.expected.wrapping_add(1);
            self.since_nack = None;
            Accept::Deliver
        } else if d < 0 {
            Accept::Duplicate
        } else {
            Accept::Gap {
                nack: self.should_nack(),
            }
        }
    }

    /// A corrupted packet arrived: whether to nack now.
    pub fn corrupted(&mut self) -> bool {
        self.should_nack()
    }

    fn should_nack(&mut self) -> bool {
        match self.since_nack {
            None => {
                self.since_nack = Some(0);
                true
            }
            Some(n) if n + 1 >= self.renack_after => {
                self.since_nack = Some(0);
                true
            }
            Some(n) => {
                self.since_nack = Some(n + 1);
                false
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_holds_acks_and_replays() {
        let mut storage = [0u8; 4 * 8];
        let mut w = TxWindow::new(&mut storage, 8);
        w.reset(65534);
        for (k, seq) in [65534u16, 65535, 0, 1].iter().enumerate() {
            w.push(*seq, &[k as u8; 3]).unwrap();
        }
        assert!(w.is_full());
        assert_eq!(w.push(2, &[9]), Err(WindowError::Full));
        assert_eq!(w.ack(65533), 0, "stale ack");
        assert_eq!(w.ack(5), 0, "ack beyond what was sent");
        assert_eq!(w.ack(0), 2, "ack across the wrap");
        let replay: heapless::Vec<u8, 8> = w.unacked_from(0).map(|p| p[0]).collect();
        assert_eq!(&replay[..], &[2, 3]);
        assert_eq!(w.unacked_from(1).count(), 1);
        assert_eq!(w.push(3, &[1]), Err(WindowError::OutOfSequence));
        w.push(2, &[4]).unwrap();
        assert_eq!(w.ack(3), 3);
        assert!(w.is_empty());
    }

    #[test]
    fn any_slot_count_keeps_every_packet_across_the_wrap() {
        // Five slots: with `seq % slots`, 65535 and 0 would share a slot.
        for slots in [3usize, 5, 7] {
            let mut storage = [0u8; 7 * 4];
            let mut w = TxWindow::new(&mut storage[..slots * 4], 4);
            w.reset(65530);
            let mut next = 65530u16;
            let mut acked = next;
            for round in 0..20u8 {
                while !w.is_full() {
                    w.push(next, &[next as u8, round]).unwrap();
                    next = next.wrapping_add(1);
                }
                // Everything held replays in order, each packet its own bytes.
                let held: heapless::Vec<u8, 8> = w.unacked_from(acked).map(|p| p[0]).collect();
                let want: heapless::Vec<u8, 8> = (0..slots as u16)
                    .map(|k| acked.wrapping_add(k) as u8)
                    .collect();
                assert_eq!(held, want, "{slots} slots, round {round}");
                // Acknowledge one or two, as a receiver would.
                acked = acked.wrapping_add(1 + (round % 2) as u16);
                w.ack(acked);
            }
        }
    }

    #[test]
    fn sequencer_delivers_in_order_and_limits_nacks() {
        let mut r = RxSequence::new(3);
        assert_eq!(r.accept(0), Accept::Deliver);
        assert_eq!(r.accept(0), Accept::Duplicate);
        assert_eq!(r.accept(2), Accept::Gap { nack: true });
        assert_eq!(r.accept(3), Accept::Gap { nack: false });
        assert_eq!(r.accept(4), Accept::Gap { nack: false });
        assert_eq!(
            r.accept(5),
            Accept::Gap { nack: true },
            "re-ask after 3 more drops"
        );
        assert_eq!(r.accept(1), Accept::Deliver);
        assert_eq!(
            r.accept(3),
            Accept::Gap { nack: true },
            "a new gap nacks at once"
        );
    }
}
