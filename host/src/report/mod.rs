//! What a run leaves on disk besides `poses.txt`: the per-epoch records
//! (`report.json`), the exterior orientations with precision (`eop.csv`), the
//! tie points (`points.ply`, E-Foto text files) and a human report with plots
//! (`report.html`).
//!
//! The records are plain data filled by the run; every writer here only reads them.

pub mod colmap;
mod export;
mod fixed;
mod glance;
pub(crate) mod html;
mod points;
mod records;
mod velocity;

pub use export::{efoto_image_index, write_efoto, write_eop_csv, write_ply};
pub use html::write_html;
pub use points::TieCollector;
pub use records::{
    sigmas_in_degrees, CameraEop, CapacityLine, EpochChi2, EpochRecord, EpochStatus, GnssRecord,
    ImageMeasurement, MemoryLine, QualitySummary, RigReport, RunReport, TiePoint, VelocityRecord,
};
pub use velocity::velocities;
