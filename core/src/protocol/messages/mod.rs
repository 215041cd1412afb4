//! The message set: one plain `Repr` per message type with `parse` (zero-copy
//! over the payload; chunk data and error text borrow it) and `emit`.
//! All integers and floats are little-endian. Layouts are tabulated in
//! `docs/protocol.md`; each struct below lists its fields in wire order.
use super::packet::EncodeError;

/// Message type byte of the header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum MessageType {
    Hello = 0x01,
    Capabilities = 0x02,
    Configure = 0x03,
    ConfigAccepted = 0x04,
    FrameBegin = 0x05,
    FrameChunk = 0x06,
    FrameEnd = 0x07,
    Aux = 0x08,
    Result = 0x09,
    Stats = 0x0A,
    Error = 0x0B,
    Ack = 0x0C,
    Nack = 0x0D,
    Reset = 0x0E,
    Points = 0x0F,
    PointsRequest = 0x10,
}

impl MessageType {
    pub fn from_u8(b: u8) -> Option<Self> {
        use MessageType::*;
        Some(match b {
            0x01 => Hello,
            0x02 => Capabilities,
            0x03 => Configure,
            0x04 => ConfigAccepted,
            0x05 => FrameBegin,
            0x06 => FrameChunk,
            0x07 => FrameEnd,
            0x08 => Aux,
            0x09 => Result,
            0x0A => Stats,
            0x0B => Error,
            0x0C => Ack,
            0x0D => Nack,
            0x0E => Reset,
            0x0F => Points,
            0x10 => PointsRequest,
            _ => return None,
        })
    }

    /// Whether the message travels in the sequenced, acknowledged stream.
    /// Ack and Nack are the control channel of that stream and are not sequenced.
    pub fn is_sequenced(self) -> bool {
        !matches!(self, MessageType::Ack | MessageType::Nack)
    }
}

/// One message: its type, how to parse it from a payload and emit it into one.
pub trait Repr<'a>: Sized {
    const TYPE: MessageType;
    fn parse(payload: &'a [u8]) -> Result<Self, ParseError>;
    /// Writes the payload; returns its length.
    fn emit(&self, buf: &mut [u8]) -> Result<usize, EncodeError>;
}

macro_rules! repr {
    ($ty:ident $(<$lt:lifetime>)?, $mt:ident, |$r:ident| $parse:block, |$s:ident, $w:ident| $emit:block) => {
        impl<'a> Repr<'a> for $ty $(<$lt>)? {
            const TYPE: MessageType = MessageType::$mt;
            fn parse(payload: &'a [u8]) -> Result<Self, ParseError> {
                let mut $r = Reader::new(payload);
                $parse
            }
            fn emit(&self, buf: &mut [u8]) -> Result<usize, EncodeError> {
                let $s = self;
                let mut $w = Writer::new(buf);
                $emit
                Ok($w.len())
            }
        }
    };
}

mod configure;
mod control;
mod frames;
mod handshake;
mod points;
mod result;
mod stats;
mod wire;

pub use configure::*;
pub use control::*;
pub use frames::*;
pub use handshake::*;
pub use points::*;
pub use result::*;
pub use stats::*;
pub use wire::*;

/// Any message, parsed by type.
// No allocator to box into: a Points message (about 500 bytes) moves by value
// like the configuration does; the firmware handles one message at a time.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Message<'a> {
    Hello(Hello),
    Capabilities(Capabilities),
    Configure(Configure),
    ConfigAccepted(ConfigAccepted),
    FrameBegin(FrameBegin),
    FrameChunk(FrameChunk<'a>),
    FrameEnd(FrameEnd),
    Aux(Aux),
    Result(EpochResult),
    Stats(Stats),
    Error(ErrorMsg<'a>),
    Ack(Ack),
    Nack(Nack),
    Reset(Reset),
    Points(Points),
    PointsRequest(PointsRequest),
}

impl<'a> Message<'a> {
    pub fn parse(type_byte: u8, payload: &'a [u8]) -> Result<Self, ParseError> {
        let t = MessageType::from_u8(type_byte).ok_or(ParseError::UnknownType(type_byte))?;
        Ok(match t {
            MessageType::Hello => Message::Hello(Hello::parse(payload)?),
            MessageType::Capabilities => Message::Capabilities(Capabilities::parse(payload)?),
            MessageType::Configure => Message::Configure(Configure::parse(payload)?),
            MessageType::ConfigAccepted => Message::ConfigAccepted(ConfigAccepted::parse(payload)?),
            MessageType::FrameBegin => Message::FrameBegin(FrameBegin::parse(payload)?),
            MessageType::FrameChunk => Message::FrameChunk(FrameChunk::parse(payload)?),
            MessageType::FrameEnd => Message::FrameEnd(FrameEnd::parse(payload)?),
            MessageType::Aux => Message::Aux(Aux::parse(payload)?),
            MessageType::Result => Message::Result(EpochResult::parse(payload)?),
            MessageType::Stats => Message::Stats(Stats::parse(payload)?),
            MessageType::Error => Message::Error(ErrorMsg::parse(payload)?),
            MessageType::Ack => Message::Ack(Ack::parse(payload)?),
            MessageType::Nack => Message::Nack(Nack::parse(payload)?),
            MessageType::Reset => Message::Reset(Reset::parse(payload)?),
            MessageType::Points => Message::Points(Points::parse(payload)?),
            MessageType::PointsRequest => Message::PointsRequest(PointsRequest::parse(payload)?),
        })
    }

    pub fn message_type(&self) -> MessageType {
        match self {
            Message::Hello(_) => MessageType::Hello,
            Message::Capabilities(_) => MessageType::Capabilities,
            Message::Configure(_) => MessageType::Configure,
            Message::ConfigAccepted(_) => MessageType::ConfigAccepted,
            Message::FrameBegin(_) => MessageType::FrameBegin,
            Message::FrameChunk(_) => MessageType::FrameChunk,
            Message::FrameEnd(_) => MessageType::FrameEnd,
            Message::Aux(_) => MessageType::Aux,
            Message::Result(_) => MessageType::Result,
            Message::Stats(_) => MessageType::Stats,
            Message::Error(_) => MessageType::Error,
            Message::Ack(_) => MessageType::Ack,
            Message::Nack(_) => MessageType::Nack,
            Message::Reset(_) => MessageType::Reset,
            Message::Points(_) => MessageType::Points,
            Message::PointsRequest(_) => MessageType::PointsRequest,
        }
    }

    /// Writes the payload; returns its length.
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize, EncodeError> {
        match self {
            Message::Hello(m) => m.emit(buf),
            Message::Capabilities(m) => m.emit(buf),
            Message::Configure(m) => m.emit(buf),
            Message::ConfigAccepted(m) => m.emit(buf),
            Message::FrameBegin(m) => m.emit(buf),
            Message::FrameChunk(m) => m.emit(buf),
            Message::FrameEnd(m) => m.emit(buf),
            Message::Aux(m) => m.emit(buf),
            Message::Result(m) => m.emit(buf),
            Message::Stats(m) => m.emit(buf),
            Message::Error(m) => m.emit(buf),
            Message::Ack(m) => m.emit(buf),
            Message::Nack(m) => m.emit(buf),
            Message::Reset(m) => m.emit(buf),
            Message::Points(m) => m.emit(buf),
            Message::PointsRequest(m) => m.emit(buf),
        }
    }
}
