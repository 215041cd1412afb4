//! The reliable endpoint, sans-IO: bytes in ([`Endpoint::receive`]), bytes out
//! ([`Endpoint::poll_transmit`]), messages delivered in order, time from the
//! caller's clock. Both the firmware's link and the host's session drive one;
//! neither keeps any reliability logic of its own.
//!
//! - Selective repeat: the sender resends only what the receiver's SACK bitmap
//!   says is missing, the receiver holds packets that arrived after a gap.
//! - Retransmission time-out from measured round trips (RFC 6298), doubled on
//!   each time-out and reset by progress. A time-out sends a probe and the
//!   oldest packet, not the window: the peer's answer says what else is lost, so
//!   a peer that was only busy costs one packet per time-out.
//! - The receiver reports how many packets arrived damaged; the sender turns that
//!   into a per-byte error rate and advises the payload size with the best
//!   goodput ([`Outbound::advised_payload`]), so a noisy line gets short packets.
//!
//! Storage comes from the caller ([`EndpointBuffers`]): `&mut [u8]` on the
//! firmware, `Vec<u8>` on the host. Nothing allocates.
use super::decoder::{DecodeError, Decoder};
use super::messages::{nack_reason, Ack, LinkCounters, Message, MessageType, Nack, ParseError};
use super::packet::{encode_packet, Header, PacketError};
use super::window::{Accept, RxReorder, Transmission, TxWindow, WindowError};
use super::{CRC_LEN, HEADER_LEN};
use core::ops::Range;

/// Tuning of an endpoint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EndpointConfig {
    /// Sequenced packets delivered between acknowledgements while input keeps coming.
    pub ack_every: u16,
    /// Free transmit slots needed before a sequenced packet is delivered: the most
    /// packets the application sends in answer to one message.
    pub tx_reserve: usize,
    /// Lower bound of the retransmission time-out (µs).
    pub min_rto_us: u64,
    /// Upper bound of the retransmission time-out with back-off (µs).
    pub max_rto_us: u64,
    /// Largest payload this endpoint emits (its transmit slots' size).
    pub max_payload: usize,
}

impl Default for EndpointConfig {
    fn default() -> Self {
        EndpointConfig {
            ack_every: 8,
            tx_reserve: 1,
            min_rto_us: 20_000,
            max_rto_us: 3_200_000,
            max_payload: super::MAX_PAYLOAD,
        }
    }
}

/// Caller storage of an endpoint.
pub struct EndpointBuffers<B> {
    /// Decoder buffer: [`super::MAX_ENCODED`] accepts every legal packet in order.
    pub decode: B,
    /// Reorder ring: equal slots of decoded packets held after a gap.
    pub reorder: B,
    /// Length of a reorder slot (a decoded packet: header, payload, CRC).
    pub reorder_slot: usize,
    /// Transmit window: equal slots of encoded packets kept until acknowledged.
    pub window: B,
    /// Length of a transmit slot (an encoded packet with its delimiter).
    pub window_slot: usize,
    /// Encoder scratch (header, payload and CRC of the largest packet sent).
    pub raw: B,
}

/// Something [`Endpoint::receive`] has for the application.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    /// The next message in order is ready: [`Inbound::message`].
    Message { seq: u16 },
    /// An intact packet of another protocol version arrived.
    Version(u8),
}

/// Why a message could not be sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SendError {
    /// The window is full: receive (acknowledgements free it) and try again.
    Full,
    /// The message does not fit in a transmit slot or the payload limit.
    TooLarge,
}

/// The receiving half: decoder, reorder ring, the message being delivered.
pub struct Inbound<B> {
    decoder: Decoder<B>,
    reorder: RxReorder<B>,
    /// Where the message being delivered sits: the decoder (`None`) or a ring slot.
    current: Option<Option<Range<usize>>>,
    current_seq: u16,
    /// The ring already holds the next message in order.
    ready: Option<Range<usize>>,
    session: Option<u32>,
    delivered_unacked: u16,
    out_of_order_unacked: u16,
    ack_now: bool,
    /// Copies of the next acknowledgement still to send.
    ack_copies: u8,
    /// Number of the peer's last probe, echoed in our acknowledgements.
    answers: u8,
    /// Decoder figures at the last damage estimate: intact and damaged runs.
    damage_mark: (u32, u32),
    damage: f32,
}

