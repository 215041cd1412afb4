//! One module per CLI command: its arguments and what it does.
pub mod adjust;
pub mod budget;
pub mod demo;
pub mod eval;
pub mod features;
pub mod match_pair;
pub mod rig;
pub mod run;
pub mod synth;
