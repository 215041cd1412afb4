//! End to end through the CLI: `run --mode seed2014 --estimate-rig` on a small
//! synthetic seed-2014 street completes, says its mode, and reports the rig and the
//! chi-square counts in report.json, read for people on stdout.
mod common;
use common::{ok, phototraverse};

#[test]
fn run_seed2014_mode_with_the_rig_estimated() {
    let t = tempfile::tempdir().unwrap();
    let d = t.path().join("seed2014");
    let r = t.path().join("run");
    let (d, r) = (d.to_str().unwrap(), r.to_str().unwrap());
    ok(&["synth", "--scene", "seed2014", "--frames", "4", "--out", d]);
    let stdout = ok(&[
        "run",
        d,
        "--out",
        r,
        "--mode",
        "seed2014",
        "--estimate-rig",
        "--link",
        "inproc",
        "--quiet",
    ]);
    assert!(stdout.contains("mode seed2014: 4 epochs"), "{stdout}");
    assert!(stdout.contains("global test over"), "{stdout}");
    assert!(stdout.contains("rig as adjusted"), "{stdout}");
    let text = std::fs::read_to_string(t.path().join("run/report.json")).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(json["mode"], "seed2014");
    assert_eq!(json["epochs"].as_array().unwrap().len(), 4);
    let q = &json["quality"];
    let adjusted = q["adjusted"].as_u64().unwrap();
    assert!(adjusted >= 1, "{q}");
    let counts = ["chi2_passed", "chi2_failed", "chi2_below"]
        .map(|k| q[k].as_u64().unwrap())
        .iter()
        .sum::<u64>();
    assert_eq!(counts, adjusted, "{q}");
    // A run below the bound says what the images delivered against the a-priori sigma.
    assert_eq!(q["apriori_sigma_px"].as_f64(), Some(0.5), "{q}");
    if q["chi2_below"].as_u64().unwrap() > 0 {
        let delivered = q["sigma0_median"].as_f64().unwrap() * 0.5;
        let said =
            format!("the images delivered about {delivered:.2} px against the a-priori 0.50 px");
        assert!(stdout.contains(&said), "{stdout}");
    }
    // Each epoch's test agrees with the summary's counts.
    let epochs = json["epochs"].as_array().unwrap();
    for (key, result) in [
        ("chi2_passed", "passed"),
        ("chi2_failed", "above"),
        ("chi2_below", "below"),
    ] {
        let n = epochs
            .iter()
            .filter(|e| e["chi2"]["result"] == result)
            .count() as u64;
        assert_eq!(n, q[key].as_u64().unwrap(), "{key}: {q}");
    }
    for e in epochs.iter().filter(|e| !e["chi2"].is_null()) {
        let c = &e["chi2"];
        assert_eq!(e["chi2_passed"], c["result"] == "passed", "{e}");
        let s0 = e["sigma0"].as_f64().unwrap();
        let dof = c["dof"].as_f64().unwrap();
        assert!(
            (c["statistic"].as_f64().unwrap() - s0 * s0 * dof).abs() < 1e-9 * dof,
            "{c}"
        );
    }
    // The estimated base stays near the calibrated 0.4 m rig (seed 000's bar).
    let rig = &json["rig"];
    let b: Vec<f64> = rig["base_m"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let cal: Vec<f64> = rig["calibration_base_m"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let len = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    assert!((len(&b) - len(&cal)).abs() < 0.01, "{rig}");
    assert!(
        rig["std"]
            .as_array()
            .unwrap()
            .iter()
            .all(|v| v.as_f64().unwrap() > 0.0),
        "{rig}"
    );
}

#[test]
fn unknown_mode_is_refused_with_the_choices() {
    let out = phototraverse(&["run", "nowhere", "--mode", "seed1999"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("seed2014") && err.contains("seed2006"),
        "{err}"
    );
}
