//! Helpers shared by the tests that drive the `phototraverse` binary.
#![allow(dead_code)]
use std::process::{Command, Output};

/// Runs the binary with `args`.
pub fn phototraverse(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_phototraverse"))
        .args(args)
        .output()
        .expect("binary runs")
}

/// Runs the binary with `args`, which must succeed; its standard output.
pub fn ok(args: &[&str]) -> String {
    let out = phototraverse(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}
