//! The message set: one plain `Repr` per message type with `parse` (zero-copy
//! over the payload; chunk data and error text borrow it) and `emit`.
//! All integers and floats are little-endian. Layouts are tabulated in
//! `docs/protocol.md`; each struct below lists its fields in wire order.
use super::packet::EncodeError;
use crate::camera::{CalibrationPrecision, Interior, Rig};
use core::ops::{BitOr, BitOrAssign};

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

/// Why a payload could not be parsed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParseError {
    /// The payload ends before a field.
    Truncated,
    /// A field holds a value outside its domain (named).
    Invalid(&'static str),
    /// A type byte no message has.
    UnknownType(u8),
}

/// Little-endian field reader over a payload.
pub struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    pub fn new(buf: &'a [u8]) -> Self {
        Reader { buf, pos: 0 }
    }
    pub fn bytes(&mut self, n: usize) -> Result<&'a [u8], ParseError> {
        let end = self.pos.checked_add(n).ok_or(ParseError::Truncated)?;
        let s = self.buf.get(self.pos..end).ok_or(ParseError::Truncated)?;
        self.pos = end;
        Ok(s)
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N], ParseError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.bytes(N)?);
        Ok(a)
    }
    pub fn u8(&mut self) -> Result<u8, ParseError> {
        Ok(self.array::<1>()?[0])
    }
    pub fn u16(&mut self) -> Result<u16, ParseError> {
        Ok(u16::from_le_bytes(self.array()?))
    }
    pub fn u32(&mut self) -> Result<u32, ParseError> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    pub fn u64(&mut self) -> Result<u64, ParseError> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    pub fn f32(&mut self) -> Result<f32, ParseError> {
        Ok(f32::from_le_bytes(self.array()?))
    }
    pub fn f64(&mut self) -> Result<f64, ParseError> {
        Ok(f64::from_le_bytes(self.array()?))
    }
    pub fn f64s<const N: usize>(&mut self) -> Result<[f64; N], ParseError> {
        let mut a = [0.0; N];
        for v in a.iter_mut() {
            *v = self.f64()?;
        }
        Ok(a)
    }
    pub fn u32s<const N: usize>(&mut self) -> Result<[u32; N], ParseError> {
        let mut a = [0; N];
        for v in a.iter_mut() {
            *v = self.u32()?;
        }
        Ok(a)
    }
    pub fn rest(&mut self) -> &'a [u8] {
        let s = &self.buf[self.pos..];
        self.pos = self.buf.len();
        s
    }
    pub fn remaining(&self) -> usize {
        self.buf.len() - self.pos
    }
}

/// Little-endian field writer into a payload buffer.
pub struct Writer<'a> {
    buf: &'a mut [u8],
    pos: usize,
}

impl<'a> Writer<'a> {
    pub fn new(buf: &'a mut [u8]) -> Self {
        Writer { buf, pos: 0 }
    }
    pub fn bytes(&mut self, b: &[u8]) -> Result<(), EncodeError> {
        let end = self.pos + b.len();
        let dst = self
            .buf
            .get_mut(self.pos..end)
            .ok_or(EncodeError::PayloadTooLarge)?;
        dst.copy_from_slice(b);
        self.pos = end;
        Ok(())
    }
    pub fn u8(&mut self, v: u8) -> Result<(), EncodeError> {
        self.bytes(&[v])
    }
    pub fn u16(&mut self, v: u16) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }
    pub fn u32(&mut self, v: u32) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }
    pub fn u64(&mut self, v: u64) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }
    pub fn f32(&mut self, v: f32) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }
    pub fn f64(&mut self, v: f64) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }
    pub fn f64s(&mut self, v: &[f64]) -> Result<(), EncodeError> {
        v.iter().try_for_each(|x| self.f64(*x))
    }
    pub fn u32s(&mut self, v: &[u32]) -> Result<(), EncodeError> {
        v.iter().try_for_each(|x| self.u32(*x))
    }
    pub fn len(&self) -> usize {
        self.pos
    }
    pub fn is_empty(&self) -> bool {
        self.pos == 0
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

/// Payload version of [`Configure`] this build writes. Later versions append
/// fields; a parser reads the fields it knows and ignores the rest.
pub const CONFIG_VERSION: u16 = 4;

/// Pipeline capacities and thresholds, plain numbers the firmware maps to its config.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pipeline {
    pub max_width: u16,
    pub max_height: u16,
    /// Bytes per pixel of the largest frame format to buffer (1 or 2).
    pub pixel_bytes: u8,
    pub octaves: u8,
    pub scales_per_octave: u8,
    pub keypoints_per_image: u32,
    pub window_len: u16,
    pub track_capacity: u32,
    pub contrast_threshold: f32,
    pub edge_ratio: f32,
    pub match_ratio: f32,
    pub max_disparity_px: f32,
    /// Extract at half-pixel scales too (OpenCV's doubled image): about twice the
    /// keypoints and half the drift for twice the extractor's time, same memory
    /// (v2 flags bit 1).
    pub fine_octave: bool,
    /// Epochs that left the window whose observations still count (v3); `None`
    /// keeps the firmware's default.
    pub fixed_epochs: Option<u16>,
}

/// The v3 `fixed_epochs` value that says "the firmware's default".
const FIRMWARE_DEFAULT_U16: u16 = u16::MAX;

