//! Stereo and temporal matching, quad tie points and tracks.
//!
//! One file per concern: [`config`] (configuration, budget), [`distance`] (u8 descriptor
//! distance with early exit), [`grid`] (spatial index), [`search`] (the shared
//! mutual/ratio matcher), [`stereo`] (epipolar bands), [`temporal`] (guided windows),
//! [`predict`] (motion predictions), [`quad`] (loop closure), [`spread`] (Von Gruber
//! regions), [`tracks`], [`refine`] (NCC sub-pixel), and [`matcher`] which runs an epoch.

pub mod config;
pub mod distance;
pub mod grid;
pub mod matcher;
pub mod motion;
pub mod predict;
pub mod quad;
pub mod refine;
pub mod search;
pub mod spread;
pub mod stereo;
#[cfg(any(test, feature = "testkit"))]
pub mod synthetic;
pub mod temporal;
pub mod tracks;

#[cfg(test)]
mod tests;

pub use config::{MatchConfig, MatchError, RefineConfig, StereoGeometry, NONE};
pub use matcher::{
    EpochReport, MatchOutcome, Matcher, StereoFeatures, StereoMatch, StereoStats, TemporalMode,
    TiePoint,
};
pub use predict::{predict_positions, relative_motion, triangulate};
pub use quad::{Quad, QuadStats};
pub use search::{Best, Features, PairStats};
pub use tracks::{Observation, Track, TrackStats};
