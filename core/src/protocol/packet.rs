//! The packet inside the COBS framing, smoltcp `wire` style:
//!
//! | offset | size | field                                   |
//! |--------|------|-----------------------------------------|
//! | 0      | 1    | protocol version ([`PROTOCOL_VERSION`]) |
//! | 1      | 1    | message type ([`MessageType`])          |
//! | 2      | 2    | sequence number, u16 LE                 |
//! | 4      | 2    | payload length N, u16 LE                |
//! | 6      | N    | payload                                 |
//! | 6 + N  | 4    | CRC-32 of bytes 0 .. 6 + N, u32 LE      |
use super::cobs;
use super::crc::crc32;
use super::messages::MessageType;
use super::{MAX_ENCODED, MAX_PAYLOAD, PROTOCOL_VERSION};

/// Bytes of the header.
pub const HEADER_LEN: usize = 6;
/// Bytes of the trailing CRC.
pub const CRC_LEN: usize = 4;

mod field {
    use core::ops::Range;
    pub const VERSION: usize = 0;
    pub const TYPE: usize = 1;
    pub const SEQ: Range<usize> = 2..4;
    pub const LEN: Range<usize> = 4..6;
}

/// Why a decoded packet was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PacketError {
    /// Shorter than header + CRC, or shorter than the header's payload length says.
    Truncated,
    /// Longer than the header's payload length says.
    TrailingBytes,
    /// The CRC does not match.
    Crc,
    /// A protocol version this side does not speak.
    Version(u8),
    /// Payload length above [`MAX_PAYLOAD`].
    Oversized,
}

/// A read-only or read-write view of one decoded packet (header, payload, CRC).
#[derive(Debug, Clone, Copy)]
pub struct Packet<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Packet<T> {
    /// Wraps a buffer without any check.
    pub const fn new_unchecked(buffer: T) -> Self {
        Packet { buffer }
    }

    /// Wraps a buffer after checking lengths, version and CRC, so the accessors cannot fail.
    pub fn new_checked(buffer: T) -> Result<Self, PacketError> {
        let p = Self::new_unchecked(buffer);
        p.check()?;
        Ok(p)
    }

    fn check(&self) -> Result<(), PacketError> {
        let b = self.buffer.as_ref();
        if b.len() < HEADER_LEN + CRC_LEN {
            return Err(PacketError::Truncated);
        }
        let n = self.payload_len() as usize;
        if n > MAX_PAYLOAD {
            return Err(PacketError::Oversized);
        }
        let total = HEADER_LEN + n + CRC_LEN;
        if b.len() < total {
            return Err(PacketError::Truncated);
        }
        if b.len() > total {
            return Err(PacketError::TrailingBytes);
        }
        // CRC before version: a version byte hit by noise is noise, not a peer.
        let stored = u32::from_le_bytes([b[total - 4], b[total - 3], b[total - 2], b[total - 1]]);
        if crc32(&b[..total - CRC_LEN]) != stored {
            return Err(PacketError::Crc);
        }
        if self.version() != PROTOCOL_VERSION {
            return Err(PacketError::Version(self.version()));
        }
        Ok(())
    }

    pub fn version(&self) -> u8 {
        self.buffer.as_ref()[field::VERSION]
    }

    /// The raw message type byte (see [`MessageType::from_u8`]).
    pub fn type_byte(&self) -> u8 {
        self.buffer.as_ref()[field::TYPE]
    }

    pub fn message_type(&self) -> Option<MessageType> {
        MessageType::from_u8(self.type_byte())
    }

    pub fn seq(&self) -> u16 {
        let b = self.buffer.as_ref();
        u16::from_le_bytes([b[field::SEQ.start], b[field::SEQ.start + 1]])
    }

    pub fn payload_len(&self) -> u16 {
        let b = self.buffer.as_ref();
        u16::from_le_bytes([b[field::LEN.start], b[field::LEN.start + 1]])
    }

    pub fn payload(&self) -> &[u8] {
        let n = self.payload_len() as usize;
        &self.buffer.as_ref()[HEADER_LEN..HEADER_LEN + n]
    }
}

impl<'a> Packet<&'a [u8]> {
    /// The payload, borrowed from the buffer rather than from the view.
    pub fn into_payload(self) -> &'a [u8] {
        let n = self.payload_len() as usize;
        &self.buffer[HEADER_LEN..HEADER_LEN + n]
    }

    /// The whole packet (header, payload, CRC).
    pub fn into_inner(self) -> &'a [u8] {
        self.buffer
    }
}

/// The header fields of a packet to emit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Header {
    pub message: MessageType,
    pub seq: u16,
}

/// A failure while encoding a packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EncodeError {
    /// The payload does not fit in [`MAX_PAYLOAD`] or the caller's buffer.
    PayloadTooLarge,
    /// The output buffer cannot hold the encoded packet.
    BufferTooSmall,
}

/// Builds one wire packet: `raw` receives header + payload + CRC (the payload
/// written by `payload`, which returns its length), then `out` receives its
/// COBS encoding followed by the 0x00 delimiter. Returns the bytes in `out`.
pub fn encode_packet(
    header: Header,
    raw: &mut [u8],
    out: &mut [u8],
    payload: impl FnOnce(&mut [u8]) -> Result<usize, EncodeError>,
) -> Result<usize, EncodeError> {
    if raw.len() < HEADER_LEN + CRC_LEN {
        return Err(EncodeError::BufferTooSmall);
    }
    let room = (raw.len() - HEADER_LEN - CRC_LEN).min(MAX_PAYLOAD);
    let n = payload(&mut raw[HEADER_LEN..HEADER_LEN + room])?;
    if n > room {
        return Err(EncodeError::PayloadTooLarge);
    }
    raw[field::VERSION] = PROTOCOL_VERSION;
    raw[field::TYPE] = header.message as u8;
    raw[field::SEQ].copy_from_slice(&header.seq.to_le_bytes());
    raw[field::LEN].copy_from_slice(&(n as u16).to_le_bytes());
    let body = HEADER_LEN + n;
    let crc = crc32(&raw[..body]);
    raw[body..body + CRC_LEN].copy_from_slice(&crc.to_le_bytes());
    let total = body + CRC_LEN;
    let enc = cobs::encode(&raw[..total], out).map_err(|_| EncodeError::BufferTooSmall)?;
    if enc >= out.len() {
        return Err(EncodeError::BufferTooSmall);
    }
    out[enc] = 0;
    Ok(enc + 1)
}

/// Scratch for [`encode_packet`] sized for the largest packet.
pub struct PacketBuffers {
    pub raw: [u8; HEADER_LEN + MAX_PAYLOAD + CRC_LEN],
    pub wire: [u8; MAX_ENCODED],
}

impl Default for PacketBuffers {
    fn default() -> Self {
        PacketBuffers {
            raw: [0; HEADER_LEN + MAX_PAYLOAD + CRC_LEN],
            wire: [0; MAX_ENCODED],
        }
    }
}

impl PacketBuffers {
    /// Encodes into the internal buffers; returns the wire bytes (delimiter included).
    pub fn encode(
        &mut self,
        header: Header,
        payload: impl FnOnce(&mut [u8]) -> Result<usize, EncodeError>,
    ) -> Result<&[u8], EncodeError> {
        let n = encode_packet(header, &mut self.raw, &mut self.wire, payload)?;
        Ok(&self.wire[..n])
    }
}
