//! End-to-end tests of `phototraverse adjust` on the example block
//! (examples/block, a synthetic block with known truth and 10 % blunders).
use phototraverse_core::camera::{Camera, Pose};
use phototraverse_core::testkit::{drive, Rng};
use phototraverse_host::block::{Block, Image, PixelObservation, Settings};
use std::f64::consts::TAU;
use std::path::{Path, PathBuf};
use std::process::Command;

fn example_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../examples/block")
}

/// The block of examples/block: the test kit's drive (4 epochs, 60 points) in
/// pixels of the test rig, every 10th observation moved by 10..50 px, starting
/// from orientations a few cm and tenths of a degree off. Also the true left poses
/// and the observations.txt line numbers of the blunders (one comment line comes
/// first).
fn example() -> (Block, Vec<Pose>, Vec<usize>) {
    let d = drive(2026, 4, 60, 0.0, 0);
    let mut rng = Rng(7);
    let mut blunder_lines = Vec::new();
    let observations = d
        .observations
        .iter()
        .enumerate()
        .map(|(k, o)| {
            let cam = match o.camera {
                Camera::Left => &d.rig.left,
                Camera::Right => &d.rig.right,
            };
            let mut px = cam.corrected_to_pixel(o.xy[0], o.xy[1]).unwrap();
            if (k + 1) % 10 == 0 {
                let (size, angle) = (rng.uniform(10.0, 50.0), rng.uniform(0.0, TAU));
                px[0] += size * angle.cos();
                px[1] += size * angle.sin();
                blunder_lines.push(k + 2);
            }
            PixelObservation {
                line: 0,
                point: 100 + o.point as u64,
                epoch: o.epoch as u32,
                camera: o.camera,
                px,
            }
        })
        .collect();
    let images = d
        .poses
        .iter()
        .enumerate()
        .map(|(k, t)| Image {
            epoch: k as u32,
            time_s: 0.2 * k as f64,
            pose: if k > 0 {
                rng.perturbed(t, 0.005, 0.05)
            } else {
                *t
            },
        })
        .collect();
    let block = Block {
        rig: d.rig,
        settings: Settings::default(),
        images,
        observations,
        control: Vec::new(),
        gnss: Vec::new(),
        odometer: Vec::new(),
    };
    (block, d.poses, blunder_lines)
}

fn run(block: &Path, out: &Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_phototraverse"))
        .arg("adjust")
        .arg(block)
        .arg("--out")
        .arg(out)
        .output()
        .expect("run phototraverse")
}

#[test]
fn example_block_is_what_the_generator_writes() {
    let tmp = tempfile::tempdir().unwrap();
    let (block, _, _) = example();
    block.write(tmp.path()).unwrap();
    if std::env::var_os("PHOTOTRAVERSE_UPDATE_EXAMPLE").is_some() {
        block.write(&example_dir()).unwrap();
    }
    for f in ["block.txt", "images.txt", "observations.txt"] {
        let a = std::fs::read_to_string(tmp.path().join(f)).unwrap();
        let b = std::fs::read_to_string(example_dir().join(f)).unwrap();
        assert_eq!(
            a, b,
            "{f} differs from the generator (PHOTOTRAVERSE_UPDATE_EXAMPLE=1 rewrites it)"
        );
    }
    // Reading back gives the same block (up to the printed precision).
    let back = Block::read(&example_dir()).unwrap();
    assert_eq!(back.observations.len(), block.observations.len());
    assert_eq!(back.images.len(), 4);
}

#[test]
fn adjust_cli_recovers_the_truth_and_flags_the_blunders() {
    let tmp = tempfile::tempdir().unwrap();
    let out = run(&example_dir(), tmp.path());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("report.json")).unwrap())
            .unwrap();
    let sigma0 = report["sigma0"].as_f64().unwrap();
    assert!((sigma0 - 1.0).abs() < 0.15, "sigma0 {sigma0}");
    assert_eq!(report["chi_square"]["passed"], true);
    // The blunders: all flagged, few others.
    let (block, truth, blunders) = example();
    let flagged = std::fs::read_to_string(tmp.path().join("flagged.csv")).unwrap();
    let lines: Vec<usize> = flagged
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    let caught = blunders.iter().filter(|k| lines.contains(k)).count();
    assert!(
        caught as f64 >= 0.95 * blunders.len() as f64,
        "caught {caught}/{}",
        blunders.len()
    );
    assert!(
        lines.len() <= blunders.len() + block.observations.len() / 50,
        "{} flagged",
        lines.len()
    );
    // Left camera orientations within 4 sigma of the truth.
    let csv = std::fs::read_to_string(tmp.path().join("orientations.csv")).unwrap();
    for row in csv
        .lines()
        .skip(1)
        .filter(|r| r.split(',').nth(1) == Some("left"))
    {
        let v: Vec<f64> = row.split(',').filter_map(|x| x.parse().ok()).collect();
        let e = v[0] as usize;
        let t = truth[e].to_params();
        let est = [
            v[1].to_radians(),
            v[2].to_radians(),
            v[3].to_radians(),
            v[4],
            v[5],
            v[6],
        ];
        let sd = [
            v[7].to_radians(),
            v[8].to_radians(),
            v[9].to_radians(),
            v[10],
            v[11],
            v[12],
        ];
        for i in 0..6 {
            assert!(
                (est[i] - t[i]).abs() <= 4.0 * sd[i] + 2e-5,
                "epoch {e} param {i}: {} vs {} (std {})",
                est[i],
                t[i],
                sd[i]
            );
        }
    }
    let points = std::fs::read_to_string(tmp.path().join("points.csv")).unwrap();
    assert_eq!(points.lines().count(), 61);
}