impl<B: AsMut<[u8]> + AsRef<[u8]>> Inbound<B> {
    /// The message being delivered and its sequence number, or why it cannot be
    /// parsed (it is intact: its sequence number is used up all the same).
    pub fn message(&self) -> Option<(u16, Result<Message<'_>, ParseError>)> {
        let packet = self.current_packet()?;
        let t = packet.type_byte();
        Some((self.current_seq, Message::parse(t, packet.into_payload())))
    }

    /// The type of the message being delivered, without parsing it (`None` for an
    /// unknown type byte).
    pub fn message_type(&self) -> Option<MessageType> {
        self.current_packet()?.message_type()
    }

    fn current_packet(&self) -> Option<super::Packet<&[u8]>> {
        match self.current.clone()? {
            None => self.decoder.packet(),
            Some(range) => Some(super::Packet::new_unchecked(self.reorder.bytes(range))),
        }
    }

    /// Decoding figures of what arrived.
    pub fn decoder_counters(&self) -> &super::decoder::DecoderCounters {
        self.decoder.counters()
    }

    fn damaged(&self) -> u32 {
        let c = self.decoder.counters();
        c.crc_errors + c.framing_errors + c.oversized + c.truncated
    }

    /// Fraction of the runs received lately that were damaged: updated every
    /// 64 runs, half the weight on the newest.
    fn damage_rate(&mut self) -> f32 {
        let (good, bad) = (self.decoder.counters().packets, self.damaged());
        let (g0, b0) = self.damage_mark;
        let (dg, db) = (good.wrapping_sub(g0), bad.wrapping_sub(b0));
        if dg + db >= 64 {
            let recent = db as f32 / (dg + db) as f32;
            self.damage = 0.5 * (self.damage + recent);
            self.damage_mark = (good, bad);
        }
        self.damage
    }
}

/// Round-trip estimate and retransmission time-out (RFC 6298).
#[derive(Debug, Clone, Copy)]
struct Rtt {
    srtt: Option<u64>,
    rttvar: u64,
    backoff: u32,
}

impl Rtt {
    fn rto(&self, cfg: &EndpointConfig) -> u64 {
        let base = match self.srtt {
            Some(s) => s + 4 * self.rttvar,
            None => cfg.min_rto_us,
        };
        base.max(cfg.min_rto_us)
            .saturating_mul(1 << self.backoff)
            .min(cfg.max_rto_us)
    }

    fn sample(&mut self, r: u64) {
        match self.srtt {
            None => {
                self.srtt = Some(r);
                self.rttvar = r / 2;
            }
            Some(s) => {
                self.rttvar = (3 * self.rttvar + s.abs_diff(r)) / 4;
                self.srtt = Some((7 * s + r) / 8);
            }
        }
    }
}

/// The line's damage rate as the peer sees our packets: decayed counts of
/// intact and damaged packets, and the mean length of what we sent.
#[derive(Debug, Clone, Copy, Default)]
struct LineQuality {
    /// Peer's counters at its last acknowledgement.
    peer: Option<(u16, u16)>,
    good: f32,
    bad: f32,
    /// Mean wire length of our packets (decayed).
    mean_len: f32,
}

/// Decayed counts stop growing here, so the estimate follows a line that changes.
const QUALITY_MEMORY: f32 = 512.0;
/// Bytes a packet costs beyond its payload: header, chunk header, CRC, COBS and delimiter.
const PACKET_OVERHEAD: f32 = (HEADER_LEN + 9 + CRC_LEN + 3) as f32;

impl LineQuality {
    fn sent(&mut self, len: usize) {
        let a = 1.0 / 64.0;
        self.mean_len = if self.mean_len == 0.0 {
            len as f32
        } else {
            self.mean_len + a * (len as f32 - self.mean_len)
        };
    }

    fn peer_counts(&mut self, received: u16, damaged: u16) {
        if let Some((r0, d0)) = self.peer {
            let good = received.wrapping_sub(r0) as f32;
            let bad = damaged.wrapping_sub(d0) as f32;
            self.good += good;
            self.bad += bad;
            let total = self.good + self.bad;
            if total > QUALITY_MEMORY {
                let k = QUALITY_MEMORY / total;
                self.good *= k;
                self.bad *= k;
            }
        }
        self.peer = Some((received, damaged));
    }