impl Default for Pipeline {
    fn default() -> Self {
        Pipeline {
            max_width: 640,
            max_height: 480,
            pixel_bytes: 1,
            octaves: 4,
            scales_per_octave: 3,
            keypoints_per_image: 1000,
            window_len: 5,
            track_capacity: 2000,
            contrast_threshold: 0.02,
            edge_ratio: 10.0,
            match_ratio: 0.8,
            max_disparity_px: 128.0,
            fine_octave: false,
            fixed_epochs: None,
        }
    }
}

/// How the firmware adjusts, as the Configure v2 mode byte names it. The wire's own
/// codes: the firmware maps them to its pipeline's modes, so the format does not
/// move when the pipeline does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AdjustMode {
    /// The sliding window (the project's default).
    #[default]
    Window,
    /// Seed 000 (Lemes Neto 2014): two-epoch sequences, one re-weighting.
    Seed2014,
    /// Seed 002 (Barbosa 2006): seven bases adjusted together.
    Seed2006,
}

impl AdjustMode {
    pub const ALL: [AdjustMode; 3] = [
        AdjustMode::Window,
        AdjustMode::Seed2014,
        AdjustMode::Seed2006,
    ];

    /// Wire code.
    pub const fn code(self) -> u8 {
        match self {
            AdjustMode::Window => 0,
            AdjustMode::Seed2014 => 1,
            AdjustMode::Seed2006 => 2,
        }
    }

    /// The mode of a wire code; a code this build does not know is refused, since
    /// adjusting in another mode than the host asked for would be silently wrong.
    pub fn parse(code: u8) -> Result<Self, ParseError> {
        Self::ALL
            .into_iter()
            .find(|m| m.code() == code)
            .ok_or(ParseError::Invalid("adjustment mode"))
    }
}

/// How the firmware adjusts (Configure v2; a v1 payload gets [`TraverseSettings::default`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraverseSettings {
    /// Window (the project's default) or one of the seed procedures.
    pub mode: AdjustMode,
    /// Estimate the relative orientation of the rig in the adjustment.
    pub estimate_rig: bool,
    /// A-priori standard deviation of an image measurement, pixels.
    pub sigma_px: f64,
    /// The datum: the left camera at epoch 0, omega, phi, kappa (rad), X, Y, Z (m).
    pub datum: [f64; 6],
    /// Test the calibration and correct it where the images call for it (v4 flag;
    /// `false` holds it as given). A v1-v3 payload gets the check.
    pub check_calibration: bool,
    /// The calibration's stated precision (v4; earlier payloads get
    /// [`CalibrationPrecision::UNSTATED`]).
    pub calibration_precision: CalibrationPrecision,
}

impl Default for TraverseSettings {
    /// What a v1 firmware did: window mode, fixed rig, 0.5 px, a level camera
    /// looking along +Y at the origin (omega 90 degrees).
    fn default() -> Self {
        TraverseSettings {
            mode: AdjustMode::Window,
            estimate_rig: false,
            sigma_px: 0.5,
            datum: [core::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0, 0.0, 0.0],
            check_calibration: true,
            calibration_precision: CalibrationPrecision::UNSTATED,
        }
    }
}

/// Bit 0 of the v2 flags byte: estimate the rig.
const CONFIG_ESTIMATE_RIG: u8 = 1;
/// Bit 1 of the v2 flags byte: the extractor's fine octave ([`Pipeline::fine_octave`]).
const CONFIG_FINE_OCTAVE: u8 = 2;
/// Bit 2 of the flags byte (v4): hold the calibration as given, no check
/// ([`TraverseSettings::check_calibration`] false).
const CONFIG_HOLD_CALIBRATION: u8 = 4;

/// Host -> firmware: the rig and the pipeline. Answered by ConfigAccepted or Error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Configure {
    pub version: u16,
    pub rig: Rig,
    pub pipeline: Pipeline,
    /// Version 2 fields (defaults when the payload is version 1).
    pub traverse: TraverseSettings,
}

/// A setting of a configuration out of its range: its name (as in the settings
/// file) and the rule it breaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SettingError {
    pub field: &'static str,
    pub rule: &'static str,
}

impl core::fmt::Display for SettingError {
    fn fmt(&self, f: &mut core::fmt::Formatter) -> core::fmt::Result {
        write!(f, "{} {}", self.field, self.rule)
    }
}

/// Most keypoints per image a configuration may ask for.
pub const MAX_KEYPOINTS_PER_IMAGE: u32 = 100_000;

impl Configure {
    /// The limits of every setting, one place for both sides: the host checks a
    /// settings file with them before it sends anything, the firmware every
    /// Configure it receives, and both name the setting that breaks them.
    pub fn validate(&self) -> Result<(), SettingError> {
        let p = &self.pipeline;
        let t = &self.traverse;
        let bad = |field, rule| Err(SettingError { field, rule });
        let finite_pos = |v: f64| v.is_finite() && v > 0.0;
        if p.max_width == 0 || p.max_height == 0 {
            return bad("max_width, max_height", "must be at least 1 pixel");
        }
        if !(1..=2).contains(&p.pixel_bytes) {
            return bad("pixel_bytes", "must be 1 or 2");
        }
        if !(8..=MAX_KEYPOINTS_PER_IMAGE).contains(&p.keypoints_per_image) {
            return bad("keypoints_per_image", "must be in 8..=100000");
        }
        if !(1..=8).contains(&p.octaves) {
            return bad("octaves", "must be 1..=8");
        }
        if !(1..=6).contains(&p.scales_per_octave) {
            return bad("scales_per_octave", "must be 1..=6");
        }
        if p.window_len < 2 {
            return bad("window", "must be at least 2 epochs");
        }
        if p.fixed_epochs.is_some_and(|f| f > 64) {
            return bad("fixed_epochs", "must be at most 64");
        }
        if p.track_capacity < 8 {
            return bad("track_capacity", "must be at least 8");
        }
        if !(p.contrast_threshold.is_finite() && p.contrast_threshold >= 0.0) {
            return bad("contrast_threshold", "must be finite and at least 0");
        }
        if !finite_pos(p.edge_ratio as f64) {
            return bad("edge_ratio", "must be finite and positive");
        }
        if !(p.match_ratio > 0.0 && p.match_ratio <= 1.0) {
            return bad("match_ratio", "must be in (0, 1]");
        }
        // A range below one pixel searches nothing: every epoch would be flagged.
        if !(p.max_disparity_px.is_finite() && p.max_disparity_px >= 1.0) {
            return bad(
                "max_disparity_px",
                "must be at least 1 pixel (the stereo search range)",
            );
        }
        if !finite_pos(t.sigma_px) {
            return bad("sigma_px", "must be finite and positive");
        }
        if !t.datum.iter().all(|v| v.is_finite()) {
            return bad("datum", "values must be finite");
        }
        if !t.calibration_precision.valid() {
            return bad(
                "precision",
                "principal point, focal, angles and base must be positive and finite",
            );
        }
        Ok(())
    }
}

