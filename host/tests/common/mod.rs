//! Helpers shared by the tests that drive the `phototraverse` binary.
#![allow(dead_code)]
use std::path::Path;
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

/// Vertices of points.ply: x y z sx sy sz id observations.
pub fn read_ply(path: &Path) -> Vec<Vec<String>> {
    let t = std::fs::read_to_string(path).unwrap();
    let (header, body) = t.split_once("end_header\n").unwrap();
    let n: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .parse()
        .unwrap();
    let rows: Vec<Vec<String>> = body
        .lines()
        .map(|l| l.split(' ').map(String::from).collect())
        .collect();
    assert_eq!(rows.len(), n, "vertex count of {}", path.display());
    assert!(rows.iter().all(|r| r.len() == 8));
    rows
}
