//! Serial framing protocol, smoltcp `wire` style.
//!
//! On the wire every packet is `COBS(header | payload | CRC-32) 0x00`:
//! - [`cobs`]: byte stuffing so 0x00 delimits packets;
//! - [`crc`]: CRC-32 of packets and whole frames;
//! - `packet`: the header view (`Packet::new_checked`, accessors) and the encoder;
//! - [`messages`]: one repr per message with `parse`/`emit`;
//! - `decoder`: the streaming decoder in fixed memory that resynchronises at delimiters;
//! - `window`: the selective-repeat sender window and the receiver's reorder ring;
//! - [`endpoint`]: the sans-IO reliable endpoint both sides drive (bytes in, bytes and messages out);
//! - [`assembly`]: frames assembled from chunks into preallocated buffers.
//!
//! The format is documented in `docs/protocol.md`.
pub mod assembly;
pub mod cobs;
pub mod crc;
pub(crate) mod decoder;
pub mod endpoint;
pub mod messages;
pub(crate) mod packet;
#[cfg(any(test, feature = "samples"))]
pub mod samples;
pub(crate) mod window;

#[cfg(test)]
mod tests;

pub use decoder::{DecodeError, Decoder};
pub use endpoint::{Endpoint, EndpointBuffers, EndpointConfig, Event, SendError};
pub use messages::{Message, MessageType, Repr};
pub use packet::{
    encode_packet, EncodeError, Header, Packet, PacketBuffers, PacketError, CRC_LEN, HEADER_LEN,
};

/// Version byte of every packet header. Version 2: a Result carries both cameras'
/// standard deviations, as `f32`.
pub const PROTOCOL_VERSION: u8 = 2;
/// Largest payload of any packet.
pub const MAX_PAYLOAD: usize = 4096;
/// Largest packet before COBS (header, payload, CRC).
pub const MAX_PACKET: usize = HEADER_LEN + MAX_PAYLOAD + CRC_LEN;
/// Largest packet on the wire: COBS encoding plus the delimiter. A decoder
/// buffer of this size accepts every legal packet.
pub const MAX_ENCODED: usize = cobs::max_encoded_len(MAX_PACKET) + 1;

/// Bytes on the wire of a packet with `payload` bytes in the worst case (all non-zero data).
pub const fn wire_len(payload: usize) -> usize {
    cobs::max_encoded_len(HEADER_LEN + payload + CRC_LEN) + 1
}