fn parse_interior(r: &mut Reader) -> Result<Interior, ParseError> {
    Ok(Interior {
        width_px: r.u32()?,
        height_px: r.u32()?,
        pixel_size_mm: r.f64s()?,
        focal_mm: r.f64()?,
        principal_point_mm: r.f64s()?,
        radial: r.f64s()?,
        decentering: r.f64s()?,
    })
}

fn emit_interior(w: &mut Writer, i: &Interior) -> Result<(), EncodeError> {
    w.u32(i.width_px)?;
    w.u32(i.height_px)?;
    w.f64s(&i.pixel_size_mm)?;
    w.f64(i.focal_mm)?;
    w.f64s(&i.principal_point_mm)?;
    w.f64s(&i.radial)?;
    w.f64s(&i.decentering)
}

repr!(
    Configure,
    Configure,
    |r| {
        let version = r.u16()?;
        if version == 0 {
            return Err(ParseError::Invalid("configuration version 0"));
        }
        let rig = Rig {
            left: parse_interior(&mut r)?,
            right: parse_interior(&mut r)?,
            relative_angles: r.f64s()?,
            base_m: r.f64s()?,
        };
        let pipeline = Pipeline {
            max_width: r.u16()?,
            max_height: r.u16()?,
            pixel_bytes: r.u8()?,
            octaves: r.u8()?,
            scales_per_octave: r.u8()?,
            keypoints_per_image: r.u32()?,
            window_len: r.u16()?,
            track_capacity: r.u32()?,
            contrast_threshold: r.f32()?,
            edge_ratio: r.f32()?,
            match_ratio: r.f32()?,
            max_disparity_px: r.f32()?,
            fine_octave: false,
            fixed_epochs: None,
        };
        let mut settings = TraverseSettings::default();
        let mut pipeline = pipeline;
        let mut flags = 0;
        if version >= 2 {
            let code = r.u8()?;
            flags = r.u8()?;
            settings.sigma_px = r.f64()?;
            settings.datum = r.f64s()?;
            settings.mode = AdjustMode::parse(code)?;
            settings.estimate_rig = flags & CONFIG_ESTIMATE_RIG != 0;
            pipeline.fine_octave = flags & CONFIG_FINE_OCTAVE != 0;
        }
        if version >= 3 {
            let f = r.u16()?;
            pipeline.fixed_epochs = (f != FIRMWARE_DEFAULT_U16).then_some(f);
        }
        if version >= 4 {
            settings.check_calibration = flags & CONFIG_HOLD_CALIBRATION == 0;
            let p = &mut settings.calibration_precision;
            p.principal_point_px = r.f64()?;
            p.focal = r.f64()?;
            p.angles_rad = r.f64()?;
            p.base_m = r.f64()?;
            if !p.valid() {
                return Err(ParseError::Invalid("calibration precision"));
            }
        }
        // Fields of later versions follow; this build ignores them.
        let _ = r.rest();
        Ok(Configure {
            version,
            rig,
            pipeline,
            traverse: settings,
        })
    },
    |s, w| {
        w.u16(s.version)?;
        emit_interior(&mut w, &s.rig.left)?;
        emit_interior(&mut w, &s.rig.right)?;
        w.f64s(&s.rig.relative_angles)?;
        w.f64s(&s.rig.base_m)?;
        let p = &s.pipeline;
        w.u16(p.max_width)?;
        w.u16(p.max_height)?;
        w.u8(p.pixel_bytes)?;
        w.u8(p.octaves)?;
        w.u8(p.scales_per_octave)?;
        w.u32(p.keypoints_per_image)?;
        w.u16(p.window_len)?;
        w.u32(p.track_capacity)?;
        w.f32(p.contrast_threshold)?;
        w.f32(p.edge_ratio)?;
        w.f32(p.match_ratio)?;
        w.f32(p.max_disparity_px)?;
        // A version-1 message carries only the fields above.
        if s.version >= 2 {
            let t = &s.traverse;
            w.u8(t.mode.code())?;
            let rig_flag = if t.estimate_rig {
                CONFIG_ESTIMATE_RIG
            } else {
                0
            };
            let octave_flag = if p.fine_octave { CONFIG_FINE_OCTAVE } else { 0 };
            let hold_flag = if s.version >= 4 && !t.check_calibration {
                CONFIG_HOLD_CALIBRATION
            } else {
                0
            };
            w.u8(rig_flag | octave_flag | hold_flag)?;
            w.f64(t.sigma_px)?;
            w.f64s(&t.datum)?;
        }
        if s.version >= 3 {
            w.u16(p.fixed_epochs.unwrap_or(FIRMWARE_DEFAULT_U16))?;
        }
        if s.version >= 4 {
            let c = &s.traverse.calibration_precision;
            w.f64(c.principal_point_px)?;
            w.f64(c.focal)?;
            w.f64(c.angles_rad)?;
            w.f64(c.base_m)?;
        }
    }
);

