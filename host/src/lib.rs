//! phototraverse host: datasets, synthetic street sequences, evaluation, the
//! emulated rig link and the CLI's commands.
pub mod commands;
pub mod link;
pub mod report;
pub mod session;
