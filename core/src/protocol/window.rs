//! Selective repeat: the sender's window of encoded packets, each with its own
//! transmission state, and the receiver's reorder ring that holds packets that
//! arrived after a gap. Acknowledgements carry the next expected sequence number
//! and a bitmap of the packets held after it (SACK), so a loss costs the lost
//! packet, not the window behind it.

/// Most slots a window or a reorder ring may have (the SACK bitmap is a `u64`).
pub const MAX_WINDOW: usize = 64;

/// `a - b` in sequence space (u16 wrap-around), as a signed distance.
pub fn seq_diff(a: u16, b: u16) -> i16 {
    a.wrapping_sub(b) as i16
}

/// Slots of `slot_len` bytes in `len` bytes of storage, at most [`MAX_WINDOW`].
fn slot_count(len: usize, slot_len: usize) -> usize {
    len.checked_div(slot_len).unwrap_or(0).min(MAX_WINDOW)
}

/// Later transmissions delivered before an unacknowledged packet is declared lost
/// without waiting for its time-out. Three, as TCP's duplicate acknowledgement
/// threshold: the link may swap neighbouring packets, which is not a loss.
const REORDER_THRESHOLD: u32 = 3;

/// Transmission state of one held packet.
#[derive(Debug, Clone, Copy, Default)]
struct Slot {
    len: u16,
    /// Time of the last transmission, `None` before the first.
    sent_at: Option<u64>,
    /// Order of the last transmission among all transmissions of this window.
    order: u32,
    /// Transmitted more than once (its round trip says nothing: Karn's rule).
    retransmitted: bool,
    /// The receiver holds it (selectively acknowledged).
    sacked: bool,
    /// Declared lost: resend before anything new.
    lost: bool,
}

/// Held packets never sent, held by the receiver (selectively acknowledged), and
/// declared lost: disjoint sets (a packet is sacked or lost only once sent, and a
/// sacked one is not lost). The never-sent ones are the newest: packets are pushed
/// at the end and the first of them goes first.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Tally {
    unsent: usize,
    sacked: usize,
    lost: usize,
}

impl Tally {
    /// The held packet `s` leaves the window.
    fn release(&mut self, s: &Slot) {
        self.unsent -= usize::from(s.sent_at.is_none());
        self.sacked -= usize::from(s.sacked);
        self.lost -= usize::from(s.lost);
    }
}

/// What an acknowledgement did to the window.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AckOutcome {
    /// Packets released (cumulatively acknowledged).
    pub released: usize,
    /// Packets newly held by the receiver (selectively acknowledged).
    pub sacked: usize,
    /// Packets newly declared lost because later ones arrived.
    pub lost: usize,
    /// Round trip of a packet sent once and acknowledged now (µs).
    pub rtt_us: Option<u64>,
}

/// Why a transmission was chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transmission {
    New,
    /// Resent because later packets (or a probe sent after it) arrived and this
    /// one did not.
    Lost,
}

/// A packet could not be held.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WindowError {
    Full,
    /// The encoded packet is larger than a slot.
    TooLarge,
}

/// The sender's selective-repeat window over caller storage cut in equal slots.
pub struct TxWindow<B> {
    storage: B,
    slot_len: usize,
    slots: usize,
    state: [Slot; MAX_WINDOW],
    /// Sequence number of the oldest unacknowledged packet.
    base: u16,
    /// Slot of the oldest packet: the slots are a ring from here, so any slot count
    /// works across the sequence wrap (`seq % slots` would not: 65535 and 0 are
    /// consecutive packets but `65535 % 5 == 0 % 5`).
    head: usize,
    /// Packets held (unacknowledged).
    count: usize,
    /// How many of the held packets are in each state: the sender asks what is due
    /// each time it polls, and counting saves a pass over the window per poll.
    tally: Tally,
    /// Transmissions so far (the order of the next one).
    transmissions: u32,
    /// Start of the retransmission timer: the last progress (an acknowledgement
    /// that released or held something new), the last probe, or the first
    /// transmission into an empty flight; `None` while nothing is in flight.
    timer: Option<u64>,
}

impl<B: AsMut<[u8]> + AsRef<[u8]>> TxWindow<B> {
    /// A window of `storage.len() / slot_len` slots (at most [`MAX_WINDOW`]).
    pub fn new(storage: B, slot_len: usize) -> Self {
        let slots = slot_count(storage.as_ref().len(), slot_len);
        TxWindow {
            storage,
            slot_len,
            slots,
            state: [Slot::default(); MAX_WINDOW],
            base: 0,
            head: 0,
            count: 0,
            tally: Tally::default(),
            transmissions: 0,
            timer: None,
        }
    }