/// Firmware -> host: the configuration fits; its predicted memory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConfigAccepted {
    /// Predicted bytes of the whole configuration (frames included).
    pub predicted_bytes: u32,
    /// Bytes of the two frame buffers.
    pub frame_bytes: u32,
    /// Working storage available.
    pub capacity_bytes: u32,
}
repr!(
    ConfigAccepted,
    ConfigAccepted,
    |r| {
        Ok(ConfigAccepted {
            predicted_bytes: r.u32()?,
            frame_bytes: r.u32()?,
            capacity_bytes: r.u32()?,
        })
    },
    |s, w| {
        w.u32(s.predicted_bytes)?;
        w.u32(s.frame_bytes)?;
        w.u32(s.capacity_bytes)?;
    }
);

/// Camera of a stereo pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Camera {
    Left = 0,
    Right = 1,
}

impl Camera {
    fn parse(b: u8) -> Result<Self, ParseError> {
        match b {
            0 => Ok(Camera::Left),
            1 => Ok(Camera::Right),
            _ => Err(ParseError::Invalid("camera")),
        }
    }
    pub fn index(self) -> usize {
        self as usize
    }
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
        let camera = Camera::parse(r.u8()?)?;
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
            camera: Camera::parse(r.u8()?)?,
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
            camera: Camera::parse(r.u8()?)?,
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

/// Status of an epoch's result.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EpochStatus {
    /// Oriented.
    Ok,
    /// Features extracted, no orientation (the firmware runs the feature processor).
    FeaturesOnly,
    /// Image statistics only (bring-up processor).
    StatsOnly,
    /// The epoch's frames could not be assembled (lost chunk, CRC): the epoch is lost.
    Lost,
    /// The processor failed on this epoch (see the Error message), or refused its frames.
    Failed,
    /// Oriented, but flagged (see the [`ResultFlags`]).
    Flagged,
    /// Not oriented from the images: the pose is the motion prediction.
    Predicted,
    /// A code this build does not know (a newer firmware's); never one of the codes
    /// above, which parse to their own variants. Kept rather than refused so a host
    /// can still report the epoch.
    Unknown(u8),
}

impl EpochStatus {
    const KNOWN: [EpochStatus; 7] = [
        EpochStatus::Ok,
        EpochStatus::FeaturesOnly,
        EpochStatus::StatsOnly,
        EpochStatus::Lost,
        EpochStatus::Failed,
        EpochStatus::Flagged,
        EpochStatus::Predicted,
    ];

    /// Wire code.
    pub const fn code(self) -> u8 {
        match self {
            EpochStatus::Ok => 0,
            EpochStatus::FeaturesOnly => 1,
            EpochStatus::StatsOnly => 2,
            EpochStatus::Lost => 3,
            EpochStatus::Failed => 4,
            EpochStatus::Flagged => 5,
            EpochStatus::Predicted => 6,
            EpochStatus::Unknown(code) => code,
        }
    }

    pub fn from_code(code: u8) -> Self {
        Self::KNOWN
            .into_iter()
            .find(|s| s.code() == code)
            .unwrap_or(EpochStatus::Unknown(code))
    }
}

/// What went wrong or was noteworthy at an epoch, one bit each. Bits this build
/// does not name (a newer firmware's) are kept as they came.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ResultFlags(pub u32);

impl ResultFlags {
    pub const NONE: ResultFlags = ResultFlags(0);
    /// Too few tie points to the previous epoch: the epoch leans on its prediction.
    pub const FEW_TIE_POINTS: ResultFlags = ResultFlags(1 << 0);
    /// Continuity was lost (a frame from another place, a large jump): too few
    /// descriptor matches and too few tie points carried the epoch.
    pub const LOST: ResultFlags = ResultFlags(1 << 1);
    /// An image has no usable keypoints (textureless, dark, saturated).
    pub const NO_FEATURES: ResultFlags = ResultFlags(1 << 2);
    /// No stereo match at this epoch.
    pub const NO_STEREO: ResultFlags = ResultFlags(1 << 3);
    /// The frames repeat the previous epoch's: the previous pose is repeated.
    pub const REPEATED: ResultFlags = ResultFlags(1 << 4);
    /// The global chi-square test of the adjustment failed (upper tail).
    pub const CHI2: ResultFlags = ResultFlags(1 << 5);
    /// The adjustment failed (singular, no redundancy).
    pub const SOLVE_FAILED: ResultFlags = ResultFlags(1 << 6);
    /// The frames were refused (size, capacity): the epoch was skipped.
    pub const BAD_IMAGE: ResultFlags = ResultFlags(1 << 7);
    /// A capacity was reached (points or observations dropped).
    pub const CAPACITY: ResultFlags = ResultFlags(1 << 8);
    /// Informational: the resection failed and the motion prediction started the adjustment.
    pub const NO_RESECTION: ResultFlags = ResultFlags(1 << 9);
    /// Informational: the camera was found again by a resection on the previous stereo
    /// pair's points matched without the motion prior.
    pub const RELOCALIZED: ResultFlags = ResultFlags(1 << 10);
    /// Informational: the calibration check found the calibration significantly wrong
    /// and corrected it (the rig's relative orientation and the interior orientation).
    pub const CALIBRATION_CORRECTED: ResultFlags = ResultFlags(1 << 11);
    /// Informational: no resection posed the camera; its rotation came from the
    /// temporal matches, its position from the prediction.
    pub const ROTATION_FROM_MATCHES: ResultFlags = ResultFlags(1 << 12);

