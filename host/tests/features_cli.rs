//! End to end: `phototraverse features IMAGE --out FILE` writes COLMAP's text format.

use std::path::Path;
use std::process::{Command, Output};

/// `phototraverse features SRC --out OUT EXTRA...`.
fn features(src: &Path, out: &Path, extra: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_phototraverse"))
        .args([
            "features",
            src.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .args(extra)
        .output()
        .unwrap()
}

fn textured_png(path: &Path, w: u32, h: u32) {
    let img = image::GrayImage::from_fn(w, h, |x, y| {
        let (fx, fy) = (x as f32, y as f32);
        let v = 128.0
            + 60.0 * (fx * 0.21).sin() * (fy * 0.17).cos()
            + 40.0 * ((fx + 2.0 * fy) * 0.05).sin()
            + 25.0 * ((fx * fx + fy * fy).sqrt() * 0.3).cos();
        image::Luma([v.clamp(0.0, 255.0) as u8])
    });
    img.save(path).unwrap();
}

#[test]
fn writes_colmap_text_features() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("img.png");
    let out = dir.path().join("img.txt");
    let (w, h) = (160u32, 120u32);
    textured_png(&src, w, h);
    let run = features(&src, &out, &["--max-keypoints", "50"]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        stdout.contains(" ms"),
        "prints the extraction time: {stdout}"
    );
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    let header: Vec<usize> = lines
        .next()
        .unwrap()
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!(header.len(), 2);
    assert_eq!(header[1], 128);
    let n = header[0];
    assert!(n > 5 && n <= 50, "{n} features");
    let mut count = 0;
    for line in lines {
        let f: Vec<f64> = line
            .split_whitespace()
            .map(|v| v.parse().unwrap())
            .collect();
        assert_eq!(f.len(), 4 + 128);
        // Corner convention: pixel centres at c + 0.5, so 0.5 <= x <= w - 0.5.
        assert!(f[0] >= 0.5 && f[0] <= w as f64 - 0.5 && f[1] >= 0.5 && f[1] <= h as f64 - 0.5);
        assert!(f[2] > 0.0);
        assert!((0.0..std::f64::consts::TAU).contains(&f[3]));
        assert!(f[4..]
            .iter()
            .all(|&d| d.fract() == 0.0 && (0.0..=255.0).contains(&d)));
        assert!(f[4..].iter().any(|&d| d > 0.0));
        count += 1;
    }
    assert_eq!(count, n);
    // The same image gives the same file.
    let out2 = dir.path().join("again.txt");
    let run2 = features(&src, &out2, &["--max-keypoints", "50"]);
    assert!(run2.status.success());
    assert_eq!(text, std::fs::read_to_string(&out2).unwrap());
}

#[test]
fn refuses_a_missing_image() {
    let dir = tempfile::tempdir().unwrap();
    let run = features(&dir.path().join("none.png"), &dir.path().join("o.txt"), &[]);
    assert!(!run.status.success());
    assert!(String::from_utf8_lossy(&run.stderr).contains("none.png"));
}

/// The flag set bench/sift runs against its bars (speed, memory, quality against OpenCV): accepted, deterministic; a bad
/// operator name or grid is refused with a message.
#[test]
fn issue3_flag_set_runs_deterministically_and_bad_values_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("img.png");
    textured_png(&src, 160, 120);
    let bar = [
        "--fine-octave",
        "--input-sigma",
        "0",
        "--grid",
        "1x1",
        "--soft-orientation",
        "--descriptor-grid",
        "8",
        "--orientation-stride-sigma",
        "2",
        "--orientation-radius",
        "3",
    ];
    let run = |out: &str, extra: &[&str]| {
        let out = dir.path().join(out);
        (features(&src, &out, extra), out)
    };
    let (a, fa) = run("a.txt", &bar);
    assert!(a.status.success(), "{}", String::from_utf8_lossy(&a.stderr));
    let (b, fb) = run("b.txt", &bar);
    assert!(b.status.success());
    let ta = std::fs::read_to_string(fa).unwrap();
    assert!(ta.lines().count() > 5);
    assert_eq!(ta, std::fs::read_to_string(fb).unwrap());
    for bad in [
        &["--gradient", "sobel"][..],
        &["--fine-gradient", "x"][..],
        &["--descriptor-grid", "10"][..],
    ] {
        let (r, _) = run("bad.txt", bad);
        assert!(!r.status.success(), "{bad:?} accepted");
        assert!(!r.stderr.is_empty());
    }
}
