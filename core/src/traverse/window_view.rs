//! The window's observations in the input's terms, for reports (tie point exports,
//! residual histograms).
use super::*;

/// One image observation of the window in the input's terms (see
/// [`Traverse::window_observation`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WindowObservation {
    /// Track id of the tie point (the observation's tag).
    pub track_id: u32,
    /// Window point index, stable while the point is in the window.
    pub point: u32,
    /// Input epoch index.
    pub epoch: u32,
    /// 0 = left, 1 = right.
    pub camera: u8,
    /// Flagged as a blunder by the last adjustment.
    pub flagged: bool,
}

impl Traverse<'_> {
    /// Number of image observations in the window.
    pub fn window_observation_count(&self) -> usize {
        self.window.observations().len()
    }

    /// Indices of the window observations of `point` ([`WindowObservation::point`]) as
    /// of the last adjustment; `None` when the window changed since (scan instead).
    pub fn window_point_observations(&self, point: u32) -> Option<&[u32]> {
        self.window.point_observations(point)
    }

    /// Observation `i` of the window (storage order), cheap: no projection.
    pub fn window_observation(&self, i: usize) -> Option<WindowObservation> {
        let o = self.window.observations().get(i)?;
        let first = self.window.epoch_id(0)?;
        let slot = o.epoch.checked_sub(first)? as usize;
        let epoch = *self.window_inputs.get(slot)?;
        (slot < self.window.n_epochs()).then_some(WindowObservation {
            track_id: o.tag,
            point: o.point,
            epoch,
            camera: o.camera,
            flagged: o.is_flagged(),
        })
    }

    /// Measured pixel (column, row; pixel-centre convention) of observation `i`
    /// and its residual (observed - computed) in pixels at the last adjustment;
    /// no residual when its point is excluded or behind the camera.
    pub fn window_observation_pixels(&self, i: usize) -> Option<([f64; 2], Option<[f64; 2]>)> {
        let o = self.window.observations().get(i)?;
        let interior = if o.camera == 0 {
            &self.cfg.rig.left
        } else {
            &self.cfg.rig.right
        };
        let px = {
            let [x, y] = o.xy_mm();
            interior.corrected_to_pixel(x, y)
        }
        .ok()?;
        let [sx, sy] = interior.pixel_size_mm;
        let residual = (!self.window.point_excluded(o.point))
            .then(|| self.window.residual(i))
            .flatten()
            .map(|[vx, vy]| [vx / sx, vy / sy]);
        Some((px, residual))
    }

    /// Adjusted object coordinates of window point `point` and their standard deviations.
    pub fn window_point(&self, point: u32) -> Option<([f64; 3], Option<[f64; 3]>)> {
        Some((self.window.point(point)?, self.window.point_std(point)))
    }
}