    pub const fn bits(self) -> u32 {
        self.0
    }

    /// Whether every bit of `other` is set.
    pub const fn contains(self, other: ResultFlags) -> bool {
        self.0 & other.0 == other.0
    }

    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }
}

impl BitOr for ResultFlags {
    type Output = ResultFlags;
    fn bitor(self, rhs: ResultFlags) -> ResultFlags {
        ResultFlags(self.0 | rhs.0)
    }
}

impl BitOrAssign for ResultFlags {
    fn bitor_assign(&mut self, rhs: ResultFlags) {
        self.0 |= rhs.0;
    }
}

/// Counts of an epoch; a processor that does not produce an item sends 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counts {
    /// Keypoints of the left and right image.
    pub keypoints: [u32; 2],
    /// Left-right matches of the epoch.
    pub stereo_matches: u32,
    /// Tie points linking this epoch to the previous one (seen in both stereo pairs).
    pub tie_points: u32,
    /// Tie points in the adjustment window after this epoch.
    pub window_points: u32,
    /// Image observations in the adjustment window after this epoch.
    pub observations: u32,
    /// Tie points this epoch added to the window.
    pub new_points: u32,
    /// Items dropped because a capacity was full.
    pub dropped: u32,
}

/// The adjustment of the window that ended with an epoch.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Adjustment {
    /// A-posteriori sigma0 (a-priori 1).
    pub sigma0: f64,
    /// RMS image residual of the window, pixels.
    pub rms_px: f64,
    /// Statistic of the global test, `vTPv` with the a-priori variance factor 1;
    /// chi-square with `redundancy` degrees of freedom.
    pub chi2: f64,
    /// Redundancy of the adjustment: the degrees of freedom of `chi2`.
    pub redundancy: u32,
    /// Standard deviations of the left perspective centre X, Y, Z (m) relative to the
    /// recent past (the poses that left the window held exact); 0: not estimated.
    pub relative_sd_m: [f32; 3],
    /// The left perspective centre's displacement from the previous epoch's (m), both
    /// as adjusted in this window: the images' step, undistorted by GNSS fixes, which
    /// move the window as a whole. `None` when the previous epoch is not in the window.
    /// `f32` keeps a few tenths of a micrometre on a step of metres.
    pub step_m: Option<[f32; 3]>,
}

/// What the feature extractor found in each image (left, right).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SiftCounts {
    /// 3x3x3 scale-space extrema above the preliminary contrast threshold.
    pub extrema: [u32; 2],
    /// Refined keypoint locations accepted (contrast and edge tests passed).
    pub refined: [u32; 2],
}

/// Statistics of each image (left, right), for checking that the frames arrived whole.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ImageStats {
    /// Mean grey value.
    pub mean: [f64; 2],
    /// Mean absolute gradient, `|dx| + |dy|` per pixel.
    pub gradient_energy: [f64; 2],
    /// Median grey value.
    pub median: [u8; 2],
}

/// The figures only one kind of processor produces. A processor answers an epoch
/// alone, so a Result carries one block at most; and the blocks together would
/// not fit the firmware's 256-byte transmit slot with the rig block.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Figures {
    #[default]
    None,
    Adjustment(Adjustment),
    Sift(SiftCounts),
    ImageStats(ImageStats),
}

/// Wire codes of the [`Figures`] kinds.
mod figures_kind {
    pub const NONE: u8 = 0;
    pub const ADJUSTMENT: u8 = 1;
    pub const SIFT: u8 = 2;
    pub const IMAGE_STATS: u8 = 3;
}

impl Figures {
    fn parse(r: &mut Reader) -> Result<Self, ParseError> {
        Ok(match r.u8()? {
            figures_kind::NONE => Figures::None,
            figures_kind::ADJUSTMENT => Figures::Adjustment(Adjustment {
                sigma0: r.f64()?,
                rms_px: r.f64()?,
                chi2: r.f64()?,
                redundancy: r.u32()?,
                relative_sd_m: [r.f32()?, r.f32()?, r.f32()?],
                step_m: match r.u8()? {
                    0 => None,
                    1 => Some([r.f32()?, r.f32()?, r.f32()?]),
                    _ => return Err(ParseError::Invalid("result step presence")),
                },
            }),
            figures_kind::SIFT => Figures::Sift(SiftCounts {
                extrema: r.u32s()?,
                refined: r.u32s()?,
            }),
            figures_kind::IMAGE_STATS => Figures::ImageStats(ImageStats {
                mean: r.f64s()?,
                gradient_energy: r.f64s()?,
                median: [r.u8()?, r.u8()?],
            }),
            _ => return Err(ParseError::Invalid("result figures kind")),
        })
    }