    pub fn capacity(&self) -> usize {
        self.slots
    }

    pub fn len(&self) -> usize {
        self.count
    }

    #[cfg(test)]
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    pub fn is_full(&self) -> bool {
        self.count >= self.slots
    }

    /// Sequence number of the oldest packet held.
    #[cfg(test)]
    pub fn base(&self) -> u16 {
        self.base
    }

    /// Sequence number the next packet pushed gets.
    pub fn next_seq(&self) -> u16 {
        self.base.wrapping_add(self.count as u16)
    }

    /// Forgets everything and restarts at `next_seq`.
    pub fn reset(&mut self, next_seq: u16) {
        self.base = next_seq;
        self.head = 0;
        self.count = 0;
        self.tally = Tally::default();
        self.timer = None;
    }

    /// The slot of the packet `k` places after the oldest (`k < slots`).
    fn slot_at(&self, k: usize) -> usize {
        (self.head + k) % self.slots
    }

    /// Holds a packet with the next sequence number, written by `encode` into the
    /// slot (it returns the bytes written); returns that sequence number.
    pub fn push_with<E>(
        &mut self,
        encode: impl FnOnce(u16, &mut [u8]) -> Result<usize, E>,
    ) -> Result<Result<u16, E>, WindowError> {
        if self.is_full() {
            return Err(WindowError::Full);
        }
        let seq = self.next_seq();
        let i = self.slot_at(self.count);
        let start = i * self.slot_len;
        let slot = &mut self.storage.as_mut()[start..start + self.slot_len];
        let n = match encode(seq, slot) {
            Ok(n) => n,
            Err(e) => return Ok(Err(e)),
        };
        if n > self.slot_len {
            return Err(WindowError::TooLarge);
        }
        self.state[i] = Slot {
            len: n as u16,
            ..Slot::default()
        };
        self.count += 1;
        self.tally.unsent += 1;
        Ok(Ok(seq))
    }

    /// Holds the encoded packet `bytes`; returns its sequence number.
    #[cfg(test)]
    pub fn push(&mut self, bytes: &[u8]) -> Result<u16, WindowError> {
        if bytes.len() > self.slot_len {
            return Err(WindowError::TooLarge);
        }
        self.push_with(|_, slot| {
            slot[..bytes.len()].copy_from_slice(bytes);
            Ok::<_, ()>(bytes.len())
        })
        .map(|r| r.unwrap_or(0))
    }

    /// Applies an acknowledgement: every packet before `next_expected` is
    /// released, and bit `i` of `sack` says the receiver holds `next_expected + 1 + i`.
    /// Stale or bogus acknowledgements (outside the window) release nothing.
    pub fn ack(&mut self, now: u64, next_expected: u16, sack: u64) -> AckOutcome {
        let mut out = AckOutcome::default();
        let mut latest = None::<u32>;
        // Karn's rule for the order as for the round trip: of a packet sent more than once
        // it is not known which copy arrived. Counting its last transmission as delivered
        // declared lost everything sent before a time-out's probe that a busy receiver had
        // simply not reached yet, and the whole window went again.
        let mut note = |s: &Slot, out: &mut AckOutcome| {
            if let (Some(t), false) = (s.sent_at, s.retransmitted) {
                latest = Some(latest.map_or(s.order, |l: u32| l.max(s.order)));
                if out.rtt_us.is_none() {
                    out.rtt_us = Some(now.saturating_sub(t));
                }
            }
        };
        let d = seq_diff(next_expected, self.base);
        if d > 0 && d as usize <= self.count {
            for k in 0..d as usize {
                let s = self.state[self.slot_at(k)];
                if !s.sacked {
                    note(&s, &mut out);
                }
                self.tally.release(&s);
            }
            self.base = next_expected;
            self.head = self.slot_at(d as usize);
            self.count -= d as usize;
            out.released = d as usize;
        }
        // The bitmap is relative to `next_expected`, which may lag our base (an old ack).
        let offset = seq_diff(self.base, next_expected);
        if (0..=MAX_WINDOW as i16).contains(&offset) {
            for k in 0..self.count {
                let bit = k as i16 + offset - 1;
                if !(0..64).contains(&bit) || sack & (1u64 << bit) == 0 {
                    continue;
                }
                let i = self.slot_at(k);
                if !self.state[i].sacked && self.state[i].sent_at.is_some() {
                    let s = self.state[i];
                    note(&s, &mut out);
                    self.state[i].sacked = true;
                    self.state[i].lost = false;
                    self.tally.sacked += 1;
                    self.tally.lost -= usize::from(s.lost);
                    out.sacked += 1;
                }
            }
        }
        if let Some(latest) = latest {
            out.lost = self.mark_lost(latest);
        }
        if out.released + out.sacked > 0 {
            self.timer = self.in_flight().then_some(now);
        }
        out
    }

