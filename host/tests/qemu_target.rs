//! The firmware on the emulated Cortex-M7 (QEMU's mps2-an500): a short synthetic
//! sequence through `run --link qemu` gives the poses of the hosted firmware to the
//! bit, with the target's sections, stack and instruction counts in report.json; a
//! configuration too large for a part's memory map fails to link.
//!
//! QEMU and the Rust target thumbv7em-none-eabihf are installed by
//! `scripts/install-qemu.sh` (CI runs it and sets PHOTOTRAVERSE_REQUIRE_QEMU=1, which
//! turns their absence into a failure). Without them, and without that variable, these
//! tests say so and pass: the README's test command runs on a machine with a Rust
//! toolchain alone.
mod common;

use common::phototraverse;
use std::path::Path;
use std::process::Command;

/// Whether the tests can run here; panics when CI requires them and they cannot.
fn target_tools() -> bool {
    let qemu = Command::new("qemu-system-arm")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    let sysroot = Command::new("rustc")
        .args(["--print", "sysroot"])
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_default();
    let target = Path::new(&sysroot)
        .join("lib/rustlib/thumbv7em-none-eabihf")
        .is_dir();
    if qemu && target {
        return true;
    }
    let missing = format!(
        "{}{}",
        if qemu { "" } else { "qemu-system-arm " },
        if target {
            ""
        } else {
            "the Rust target thumbv7em-none-eabihf"
        }
    );
    assert!(
        std::env::var_os("PHOTOTRAVERSE_REQUIRE_QEMU").is_none(),
        "PHOTOTRAVERSE_REQUIRE_QEMU is set but {missing} is missing (scripts/install-qemu.sh)"
    );
    eprintln!("skipped: {missing} missing (scripts/install-qemu.sh installs them)");
    false
}

fn profile() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../configs/embedded-320x240.toml")
        .display()
        .to_string()
}

/// The element of the JSON array `list` whose `key` is `name`.
fn named<'a>(list: &'a serde_json::Value, key: &str, name: &str) -> &'a serde_json::Value {
    list.as_array()
        .unwrap()
        .iter()
        .find(|v| v[key] == name)
        .unwrap_or_else(|| panic!("no {key} {name} in {list}"))
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn the_cortex_m7_image_orients_a_sequence_as_the_hosted_firmware_does() {
    if !target_tools() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("seq");
    let data_s = data.to_str().unwrap();
    let synth = phototraverse(&[
        "synth", "--scene", "curves", "--frames", "4", "--size", "320x240", "--out", data_s,
    ]);
    assert!(synth.status.success(), "{synth:?}");
    let config = profile();
    let mut outs = Vec::new();
    for link in ["child", "qemu"] {
        let out = tmp.path().join(link);
        let o = phototraverse(&[
            "run",
            data_s,
            "--config",
            &config,
            "--link",
            link,
            "--quiet",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(
            o.status.success(),
            "--link {link}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        outs.push((out, String::from_utf8_lossy(&o.stdout).to_string()));
    }
    let poses = |d: &Path| std::fs::read_to_string(d.join("poses.txt")).unwrap();
    let (child, qemu) = (&outs[0].0, &outs[1].0);
    assert_eq!(poses(child).lines().count(), 4);
    // The same arithmetic (IEEE f64, no fused multiply-adds, the same libm) on both.
    assert_eq!(
        poses(child),
        poses(qemu),
        "poses differ between x86-64 and the M7"
    );
    assert!(
        outs[1].1.contains("M instructions per epoch"),
        "{}",
        outs[1].1
    );
    assert!(
        outs[1].1.contains("estimate, not a measurement"),
        "{}",
        outs[1].1
    );

    let r = json(&qemu.join("report.json"));
    let t = &r["target"];
    assert_eq!(t["part"], "mps2-an500");
    let section = |name: &str| {
        named(&t["sections"], "name", name)["bytes"]
            .as_u64()
            .unwrap()
    };
    assert!(section(".text") > 100_000, "{t}");
    // The statics were sized from the configuration's prediction.
    assert_eq!(
        section(".arena"),
        t["predicted"]["arena_bytes"].as_u64().unwrap()
    );
    assert_eq!(section(".frames"), 2 * 320 * 240);
    let stack = &t["stack"];
    let (used, reserved) = (
        stack["used_bytes"].as_u64().unwrap(),
        stack["reserved_bytes"].as_u64().unwrap(),
    );
    assert!(used > 1024 && used < reserved, "stack {used} of {reserved}");
    let time = &t["time"];
    assert_eq!(time["epochs"], 4);
    let per_epoch = time["instructions_per_epoch_median"].as_f64().unwrap();
    assert!(per_epoch > 1e6, "{time}");
    let sift = named(&time["stages"], "stage", "sift_left");
    assert!(sift["instructions_median"].as_f64().unwrap() > 0.0);
    // Capacities: counted on the target, within what they reserve.
    for c in r["capacities"].as_array().unwrap() {
        assert!(c["peak"].as_u64() <= c["reserved"].as_u64(), "{c}");
    }
    let kp = named(&r["capacities"], "name", "keypoints_per_image");
    assert!(kp["peak"].as_u64().unwrap() > 0);
    // The hosted run has the capacities too, and no target.
    let hosted = json(&child.join("report.json"));
    assert_eq!(hosted["capacities"], r["capacities"]);
    assert!(hosted.get("target").is_none());
}

#[test]
fn a_configuration_too_large_for_the_part_fails_to_link() {
    if !target_tools() {
        return;
    }
    // The defaults at 640x480 need about 2.4 MiB besides the frames: more than the
    // STM32H743's 512 KiB AXI SRAM.
    let o = phototraverse(&["budget", "--part", "stm32h743"]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("does not fit the stm32h743 memory map")
            && err.contains("'.arena' will not fit in region 'AXISRAM': overflowed by"),
        "{err}"
    );
    // The embedded profile at 320x240 fits, and the image shows its sections.
    let config = profile();
    let o = phototraverse(&[
        "budget",
        "--part",
        "stm32h743",
        "--width",
        "320",
        "--height",
        "240",
        "--config",
        &config,
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.contains("linked: the configuration fits"), "{out}");
    let arena_line = out
        .lines()
        .find(|l| l.trim_start().starts_with(".arena"))
        .unwrap();
    let cols: Vec<&str> = arena_line.split_whitespace().collect();
    assert_eq!(
        cols[1], cols[2],
        "the arena as predicted and as linked: {arena_line}"
    );
}