    /// Damaged bytes per byte sent, if anything arrived damaged.
    fn byte_error_rate(&self) -> Option<f32> {
        let total = self.good + self.bad;
        if self.bad <= 0.0 || total <= 0.0 || self.mean_len <= 0.0 {
            return None;
        }
        let q = (self.bad / total).min(0.99);
        Some(-libm::log1pf(-q) / self.mean_len)
    }

    /// The payload that carries the most data per byte sent at byte error rate
    /// `e`: maximises `L / (L + O) * exp(-e (L + O))`, whose optimum solves
    /// `O / (L (L + O)) = e`.
    fn best_payload(&self, min: usize, max: usize) -> usize {
        let Some(e) = self.byte_error_rate() else {
            return max;
        };
        let o = PACKET_OVERHEAD;
        let l = (-o + libm::sqrtf(o * o + 4.0 * o / e)) / 2.0;
        (l as usize).clamp(min, max.max(min))
    }
}

/// The sending half: the selective-repeat window, encoder scratch, timers.
pub struct Outbound<B> {
    window: TxWindow<B>,
    raw: B,
    rtt: Rtt,
    quality: LineQuality,
    cfg: EndpointConfig,
    /// Figures of both halves, as reported to the peer (Stats) and the user.
    pub counters: LinkCounters,
    /// Transmissions by cause, acknowledgements and time-outs.
    pub sent: SentCounters,
    /// A lost packet just resent that goes out once more (see [`REPEAT_DAMAGE`]).
    repeat: Option<u16>,
    /// The probe waiting for its answer: its number and its place among our
    /// transmissions.
    probe: Option<(u8, u32)>,
    /// Number of the last probe sent.
    probes: u8,
    /// The oldest packet goes again after the probe.
    probe_resend: bool,
    /// Packets the peer takes beyond its next expected one while a gap is open
    /// (its last acknowledgement's `window`).
    peer_window: Option<u16>,
}

/// Damage rate of our packets above which a packet resent because it was lost
/// goes out twice. A resend lost again stalls the window until a time-out when
/// nothing newer is in flight to reveal it; two copies make that the square of
/// the damage rate, for the price of one packet per loss.
const REPEAT_DAMAGE: f32 = 0.02;

/// What the sending half put on the wire.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SentCounters {
    pub packets: u64,
    pub bytes: u64,
    /// Resent because later packets, or a probe sent after them, arrived first.
    pub resent_lost: u64,
    /// Resent with a probe: the oldest packet in flight, one per time-out.
    pub resent_timeout: u64,
    /// Second copies of lost packets resent on a damaging line.
    pub repeats: u64,
    /// Time-outs, each answered by a probe (each doubles the time-out).
    pub timeouts: u64,
    pub acks: u64,
    pub nacks: u64,
}

impl<B: AsMut<[u8]> + AsRef<[u8]>> Outbound<B> {
    /// Queues a sequenced message; it goes out at the next [`Endpoint::poll_transmit`].
    pub fn send(&mut self, msg: &Message) -> Result<u16, SendError> {
        let t = msg.message_type();
        debug_assert!(t.is_sequenced());
        let raw = self.raw.as_mut();
        let room = self.cfg.max_payload;
        let held = self.window.push_with(|seq, slot| {
            encode_packet(Header { message: t, seq }, raw, slot, |p| {
                let n = p.len().min(room);
                msg.emit(&mut p[..n])
            })
        });
        match held {
            Ok(Ok(seq)) => Ok(seq),
            Ok(Err(_)) | Err(WindowError::TooLarge) => Err(SendError::TooLarge),
            Err(WindowError::Full) => Err(SendError::Full),
        }
    }

    /// Packets to keep in flight at most. In order the peer takes any packet,
    /// so a clean line gets the whole window; once the line has lost or damaged
    /// packets, no more than the peer holds after a gap: a packet beyond it is
    /// dropped and comes back only after a time-out.
    pub fn send_limit(&self) -> usize {
        let lossy = self.damage_rate() > 0.0 || self.sent.resent_lost > 0;
        match self.peer_window {
            Some(w) if lossy => self.window.capacity().min(w.max(1) as usize),
            _ => self.window.capacity(),
        }
    }

    /// Packets that can be queued now.
    pub fn room(&self) -> usize {
        self.window.capacity() - self.window.len()
    }

    pub fn capacity(&self) -> usize {
        self.window.capacity()
    }

    /// Packets sent and not yet acknowledged.
    pub fn in_flight(&self) -> usize {
        self.window.len()
    }

