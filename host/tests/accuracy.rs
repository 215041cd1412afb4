//! End-to-end accuracy: a rendered street through the in-process firmware with the
//! default configuration, against its ground truth. The bounds are below what the
//! traverse reached before tie points kept their anchor templates (a track whose
//! template was re-taken at every epoch wandered over the surface, and the window
//! could add nothing over frame-to-frame odometry): on this sequence that floor was
//! `FLOOR_DRIFT_PCT` and `FLOOR_DEG_PER_M`.
mod common;
use common::ok;
use phototraverse_host::dataset::{kitti, Dataset};
use std::path::Path;

/// Epochs of the sequence: long enough for segments of tens of metres.
const FRAMES: &str = "60";
/// Before the fix, on this very sequence (`run --link inproc`, defaults).
const FLOOR_DRIFT_PCT: f64 = 0.1453;
const FLOOR_DEG_PER_M: f64 = 0.0020;
/// The bounds: below the floor by more than the spread between realisations of
/// one configuration; the traverse gives 0.096 % and 0.0011 deg/m here.
const MAX_DRIFT_PCT: f64 = 0.12;
const MAX_DEG_PER_M: f64 = 0.0016;
// The bounds are ones the old floor fails.
const _: () =
    assert!(MAX_DRIFT_PCT < 0.85 * FLOOR_DRIFT_PCT && MAX_DEG_PER_M < 0.85 * FLOOR_DEG_PER_M);

fn number(v: &serde_json::Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} missing in {v}"))
}

/// Renders a sequence (`synth` with `args`) into `ds`.
fn synthesize(ds: &Path, args: &[&str]) {
    let mut synth = vec!["synth", "--out", ds.to_str().unwrap()];
    synth.extend(args);
    ok(&synth);
}

/// Runs `ds` through the in-process firmware (with `args` besides) into `out`; its
/// translation drift (%), rotation drift (deg/m) and the epochs whose calibration
/// the check corrected.
fn run_and_evaluate(ds: &Path, out: &Path, args: &[&str]) -> (f64, f64, usize) {
    let s = |p: &Path| p.to_str().unwrap().to_owned();
    let mut run = vec!["run", ds.to_str().unwrap(), "--out", out.to_str().unwrap()];
    run.extend(["--link", "inproc"]);
    run.extend(args);
    ok(&run);
    let json = out.join("eval.json");
    ok(&[
        "eval",
        &s(&ds.join("gt_poses.txt")),
        &s(&out.join("poses.txt")),
        "--json",
        &s(&json),
    ]);
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let report = std::fs::read_to_string(out.join("report.json")).unwrap();
    (
        number(&v, "translation_drift_pct"),
        number(&v, "rotation_drift_deg_per_m"),
        report.matches("calibration corrected").count(),
    )
}

/// Renders a sequence (`synth` with `args`) and runs it with the defaults:
/// [`run_and_evaluate`].
fn render_and_run(args: &[&str]) -> (f64, f64, usize) {
    let t = tempfile::tempdir().unwrap();
    let ds = t.path().join("ds");
    synthesize(&ds, args);
    run_and_evaluate(&ds, &t.path().join("out"), &[])
}

#[test]
fn straight_street_beats_the_old_floor_through_the_firmware() {
    let (drift, rot, corrected) = render_and_run(&["--scene", "straight", "--frames", FRAMES]);
    assert!(
        drift <= MAX_DRIFT_PCT && rot <= MAX_DEG_PER_M,
        "drift {drift:.4} % (bound {MAX_DRIFT_PCT}), rotation {rot:.5} deg/m (bound {MAX_DEG_PER_M})"
    );
    // A perfect calibration passes the calibration check at every epoch.
    assert_eq!(corrected, 0, "the check corrected a perfect calibration");
}

/// The hand-held walk's drift with its exact calibration held (0.100 %), and with the
/// false correction that counting rejections whatever their step made (0.224 %).
const MAX_HANDHELD_DRIFT_PCT: f64 = 0.15;

