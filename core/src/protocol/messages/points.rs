//! Tie points and their observations (firmware -> host, pulled by the host).
use super::*;

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
