//! Streaming decoder in fixed memory: bytes in, packets out. It accumulates
//! bytes up to each 0x00 delimiter in the caller's buffer, COBS-decodes them in
//! place and checks the packet. Anything bad is counted and dropped, and
//! decoding resumes at the next delimiter.
use super::cobs;
use super::packet::{Packet, PacketError};

/// Why a delimited run of bytes was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DecodeError {
    /// More bytes than the buffer holds before a delimiter.
    Oversized,
    /// Invalid COBS.
    Framing,
    /// A decoded packet failed its checks.
    Packet(PacketError),
}

/// What the decoder has seen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DecoderCounters {
    pub packets: u32,
    pub crc_errors: u32,
    pub framing_errors: u32,
    pub oversized: u32,
    pub truncated: u32,
    pub version_errors: u32,
    /// Bytes consumed in total.
    pub bytes: u64,
}

/// One step of [`Decoder::feed`]: bytes consumed and, when a delimiter closed a
/// non-empty run, the packet or why it was dropped.
pub type Feed<'s> = (usize, Option<Result<Packet<&'s [u8]>, DecodeError>>);

/// The streaming decoder over a caller-provided buffer (`&mut [u8]` on the
/// firmware, an owned buffer on the host; size it with [`super::MAX_ENCODED`]
/// to accept every legal packet).
pub struct Decoder<B> {
    buf: B,
    len: usize,
    overflow: bool,
    /// Length of the packet the last feed returned (0: none), still in `buf`.
    last: usize,
    counters: DecoderCounters,
}

impl<B: AsMut<[u8]>> Decoder<B> {
    pub fn new(buf: B) -> Self {
        Decoder {
            buf,
            len: 0,
            overflow: false,
            last: 0,
            counters: DecoderCounters::default(),
        }
    }

    pub fn counters(&self) -> &DecoderCounters {
        &self.counters
    }

    /// The packet the last [`Decoder::feed`] returned, until the next feed.
    pub fn packet(&self) -> Option<Packet<&[u8]>>
    where
        B: AsRef<[u8]>,
    {
        (self.last > 0).then(|| Packet::new_unchecked(&self.buf.as_ref()[..self.last]))
    }

    /// Forgets a partial packet (after a link reset).
    pub fn clear(&mut self) {
        self.len = 0;
        self.last = 0;
        self.overflow = false;
    }

    /// Consumes bytes of `input` up to and including the first delimiter and
    /// returns how many were consumed and, if a delimiter closed a non-empty
    /// run, the packet or why it was dropped. Call again with the rest.
    pub fn feed<'s>(&'s mut self, input: &[u8]) -> Feed<'s> {
        self.last = 0;
        let delim = memchr::memchr(0, input);
        let data = &input[..delim.unwrap_or(input.len())];
        let buf = self.buf.as_mut();
        let room = buf.len() - self.len;
        if data.len() > room || self.overflow {
            self.overflow = true;
        } else {
            buf[self.len..self.len + data.len()].copy_from_slice(data);
            self.len += data.len();
        }
        let Some(pos) = delim else {
            self.counters.bytes += input.len() as u64;
            return (input.len(), None);
        };
        let consumed = pos + 1;
        self.counters.bytes += consumed as u64;
        let len = core::mem::replace(&mut self.len, 0);
        if core::mem::replace(&mut self.overflow, false) {
            self.counters.oversized += 1;
            return (consumed, Some(Err(DecodeError::Oversized)));
        }
        if len == 0 {
            // Back-to-back delimiters: senders may flush the line with them.
            return (consumed, None);
        }
        let n = match cobs::decode_in_place(&mut buf[..len]) {
            Ok(n) => n,
            Err(_) => {
                self.counters.framing_errors += 1;
                return (consumed, Some(Err(DecodeError::Framing)));
            }
        };
        match Packet::new_checked(&buf[..n]) {
            Ok(p) => {
                self.counters.packets += 1;
                self.last = n;
                (consumed, Some(Ok(p)))
            }
            Err(e) => {
                match e {
                    PacketError::Crc => self.counters.crc_errors += 1,
                    PacketError::Version(_) => self.counters.version_errors += 1,
                    PacketError::Oversized => self.counters.oversized += 1,
                    PacketError::Truncated | PacketError::TrailingBytes => {
                        self.counters.truncated += 1
                    }
                }
                (consumed, Some(Err(DecodeError::Packet(e))))
            }
        }
    }
}
