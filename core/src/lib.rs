//! phototraverse core: the on-board processing of a photogrammetric traverse.
//!
//! `#![no_std]` and without `alloc`: every buffer is carved by the caller from a
//! [`budget::Arena`] sized by a [`budget::MemoryBudget`] predicted from the
//! configuration, so the same code runs on a microcontroller and on the host.
//!
//! Data flows one way through the modules, one per pipeline stage:
//! [`image`] -> `sift` -> `matching` -> [`camera`] -> `adjust` -> `traverse`;
//! `protocol` carries frames in and results out. It is a leaf on [`camera`] and
//! [`image`] types with its own codes for modes, statuses and flags: the firmware
//! maps them to the traverse's, so the wire format stays put when the pipeline moves.
#![no_std]
#![forbid(unsafe_op_in_unsafe_fn)]

pub mod adjust;
pub mod budget;
pub mod camera;
pub mod features;
pub mod image;
pub mod matching;
pub mod protocol;
pub mod sift;
#[cfg(any(test, feature = "testkit"))]
pub mod testkit;
pub mod traverse;
