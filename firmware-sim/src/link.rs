//! The firmware's side of the link: reads the port, drives the core's reliable
//! [`Endpoint`] and writes what it has to send. Reliability (sequencing,
//! acknowledgements, selective repeat, time-outs) is the endpoint's; this module
//! only moves bytes between the port and it, and hands messages to the application.
use core::fmt::Write as _;
use embedded_io::{Read, Write};
use phototraverse_core::protocol::messages::{
    ErrorCode, ErrorMsg, LinkCounters, Message, MessageType, MAX_ERROR_TEXT,
};
use phototraverse_core::protocol::{
    wire_len, Endpoint, EndpointBuffers, EndpointConfig, Event, CRC_LEN, HEADER_LEN, MAX_ENCODED,
};
use phototraverse_core::traverse::Clock;

/// Largest payload the firmware itself sends (results, statistics, errors).
pub const TX_MAX_PAYLOAD: usize = 256;
/// Bytes of one retransmission slot.
pub const TX_SLOT: usize = wire_len(TX_MAX_PAYLOAD);
/// Packets the firmware keeps unacknowledged.
pub const TX_SLOTS: usize = 16;
/// Largest payload the firmware holds when it arrives after a gap: a frame
/// chunk of 256 bytes with its header. Larger packets are taken in order only.
pub const RX_HELD_PAYLOAD: usize = 256 + phototraverse_core::protocol::messages::CHUNK_HEADER_LEN;
/// Bytes of one reorder slot (a decoded packet).
pub const RX_SLOT: usize = HEADER_LEN + RX_HELD_PAYLOAD + CRC_LEN;
/// Packets held after a gap.
pub const RX_SLOTS: usize = 32;
/// Sequenced packets the host may send beyond the last acknowledgement: the
/// one expected and those the reorder ring holds.
pub const RX_WINDOW: u16 = RX_SLOTS as u16 + 1;
/// Bytes read from the port at a time.
pub const READ_CHUNK: usize = 2048;
/// Free transmit slots needed before a sequenced packet is taken in: the most
/// packets the application sends in answer to one message.
const TX_RESERVE: usize = 4;

/// Static storage of the link: decoder, reorder ring, transmit window, encoder
/// scratch and read buffer.
pub struct LinkBuffers {
    decode: [u8; MAX_ENCODED],
    reorder: [u8; RX_SLOT * RX_SLOTS],
    window: [u8; TX_SLOT * TX_SLOTS],
    raw: [u8; HEADER_LEN + TX_MAX_PAYLOAD + CRC_LEN],
    read: [u8; READ_CHUNK],
}