    /// Whether a packet was sent and neither acknowledged nor declared lost.
    fn in_flight(&self) -> bool {
        let t = self.tally;
        self.count > t.unsent + t.sacked + t.lost
    }

    /// The order the next transmission gets: a probe sent now stands after
    /// every packet sent before it.
    pub fn transmissions(&self) -> u32 {
        self.transmissions
    }

    /// Declares lost every packet in flight sent before the transmission
    /// `order`: the peer answered a probe sent after them and does not hold them.
    pub fn lost_before(&mut self, order: u32) -> usize {
        self.declare_lost(0, |s| (s.order.wrapping_sub(order) as i32) < 0)
    }

    /// Declares lost every packet in flight last sent at or before `time`.
    pub fn lost_sent_by(&mut self, time: u64) -> usize {
        self.declare_lost(0, |s| s.sent_at.is_some_and(|t| t <= time))
    }

    /// Declares lost every packet in flight from the `from`-th held one on for which
    /// `lost_if` holds: the one place where a packet becomes lost, so the tally follows.
    fn declare_lost(&mut self, from: usize, lost_if: impl Fn(&Slot) -> bool) -> usize {
        let mut lost = 0;
        for k in from..self.count {
            let i = self.slot_at(k);
            let s = &mut self.state[i];
            if s.sent_at.is_some() && !s.sacked && !s.lost && lost_if(s) {
                s.lost = true;
                lost += 1;
            }
        }
        self.tally.lost += lost;
        lost
    }

    /// Declares lost the packets sent enough transmissions before the latest one
    /// delivered; with fewer packets in flight after it, any later delivery will do.
    fn mark_lost(&mut self, latest_delivered: u32) -> usize {
        let transmissions = self.transmissions;
        self.declare_lost(0, |s| {
            let after = transmissions.wrapping_sub(s.order).saturating_sub(1);
            let delivered_after = latest_delivered.wrapping_sub(s.order) as i32;
            delivered_after >= REORDER_THRESHOLD.min(after.max(1)) as i32
        })
    }

    /// The next packet to put on the wire at `now`: lost packets first, then
    /// new ones. Records the transmission. A time-out resends only the oldest
    /// packet, with a probe (see [`TxWindow::timer_expired`]); the answer says
    /// what else is lost, so a receiver that was only busy costs one packet.
    /// Returns why it goes and its sequence number ([`TxWindow::packet`] gives its bytes).
    pub fn next_transmission(&mut self, now: u64) -> Option<(Transmission, u16)> {
        let (k, why) = if self.tally.lost > 0 {
            let k = (0..self.count).find(|&k| self.state[self.slot_at(k)].lost)?;
            (k, Transmission::Lost)
        } else if self.tally.unsent > 0 {
            (self.count - self.tally.unsent, Transmission::New)
        } else {
            return None;
        };
        Some((why, self.record(k, now, why != Transmission::New)))
    }

    /// Records a transmission of the packet `k` places after the oldest at
    /// `now`; returns its sequence number.
    fn record(&mut self, k: usize, now: u64, again: bool) -> u16 {
        if self.timer.is_none() {
            self.timer = Some(now);
        }
        let s = &mut self.state[self.slot_at(k)];
        self.tally.unsent -= usize::from(s.sent_at.is_none());
        self.tally.lost -= usize::from(s.lost);
        s.retransmitted |= again;
        s.sent_at = Some(now);
        s.lost = false;
        s.order = self.transmissions;
        self.transmissions = self.transmissions.wrapping_add(1);
        self.base.wrapping_add(k as u16)
    }

    /// Records a resend of the oldest packet in flight (a time-out's probe
    /// carries it: the packet most likely to hold the window up); returns its
    /// sequence number.
    pub fn resend_oldest(&mut self, now: u64) -> Option<u16> {
        let k = (0..self.count).find(|&k| {
            let s = &self.state[self.slot_at(k)];
            s.sent_at.is_some() && !s.sacked
        })?;
        Some(self.record(k, now, true))
    }

    /// The encoded bytes of the held packet `seq`, if it is still held.
    pub fn packet(&self, seq: u16) -> Option<&[u8]> {
        let k = seq_diff(seq, self.base);
        if k < 0 || k as usize >= self.count {
            return None;
        }
        let i = self.slot_at(k as usize);
        let start = i * self.slot_len;
        Some(&self.storage.as_ref()[start..start + self.state[i].len as usize])
    }

