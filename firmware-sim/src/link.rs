//! The firmware's side of the reliable link: reads bytes, decodes packets,
//! keeps the receive sequence (acks, rate-limited nacks, duplicates), answers
//! link-level faults, and hands in-order messages to the application. Sending
//! keeps sequenced packets in a go-back-N window until the host acknowledges them.
use core::fmt::Write as _;
use embedded_io::{Read, Write};
use phototraverse_core::protocol::messages::{
    nack_reason, Ack, ErrorCode, ErrorMsg, LinkCounters, Message, MessageType, Nack, MAX_ERROR_TEXT,
};
use phototraverse_core::protocol::window::{Accept, RxSequence, TxWindow};
use phototraverse_core::protocol::{
    encode_packet, wire_len, DecodeError, Decoder, Header, PacketError, MAX_ENCODED, MAX_PACKET,
    MAX_PAYLOAD,
};

/// Largest payload the firmware itself sends (results, statistics, errors).
pub const TX_MAX_PAYLOAD: usize = 256;
/// Bytes of one retransmission slot.
pub const TX_SLOT: usize = wire_len(TX_MAX_PAYLOAD);
/// Packets the firmware keeps unacknowledged.
pub const TX_SLOTS: usize = 16;
/// Bytes read from the port at a time.
pub const READ_CHUNK: usize = 2048;
/// Sequenced packets the host may send beyond the last acknowledgement.
pub const RX_WINDOW: u16 = 64;
/// Free transmit slots needed before a sequenced packet is taken in: the most
/// packets the application sends in answer to one message.
const TX_RESERVE: usize = 4;

/// Static storage of the link (about 29 KiB): decoder, encoder scratch, window.
pub struct LinkBuffers {
    decode: [u8; MAX_ENCODED],
    raw: [u8; MAX_PACKET],
    wire: [u8; MAX_ENCODED],
    window: [u8; TX_SLOT * TX_SLOTS],
    read: [u8; READ_CHUNK],
}

impl LinkBuffers {
    pub const fn new() -> Self {
        LinkBuffers {
            decode: [0; MAX_ENCODED],
            raw: [0; MAX_PACKET],
            wire: [0; MAX_ENCODED],
            window: [0; TX_SLOT * TX_SLOTS],
            read: [0; READ_CHUNK],
        }
    }

    pub const BYTES: usize = core::mem::size_of::<Self>();
}

impl Default for LinkBuffers {
    fn default() -> Self {
        Self::new()
    }
}

/// The sending half: encoder scratch and the retransmission window.
pub struct Tx<'b> {
    raw: &'b mut [u8],
    wire: &'b mut [u8],
    window: TxWindow<'b>,
    next_seq: u16,
    pub counters: LinkCounters,
}

impl<'b> Tx<'b> {
    /// Sends `msg`: sequenced messages are kept for retransmission.
    pub fn send<P: Write>(&mut self, port: &mut P, msg: &Message) -> Result<(), P::Error> {
        let t = msg.message_type();
        let seq = self.next_seq;
        let n = match encode_packet(Header { message: t, seq }, self.raw, self.wire, |p| {
            let room = p.len().min(TX_MAX_PAYLOAD);
            msg.emit(&mut p[..room])
        }) {
            Ok(n) => n,
            // Only a programming error can get here (every firmware message fits):
            // dropping it is better than halting the link.
            Err(_) => return Ok(()),
        };
        if t.is_sequenced() {
            if self.window.push(seq, &self.wire[..n]).is_err() {
                // The link layer keeps TX_RESERVE slots free before delivering.
                self.counters.unexpected += 1;
                return Ok(());
            }
            self.next_seq = seq.wrapping_add(1);
        }
        port.write_all(&self.wire[..n])?;
        port.flush()
    }

