//! The on-board program: reads framed messages from a byte link, drives the
//! core traverse and answers with results. `no_std`, no allocation: the link
//! buffers are one static [`link::LinkBuffers`] and everything a configuration
//! needs is carved from the caller's working storage by a budget-sized arena.
//!
//! - [`link`]: the reliable link over `embedded_io::Read + Write`;
//! - [`firmware`]: the protocol loop (hello, configure, frames, epochs);
//! - [`processor`]: the per-epoch work behind [`processor::EpochProcessor`].
#![no_std]

pub mod firmware;
#[cfg(feature = "host")]
pub mod hosted;
pub mod link;
pub mod processor;
pub mod traverse_processor;

pub use firmware::{configuration_budget, frame_bytes, Firmware, Limits, FIRMWARE_VERSION};
pub use link::LinkBuffers;
pub use processor::{
    Clock, EpochInput, EpochOutput, EpochProcessor, ImageStatsFactory, NoClock, ProcessorFactory,
    SiftFactory,
};
pub use traverse_processor::{traverse_config, TraverseFactory, TraverseProcessor};
