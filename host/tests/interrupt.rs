//! Ctrl-C (SIGINT) and SIGTERM during `run`: the run stops between epochs, writes every
//! output for the epochs done, says it was interrupted and exits with status 130.
#![cfg(unix)]
mod common;
use common::ok;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const FRAMES: usize = 40;

/// Lines of `path` (0 while it does not exist).
fn lines(path: &Path) -> usize {
    std::fs::read_to_string(path).map_or(0, |t| t.lines().count())
}

/// Runs `DATASET` over `link`, sends `signal` once three epochs are on disk, and checks
/// what the interrupted run left.
fn interrupted_run_keeps_its_outputs(link: &str, signal: libc::c_int) {
    let t = tempfile::tempdir().unwrap();
    let (ds, out) = (t.path().join("ds"), t.path().join("out"));
    let s = |p: &Path| p.to_str().unwrap().to_owned();
    let frames = FRAMES.to_string();
    ok(&[
        "synth",
        "--scene",
        "straight",
        "--frames",
        &frames,
        "--size",
        "320x240",
        "--out",
        &s(&ds),
    ]);
    let mut child = Command::new(env!("CARGO_BIN_EXE_phototraverse"))
        .args(["run", &s(&ds), "--out", &s(&out), "--link", link, "--quiet"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let poses = out.join("poses.txt");
    let start = Instant::now();
    while lines(&poses) < 3 {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no epoch came back"
        );
        assert!(child.try_wait().unwrap().is_none(), "the run ended early");
        std::thread::sleep(Duration::from_millis(5));
    }
    // SAFETY: kill(2) on the child's own pid, which has not been waited for yet.
    assert_eq!(unsafe { libc::kill(child.id() as libc::pid_t, signal) }, 0);
    let result = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert_eq!(result.status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("interrupted after"), "{stderr}");

    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["interrupted"], true);
    let done = report["epochs"].as_array().unwrap().len();
    assert!((3..FRAMES).contains(&done), "{done} epochs");
    // Every output holds exactly the epochs done.
    assert_eq!(lines(&poses), done);
    let eop = std::fs::read_to_string(out.join("eop.csv")).unwrap();
    assert_eq!(eop.lines().filter(|l| l.contains(",left,")).count(), done);
    // read_ply checks that the header's vertex count is the number of vertices written.
    let ply = common::read_ply(&out.join("points.ply"));
    assert!(!ply.is_empty(), "no tie point");
    assert!(std::fs::read_to_string(out.join("report.html"))
        .unwrap()
        .contains("Interrupted"));
    assert!(out.join("efoto").join("points.txt").is_file());
}

#[test]
fn ctrl_c_over_a_child_firmware_leaves_every_output() {
    interrupted_run_keeps_its_outputs("child", libc::SIGINT);
}

#[test]
fn sigterm_in_process_leaves_every_output() {
    interrupted_run_keeps_its_outputs("inproc", libc::SIGTERM);
}