    /// When the retransmission timer expires with the time-out `rto`, if
    /// anything is in flight.
    pub fn next_timeout(&self, rto: u64) -> Option<u64> {
        let start = self.timer?;
        self.in_flight().then(|| start.saturating_add(rto))
    }

    /// Whether the timer expired at `now`; if so it restarts (the caller sends
    /// a probe), so one expiry is one event.
    pub fn timer_expired(&mut self, now: u64, rto: u64) -> bool {
        match self.next_timeout(rto) {
            Some(at) if now >= at => {
                self.timer = Some(now);
                true
            }
            _ => false,
        }
    }

    /// Whether a packet waits to be sent or resent without a timer.
    pub fn has_due(&self) -> bool {
        self.tally.unsent + self.tally.lost > 0
    }

    /// Marks every packet in flight from `from` on as lost (the receiver asked
    /// for them again).
    pub fn resend_from(&mut self, from: u16) {
        let skip = seq_diff(from, self.base).clamp(0, self.count as i16) as usize;
        self.declare_lost(skip, |_| true);
    }
}

/// What the receiver did with a sequenced packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Accept {
    /// The next one: deliver it now.
    Deliver,
    /// After a gap: kept in the reorder ring until the gap is filled.
    Held,
    /// Already delivered or already held: dropped.
    Duplicate,
    /// Too far ahead for the ring (or larger than a slot): dropped, to be resent.
    Beyond,
}

/// The receiver's sequencer and reorder ring over caller storage cut in equal
/// slots. Packets are stored decoded (header, payload, CRC), as the decoder
/// left them.
pub struct RxReorder<B> {
    storage: B,
    slot_len: usize,
    slots: usize,
    lens: [u16; MAX_WINDOW],
    expected: u16,
    /// Slot of `expected + 1`.
    head: usize,
    /// Bit `i`: `expected + 1 + i` is held.
    held: u64,
}

impl<B: AsMut<[u8]> + AsRef<[u8]>> RxReorder<B> {
    pub fn new(storage: B, slot_len: usize) -> Self {
        let slots = slot_count(storage.as_ref().len(), slot_len);
        RxReorder {
            storage,
            slot_len,
            slots,
            lens: [0; MAX_WINDOW],
            expected: 0,
            head: 0,
            held: 0,
        }
    }

    pub fn expected(&self) -> u16 {
        self.expected
    }

    /// Packets after `expected` the ring can hold.
    pub fn capacity(&self) -> usize {
        self.slots
    }

    /// Bit `i`: `expected + 1 + i` is held (the SACK bitmap).
    pub fn held(&self) -> u64 {
        self.held
    }

    /// Restarts at `expected` with nothing held (a new session).
    pub fn reset(&mut self, expected: u16) {
        self.expected = expected;
        self.head = 0;
        self.held = 0;
    }

    /// Decides what to do with `packet` (its decoded bytes) numbered `seq`, and
    /// keeps it when it arrived after a gap.
    pub fn accept(&mut self, seq: u16, packet: &[u8]) -> Accept {
        let d = seq_diff(seq, self.expected);
        if d == 0 {
            return Accept::Deliver;
        }
        if d < 0 {
            return Accept::Duplicate;
        }
        let bit = d as usize - 1;
        if bit >= self.slots || packet.len() > self.slot_len {
            return Accept::Beyond;
        }
        if self.held & (1 << bit) != 0 {
            return Accept::Duplicate;
        }
        let i = (self.head + bit) % self.slots;
        let start = i * self.slot_len;
        self.storage.as_mut()[start..start + packet.len()].copy_from_slice(packet);
        self.lens[i] = packet.len() as u16;
        self.held |= 1 << bit;
        Accept::Held
    }

    /// The expected packet was delivered: move on. Returns the slot range of the
    /// next packet when the ring already holds it.
    pub fn advance(&mut self) -> Option<core::ops::Range<usize>> {
        self.expected = self.expected.wrapping_add(1);
        let next = self.held & 1 != 0;
        let i = self.head;
        self.held >>= 1;
        if self.slots > 0 {
            self.head = (self.head + 1) % self.slots;
        }
        next.then(|| i * self.slot_len..i * self.slot_len + self.lens[i] as usize)
    }

    /// Decoded bytes of a held packet (a range from [`RxReorder::advance`]).
    pub fn bytes(&self, range: core::ops::Range<usize>) -> &[u8] {
        &self.storage.as_ref()[range]
    }
}

#[cfg(test)]
mod tests;