    /// Whether the retransmission timer expired: if so, the number of the probe
    /// to send, the time-out doubled and the probe awaited.
    fn probe_due(&mut self, now: u64) -> Option<u8> {
        let rto = self.rtt.rto(&self.cfg);
        if !self.window.timer_expired(now, rto) {
            return None;
        }
        self.sent.timeouts += 1;
        if self.damage_rate() > REPEAT_DAMAGE {
            // On a line that damages packets a time-out is more likely a loss
            // than a busy peer: resend what has been in flight for a time-out
            // now rather than a round trip later (the probe or its answer may
            // be damaged too).
            self.window.lost_sent_by(now.saturating_sub(rto));
        }
        self.rtt.backoff = (self.rtt.backoff + 1).min(4);
        self.probes = self.probes.wrapping_add(1).max(1);
        self.probe = Some((self.probes, self.window.transmissions()));
        self.probe_resend = true;
        Some(self.probes)
    }

    /// The current retransmission time-out (µs).
    pub fn rto_us(&self) -> u64 {
        self.rtt.rto(&self.cfg)
    }

    /// The payload size with the best goodput on the line as the peer sees it,
    /// between `min` and `max` bytes (`max` while nothing arrived damaged).
    pub fn advised_payload(&self, min: usize, max: usize) -> usize {
        self.quality.best_payload(min, max)
    }

    /// Packets of ours the peer received damaged, as a fraction (decayed).
    pub fn damage_rate(&self) -> f32 {
        let total = self.quality.good + self.quality.bad;
        if total > 0.0 {
            self.quality.bad / total
        } else {
            0.0
        }
    }

    /// Forgets everything and restarts the sequence at 0.
    pub fn restart(&mut self) {
        self.window.reset(0);
        self.repeat = None;
        self.probe = None;
        self.probe_resend = false;
        self.rtt.backoff = 0;
    }

    /// An acknowledgement or a request to resend from the peer.
    fn on_control(&mut self, now: u64, msg: &Message) {
        match *msg {
            Message::Ack(a) => {
                self.quality.peer_counts(a.received, a.damaged);
                self.peer_window = Some(a.window);
                self.on_ack(now, a.next_expected, a.sack);
                match self.probe {
                    Some((number, order)) if a.answers == number => {
                        self.probe = None;
                        self.window.lost_before(order);
                    }
                    _ => {}
                }
            }
            Message::Nack(n) => {
                self.on_ack(now, n.expected, 0);
                self.window.resend_from(n.expected);
            }
            _ => {}
        }
    }

    fn on_ack(&mut self, now: u64, next_expected: u16, sack: u64) {
        let out = self.window.ack(now, next_expected, sack);
        if let Some(r) = out.rtt_us {
            self.rtt.sample(r);
        }
        if out.released + out.sacked > 0 {
            self.rtt.backoff = 0;
        }
    }

    /// The next data packet due at `now` (a second copy of a lost one, the
    /// oldest after a probe, lost, new), its transmission counted;
    /// acknowledgements and probes go through [`Endpoint::poll_transmit`].
    pub fn poll_data(&mut self, now: u64) -> Option<&[u8]> {
        let seq = self.next_data(now)?;
        let len = self.window.packet(seq)?.len();
        self.sent.packets += 1;
        self.sent.bytes += len as u64;
        // The peer's counts cover every copy, so the mean length does too.
        self.quality.sent(len);
        self.window.packet(seq)
    }

    /// Chooses the next data packet and counts why it goes.
    fn next_data(&mut self, now: u64) -> Option<u16> {
        if let Some(seq) = self.repeat.take() {
            if self.window.packet(seq).is_some() {
                self.sent.repeats += 1;
                return Some(seq);
            }
        }
        if core::mem::take(&mut self.probe_resend) {
            if let Some(seq) = self.window.resend_oldest(now) {
                self.sent.resent_timeout += 1;
                self.counters.retransmissions += 1;
                return Some(seq);
            }
        }
        let damage = self.damage_rate();
        let (why, seq) = self.window.next_transmission(now)?;
        if why == Transmission::Lost {
            self.sent.resent_lost += 1;
            self.counters.retransmissions += 1;
            if damage > REPEAT_DAMAGE {
                self.repeat = Some(seq);
            }
        }
        Some(seq)
    }
}

/// Room for one control packet (Ack or Nack) on the wire.
const CONTROL_WIRE: usize = 48;

