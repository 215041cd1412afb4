//! Tie points gathered from the firmware's reports (protocol message `Points`):
//! the last estimate of each track wins, measurements are keyed by track, epoch
//! and camera, so a record the firmware sends twice is kept once.
use super::records::{ImageMeasurement, TiePoint};
use phototraverse_core::protocol::messages::{PointObservation, Points};
use std::collections::BTreeMap;

/// A measurement as reported: pixel, residual (pixels) and flags.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Measured {
    col: f32,
    row: f32,
    residual_px: Option<[f32; 2]>,
    flagged: bool,
}

/// Tie points and their measurements received so far.
#[derive(Debug, Clone, Default)]
pub struct TieCollector {
    /// Track id -> object coordinates and standard deviations.
    points: BTreeMap<u32, ([f64; 3], [f32; 3])>,
    /// (track, epoch, camera) -> measurement.
    measurements: BTreeMap<(u32, u32, u8), Measured>,
    messages: usize,
}

impl TieCollector {
    /// Takes in one Points message.
    pub fn absorb(&mut self, msg: &Points) {
        self.messages += 1;
        for p in msg.points() {
            self.points.insert(p.track, (p.xyz, p.std));
        }
        for o in msg.observations() {
            let residual_px = (o.flags & PointObservation::NO_RESIDUAL == 0
                && o.residual_px.iter().all(|v| v.is_finite()))
            .then_some(o.residual_px);
            if !(o.col.is_finite() && o.row.is_finite()) {
                continue;
            }
            self.measurements.insert(
                (o.track, o.epoch, o.camera),
                Measured {
                    col: o.col,
                    row: o.row,
                    residual_px,
                    flagged: o.flags & PointObservation::FLAGGED != 0,
                },
            );
        }
    }

    /// Points messages taken in.
    pub fn messages(&self) -> usize {
        self.messages
    }

    /// Image measurements received.
    pub fn measurement_count(&self) -> usize {
        self.measurements.len()
    }

    /// Every point with a final estimate and its measurements (blunders left
    /// out), ordered by track id; sigma `None` when the adjustment gave none. A point
    /// left with fewer than two measurements once its blunders are out is no tie
    /// point (one ray does not position it) and is left out.
    pub fn tie_points(&self) -> Vec<TiePoint> {
        let mut out: BTreeMap<u32, TiePoint> = self
            .points
            .iter()
            .map(|(&id, &(xyz, std))| {
                let sigma = (std != [0.0; 3]).then(|| std.map(|s| s as f64));
                let measurements = Vec::new();
                let p = TiePoint {
                    id,
                    xyz,
                    sigma,
                    measurements,
                };
                (id, p)
            })
            .collect();
        for (&(track, epoch, camera), m) in &self.measurements {
            if m.flagged {
                continue;
            }
            if let Some(p) = out.get_mut(&track) {
                p.measurements.push(ImageMeasurement {
                    epoch: epoch as usize,
                    camera,
                    col: m.col as f64,
                    row: m.row as f64,
                });
            }
        }
        out.into_values()
            .filter(|p| p.measurements.len() >= 2)
            .collect()
    }

    /// Residual lengths, pixels, of every measurement with a final residual
    /// (flagged ones included: the histogram shows the blunders too).
    pub fn residuals_px(&self) -> Vec<f32> {
        self.measurements
            .values()
            .filter_map(|m| m.residual_px)
            .map(|[x, y]| (x * x + y * y).sqrt())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use phototraverse_core::protocol::messages::PointRecord;

    fn obs(track: u32, epoch: u32, camera: u8, flags: u8) -> PointObservation {
        PointObservation {
            track,
            epoch,
            camera,
            flags,
            col: 10.0 + epoch as f32,
            row: 5.0,
            residual_px: [0.3, 0.4],
        }
    }

    #[test]
    fn last_estimate_wins_and_duplicates_count_once() {
        let mut c = TieCollector::default();
        let mut m = Points::new(3, 0);
        for o in [
            obs(1, 2, 0, 0),
            obs(1, 2, 1, 0),
            obs(1, 3, 0, PointObservation::FLAGGED),
            obs(2, 3, 0, PointObservation::NO_RESIDUAL),
        ] {
            assert!(m.push_observation(o, 4096));
        }
        let rec = |x: f64| PointRecord {
            track: 1,
            xyz: [x, 2.0, 3.0],
            std: [0.1, 0.2, 0.3],
        };
        assert!(m.push_point(rec(1.0), 4096));
        c.absorb(&m);
        let mut again = Points::new(4, 0);
        assert!(again.push_observation(obs(1, 2, 0, 0), 4096));
        assert!(again.push_point(rec(1.5), 4096));
        c.absorb(&again);
        assert_eq!(c.measurement_count(), 4);
        let pts = c.tie_points();
        // Track 2 has no final point: not written; track 1 keeps its last estimate
        // and its two unflagged measurements.
        assert_eq!(pts.len(), 1);
        assert_eq!(pts[0].xyz, [1.5, 2.0, 3.0]);
        assert_eq!(pts[0].measurements.len(), 2);
        assert!((pts[0].sigma.unwrap()[2] - 0.3).abs() < 1e-6);
        // Residuals: three with a value (0.5 px each), the flagged one included.
        let r = c.residuals_px();
        assert_eq!(r.len(), 3);
        assert!(r.iter().all(|v| (v - 0.5).abs() < 1e-6));
    }

    #[test]
    fn a_point_left_with_one_unflagged_measurement_is_not_a_tie_point() {
        let mut c = TieCollector::default();
        let mut m = Points::new(1, 0);
        assert!(m.push_observation(obs(7, 2, 0, 0), 4096));
        assert!(m.push_observation(obs(7, 2, 1, PointObservation::FLAGGED), 4096));
        let p = PointRecord {
            track: 7,
            xyz: [1.0, 2.0, 3.0],
            std: [0.1; 3],
        };
        assert!(m.push_point(p, 4096));
        c.absorb(&m);
        assert!(c.tie_points().is_empty());
        assert_eq!(c.measurement_count(), 2);
    }
}