    fn emit(&self, w: &mut Writer) -> Result<(), EncodeError> {
        match self {
            Figures::None => w.u8(figures_kind::NONE),
            Figures::Adjustment(a) => {
                w.u8(figures_kind::ADJUSTMENT)?;
                w.f64s(&[a.sigma0, a.rms_px, a.chi2])?;
                w.u32(a.redundancy)?;
                a.relative_sd_m.iter().try_for_each(|v| w.f32(*v))?;
                match a.step_m {
                    None => w.u8(0),
                    Some(step) => {
                        w.u8(1)?;
                        step.iter().try_for_each(|v| w.f32(*v))
                    }
                }
            }
            Figures::Sift(s) => {
                w.u8(figures_kind::SIFT)?;
                w.u32s(&s.extrema)?;
                w.u32s(&s.refined)
            }
            Figures::ImageStats(s) => {
                w.u8(figures_kind::IMAGE_STATS)?;
                w.f64s(&s.mean)?;
                w.f64s(&s.gradient_energy)?;
                w.bytes(&s.median)
            }
        }
    }
}

/// Firmware -> host: result of one epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpochResult {
    pub epoch: u32,
    pub status: EpochStatus,
    /// Left camera: omega, phi, kappa (rad), X, Y, Z (m).
    pub pose: [f64; 6],
    /// Standard deviations of `pose`.
    pub sigma: [f64; 6],
    pub flags: ResultFlags,
    pub counts: Counts,
    /// The processor's own figures.
    pub figures: Figures,
    /// Optional trailing block: the rig as estimated by the adjustment (sent only
    /// when it can differ from the calibration).
    pub rig: Option<RigEstimate>,
}

/// The relative orientation estimated with an epoch. `f32` on the wire keeps a
/// Result within a 256-byte transmit slot; the values are small (angles of a few
/// mrad, a base under a few metres), so `f32` keeps nanoradians and tens of nanometres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigEstimate {
    /// Relative angles omega, phi, kappa (rad) and base bx, by, bz (m), as in [`Rig`].
    pub params: [f32; 6],
    /// Their standard deviations (zero when not available).
    pub std: [f32; 6],
}

impl RigEstimate {
    fn parse(r: &mut Reader) -> Result<Self, ParseError> {
        let mut v = [0f32; 12];
        for x in v.iter_mut() {
            *x = r.f32()?;
        }
        Ok(RigEstimate {
            params: core::array::from_fn(|i| v[i]),
            std: core::array::from_fn(|i| v[6 + i]),
        })
    }

    fn emit(&self, w: &mut Writer) -> Result<(), EncodeError> {
        for x in self.params.iter().chain(self.std.iter()) {
            w.f32(*x)?;
        }
        Ok(())
    }
}

impl EpochResult {
    pub fn empty(epoch: u32, status: EpochStatus) -> Self {
        EpochResult {
            epoch,
            status,
            pose: [0.0; 6],
            sigma: [0.0; 6],
            flags: ResultFlags::NONE,
            counts: Counts::default(),
            figures: Figures::None,
            rig: None,
        }
    }

    pub fn adjustment(&self) -> Option<&Adjustment> {
        match &self.figures {
            Figures::Adjustment(a) => Some(a),
            _ => None,
        }
    }

    pub fn sift(&self) -> Option<&SiftCounts> {
        match &self.figures {
            Figures::Sift(s) => Some(s),
            _ => None,
        }
    }

    pub fn image_stats(&self) -> Option<&ImageStats> {
        match &self.figures {
            Figures::ImageStats(s) => Some(s),
            _ => None,
        }
    }
}

repr!(
    EpochResult,
    Result,
    |r| {
        Ok(EpochResult {
            epoch: r.u32()?,
            status: EpochStatus::from_code(r.u8()?),
            pose: r.f64s()?,
            sigma: r.f64s()?,
            flags: ResultFlags(r.u32()?),
            counts: Counts {
                keypoints: r.u32s()?,
                stereo_matches: r.u32()?,
                tie_points: r.u32()?,
                window_points: r.u32()?,
                observations: r.u32()?,
                new_points: r.u32()?,
                dropped: r.u32()?,
            },
            figures: Figures::parse(&mut r)?,
            rig: if r.remaining() > 0 {
                Some(RigEstimate::parse(&mut r)?)
            } else {
                None
            },
        })
    },
    |s, w| {
        w.u32(s.epoch)?;
        w.u8(s.status.code())?;
        w.f64s(&s.pose)?;
        w.f64s(&s.sigma)?;
        w.u32(s.flags.bits())?;
        let c = &s.counts;
        w.u32s(&c.keypoints)?;
        w.u32s(&[
            c.stereo_matches,
            c.tie_points,
            c.window_points,
            c.observations,
            c.new_points,
            c.dropped,
        ])?;
        s.figures.emit(&mut w)?;
        if let Some(rig) = &s.rig {
            rig.emit(&mut w)?;
        }
    }
);

/// Pipeline stages timed in [`Stats`].
pub mod stage {
    pub const ASSEMBLE: usize = 0;
    pub const SIFT_LEFT: usize = 1;
    pub const SIFT_RIGHT: usize = 2;
    pub const STEREO_MATCH: usize = 3;
    pub const TEMPORAL_MATCH: usize = 4;
    pub const INITIAL_VALUES: usize = 5;
    pub const ADJUST: usize = 6;
    pub const TOTAL: usize = 7;
    pub const COUNT: usize = 8;
    pub const NAMES: [&str; COUNT] = [
        "assemble",
        "sift_left",
        "sift_right",
        "stereo_match",
        "temporal_match",
        "initial_values",
        "adjust",
        "total",
    ];
}