#[test]
fn the_hand_held_walks_exact_calibration_is_kept() {
    // Its tie points, matched by least squares, make the exact rig's small systematic
    // errors significant: the score test rejected it at epochs 22 to 29, each time
    // asking for a step of 0.015 to 0.022 px. Counted towards the sustained rule, those
    // corrected the rig 0.014 deg off in phi (`docs/traverse.md`). The walk depends on
    // its length: 100 epochs is the benchmark's, which showed it.
    let (drift, _, corrected) = render_and_run(&["--scene", "handheld", "--frames", "100"]);
    assert_eq!(corrected, 0, "the check corrected an exact calibration");
    assert!(
        drift <= MAX_HANDHELD_DRIFT_PCT,
        "drift {drift:.4} % (bound {MAX_HANDHELD_DRIFT_PCT})"
    );
}

/// The calibration errors of the miscalibrated rig: the right camera's and the
/// left one's focal length 0.3 %, principal points 1 px, the relative rotation
/// 0.05 deg (the base is exact: images alone cannot tell its length).
const CALIBRATION_ERROR: &str = "focal=0.003,pp_px=1,rel_deg=0.05";
/// The default (calibration check) gives 0.64 % on this sequence, the calibration
/// held as given 5.8 %.
const MAX_MISCALIBRATED_DRIFT_PCT: f64 = 1.2;

#[test]
fn a_miscalibrated_rig_is_corrected_by_default() {
    let t = tempfile::tempdir().unwrap();
    let ds = t.path().join("ds");
    let scene = ["--scene", "curves", "--frames", "40"];
    synthesize(
        &ds,
        &[&scene[..], &["--calib-error", CALIBRATION_ERROR]].concat(),
    );
    let ((drift, rot, corrected), (held_drift, held_rot, held_corrected)) =
        default_and_held(&ds, t.path());
    assert!(corrected >= 1 && held_corrected == 0);
    assert!(
        drift <= MAX_MISCALIBRATED_DRIFT_PCT && drift < 0.5 * held_drift && rot < held_rot,
        "default {drift:.3} % {rot:.4} deg/m; calibration held as given {held_drift:.3} % \
         {held_rot:.4} deg/m"
    );
}

/// How far the calibration below puts the right principal point from the images', in
/// pixels along the rows: a disparity offset alone.
const DISPARITY_OFFSET_PX: f64 = 0.3;

#[test]
fn a_calibration_rejected_epoch_after_epoch_is_corrected_for_a_small_step() {
    // The offset's correction moves the newest epoch's observations by less than the
    // 0.1 px a correction must have (but more than the sustained rule's 0.04 px), yet it
    // makes the steps long (1.6 % drift here), and the test rejects the calibration at
    // epochs 9 to 21. Corrected at the eighth rejection in a row, the drift is 1.44 %:
    // the estimation after it, in the window's three epochs, does not find the offset
    // either (`docs/traverse.md`).
    let t = tempfile::tempdir().unwrap();
    let ds = t.path().join("ds");
    synthesize(&ds, &["--scene", "curves", "--frames", "40"]);
    move_right_principal_point(&ds, -DISPARITY_OFFSET_PX);
    let ((drift, _, corrected), (held_drift, _, _)) = default_and_held(&ds, t.path());
    assert!(corrected >= 1, "the calibration was never corrected");
    assert!(
        drift < held_drift,
        "default {drift:.3} %; calibration held as given {held_drift:.3} %"
    );
}

/// Runs `ds` with the default configuration and with the calibration held as given
/// (`check_calibration = false`), outputs under `dir`: [`run_and_evaluate`] of each.
fn default_and_held(ds: &Path, dir: &Path) -> ((f64, f64, usize), (f64, f64, usize)) {
    let default = run_and_evaluate(ds, &dir.join("default"), &[]);
    let held = dir.join("held.toml");
    std::fs::write(&held, "check_calibration = false\n").unwrap();
    let config = held.to_str().unwrap();
    (
        default,
        run_and_evaluate(ds, &dir.join("held"), &["--config", config]),
    )
}

/// Moves the right camera's principal point by `dx_px` along the rows in the KITTI
/// `calib.txt` of the sequence in `ds`: the rig as the dataset reader builds it (size
/// from the images), written back by the dataset's own writer.
fn move_right_principal_point(ds: &Path, dx_px: f64) {
    let mut rig = Dataset::open(ds).unwrap().rig;
    rig.right.principal_point_mm[0] += dx_px * rig.right.pixel_size_mm[0];
    std::fs::write(ds.join("calib.txt"), kitti::calib_text(&rig)).unwrap();
}
