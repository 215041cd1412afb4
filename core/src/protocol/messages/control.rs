//! The link's control messages: errors, acknowledgements, negative acknowledgements and
//! resets.
use super::*;

/// Error codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u16)]
pub enum ErrorCode {
    /// A packet failed its CRC or framing.
    Corrupted = 1,
    /// A packet of another protocol version.
    Version = 2,
    /// A packet larger than the receiver's buffer.
    Oversized = 3,
    /// A message type or payload the receiver cannot use now.
    Unexpected = 4,
    /// A payload that does not parse.
    Malformed = 5,
    /// A configuration that does not fit the firmware's memory or limits.
    ConfigTooLarge = 6,
    /// A configuration with invalid values.
    ConfigInvalid = 7,
    /// Frame data before a configuration.
    NotConfigured = 8,
    /// A frame larger than the configured capacity.
    FrameTooLarge = 9,
    /// A chunk whose offset is not the next expected byte.
    ChunkOutOfOrder = 10,
    /// The assembled frame's length or CRC differs from FrameEnd.
    FrameCrc = 11,
    /// A frame of an epoch was abandoned (a new epoch started first).
    EpochIncomplete = 12,
    /// The processor failed.
    Processing = 13,
    /// A frame whose width or height differs from the configured camera's.
    FrameSize = 14,
    /// Anything else.
    Other = 0xFFFF,
}

impl ErrorCode {
    pub fn from_u16(v: u16) -> Self {
        use ErrorCode::*;
        match v {
            1 => Corrupted,
            2 => Version,
            3 => Oversized,
            4 => Unexpected,
            5 => Malformed,
            6 => ConfigTooLarge,
            7 => ConfigInvalid,
            8 => NotConfigured,
            9 => FrameTooLarge,
            10 => ChunkOutOfOrder,
            11 => FrameCrc,
            12 => EpochIncomplete,
            13 => Processing,
            14 => FrameSize,
            _ => Other,
        }
    }
}

/// Most bytes of error text.
pub const MAX_ERROR_TEXT: usize = 160;

/// Either side: something went wrong; `text` is human-readable UTF-8.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ErrorMsg<'a> {
    pub code: ErrorCode,
    /// Epoch concerned, or `u32::MAX`.
    pub epoch: u32,
    /// Sequence number of the offending packet, or `u16::MAX`.
    pub seq: u16,
    pub text: &'a str,
}
repr!(
    ErrorMsg<'a>,
    Error,
    |r| {
        let code = ErrorCode::from_u16(r.u16()?);
        let epoch = r.u32()?;
        let seq = r.u16()?;
        let text = core::str::from_utf8(r.rest())
            .map_err(|_| ParseError::Invalid("error text is not UTF-8"))?;
        Ok(ErrorMsg {
            code,
            epoch,
            seq,
            text,
        })
    },
    |s, w| {
        w.u16(s.code as u16)?;
        w.u32(s.epoch)?;
        w.u16(s.seq)?;
        let mut n = s.text.len().min(MAX_ERROR_TEXT);
        while !s.text.is_char_boundary(n) {
            n -= 1;
        }
        w.bytes(&s.text.as_bytes()[..n])?;
    }
);

/// Acknowledgement: every sequenced packet before `next_expected` arrived, the
/// bitmap `sack` says which after it are held (bit `i`: `next_expected + 1 + i`),
/// and two wrapping counters say how clean the line is from the receiver's side,
/// which the sender uses to size its packets. An Ack with a `probe` number asks
/// the peer for an Ack at once, which carries that number in `answers`: a sender
/// whose retransmission timer expired learns what is lost before it resends anything.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Ack {
    pub next_expected: u16,
    /// Packets the receiver accepts beyond `next_expected`.
    pub window: u16,
    pub sack: u64,
    /// Intact packets received so far (wrapping).
    pub received: u16,
    /// Damaged runs (CRC, framing, oversized, truncated) received so far (wrapping).
    pub damaged: u16,
    /// Number of this probe (1 to 255, wrapping), 0 when it is no probe.
    pub probe: u8,
    /// Number of the last probe of the peer answered, 0 before the first.
    pub answers: u8,
}
repr!(
    Ack,
    Ack,
    |r| {
        Ok(Ack {
            next_expected: r.u16()?,
            window: r.u16()?,
            sack: r.u64()?,
            received: r.u16()?,
            damaged: r.u16()?,
            probe: r.u8()?,
            answers: r.u8()?,
        })
    },
    |s, w| {
        w.u16(s.next_expected)?;
        w.u16(s.window)?;
        w.u64(s.sack)?;
        w.u16(s.received)?;
        w.u16(s.damaged)?;
        w.u8(s.probe)?;
        w.u8(s.answers)?;
    }
);

/// Negative acknowledgement: resend every unacknowledged packet from `expected`
/// on now. A host waiting for answers sends it after a retransmission time-out
/// without input, so a firmware's lost answer comes back without the firmware's
/// own timer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Nack {
    pub expected: u16,
    /// [`nack_reason`].
    pub reason: u8,
}

pub mod nack_reason {
    /// The receiver waited a retransmission time-out for answers.
    pub const TIMEOUT: u8 = 3;
}

repr!(
    Nack,
    Nack,
    |r| {
        Ok(Nack {
            expected: r.u16()?,
            reason: r.u8()?,
        })
    },
    |s, w| {
        w.u16(s.expected)?;
        w.u8(s.reason)?;
    }
);

/// Host -> firmware: drop the configuration and any partial epoch; answered by Capabilities.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reset {
    pub reason: u8,
}
repr!(
    Reset,
    Reset,
    |r| { Ok(Reset { reason: r.u8()? }) },
    |s, w| {
        w.u8(s.reason)?;
    }
);
