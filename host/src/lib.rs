//! phototraverse host: datasets, synthetic street sequences, evaluation, the
//! emulated rig link and the CLI's commands.
pub mod block;
pub mod commands;
pub mod dataset;
pub mod eval;
pub mod interrupt;
pub mod link;
pub mod mcu;
pub mod pipeline;
pub mod poses;
pub mod report;
pub mod runner;
pub mod session;
pub mod smoothing;
pub mod synth;