    /// Sends an error with a formatted text.
    pub fn error<P: Write>(
        &mut self,
        port: &mut P,
        code: ErrorCode,
        epoch: u32,
        seq: u16,
        text: core::fmt::Arguments,
    ) -> Result<(), P::Error> {
        let mut s = heapless::String::<MAX_ERROR_TEXT>::new();
        // A text longer than the capacity is cut, which is fine for a message.
        let _ = s.write_fmt(text);
        self.send(
            port,
            &Message::Error(ErrorMsg {
                code,
                epoch,
                seq,
                text: &s,
            }),
        )
    }

    fn retransmit_from<P: Write>(&mut self, port: &mut P, from: u16) -> Result<(), P::Error> {
        for pkt in self.window.unacked_from(from) {
            port.write_all(pkt)?;
            self.counters.retransmissions += 1;
        }
        port.flush()
    }

    fn has_room(&self) -> bool {
        self.window.capacity() - self.window.len() >= TX_RESERVE
    }

    fn restart(&mut self) {
        self.next_seq = 0;
        self.window.reset(0);
    }
}

/// What the application decided after a message.
pub enum Flow<R> {
    Continue,
    Exit(R),
}

/// How [`Link::serve`] ended.
pub enum Served<R> {
    /// The application asked to leave with this value.
    Exit(R),
    /// The port reached end of input.
    Eof,
}

/// The receiving half and the link state.
pub struct Link<'b> {
    decoder: Decoder<&'b mut [u8]>,
    read: &'b mut [u8],
    pos: usize,
    end: usize,
    rx: RxSequence,
    session: Option<u32>,
    unacked: u16,
    pub tx: Tx<'b>,
}

impl<'b> Link<'b> {
    pub fn new(buffers: &'b mut LinkBuffers) -> Self {
        let LinkBuffers {
            decode,
            raw,
            wire,
            window,
            read,
        } = buffers;
        Link {
            decoder: Decoder::new(decode),
            read,
            pos: 0,
            end: 0,
            rx: RxSequence::new(RX_WINDOW / 2),
            session: None,
            unacked: 0,
            tx: Tx {
                raw,
                wire,
                window: TxWindow::new(window, TX_SLOT),
                next_seq: 0,
                counters: LinkCounters::default(),
            },
        }
    }

    /// Link counters: decoding, sequencing and retransmissions.
    pub fn counters(&self) -> LinkCounters {
        self.tx.counters
    }

    fn ack<P: Write>(
        tx: &mut Tx,
        rx: &RxSequence,
        unacked: &mut u16,
        port: &mut P,
    ) -> Result<(), P::Error> {
        *unacked = 0;
        let ack = Ack {
            next_expected: rx.expected(),
            window: RX_WINDOW,
        };
        tx.send(port, &Message::Ack(ack))
    }

    fn nack<P: Write>(
        tx: &mut Tx,
        rx: &RxSequence,
        port: &mut P,
        reason: u8,
    ) -> Result<(), P::Error> {
        let nack = Nack {
            expected: rx.expected(),
            reason,
        };
        tx.send(port, &Message::Nack(nack))
    }