/// One end of the reliable link.
pub struct Endpoint<B> {
    pub rx: Inbound<B>,
    pub tx: Outbound<B>,
    nudge: bool,
    control: [u8; CONTROL_WIRE],
}

impl<B: AsMut<[u8]> + AsRef<[u8]>> Endpoint<B> {
    pub fn new(buffers: EndpointBuffers<B>, cfg: EndpointConfig) -> Self {
        let EndpointBuffers {
            decode,
            reorder,
            reorder_slot,
            window,
            window_slot,
            raw,
        } = buffers;
        Endpoint {
            rx: Inbound {
                decoder: Decoder::new(decode),
                reorder: RxReorder::new(reorder, reorder_slot),
                current: None,
                current_seq: 0,
                ready: None,
                session: None,
                delivered_unacked: 0,
                out_of_order_unacked: 0,
                ack_now: false,
                ack_copies: 0,
                answers: 0,
                damage_mark: (0, 0),
                damage: 0.0,
            },
            tx: Outbound {
                window: TxWindow::new(window, window_slot),
                raw,
                rtt: Rtt {
                    srtt: None,
                    rttvar: 0,
                    backoff: 0,
                },
                quality: LineQuality::default(),
                cfg,
                counters: LinkCounters::default(),
                sent: SentCounters::default(),
                repeat: None,
                probe: None,
                probes: 0,
                probe_resend: false,
                peer_window: None,
            },
            nudge: false,
            control: [0; CONTROL_WIRE],
        }
    }

    /// Packets the peer may send beyond the next expected one: what the reorder
    /// ring holds, plus the one expected.
    pub fn rx_window(&self) -> u16 {
        self.rx.reorder.capacity() as u16 + 1
    }

    /// Consumes bytes of `input` until a message is ready for the application
    /// (read it with [`Inbound::message`] before the next call) or the input is
    /// used up; returns the bytes consumed and the event.
    pub fn receive(&mut self, now: u64, input: &[u8]) -> (usize, Option<Event>) {
        self.rx.current = None;
        let mut used = 0;
        loop {
            let room = self.tx.room() >= self.tx.cfg.tx_reserve;
            if self.rx.ready.is_some() && room {
                let range = self.rx.ready.take();
                return (used, Some(self.deliver(range)));
            }
            if used == input.len() {
                // A message already held waits until acknowledgements free the
                // transmit window.
                return (used, None);
            }
            let (n, fed) = self.rx.decoder.feed(&input[used..]);
            used += n;
            let packet = match fed {
                None => continue,
                Some(Ok(p)) => p,
                Some(Err(DecodeError::Packet(PacketError::Version(v)))) => {
                    return (used, Some(Event::Version(v)))
                }
                // Noise: the SACK bitmap of our next acknowledgement says what is missing.
                Some(Err(_)) => continue,
            };
            let seq = packet.seq();
            let t = MessageType::from_u8(packet.type_byte());
            if t.is_some_and(|t| !t.is_sequenced()) {
                if let Ok(m) = Message::parse(packet.type_byte(), packet.payload()) {
                    if let Message::Ack(a) = m {
                        if a.probe != 0 {
                            self.rx.answers = a.probe;
                            self.rx.ack_now = true;
                        }
                    }
                    self.tx.on_control(now, &m);
                }
                continue;
            }
            if t == Some(MessageType::Hello) {
                if let Ok(Message::Hello(h)) = Message::parse(packet.type_byte(), packet.payload())
                {
                    if self.rx.session != Some(h.session) {
                        // A new peer session: both sequence spaces restart here.
                        self.rx.session = Some(h.session);
                        self.rx.reorder.reset(seq);
                        self.rx.ready = None;
                        self.tx.restart();
                    }
                }
            }
            let bytes = packet.into_inner();
            match self.rx.reorder.accept(seq, bytes) {
                Accept::Deliver if self.tx.room() < self.tx.cfg.tx_reserve => {
                    // No room to answer: the peer resends it once our answers are acknowledged.
                    self.tx.counters.unexpected += 1;
                }
                Accept::Deliver => return (used, Some(self.deliver(None))),
                Accept::Held => {
                    self.tx.counters.gaps += 1;
                    // Every second packet held: the sender's loss detection
                    // needs three later packets acknowledged, and acknowledging
                    // each one would double the reverse traffic.
                    self.rx.out_of_order_unacked += 1;
                    if self.rx.out_of_order_unacked % 2 == 1 {
                        self.rx.ack_now = true;
                    }
                }
                Accept::Duplicate => {
                    // Our acknowledgement was lost or is late: say it again.
                    self.tx.counters.duplicates += 1;
                    self.rx.ack_now = true;
                }
                Accept::Beyond => self.rx.ack_now = true,
            }
        }
    }