/// Link counters of one side.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LinkCounters {
    pub packets_ok: u32,
    pub crc_errors: u32,
    pub framing_errors: u32,
    pub oversized: u32,
    pub unexpected: u32,
    pub duplicates: u32,
    pub gaps: u32,
    pub retransmissions: u32,
}

impl LinkCounters {
    fn emit(&self, w: &mut Writer) -> Result<(), EncodeError> {
        w.u32s(&[
            self.packets_ok,
            self.crc_errors,
            self.framing_errors,
            self.oversized,
        ])?;
        w.u32s(&[
            self.unexpected,
            self.duplicates,
            self.gaps,
            self.retransmissions,
        ])
    }
    fn parse(r: &mut Reader) -> Result<Self, ParseError> {
        let [packets_ok, crc_errors, framing_errors, oversized, unexpected, duplicates, gaps, retransmissions] =
            r.u32s::<8>()?;
        Ok(LinkCounters {
            packets_ok,
            crc_errors,
            framing_errors,
            oversized,
            unexpected,
            duplicates,
            gaps,
            retransmissions,
        })
    }
}

/// Firmware -> host: timings and memory after an epoch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stats {
    pub epoch: u32,
    /// Microseconds per [`stage`].
    pub timings_us: [u32; stage::COUNT],
    pub memory_predicted: u32,
    /// Measured high-water mark of the working storage.
    pub memory_high_water: u32,
    pub memory_capacity: u32,
    pub epochs_ok: u32,
    pub epochs_lost: u32,
    /// The firmware's receive side and its retransmissions.
    pub link: LinkCounters,
    /// Each [`capacity`]'s highest use so far against what is reserved (zero for a
    /// processor without it).
    pub capacities: [CapacityUse; capacity::COUNT],
    /// The stack's high-water mark, on a target that paints its stack.
    pub stack: Option<StackUse>,
}

/// The capacities whose peak use the firmware reports, in [`Stats::capacities`].
pub mod capacity {
    /// Keypoints of one image (the larger of left and right).
    pub const KEYPOINTS: usize = 0;
    /// Left-right matches of an epoch.
    pub const STEREO_MATCHES: usize = 1;
    /// Live tracks.
    pub const TRACKS: usize = 2;
    /// Tie points linking an epoch to the previous one.
    pub const TIE_POINTS: usize = 3;
    /// Tie points in the adjustment window.
    pub const WINDOW_POINTS: usize = 4;
    /// Image observations in the adjustment window.
    pub const WINDOW_OBSERVATIONS: usize = 5;
    /// Image patches kept for area tracking.
    pub const PATCHES: usize = 6;
    pub const COUNT: usize = 7;
    pub const NAMES: [&str; COUNT] = [
        "keypoints_per_image",
        "stereo_matches",
        "tracks",
        "tie_points",
        "window_points",
        "window_observations",
        "patches",
    ];
}

/// The highest use of a capacity against the items reserved for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CapacityUse {
    pub peak: u32,
    pub reserved: u32,
}

impl CapacityUse {
    /// Raises the peak to `used` if higher.
    pub fn record(&mut self, used: usize) {
        self.peak = self.peak.max(used.min(u32::MAX as usize) as u32);
    }
}

/// The stack's high-water mark, bytes, against the bytes reserved for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StackUse {
    pub used: u32,
    pub reserved: u32,
}

repr!(
    Stats,
    Stats,
    |r| {
        Ok(Stats {
            epoch: r.u32()?,
            timings_us: r.u32s()?,
            memory_predicted: r.u32()?,
            memory_high_water: r.u32()?,
            memory_capacity: r.u32()?,
            epochs_ok: r.u32()?,
            epochs_lost: r.u32()?,
            link: LinkCounters::parse(&mut r)?,
            capacities: {
                let mut c = [CapacityUse::default(); capacity::COUNT];
                for u in c.iter_mut() {
                    *u = CapacityUse {
                        peak: r.u32()?,
                        reserved: r.u32()?,
                    };
                }
                c
            },
            stack: match r.u8()? {
                0 => None,
                1 => Some(StackUse {
                    used: r.u32()?,
                    reserved: r.u32()?,
                }),
                _ => return Err(ParseError::Invalid("stats stack presence")),
            },
        })
    },
    |s, w| {
        w.u32(s.epoch)?;
        w.u32s(&s.timings_us)?;
        w.u32s(&[
            s.memory_predicted,
            s.memory_high_water,
            s.memory_capacity,
            s.epochs_ok,
            s.epochs_lost,
        ])?;
        s.link.emit(&mut w)?;
        for c in &s.capacities {
            w.u32s(&[c.peak, c.reserved])?;
        }
        match s.stack {
            None => w.u8(0)?,
            Some(st) => {
                w.u8(1)?;
                w.u32s(&[st.used, st.reserved])?;
            }
        }
    }
);

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

// ----- Tie points and their observations (firmware -> host, pulled by the host) -----

/// Most point records one [`Points`] message holds.
pub const POINTS_MAX: usize = 6;
/// Most observation records one [`Points`] message holds.
pub const POINT_OBS_MAX: usize = 9;
/// Bytes of the [`Points`] header (report, index, flags, the two counts).
pub const POINTS_HEADER_LEN: usize = 9;
/// Bytes of one [`PointRecord`] on the wire.
pub const POINT_RECORD_LEN: usize = 40;
/// Bytes of one [`PointObservation`] on the wire.
pub const POINT_OBS_RECORD_LEN: usize = 26;

