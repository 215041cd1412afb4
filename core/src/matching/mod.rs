//! Stereo and temporal matching, quad tie points and tracks.
//!
//! One file per concern: `config` (configuration, budget), `distance` (u8 descriptor
//! distance with early exit), `grid` (spatial index), `search` (the shared
//! mutual/ratio matcher), `stereo` (epipolar bands), `temporal` (guided windows),
//! `predict` (motion predictions), `quad` (loop closure), `spread` (Von Gruber
//! regions), `tracks`, `refine` (NCC sub-pixel), `lsm` (least-squares matching), and
//! `matcher` which runs an epoch.

pub(crate) mod config;
pub(crate) mod distance;
pub(crate) mod grid;
pub(crate) mod lsm;
pub(crate) mod matcher;
pub(crate) mod motion;
pub(crate) mod predict;
pub(crate) mod quad;
pub(crate) mod refine;
pub(crate) mod search;
pub(crate) mod spread;
pub(crate) mod stereo;
#[cfg(any(test, feature = "testkit"))]
pub mod synthetic;
pub(crate) mod temporal;
pub(crate) mod tracks;

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
pub use stereo::EpipolarOffset;
pub use tracks::{Observation, StereoPx, Track, TrackStats};
