//! A KITTI odometry tree as users have it: `sequences/00` with the colour pair
//! (`image_2/`, `image_3/`), `calib.txt` with P0..P3, `times.txt`, and the ground truth
//! in `poses/00.txt` beside `sequences/`. `run` takes it with no flags: the colour pair
//! (no grey one there), converted to grey, and the poses found and evaluated.
mod common;
use common::ok;
use std::path::Path;

/// Copies the grey images of `from` into `to` as RGB PNGs.
fn as_colour(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let path = entry.unwrap().path();
        let rgb = image::open(&path).unwrap().to_rgb8();
        rgb.save(to.join(path.file_name().unwrap())).unwrap();
    }
}

#[test]
fn a_kitti_tree_with_colour_images_runs_with_no_flags_and_is_evaluated() {
    let t = tempfile::tempdir().unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_owned();
    let grey = t.path().join("grey");
    ok(&[
        "synth",
        "--scene",
        "straight",
        "--frames",
        "12",
        "--size",
        "320x240",
        "--out",
        &s(&grey),
    ]);
    let seq = t.path().join("kitti").join("sequences").join("00");
    as_colour(&grey.join("image_0"), &seq.join("image_2"));
    as_colour(&grey.join("image_1"), &seq.join("image_3"));
    // The colour pair is the grey one here (the same projections under P2 and P3), so
    // the run must give the grey dataset's poses exactly.
    let calib = std::fs::read_to_string(grey.join("calib.txt")).unwrap();
    let colour_rows = calib.replace("P0:", "P2:").replace("P1:", "P3:");
    std::fs::write(seq.join("calib.txt"), format!("{calib}{colour_rows}")).unwrap();
    std::fs::copy(grey.join("times.txt"), seq.join("times.txt")).unwrap();
    let poses = t.path().join("kitti").join("poses");
    std::fs::create_dir_all(&poses).unwrap();
    std::fs::copy(grey.join("gt_poses.txt"), poses.join("00.txt")).unwrap();

    let (out_grey, out_kitti) = (t.path().join("out-grey"), t.path().join("out-kitti"));
    ok(&[
        "run",
        &s(&grey),
        "--out",
        &s(&out_grey),
        "--link",
        "inproc",
        "--quiet",
    ]);
    let printed = ok(&[
        "run",
        &s(&seq),
        "--out",
        &s(&out_kitti),
        "--link",
        "inproc",
        "--quiet",
    ]);
    assert!(
        printed.contains("translation drift"),
        "not evaluated: {printed}"
    );
    let read = |d: &Path| std::fs::read_to_string(d.join("poses.txt")).unwrap();
    assert_eq!(read(&out_kitti), read(&out_grey));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_kitti.join("report.json")).unwrap())
            .unwrap();
    assert!(
        report["evaluation"].is_object(),
        "no evaluation in report.json"
    );

    // The grey pair on request: there is none here, and the error names the directory.
    let out =
        common::phototraverse(&["run", &s(&seq), "--cameras", "0,1", "--out", &s(&out_kitti)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("image_0"), "{err}");
    // Ground truth given by hand replaces the tree's; a wrong count is named.
    let short = t.path().join("short.txt");
    let gt = std::fs::read_to_string(grey.join("gt_poses.txt")).unwrap();
    std::fs::write(&short, gt.lines().take(5).collect::<Vec<_>>().join("\n")).unwrap();
    let out =
        common::phototraverse(&["run", &s(&seq), "--gt", &s(&short), "--out", &s(&out_kitti)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("short.txt"), "{err}");
}