impl LinkBuffers {
    pub const fn new() -> Self {
        LinkBuffers {
            decode: [0; MAX_ENCODED],
            reorder: [0; RX_SLOT * RX_SLOTS],
            window: [0; TX_SLOT * TX_SLOTS],
            raw: [0; HEADER_LEN + TX_MAX_PAYLOAD + CRC_LEN],
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

/// The sending side as the application sees it: queue a message, and it goes out.
pub struct Tx<'t, 'b> {
    ep: &'t mut phototraverse_core::protocol::endpoint::Outbound<&'b mut [u8]>,
    clock: &'t dyn Clock,
}

impl Tx<'_, '_> {
    /// Sends `msg` (kept for retransmission until acknowledged).
    pub fn send<P: Write>(&mut self, port: &mut P, msg: &Message) -> Result<(), P::Error> {
        // Full cannot happen (the endpoint keeps TX_RESERVE slots free before
        // delivering) and TooLarge is a programming error: dropping the message
        // is better than halting the link; the count says it happened.
        if self.ep.send(msg).is_err() {
            self.ep.counters.unexpected += 1;
            return Ok(());
        }
        let now = self.clock.now_us();
        while let Some(bytes) = self.ep.poll_data(now) {
            port.write_all(bytes)?;
        }
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

    /// Link figures: decoding, sequencing and retransmissions.
    pub fn counters(&self) -> LinkCounters {
        self.ep.counters
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

/// The port side of the link: the endpoint and the read buffer.
pub struct Link<'b> {
    ep: Endpoint<&'b mut [u8]>,
    read: &'b mut [u8],
    pos: usize,
    end: usize,
}

impl<'b> Link<'b> {
    pub fn new(buffers: &'b mut LinkBuffers) -> Self {
        let LinkBuffers {
            decode,
            reorder,
            window,
            raw,
            read,
        } = buffers;
        let cfg = EndpointConfig {
            tx_reserve: TX_RESERVE,
            max_payload: TX_MAX_PAYLOAD,
            ..EndpointConfig::default()
        };
        let buffers = EndpointBuffers {
            decode: &mut decode[..],
            reorder: &mut reorder[..],
            reorder_slot: RX_SLOT,
            window: &mut window[..],
            window_slot: TX_SLOT,
            raw: &mut raw[..],
        };
        Link {
            ep: Endpoint::new(buffers, cfg),
            read,
            pos: 0,
            end: 0,
        }
    }

    /// Link figures: decoding, sequencing and retransmissions.
    pub fn counters(&self) -> LinkCounters {
        self.ep.tx.counters
    }

    /// The sending side, outside [`Link::serve`].
    pub fn tx<'t>(&'t mut self, clock: &'t dyn Clock) -> Tx<'t, 'b> {
        Tx {
            ep: &mut self.ep.tx,
            clock,
        }
    }

    fn transmit<P: Write>(&mut self, port: &mut P, now: u64) -> Result<(), P::Error> {
        let mut wrote = false;
        while let Some(bytes) = self.ep.poll_transmit(now) {
            port.write_all(bytes)?;
            wrote = true;
        }
        if wrote {
            port.flush()?;
        }
        Ok(())
    }

    /// Reads and dispatches until `handler` exits or the port ends. `handler`
    /// receives every in-order message with its sequence number.
    pub fn serve<P, R>(
        &mut self,
        port: &mut P,
        clock: &dyn Clock,
        mut handler: impl FnMut(&mut Tx<'_, 'b>, &mut P, u16, Message<'_>) -> Result<Flow<R>, P::Error>,
    ) -> Result<Served<R>, P::Error>
    where
        P: Read + Write,
    {
        loop {
            let now = clock.now_us();
            // Messages the reorder ring already holds come out before more is read.
            let (n, event) = self.ep.receive(now, &self.read[self.pos..self.end]);
            self.pos += n;
            if event.is_none() && self.pos == self.end {
                // Probably about to block (the last read did not fill the buffer,
                // so the port had no more): acknowledge what arrived. After a full
                // read more is likely waiting, and acknowledgements go every
                // `ack_every` packets, so a burst costs few of them.
                if self.end < self.read.len() {
                    self.ep.acknowledge();
                }
                self.transmit(port, now)?;
                let n = port.read(self.read)?;
                if n == 0 {
                    return Ok(Served::Eof);
                }
                self.pos = 0;
                self.end = n;
                continue;
            }
            let flow = match event {
                None => Flow::Continue,
                Some(Event::Version(v)) => {
                    let mut tx = Tx {
                        ep: &mut self.ep.tx,
                        clock,
                    };
                    tx.error(
                        port,
                        ErrorCode::Version,
                        u32::MAX,
                        u16::MAX,
                        format_args!(
                            "protocol version {v} is not supported; this firmware speaks {}",
                            phototraverse_core::protocol::PROTOCOL_VERSION
                        ),
                    )?;
                    Flow::Continue
                }
                Some(Event::Message { .. }) => {
                    if !is_bulk(&self.ep) {
                        // It may start long work (the epoch, once its frames are
                        // complete): acknowledged after the work, it would run out the
                        // peer's retransmission timer, and every epoch would cost a
                        // resent packet and a duplicate.
                        self.ep.acknowledge();
                        self.transmit(port, now)?;
                    }
                    let Endpoint { rx, tx, .. } = &mut self.ep;
                    let mut tx = Tx { ep: tx, clock };
                    match rx.message() {
                        Some((seq, Ok(msg))) => handler(&mut tx, port, seq, msg)?,
                        Some((seq, Err(e))) => {
                            tx.error(
                                port,
                                ErrorCode::Malformed,
                                u32::MAX,
                                seq,
                                format_args!("{e:?}"),
                            )?;
                            Flow::Continue
                        }
                        None => Flow::Continue,
                    }
                }
            };
            if let Flow::Exit(r) = flow {
                self.transmit(port, clock.now_us())?;
                return Ok(Served::Exit(r));
            }
            // Acknowledgements and resends that came due while handling.
            self.transmit(port, now)?;
        }
    }
}

/// Whether the message ready in `ep` is frame data, which arrives in bursts
/// and is acknowledged in batches (`ack_every`, or when the port runs dry).
fn is_bulk<B: AsMut<[u8]> + AsRef<[u8]>>(ep: &Endpoint<B>) -> bool {
    ep.rx.message_type() == Some(MessageType::FrameChunk)
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use phototraverse_core::protocol::messages::{Camera, FrameChunk, FrameEnd};
    use phototraverse_core::protocol::MAX_PACKET;
    use phototraverse_core::traverse::NoClock;
    use std::boxed::Box;
    use std::vec;
    use std::vec::Vec;

    /// A port that reads given bytes, then reports the end of input, and keeps
    /// what is written.
    struct Port {
        input: Vec<u8>,
        pos: usize,
        out: Vec<u8>,
    }

    impl embedded_io::ErrorType for Port {
        type Error = core::convert::Infallible;
    }

    impl Read for Port {
        fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
            let n = buf.len().min(self.input.len() - self.pos);
            buf[..n].copy_from_slice(&self.input[self.pos..self.pos + n]);
            self.pos += n;
            Ok(n)
        }
    }

    impl Write for Port {
        fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
            self.out.extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> Result<(), Self::Error> {
            Ok(())
        }
    }

    /// The host's end, with room for a frame's worth of packets in flight.
    fn host() -> Endpoint<Vec<u8>> {
        Endpoint::new(
            EndpointBuffers {
                decode: vec![0; MAX_ENCODED],
                reorder: vec![0; 4 * MAX_PACKET],
                reorder_slot: MAX_PACKET,
                window: vec![0; 16 * MAX_ENCODED],
                window_slot: MAX_ENCODED,
                raw: vec![0; MAX_PACKET],
            },
            EndpointConfig::default(),
        )
    }

    /// The firmware's handler sees a burst of frame chunks and the frame's end; it
    /// records, for each message, how many of the host's packets were still
    /// unacknowledged when the message reached it (its work would start there).
    fn unacknowledged_at_each_message(messages: &[Message]) -> Vec<usize> {
        let mut host = host();
        let mut wire = Vec::new();
        for m in messages {
            host.tx.send(m).expect("room in the host's window");
            while let Some(bytes) = host.poll_transmit(0) {
                wire.extend_from_slice(bytes);
            }
        }
        let mut port = Port {
            input: wire,
            pos: 0,
            out: Vec::new(),
        };
        let mut buffers = Box::new(LinkBuffers::new());
        let mut link = Link::new(&mut buffers);
        let mut seen = Vec::new();
        let served = link.serve(&mut port, &NoClock, |_, port, _, _| {
            let (n, _) = host.receive(0, &port.out);
            port.out.drain(..n);
            seen.push(host.tx.in_flight());
            Ok(Flow::<()>::Continue)
        });
        assert!(matches!(served, Ok(Served::Eof)));
        seen
    }

    #[test]
    fn the_end_of_a_frame_is_acknowledged_before_the_work_it_starts() {
        let data = [7u8; 64];
        let chunk = |offset| {
            Message::FrameChunk(FrameChunk {
                epoch: 3,
                camera: Camera::Right,
                offset,
                data: &data,
            })
        };
        let end = Message::FrameEnd(FrameEnd {
            epoch: 3,
            camera: Camera::Right,
            total_bytes: 192,
            crc32: 0,
        });
        let seen = unacknowledged_at_each_message(&[chunk(0), chunk(64), chunk(128), end]);
        // The chunks go on unacknowledged (acknowledgements come in batches); when
        // the frame's end reaches the application, the host has its acknowledgement.
        assert_eq!(seen, [4, 4, 4, 0]);
    }
}