#[test]
fn invalid_block_is_refused_naming_file_and_line() {
    let tmp = tempfile::tempdir().unwrap();
    let blk = tmp.path().join("blk");
    let (block, _, _) = example();
    block.write(&blk).unwrap();
    let obs = std::fs::read_to_string(blk.join("observations.txt")).unwrap();
    let mut lines: Vec<String> = obs.lines().map(str::to_string).collect();
    lines[4] = "101 0 L 12.5 nan-ish".to_string();
    std::fs::write(blk.join("observations.txt"), lines.join("\n")).unwrap();
    let out = run(&blk, &tmp.path().join("out"));
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("observations.txt:5:") && err.contains("nan-ish"),
        "{err}"
    );

    lines[4] = "101 9 L 12.5 3.0".to_string();
    std::fs::write(blk.join("observations.txt"), lines.join("\n")).unwrap();
    let err = String::from_utf8_lossy(&run(&blk, &tmp.path().join("out")).stderr).to_string();
    assert!(
        err.contains("observations.txt:5:") && err.contains("epoch 9"),
        "{err}"
    );

    std::fs::write(
        blk.join("block.txt"),
        "camera left 10 10 1 1 8 0 0 0 0 0 0\nbase_m 0 0 0\n",
    )
    .unwrap();
    let err = String::from_utf8_lossy(&run(&blk, &tmp.path().join("out")).stderr).to_string();
    assert!(err.contains("block.txt") && err.contains("base"), "{err}");
    std::fs::write(blk.join("block.txt"), "frobnicate 3\n").unwrap();
    let err = String::from_utf8_lossy(&run(&blk, &tmp.path().join("out")).stderr).to_string();
    assert!(
        err.contains("block.txt:1:") && err.contains("frobnicate"),
        "{err}"
    );
    std::fs::remove_file(blk.join("images.txt")).unwrap();
    std::fs::write(
        blk.join("block.txt"),
        "camera left 10 10 1 1 8 0 0 0 0 0 0\nbase_m 0.5 0 0\n",
    )
    .unwrap();
    let err = String::from_utf8_lossy(&run(&blk, &tmp.path().join("out")).stderr).to_string();
    assert!(err.contains("images.txt"), "{err}");
}

mod parser_properties {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]
        /// Any text in place of one observation line is either read or refused
        /// with an error naming observations.txt and that line; never a panic.
        #[test]
        fn any_observation_line_is_read_or_refused_with_its_line(line in "[ -~]{0,40}", at in 0usize..20) {
            let tmp = tempfile::tempdir().unwrap();
            let (block, _, _) = example();
            block.write(tmp.path()).unwrap();
            let path = tmp.path().join("observations.txt");
            let text = std::fs::read_to_string(&path).unwrap();
            let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
            lines[at + 1] = line.clone();
            std::fs::write(&path, lines.join("\n")).unwrap();
            if let Err(e) = Block::read(tmp.path()) {
                let msg = format!("{e:#}");
                prop_assert!(msg.contains(&format!("observations.txt:{}:", at + 2)), "{}", msg);
            }
        }

        /// Any keyword line appended to block.txt is read or refused naming block.txt.
        #[test]
        fn any_block_line_is_read_or_refused(line in "[a-z_]{1,14}( [-0-9.e]{1,8}){0,12}") {
            let tmp = tempfile::tempdir().unwrap();
            let (block, _, _) = example();
            block.write(tmp.path()).unwrap();
            let path = tmp.path().join("block.txt");
            let mut text = std::fs::read_to_string(&path).unwrap();
            text.push_str(&line);
            text.push('\n');
            std::fs::write(&path, text).unwrap();
            if let Err(e) = Block::read(tmp.path()) {
                prop_assert!(format!("{e:#}").contains("block.txt:"), "{e:#}");
            }
        }
    }
}
