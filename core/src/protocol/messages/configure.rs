//! The configuration the host sends (rig, pipeline settings, traverse settings), its
//! limits, and the firmware's acceptance.
use super::*;
use crate::budget::Stage;
use crate::camera::{CalibrationPrecision, DistortionModel, Interior, Rig};

/// Payload version of [`Configure`] this build writes. Later versions append
/// fields; a parser reads the fields it knows and ignores the rest.
pub const CONFIG_VERSION: u16 = 5;

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

/// The pipeline's defaults ([`crate::traverse::defaults`]) at 640x480, 8-bit.
impl Default for Pipeline {
    fn default() -> Self {
        use crate::traverse::defaults::*;
        let (max_width, max_height) = (640, 480);
        Pipeline {
            max_width,
            max_height,
            pixel_bytes: 1,
            octaves: TRAVERSE_OCTAVES as u8,
            scales_per_octave: TRAVERSE_SCALES as u8,
            keypoints_per_image: TRAVERSE_KEYPOINTS as u32,
            window_len: TRAVERSE_WINDOW as u16,
            track_capacity: TRAVERSE_TRACKS as u32,
            contrast_threshold: TRAVERSE_CONTRAST,
            edge_ratio: TRAVERSE_EDGE_RATIO,
            match_ratio: TRAVERSE_MATCH_RATIO,
            max_disparity_px: max_width as f32 * TRAVERSE_DISPARITY_FRACTION,
            fine_octave: false,
            // The firmware's default, TRAVERSE_FIXED_EPOCHS (and what a v2 payload means).
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
            sigma_px: crate::traverse::defaults::TRAVERSE_SIGMA_PX,
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
        radial: {
            let [k1, k2] = r.f64s()?;
            [k1, k2, 0.0]
        },
        decentering: r.f64s()?,
        distortion_model: DistortionModel::Correction,
    })
}

/// Wire code of a [`DistortionModel`] (Configure v5).
const fn distortion_model_code(m: DistortionModel) -> u8 {
    match m {
        DistortionModel::Correction => 0,
        DistortionModel::Projection => 1,
    }
}

fn parse_distortion_model(code: u8) -> Result<DistortionModel, ParseError> {
    [DistortionModel::Correction, DistortionModel::Projection]
        .into_iter()
        .find(|m| distortion_model_code(*m) == code)
        .ok_or(ParseError::Invalid("distortion model"))
}

/// The v5 tail of one camera: its distortion model and third radial term.
fn parse_lens(r: &mut Reader, i: &mut Interior) -> Result<(), ParseError> {
    i.distortion_model = parse_distortion_model(r.u8()?)?;
    i.radial[2] = r.f64()?;
    Ok(())
}

fn emit_lens(w: &mut Writer, i: &Interior) -> Result<(), EncodeError> {
    w.u8(distortion_model_code(i.distortion_model))?;
    w.f64(i.radial[2])
}

fn emit_interior(w: &mut Writer, i: &Interior) -> Result<(), EncodeError> {
    w.u32(i.width_px)?;
    w.u32(i.height_px)?;
    w.f64s(&i.pixel_size_mm)?;
    w.f64(i.focal_mm)?;
    w.f64s(&i.principal_point_mm)?;
    w.f64s(&[i.radial[0], i.radial[1]])?;
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
        let mut rig = Rig {
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
        if version >= 5 {
            parse_lens(&mut r, &mut rig.left)?;
            parse_lens(&mut r, &mut rig.right)?;
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
        // Earlier versions carry no lens model: their cameras are read as
        // correction-model lenses with k3 = 0.
        if s.version >= 5 {
            emit_lens(&mut w, &s.rig.left)?;
            emit_lens(&mut w, &s.rig.right)?;
        }
    }
);

/// Firmware -> host: the configuration fits; its predicted memory, and what building
/// the processor carved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConfigAccepted {
    /// Predicted bytes of the whole configuration (frames included).
    pub predicted_bytes: u32,
    /// Bytes of the two frame buffers.
    pub frame_bytes: u32,
    /// Working storage available.
    pub capacity_bytes: u32,
    /// Bytes the arena carved per stage while the firmware built its buffers, in the
    /// order of [`Stage::ALL`](crate::budget::Stage::ALL) (padding included): the
    /// measurement beside each stage's predicted components.
    pub carved_bytes: [u32; CARVED_STAGES],
}

/// Stages in [`ConfigAccepted::carved_bytes`]: fixed on the wire. A new
/// [`Stage`] needs a new protocol version, which this check asks for.
pub const CARVED_STAGES: usize = 6;
const _: () = assert!(Stage::ALL.len() == CARVED_STAGES);
repr!(
    ConfigAccepted,
    ConfigAccepted,
    |r| {
        Ok(ConfigAccepted {
            predicted_bytes: r.u32()?,
            frame_bytes: r.u32()?,
            capacity_bytes: r.u32()?,
            carved_bytes: r.u32s()?,
        })
    },
    |s, w| {
        w.u32(s.predicted_bytes)?;
        w.u32(s.frame_bytes)?;
        w.u32(s.capacity_bytes)?;
        w.u32s(&s.carved_bytes)?;
    }
);
