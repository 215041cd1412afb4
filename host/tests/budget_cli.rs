//! `phototraverse budget` from the command line: its table, its exit status against
//! `--ram`, and a reader that goes away (`budget | head`) ends it quietly instead of a
//! panic on the closed pipe.
mod common;
use common::ok;
use std::process::{Command, Stdio};

#[test]
fn budget_prints_the_embedded_profile_fitting_in_512k() {
    let out = ok(&[
        "budget",
        "--width",
        "320",
        "--height",
        "240",
        "--config",
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../configs/embedded-320x240.toml"
        ),
        "--ram",
        "512K",
    ]);
    assert!(
        out.contains("excluding frames: fits in 524288 bytes of RAM"),
        "{out}"
    );
}

#[test]
fn a_configuration_that_does_not_fit_the_ram_exits_non_zero() {
    let out = common::phototraverse(&[
        "budget", "--width", "640", "--height", "480", "--ram", "512K",
    ]);
    assert_eq!(out.status.code(), Some(1));
    // The table is still printed, then why it failed.
    assert!(String::from_utf8_lossy(&out.stdout).contains("excluding frames: does NOT fit"));
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(e.contains("does not fit in 524288 bytes of RAM"), "{e}");
}

#[test]
fn a_reader_that_stops_early_ends_it_quietly() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_phototraverse"))
        .args(["budget", "--width", "640", "--height", "480"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("binary runs");
    // The reader goes away before the table is written (`budget | true`).
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(stderr.is_empty(), "{stderr}");
}

#[test]
fn a_runs_carved_memory_stands_beside_its_prediction() {
    use phototraverse_host::report::{MemoryLine, RunReport};
    let line = |name: &str, kind: &str, predicted: usize, carved: Option<usize>| MemoryLine {
        name: name.into(),
        kind: kind.into(),
        predicted_bytes: predicted,
        measured_bytes: carved,
    };
    let report = RunReport {
        memory: vec![
            line("adjust.points", "storage", 1000, None),
            line("adjust (stage)", "stage", 1000, Some(993)),
            line("total (firmware arena)", "all", 1000, Some(993)),
        ],
        ..RunReport::default()
    };
    let t = tempfile::tempdir().unwrap();
    let path = t.path().join("report.json");
    std::fs::write(&path, serde_json::to_string(&report).unwrap()).unwrap();
    let out = ok(&["budget", "--measured", path.to_str().unwrap()]);
    let lines: Vec<Vec<&str>> = out
        .lines()
        .skip_while(|l| !l.starts_with("measured by the run"))
        .map(|l| l.split_whitespace().collect())
        .collect();
    // Only the measured lines: the stage's and the whole's, predicted then carved.
    assert!(
        lines.contains(&vec!["adjust", "(stage)", "1000", "993"]),
        "{out}"
    );
    assert!(
        lines.contains(&vec!["total", "(firmware", "arena)", "1000", "993"]),
        "{out}"
    );
    assert!(!lines.iter().any(|l| l.contains(&"adjust.points")), "{out}");
}