    /// Hands the expected message to the application: from the decoder
    /// (`range` `None`) or from the reorder ring.
    fn deliver(&mut self, range: Option<Range<usize>>) -> Event {
        let seq = self.rx.reorder.expected();
        self.rx.current = Some(range);
        self.rx.current_seq = seq;
        self.rx.ready = self.rx.reorder.advance();
        self.rx.delivered_unacked += 1;
        if self.rx.delivered_unacked >= self.tx.cfg.ack_every {
            self.rx.ack_now = true;
        }
        let d = self.rx.decoder.counters();
        let c = &mut self.tx.counters;
        c.packets_ok = d.packets;
        c.crc_errors = d.crc_errors;
        c.framing_errors = d.framing_errors + d.truncated;
        c.oversized = d.oversized;
        Event::Message { seq }
    }

    /// The caller is about to wait for input: acknowledge what was delivered.
    /// On a line that damages packets the acknowledgement goes twice: it may be
    /// the last word before the peer's window is full, and a lost one would
    /// cost the peer a time-out.
    pub fn acknowledge(&mut self) {
        if self.rx.delivered_unacked > 0 || self.rx.out_of_order_unacked > 0 {
            self.rx.ack_now = true;
            self.rx.ack_copies = if self.rx.damage_rate() > REPEAT_DAMAGE {
                2
            } else {
                1
            };
        }
    }

    /// Asks the peer to resend everything unacknowledged now (the caller waited a
    /// time-out for answers).
    pub fn nudge(&mut self) {
        self.nudge = true;
    }

    /// The next bytes to put on the wire at `now`: an acknowledgement (a probe
    /// when the retransmission timer expired), a nudge, then data packets (lost
    /// ones first, then new). Call until `None`.
    pub fn poll_transmit(&mut self, now: u64) -> Option<&[u8]> {
        let probe = self.tx.probe_due(now);
        if self.rx.ack_now || probe.is_some() {
            self.rx.ack_copies = self.rx.ack_copies.saturating_sub(1);
            self.rx.ack_now = self.rx.ack_copies > 0;
            self.rx.delivered_unacked = 0;
            self.rx.out_of_order_unacked = 0;
            let d = self.rx.decoder.counters();
            let ack = Ack {
                next_expected: self.rx.reorder.expected(),
                window: self.rx_window(),
                sack: self.rx.reorder.held(),
                received: d.packets as u16,
                damaged: self.rx.damaged() as u16,
                probe: probe.unwrap_or(0),
                answers: self.rx.answers,
            };
            self.tx.sent.acks += 1;
            return self.control(&Message::Ack(ack));
        }
        if core::mem::take(&mut self.nudge) {
            let nack = Nack {
                expected: self.rx.reorder.expected(),
                reason: nack_reason::TIMEOUT,
            };
            self.tx.sent.nacks += 1;
            return self.control(&Message::Nack(nack));
        }
        self.tx.poll_data(now)
    }

    /// Encodes an unsequenced control message into the control buffer.
    fn control(&mut self, msg: &Message) -> Option<&[u8]> {
        let header = Header {
            message: msg.message_type(),
            seq: self.tx.window.next_seq(),
        };
        let n = encode_packet(header, self.tx.raw.as_mut(), &mut self.control, |p| {
            msg.emit(p)
        })
        .ok()?;
        self.tx.sent.packets += 1;
        self.tx.sent.bytes += n as u64;
        Some(&self.control[..n])
    }

    /// When [`Endpoint::poll_transmit`] will have something without new input:
    /// now when something is due, else the earliest retransmission time-out.
    pub fn poll_at(&self, now: u64) -> Option<u64> {
        let tx = &self.tx;
        if self.rx.ack_now
            || self.nudge
            || tx.repeat.is_some()
            || tx.probe_resend
            || tx.window.has_due()
        {
            return Some(now);
        }
        self.tx.window.next_timeout(self.tx.rto_us())
    }
}

#[cfg(test)]
mod tests;
