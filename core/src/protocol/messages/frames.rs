//! An epoch's images and auxiliary observations: frame begin, chunks and end per camera,
//! then GNSS and odometer.
use super::*;

pub use crate::camera::Camera;

/// The camera of a wire code (its `repr(u8)` value).
fn parse_camera(b: u8) -> Result<Camera, ParseError> {
    Camera::from_index(b).ok_or(ParseError::Invalid("camera"))
}

/// Pixel format of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelFormat {
    /// 8-bit gray, one byte per pixel.
    Gray8,
    /// Gray in u16 LE words with `bits` significant bits (9..=16), scaled to 8 bits on arrival.
    Gray16 { bits: u8 },
}

impl PixelFormat {
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            PixelFormat::Gray8 => 1,
            PixelFormat::Gray16 { .. } => 2,
        }
    }
}

/// Bytes of a `width` x `height` frame of `format`, exact on every target.
pub fn frame_bytes(width: u16, height: u16, format: PixelFormat) -> u64 {
    width as u64 * height as u64 * format.bytes_per_pixel() as u64
}

/// Host -> firmware: a frame of one camera of an epoch starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameBegin {
    pub epoch: u32,
    pub camera: Camera,
    pub format: PixelFormat,
    pub width: u16,
    pub height: u16,
    /// Exposure time stamp, microseconds.
    pub timestamp_us: u64,
}

impl FrameBegin {
    /// Bytes of the frame on the wire. In `u64`: the largest frame the fields allow
    /// (65535 x 65535 x 2 bytes) overflows the 32-bit `usize` of a microcontroller.
    pub fn frame_bytes(&self) -> u64 {
        frame_bytes(self.width, self.height, self.format)
    }
}

repr!(
    FrameBegin,
    FrameBegin,
    |r| {
        let epoch = r.u32()?;
        let camera = parse_camera(r.u8()?)?;
        let (code, bits) = (r.u8()?, r.u8()?);
        let format = match code {
            0 => PixelFormat::Gray8,
            1 if (9..=16).contains(&bits) => PixelFormat::Gray16 { bits },
            _ => return Err(ParseError::Invalid("pixel format")),
        };
        Ok(FrameBegin {
            epoch,
            camera,
            format,
            width: r.u16()?,
            height: r.u16()?,
            timestamp_us: r.u64()?,
        })
    },
    |s, w| {
        w.u32(s.epoch)?;
        w.u8(s.camera as u8)?;
        match s.format {
            PixelFormat::Gray8 => {
                w.u8(0)?;
                w.u8(8)?;
            }
            PixelFormat::Gray16 { bits } => {
                w.u8(1)?;
                w.u8(bits)?;
            }
        }
        w.u16(s.width)?;
        w.u16(s.height)?;
        w.u64(s.timestamp_us)?;
    }
);

/// Host -> firmware: bytes of a frame at a byte offset (zero-copy view of the payload).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameChunk<'a> {
    pub epoch: u32,
    pub camera: Camera,
    pub offset: u32,
    pub data: &'a [u8],
}

/// Bytes of a FrameChunk payload before its data.
pub const CHUNK_HEADER_LEN: usize = 9;

repr!(
    FrameChunk<'a>,
    FrameChunk,
    |r| {
        Ok(FrameChunk {
            epoch: r.u32()?,
            camera: parse_camera(r.u8()?)?,
            offset: r.u32()?,
            data: r.rest(),
        })
    },
    |s, w| {
        w.u32(s.epoch)?;
        w.u8(s.camera as u8)?;
        w.u32(s.offset)?;
        w.bytes(s.data)?;
    }
);

/// Host -> firmware: the frame is complete; its length and CRC-32 check the assembly.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameEnd {
    pub epoch: u32,
    pub camera: Camera,
    pub total_bytes: u32,
    pub crc32: u32,
}
repr!(
    FrameEnd,
    FrameEnd,
    |r| {
        Ok(FrameEnd {
            epoch: r.u32()?,
            camera: parse_camera(r.u8()?)?,
            total_bytes: r.u32()?,
            crc32: r.u32()?,
        })
    },
    |s, w| {
        w.u32(s.epoch)?;
        w.u8(s.camera as u8)?;
        w.u32(s.total_bytes)?;
        w.u32(s.crc32)?;
    }
);

/// Host -> firmware: auxiliary observations of an epoch (sent before its frames).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aux {
    pub epoch: u32,
    /// Bit 0: odometer valid, bit 1: GNSS valid.
    pub flags: u8,
    /// The odometer's count at the epoch (distance travelled since it started), m, and
    /// its sigma: the traverse differences the counts of consecutive window epochs.
    pub odometer_m: f64,
    pub odometer_sigma_m: f64,
    /// GNSS position in the object frame, m, and its sigmas.
    pub gnss_m: [f64; 3],
    pub gnss_sigma_m: [f64; 3],
    /// Where the GNSS antenna is, seen from the left perspective centre, in the left
    /// camera's frame (x right, y up, z backwards), m: the fix is the antenna's.
    pub gnss_lever_arm_m: [f64; 3],
}

pub const AUX_ODOMETER: u8 = 1;
pub const AUX_GNSS: u8 = 2;

repr!(
    Aux,
    Aux,
    |r| {
        Ok(Aux {
            epoch: r.u32()?,
            flags: r.u8()?,
            odometer_m: r.f64()?,
            odometer_sigma_m: r.f64()?,
            gnss_m: r.f64s()?,
            gnss_sigma_m: r.f64s()?,
            gnss_lever_arm_m: r.f64s()?,
        })
    },
    |s, w| {
        w.u32(s.epoch)?;
        w.u8(s.flags)?;
        w.f64(s.odometer_m)?;
        w.f64(s.odometer_sigma_m)?;
        w.f64s(&s.gnss_m)?;
        w.f64s(&s.gnss_sigma_m)?;
        w.f64s(&s.gnss_lever_arm_m)?;
    }
);
