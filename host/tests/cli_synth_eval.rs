//! End to end through the CLI: synth writes a dataset that Dataset::open reads,
//! eval scores it; the same seed gives the same bytes.
use phototraverse_host::dataset::Dataset;
use phototraverse_host::poses::{read_poses, write_poses};
use std::path::Path;

mod common;
use common::{ok, phototraverse};

fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.file_name().unwrap() != "synth.json" {
                out.push((
                    p.strip_prefix(dir).unwrap().display().to_string(),
                    std::fs::read(&p).unwrap(),
                ));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn synth_then_eval() {
    let t = tempfile::tempdir().unwrap();
    let d = t.path().join("straight");
    let d_str = d.to_str().unwrap();
    let stdout = ok(&[
        "synth", "--scene", "straight", "--frames", "4", "--out", d_str, "--depth",
    ]);
    assert!(stdout.contains("render time per image"), "{stdout}");
    let ds = Dataset::open(&d).unwrap();
    assert_eq!(ds.len(), 4);
    assert!((ds.rig.base_length() - 0.94).abs() < 1e-9);
    assert_eq!(ds.rig.left.focal_mm, 500.0);
    assert_eq!(ds.epochs[3].time, Some(0.3));
    let gt = ds.ground_truth.clone().unwrap();
    // About 1 m forward per epoch along KITTI z.
    assert!((gt[3][2][3] - 3.0).abs() < 0.05, "{:?}", gt[3]);
    let (l, _) = ds.load_pair(0).unwrap();
    assert_eq!((l.width, l.height), (640, 480));
    assert!(d.join("depth_1/000003.pfm").is_file());

    // eval: the ground truth against itself is 0; a 1 % scale error gives ~1 % drift.
    let gt_path = d.join("gt_poses.txt");
    let json = t.path().join("e.json");
    ok(&[
        "eval",
        gt_path.to_str().unwrap(),
        gt_path.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(v["translation_drift_pct"].as_f64().unwrap() < 1e-9);
    assert_eq!(v["ate_rmse_m"].as_f64().unwrap(), 0.0);
    let mut scaled = read_poses(&gt_path).unwrap();
    for p in &mut scaled {
        for row in p.iter_mut() {
            row[3] *= 1.01;
        }
    }
    let est = t.path().join("est.txt");
    write_poses(&est, &scaled).unwrap();
    let out = ok(&[
        "eval",
        gt_path.to_str().unwrap(),
        est.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(out.contains("translation drift"), "{out}");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let t_err = v["translation_drift_pct"].as_f64().unwrap();
    // 3 m path: lengths 0.3..2.4 m, one start frame; each segment ends at the
    // first epoch (1 m apart) beyond L, so its error is 1 % of that distance over L.
    let expect: f64 = [
        (0.3, 1.0),
        (0.6, 1.0),
        (0.9, 1.0),
        (1.2, 2.0),
        (1.5, 2.0),
        (1.8, 2.0),
        (2.1, 3.0),
        (2.4, 3.0),
    ]
    .iter()
    .map(|(l, d)| d / l)
    .sum::<f64>()
        / 8.0;
    assert!((t_err - expect).abs() < 0.01, "{t_err} vs {expect}");
    // Vibration makes the path a little longer than the chord.
    assert!((v["final_position_error_pct"].as_f64().unwrap() - 1.0).abs() < 2e-3);
    // A similarity alignment takes the scale error out, and finds it.
    assert!(v["ate_sim3_rmse_m"].as_f64().unwrap() < 1e-9, "{v}");
    assert!(
        (v["sim3_scale"].as_f64().unwrap() - 1.0 / 1.01).abs() < 1e-9,
        "{v}"
    );

    // Different pose counts are an error.
    write_poses(&est, &scaled[..3]).unwrap();
    let out = phototraverse(&["eval", gt_path.to_str().unwrap(), est.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr)
        .contains("ground truth has 4 poses but the estimate has 3"));
    // Unless the common prefix is asked for; with the plots.
    let plots = t.path().join("plots");
    let out = ok(&[
        "eval",
        gt_path.to_str().unwrap(),
        est.to_str().unwrap(),
        "--common-prefix",
        "--plots",
        plots.to_str().unwrap(),
    ]);
    assert!(out.contains("evaluating the first 3 poses"), "{out}");
    for f in ["trajectory", "error", "drift_translation", "drift_rotation"] {
        let svg = std::fs::read_to_string(plots.join(format!("{f}.svg"))).unwrap();
        assert!(
            svg.starts_with("<svg") && svg.contains("polyline"),
            "{f}.svg"
        );
    }
}

#[test]
fn eval_names_a_missing_file_and_its_cause_once() {
    let t = tempfile::tempdir().unwrap();
    let gt = t.path().join("absent.txt");
    let out = phototraverse(&["eval", gt.to_str().unwrap(), gt.to_str().unwrap()]);
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(e.contains("absent.txt: cannot read or write"), "{e}");
    assert_eq!(
        e.matches("os error 2").count(),
        1,
        "the cause printed once: {e}"
    );
}

#[test]
fn same_seed_same_bytes_with_every_imperfection() {
    let t = tempfile::tempdir().unwrap();
    let run = |name: &str, seed: &str| {
        let d = t.path().join(name);
        ok(&[
            "synth",
            "--scene",
            "seed2014",
            "--frames",
            "2",
            "--seed",
            seed,
            "--realistic",
            "--depth",
            "--out",
            d.to_str().unwrap(),
        ]);
        files(&d)
    };
    let a = run("a", "5");
    let b = run("b", "5");
    assert_eq!(a.len(), b.len());
    assert!(
        a.iter().any(|(n, _)| n.ends_with("E0001.jpg")),
        "{:?}",
        a.iter().map(|f| &f.0).collect::<Vec<_>>()
    );
    for (fa, fb) in a.iter().zip(&b) {
        assert_eq!(fa.0, fb.0);
        assert!(fa.1 == fb.1, "{} differs between runs", fa.0);
    }
    let c = run("c", "6");
    assert!(
        a.iter().zip(&c).any(|(x, y)| x.1 != y.1),
        "another seed changes the output"
    );
    // The written calibration differs from the rig that rendered.
    let ds = Dataset::open(&t.path().join("a")).unwrap();
    let (truth, _) =
        phototraverse_host::dataset::read_rig(&t.path().join("a/truth_rig.toml")).unwrap();
    assert!(((ds.rig.base_length() / truth.base_length() - 1.0).abs() - 0.003).abs() < 1e-9);
    assert_ne!(
        ds.rig.left.principal_point_mm,
        truth.left.principal_point_mm
    );
}

#[test]
fn every_scene_writes_and_kitti_refuses_distortion() {
    let t = tempfile::tempdir().unwrap();
    for scene in ["curves", "seed2006", "hard"] {
        let d = t.path().join(scene);
        ok(&[
            "synth",
            "--scene",
            scene,
            "--frames",
            "1",
            "--out",
            d.to_str().unwrap(),
        ]);
        assert_eq!(Dataset::open(&d).unwrap().len(), 1, "{scene}");
    }
    // The new scenes, small: at 320x240 (`--size`), in their own layouts (handheld:
    // rig.toml with the seed lens resampled; traffic: moving vehicles in synth.json).
    for (scene, layout_file) in [
        ("handheld", "rig.toml"),
        ("drive", "calib.txt"),
        ("traffic", "calib.txt"),
    ] {
        let d = t.path().join(scene);
        ok(&[
            "synth",
            "--scene",
            scene,
            "--frames",
            "2",
            "--size",
            "320x240",
            "--out",
            d.to_str().unwrap(),
        ]);
        let ds = Dataset::open(&d).unwrap();
        assert_eq!(ds.len(), 2, "{scene}");
        assert_eq!((ds.rig.left.width_px, ds.rig.left.height_px), (320, 240));
        assert!(d.join(layout_file).exists(), "{scene}");
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join("synth.json")).unwrap()).unwrap();
        let moving = summary["moving_fraction_max"].as_f64().unwrap();
        assert_eq!(moving > 0.0, scene == "traffic", "{scene}: {moving}");
    }
    let out = phototraverse(&[
        "synth",
        "--scene",
        "seed2014",
        "--frames",
        "1",
        "--layout",
        "kitti",
        "--out",
        t.path().join("x").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--layout rig"));
    let out = phototraverse(&[
        "synth",
        "--scene",
        "nope",
        "--out",
        t.path().join("y").to_str().unwrap(),
    ]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown scene"));
}

#[test]
fn demo_orients_the_synthetic_street_through_the_firmware() {
    let t = tempfile::tempdir().unwrap();
    let out = ok(&["demo", "--frames", "5", "--out", t.path().to_str().unwrap()]);
    assert!(
        out.contains("translation drift") && out.contains("ATE RMSE"),
        "{out}"
    );
    let run = t.path().join("run");
    let poses = std::fs::read_to_string(run.join("poses.txt")).unwrap();
    assert_eq!(poses.lines().count(), 5, "{poses}");
    for f in ["eop.csv", "report.json", "report.html"] {
        assert!(run.join(f).is_file(), "{f} missing");
    }
    // A real orientation, not a placeholder: the last epoch is 4 m ahead (1 m per epoch).
    let last: Vec<f64> = poses
        .lines()
        .last()
        .unwrap()
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    assert!((last[11] - 4.0).abs() < 0.2, "last pose {last:?}");
}

/// `--photo-textures DIR` puts real photographs on the facades: the images change, the
/// geometry (ground truth) does not; a directory without images is refused by name.
#[test]
fn photo_textures_change_the_facades_not_the_truth() {
    let t = tempfile::tempdir().unwrap();
    let photos = t.path().join("photos");
    std::fs::create_dir(&photos).unwrap();
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures");
    std::fs::copy(
        fixture.join("motorcycle_crop_left.png"),
        photos.join("motorcycle.png"),
    )
    .unwrap();
    let run = |name: &str, extra: &[&str]| {
        let d = t.path().join(name);
        let mut args = vec!["synth", "--scene", "straight", "--frames", "2"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--out", d.to_str().unwrap()]);
        ok(&args);
        d
    };
    let plain = run("plain", &[]);
    let photo = run("photo", &["--photo-textures", photos.to_str().unwrap()]);
    let image = |d: &Path| std::fs::read(d.join("image_0/000001.png")).unwrap();
    assert_ne!(image(&plain), image(&photo), "the facades changed");
    // Files may be named directly, comma-separated (the same photograph twice: the
    // same facades as the directory holding it alone, since the choice is by seed).
    let file = photos.join("motorcycle.png");
    let files = format!("{},{}", file.display(), file.display());
    let named = run("named", &["--photo-textures", &files]);
    assert_eq!(image(&named), image(&photo));
    let gt = |d: &Path| std::fs::read_to_string(d.join("gt_poses.txt")).unwrap();
    assert_eq!(gt(&plain), gt(&photo));
    let empty = t.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let out = phototraverse(&[
        "synth",
        "--scene",
        "straight",
        "--frames",
        "1",
        "--photo-textures",
        empty.to_str().unwrap(),
        "--out",
        t.path().join("x").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no image files"));
}