/// Flags of a [`Points`] message.
pub mod points_flags {
    /// More records are pending: the host asks again ([`super::PointsRequest`]).
    pub const MORE: u8 = 1;
    /// The records come from a flush (end of the sequence): the whole window was made final.
    pub const FLUSH: u8 = 2;
    /// The last message answering one request (with [`MORE`]: ask again).
    pub const ANSWER_END: u8 = 4;
}

/// A tie point in its final state: track id, object coordinates and their
/// standard deviations (zero when the adjustment gave none).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PointRecord {
    pub track: u32,
    /// Object frame, metres.
    pub xyz: [f64; 3],
    /// Standard deviations of `xyz`, metres.
    pub std: [f32; 3],
}

/// One image observation of a tie point in its final state (its epoch left the window).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PointObservation {
    pub track: u32,
    /// Input epoch index.
    pub epoch: u32,
    /// 0 = left, 1 = right.
    pub camera: u8,
    /// Bit 0: flagged as a blunder by the adjustment; bit 1: no residual (point excluded).
    pub flags: u8,
    /// Measured pixel, pixel-centre convention ((0, 0) = centre of the top-left pixel).
    pub col: f32,
    pub row: f32,
    /// Image residual observed - computed, pixels (x along columns, y along rows as photo axes).
    pub residual_px: [f32; 2],
}

impl PointObservation {
    pub const FLAGGED: u8 = 1;
    pub const NO_RESIDUAL: u8 = 2;
}

/// Firmware -> host: tie points and observations that became final, in answer
/// to a [`PointsRequest`]. A report spans as many messages as it needs (`index`
/// counts them; [`points_flags::MORE`] says the host should ask again).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Points {
    /// Epoch of the last result when the report was made.
    pub report: u32,
    /// Message index within the report, from 0.
    pub index: u16,
    /// [`points_flags`].
    pub flags: u8,
    pub n_points: u8,
    pub n_obs: u8,
    pub points: [PointRecord; POINTS_MAX],
    pub observations: [PointObservation; POINT_OBS_MAX],
}

impl Points {
    pub fn new(report: u32, index: u16) -> Self {
        Points {
            report,
            index,
            ..Default::default()
        }
    }

    /// Payload bytes of the message as it stands.
    pub fn wire_len(&self) -> usize {
        POINTS_HEADER_LEN
            + self.n_points as usize * POINT_RECORD_LEN
            + self.n_obs as usize * POINT_OBS_RECORD_LEN
    }

    pub fn points(&self) -> &[PointRecord] {
        &self.points[..(self.n_points as usize).min(POINTS_MAX)]
    }

    pub fn observations(&self) -> &[PointObservation] {
        &self.observations[..(self.n_obs as usize).min(POINT_OBS_MAX)]
    }

    /// Adds a point if it fits in `max_payload` bytes; false when full.
    pub fn push_point(&mut self, p: PointRecord, max_payload: usize) -> bool {
        let n = self.n_points as usize;
        if n >= POINTS_MAX || self.wire_len() + POINT_RECORD_LEN > max_payload {
            return false;
        }
        self.points[n] = p;
        self.n_points += 1;
        true
    }

    /// Adds an observation if it fits in `max_payload` bytes; false when full.
    pub fn push_observation(&mut self, o: PointObservation, max_payload: usize) -> bool {
        let n = self.n_obs as usize;
        if n >= POINT_OBS_MAX || self.wire_len() + POINT_OBS_RECORD_LEN > max_payload {
            return false;
        }
        self.observations[n] = o;
        self.n_obs += 1;
        true
    }
}

repr!(
    Points,
    Points,
    |r| {
        let mut m = Points::new(r.u32()?, r.u16()?);
        m.flags = r.u8()?;
        m.n_points = r.u8()?;
        m.n_obs = r.u8()?;
        if m.n_points as usize > POINTS_MAX || m.n_obs as usize > POINT_OBS_MAX {
            return Err(ParseError::Invalid("points: record count above capacity"));
        }
        for p in m.points.iter_mut().take(m.n_points as usize) {
            p.track = r.u32()?;
            p.xyz = r.f64s()?;
            p.std = [r.f32()?, r.f32()?, r.f32()?];
        }
        for o in m.observations.iter_mut().take(m.n_obs as usize) {
            o.track = r.u32()?;
            o.epoch = r.u32()?;
            o.camera = r.u8()?;
            o.flags = r.u8()?;
            o.col = r.f32()?;
            o.row = r.f32()?;
            o.residual_px = [r.f32()?, r.f32()?];
        }
        Ok(m)
    },
    |s, w| {
        w.u32(s.report)?;
        w.u16(s.index)?;
        w.u8(s.flags)?;
        w.u8(s.points().len() as u8)?;
        w.u8(s.observations().len() as u8)?;
        for p in s.points() {
            w.u32(p.track)?;
            w.f64s(&p.xyz)?;
            p.std.iter().try_for_each(|v| w.f32(*v))?;
        }
        for o in s.observations() {
            w.u32(o.track)?;
            w.u32(o.epoch)?;
            w.u8(o.camera)?;
            w.u8(o.flags)?;
            w.f32(o.col)?;
            w.f32(o.row)?;
            w.f32(o.residual_px[0])?;
            w.f32(o.residual_px[1])?;
        }
    }
);

/// Host -> firmware: send the next [`Points`] messages of the pending report
/// (answered by at least one, at most a few). `flush` = 1: the sequence ended,
/// every epoch and tie point still in the window is made final first.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PointsRequest {
    pub flush: u8,
}
repr!(
    PointsRequest,
    PointsRequest,
    |r| { Ok(PointsRequest { flush: r.u8()? }) },
    |s, w| {
        w.u8(s.flush)?;
    }
);

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
