//! phototraverse core: the on-board processing of a photogrammetric traverse.
//!
//! `#![no_std]` and without `alloc`: every buffer is carved by the caller from a
//! [`budget::Arena`] sized by a [`budget::MemoryBudget`] predicted from the
//! configuration, so the same code runs on a microcontroller and on the host.
//!
//! Data flows one way through the modules, one per pipeline stage:
//! [`image`] -> [`sift`] -> [`matching`] -> [`camera`] -> [`adjust`] -> [`traverse`];
//! [`protocol`] carries frames in and results out. It is a leaf on [`camera`],
//! [`image`] and [`budget`] types with its own codes for modes, statuses and flags: the firmware
//! maps them to the traverse's, so the wire format stays put when the pipeline moves.
//!
//! The crate root re-exports what a program that orients a stereo sequence needs: a
//! [`TraverseConfig`] (its defaults are the product's, [`traverse::defaults`]), the
//! [`MemoryBudget`] it predicts, an [`Arena`] over that many bytes, a [`Traverse`] fed
//! one [`ImageView`] pair per epoch, and an [`EpochOutput`] with each epoch's [`Pose`]s.
//! The stages stay reachable by module for programs that use one alone:
//! [`sift::Sift`], [`matching`]'s matchers, [`adjust::Window`], and
//! [`protocol::Endpoint`] for a link. Each module keeps its internals to the crate.
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

pub use budget::{Arena, MemoryBudget};
pub use camera::{Camera, Interior, Pose, RelativeOrientation, Rig};
pub use image::ImageView;
pub use traverse::{EpochOutput, EpochStatus, Traverse, TraverseConfig};
