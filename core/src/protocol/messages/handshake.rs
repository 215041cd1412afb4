//! Opening a session: the host's hello and the firmware's capabilities.
use super::*;

/// Host -> firmware: opens a session. A new `session` id resynchronises both
/// sequence spaces (a host reconnecting to a running firmware).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Hello {
    pub session: u32,
    /// Host software version (major, minor, patch).
    pub host_version: [u8; 3],
}
repr!(
    Hello,
    Hello,
    |r| {
        Ok(Hello {
            session: r.u32()?,
            host_version: [r.u8()?, r.u8()?, r.u8()?],
        })
    },
    |s, w| {
        w.u32(s.session)?;
        w.bytes(&s.host_version)?;
    }
);

/// What the firmware can processs.
pub mod processor_kind {
    /// Image statistics only (bring-up; no features).
    pub const IMAGE_STATS: u8 = 0;
    /// Reduced SIFT on both images.
    pub const SIFT: u8 = 1;
    /// The full traverse.
    pub const TRAVERSE: u8 = 2;
}

/// Firmware -> host: answer to Hello and Reset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Capabilities {
    pub firmware_version: [u8; 3],
    pub protocol_version: u8,
    /// Largest payload the firmware accepts.
    pub max_payload: u16,
    /// Packets the host may have in flight unacknowledged.
    pub rx_window: u16,
    pub max_width: u16,
    pub max_height: u16,
    /// Bit 0: gray u8, bit 1: gray u16.
    pub pixel_formats: u8,
    /// [`processor_kind`].
    pub processor: u8,
    pub max_keypoints: u32,
    /// Bytes of working storage the configuration must fit in.
    pub work_bytes: u32,
    /// Bytes of link buffers (decoder, reorder ring, retransmission window).
    pub link_bytes: u32,
    /// Largest payload the firmware holds when it arrives after a gap; larger
    /// packets are taken in order only, so a sender on a lossy line keeps below it.
    pub held_payload: u16,
}
repr!(
    Capabilities,
    Capabilities,
    |r| {
        Ok(Capabilities {
            firmware_version: [r.u8()?, r.u8()?, r.u8()?],
            protocol_version: r.u8()?,
            max_payload: r.u16()?,
            rx_window: r.u16()?,
            max_width: r.u16()?,
            max_height: r.u16()?,
            pixel_formats: r.u8()?,
            processor: r.u8()?,
            max_keypoints: r.u32()?,
            work_bytes: r.u32()?,
            link_bytes: r.u32()?,
            held_payload: r.u16()?,
        })
    },
    |s, w| {
        w.bytes(&s.firmware_version)?;
        w.u8(s.protocol_version)?;
        w.u16(s.max_payload)?;
        w.u16(s.rx_window)?;
        w.u16(s.max_width)?;
        w.u16(s.max_height)?;
        w.u8(s.pixel_formats)?;
        w.u8(s.processor)?;
        w.u32(s.max_keypoints)?;
        w.u32(s.work_bytes)?;
        w.u32(s.link_bytes)?;
        w.u16(s.held_payload)?;
    }
);