    /// Reads and dispatches until `handler` exits or the port ends. `handler`
    /// receives every in-order message with its sequence number.
    pub fn serve<P, R>(
        &mut self,
        port: &mut P,
        mut handler: impl FnMut(&mut Tx<'b>, &mut P, u16, Message<'_>) -> Result<Flow<R>, P::Error>,
    ) -> Result<Served<R>, P::Error>
    where
        P: Read + Write,
    {
        loop {
            if self.pos == self.end {
                // Probably about to block (the last read did not fill the buffer,
                // so the port had no more): acknowledge what was delivered. After
                // a full read more is likely waiting; acks then go every
                // RX_WINDOW / 4 packets, so a burst costs few acks.
                if self.unacked > 0 && self.end < self.read.len() {
                    Self::ack(&mut self.tx, &self.rx, &mut self.unacked, port)?;
                }
                let n = port.read(self.read)?;
                if n == 0 {
                    return Ok(Served::Eof);
                }
                self.pos = 0;
                self.end = n;
            }
            // Statistics the application reports carry the decoder's figures
            // (as of the previous packet: the next feed borrows the decoder).
            let d = *self.decoder.counters();
            self.tx.counters.packets_ok = d.packets;
            self.tx.counters.crc_errors = d.crc_errors;
            self.tx.counters.framing_errors = d.framing_errors + d.truncated;
            self.tx.counters.oversized = d.oversized;
            let (n, event) = self.decoder.feed(&self.read[self.pos..self.end]);
            self.pos += n;
            let Some(event) = event else { continue };
            let packet = match event {
                Ok(p) => p,
                Err(e) => {
                    self.link_fault(port, e)?;
                    continue;
                }
            };
            let seq = packet.seq();
            let msg = match Message::parse(packet.type_byte(), packet.payload()) {
                Ok(m) => m,
                Err(e) => {
                    // Intact but unusable: consume its sequence number so the stream goes on.
                    if self.rx.accept(seq) == Accept::Deliver {
                        self.unacked += 1;
                        self.tx.error(
                            port,
                            ErrorCode::Malformed,
                            u32::MAX,
                            seq,
                            format_args!("{e:?}"),
                        )?;
                    }
                    continue;
                }
            };
            match msg {
                Message::Ack(a) => {
                    self.tx.window.ack(a.next_expected);
                    continue;
                }
                Message::Nack(n) => {
                    self.tx.window.ack(n.expected);
                    self.tx.retransmit_from(port, n.expected)?;
                    continue;
                }
                Message::Hello(h) if self.session != Some(h.session) => {
                    // A new host session: both sequence spaces restart here.
                    self.session = Some(h.session);
                    self.rx.reset(seq);
                    self.tx.restart();
                }
                _ => {}
            }
            if !self.tx.has_room() {
                // Busy: do not take it; the host retransmits after our acks free the window.
                self.tx.counters.unexpected += 1;
                continue;
            }
            match self.rx.accept(seq) {
                Accept::Deliver => {
                    self.unacked += 1;
                    if self.unacked >= RX_WINDOW / 4 {
                        Self::ack(&mut self.tx, &self.rx, &mut self.unacked, port)?;
                    }
                    if let Flow::Exit(r) = handler(&mut self.tx, port, seq, msg)? {
                        return Ok(Served::Exit(r));
                    }
                }
                Accept::Duplicate => {
                    self.tx.counters.duplicates += 1;
                    Self::ack(&mut self.tx, &self.rx, &mut self.unacked, port)?;
                }
                Accept::Gap { nack } => {
                    self.tx.counters.gaps += 1;
                    if nack {
                        Self::nack(&mut self.tx, &self.rx, port, nack_reason::GAP)?;
                    }
                }
            }
        }
    }

    fn link_fault<P: Write>(&mut self, port: &mut P, e: DecodeError) -> Result<(), P::Error> {
        match e {
            DecodeError::Packet(PacketError::Version(v)) => self.tx.error(
                port,
                ErrorCode::Version,
                u32::MAX,
                u16::MAX,
                format_args!(
                    "protocol version {v} is not supported; this firmware speaks {}",
                    phototraverse_core::protocol::PROTOCOL_VERSION
                ),
            ),
            DecodeError::Oversized | DecodeError::Packet(PacketError::Oversized) => self.tx.error(
                port,
                ErrorCode::Oversized,
                u32::MAX,
                u16::MAX,
                format_args!("packet larger than {MAX_PAYLOAD} payload bytes dropped"),
            ),
            // Noise: ask for the missing packet (rate-limited), no error message per hit.
            _ => {
                if self.rx.corrupted() {
                    Self::nack(&mut self.tx, &self.rx, port, nack_reason::CORRUPTED)?;
                }
                Ok(())
            }
        }
    }
}

/// The sequenced message types the host sends and the firmware takes.
pub fn is_host_message(t: MessageType) -> bool {
    matches!(
        t,
        MessageType::Hello
            | MessageType::Configure
            | MessageType::FrameBegin
            | MessageType::FrameChunk
            | MessageType::FrameEnd
            | MessageType::Aux
            | MessageType::Reset
            | MessageType::PointsRequest
    )
}
