//! Dataset layouts and their errors, on small datasets written to temp dirs.
use image::{GrayImage, ImageBuffer, Luma, Rgb, RgbImage};
use phototraverse_host::dataset::{load_gray, Dataset, DatasetError, Layout};
use std::path::Path;

const CALIB: &str =
    "P0: 500 0 15.5 0 0 500 11.5 0 0 0 1 0\nP1: 500 0 15.5 -470 0 500 11.5 0 0 0 1 0\n";

const RIG: &str = r#"
[left]
width_px = 32
height_px = 24
pixel_size_mm = [0.01, 0.01]
focal_mm = 5.0
principal_point_mm = [0.0, 0.0]
radial = [0.0, 0.0]
decentering = [0.0, 0.0]
[right]
width_px = 32
height_px = 24
pixel_size_mm = [0.01, 0.01]
focal_mm = 5.0
principal_point_mm = [0.0, 0.0]
radial = [0.0, 0.0]
decentering = [0.0, 0.0]
[right_from_left]
omega_deg = 0.0
phi_deg = 0.0
kappa_deg = 0.0
base_mm = [940.0, 0.0, 0.0]
[datum]
omega_deg = 91.0
phi_deg = 0.0
kappa_deg = 0.0
position_m = [1.0, 2.0, 3.0]
"#;

fn gray(w: u32, h: u32, seed: u8) -> GrayImage {
    ImageBuffer::from_fn(w, h, |x, y| Luma([(x * 7 + y * 3) as u8 ^ seed]))
}

fn kitti(dir: &Path, n: usize) {
    std::fs::create_dir_all(dir.join("image_0")).unwrap();
    std::fs::create_dir_all(dir.join("image_1")).unwrap();
    std::fs::write(dir.join("calib.txt"), CALIB).unwrap();
    for k in 0..n {
        gray(32, 24, k as u8)
            .save(dir.join(format!("image_0/{k:06}.png")))
            .unwrap();
        gray(32, 24, 100 + k as u8)
            .save(dir.join(format!("image_1/{k:06}.png")))
            .unwrap();
    }
}

fn rig(dir: &Path, n: usize) {
    std::fs::create_dir_all(dir.join("left")).unwrap();
    std::fs::create_dir_all(dir.join("right")).unwrap();
    std::fs::write(dir.join("rig.toml"), RIG).unwrap();
    for k in 0..n {
        gray(32, 24, k as u8)
            .save(dir.join(format!("left/E{:03}.png", k + 1)))
            .unwrap();
        gray(32, 24, 50 + k as u8)
            .save(dir.join(format!("right/D{:03}.png", k + 1)))
            .unwrap();
    }
}

fn err(dir: &Path) -> String {
    let e: DatasetError = Dataset::open(dir).unwrap_err();
    e.to_string()
}

#[test]
fn opens_kitti_with_times_and_ground_truth() {
    let t = tempfile::tempdir().unwrap();
    kitti(t.path(), 3);
    std::fs::write(t.path().join("times.txt"), "0.0\n0.1\n0.2\n").unwrap();
    let id = "1 0 0 0 0 1 0 0 0 0 1 0\n";
    std::fs::write(t.path().join("gt_poses.txt"), id.repeat(3)).unwrap();
    let d = Dataset::open(t.path()).unwrap();
    assert_eq!(d.layout, Layout::Kitti);
    assert_eq!(d.len(), 3);
    assert_eq!(d.epochs[2].time, Some(0.2));
    assert!(d.epochs[1].right.ends_with("image_1/000001.png"));
    assert!((d.rig.base_length() - 0.94).abs() < 1e-12);
    assert_eq!((d.rig.left.width_px, d.rig.left.height_px), (32, 24));
    assert_eq!(d.ground_truth.as_ref().unwrap().len(), 3);
    let (l, r) = d.load_pair(1).unwrap();
    assert_eq!(l.data, gray(32, 24, 1).into_raw());
    assert_eq!(r.data, gray(32, 24, 101).into_raw());
}

#[test]
fn opens_rig_layout_with_seed_names() {
    let t = tempfile::tempdir().unwrap();
    rig(t.path(), 2);
    let d = Dataset::open(t.path()).unwrap();
    assert_eq!(d.layout, Layout::Rig);
    assert_eq!(
        d.epochs.iter().map(|e| e.name.as_str()).collect::<Vec<_>>(),
        ["001", "002"]
    );
    assert!((d.datum.omega.to_degrees() - 91.0).abs() < 1e-12);
    assert_eq!(d.datum.centre, [1.0, 2.0, 3.0]);
    // Seed-style files side by side in the dataset directory.
    let t2 = tempfile::tempdir().unwrap();
    std::fs::write(t2.path().join("rig.toml"), RIG).unwrap();
    for k in 1..=2 {
        gray(32, 24, k)
            .save(t2.path().join(format!("E{k:03}.png")))
            .unwrap();
        gray(32, 24, k)
            .save(t2.path().join(format!("D{k:03}.png")))
            .unwrap();
    }
    assert_eq!(Dataset::open(t2.path()).unwrap().len(), 2);
}

#[test]
fn missing_right_image() {
    let t = tempfile::tempdir().unwrap();
    kitti(t.path(), 3);
    std::fs::remove_file(t.path().join("image_1/000001.png")).unwrap();
    let e = err(t.path());
    assert!(
        e.contains("image_0/000001.png") && e.contains("missing right image for epoch `000001`"),
        "{e}"
    );
    let t = tempfile::tempdir().unwrap();
    rig(t.path(), 2);
    std::fs::remove_file(t.path().join("left/E002.png")).unwrap();
    let e = err(t.path());
    assert!(
        e.contains("right/D002.png") && e.contains("without a left image"),
        "{e}"
    );
}

#[test]
fn sizes_that_differ() {
    let t = tempfile::tempdir().unwrap();
    kitti(t.path(), 2);
    gray(30, 24, 0)
        .save(t.path().join("image_1/000001.png"))
        .unwrap();
    let e = err(t.path());
    assert!(
        e.contains("image_1/000001.png") && e.contains("size 30x24 differs from 32x24"),
        "{e}"
    );
    let t = tempfile::tempdir().unwrap();
    rig(t.path(), 1);
    gray(32, 20, 0)
        .save(t.path().join("left/E001.png"))
        .unwrap();
    let e = err(t.path());
    assert!(e.contains("left/E001.png") && e.contains("rig.toml"), "{e}");
}

#[test]
fn unreadable_file() {
    let t = tempfile::tempdir().unwrap();
    kitti(t.path(), 2);
    std::fs::write(t.path().join("image_0/000001.png"), b"not a png at all").unwrap();
    // The dataset opens (a corrupt frame costs its epoch, not the run); loading names the file.
    let ds = Dataset::open(t.path()).unwrap();
    let e = ds.load_pair(1).unwrap_err().to_string();
    assert!(
        e.contains("image_0/000001.png") && e.contains("unreadable image"),
        "{e}"
    );
    // The first image gives the size: unreadable there, the dataset cannot open.
    std::fs::write(t.path().join("image_0/000000.png"), b"not a png either").unwrap();
    let e = err(t.path());
    assert!(
        e.contains("image_0/000000.png") && e.contains("unreadable image"),
        "{e}"
    );
    // load_gray names the file too.
    let e = load_gray(&t.path().join("image_0/000001.png"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("000001.png"), "{e}");
    let e = load_gray(&t.path().join("nope.png"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("nope.png") && e.contains("cannot read"), "{e}");
}

#[test]
fn bad_calib_line() {
    let t = tempfile::tempdir().unwrap();
    kitti(t.path(), 1);
    std::fs::write(
        t.path().join("calib.txt"),
        "P0: 500 0 15.5 0 0 500 11.5 0 0 0 1 0\nP1: 500 0 15.5 -470 0 500\n",
    )
    .unwrap();
    let e = err(t.path());
    assert!(
        e.contains("calib.txt") && e.contains("line 2") && e.contains("bad calibration line"),
        "{e}"
    );
    std::fs::write(
        t.path().join("calib.txt"),
        "P0: 0 0 15.5 0 0 500 11.5 0 0 0 1 0\nP1: 500 0 15.5 -470 0 500 11.5 0 0 0 1 0\n",
    )
    .unwrap();
    let e = err(t.path());
    assert!(e.contains("non-positive focal length"), "{e}");
}

#[test]
fn missing_rig_key_and_bad_focal() {
    let t = tempfile::tempdir().unwrap();
    rig(t.path(), 1);
    std::fs::write(
        t.path().join("rig.toml"),
        RIG.replacen("base_mm = [940.0, 0.0, 0.0]\n", "", 1),
    )
    .unwrap();
    let e = err(t.path());
    assert!(e.contains("rig.toml") && e.contains("base_mm"), "{e}");
    std::fs::write(
        t.path().join("rig.toml"),
        RIG.replacen("focal_mm = 5.0", "focal_mm = -5.0", 1),
    )
    .unwrap();
    let e = err(t.path());
    assert!(
        e.contains("left camera") && e.contains("non-positive focal length"),
        "{e}"
    );
}

#[test]
fn wrong_counts_of_times_and_poses() {
    let t = tempfile::tempdir().unwrap();
    kitti(t.path(), 2);
    std::fs::write(t.path().join("times.txt"), "0.0\n").unwrap();
    let e = err(t.path());
    assert!(
        e.contains("times.txt") && e.contains("1 lines for 2 epochs"),
        "{e}"
    );
    std::fs::write(t.path().join("times.txt"), "0.0\nabc\n").unwrap();
    assert!(err(t.path()).contains("`abc` is not a number"));
    std::fs::remove_file(t.path().join("times.txt")).unwrap();
    std::fs::write(t.path().join("gt_poses.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n").unwrap();
    assert!(err(t.path()).contains("gt_poses.txt"));
}

#[test]
fn not_a_dataset() {
    let t = tempfile::tempdir().unwrap();
    assert!(err(t.path()).contains("not a dataset"));
}

#[test]
fn sixteen_bit_and_colour_images_become_8_bit_gray() {
    let t = tempfile::tempdir().unwrap();
    let g16: ImageBuffer<Luma<u16>, Vec<u16>> =
        ImageBuffer::from_fn(4, 2, |x, y| Luma([(x * 16000 + y * 300) as u16]));
    g16.save(t.path().join("a.png")).unwrap();
    let g = load_gray(&t.path().join("a.png")).unwrap();
    assert_eq!((g.width, g.height), (4, 2));
    assert_eq!(
        g.data[..4],
        [
            0,
            (16000u32 >> 8) as u8,
            (32000u32 >> 8) as u8,
            (48000u32 >> 8) as u8
        ]
    );
    assert_eq!(g.data[4], (300u32 >> 8) as u8);
    let rgb: RgbImage = ImageBuffer::from_fn(3, 1, |x, _| {
        if x == 0 {
            Rgb([255, 255, 255])
        } else if x == 1 {
            Rgb([0, 0, 0])
        } else {
            Rgb([0, 255, 0])
        }
    });
    rgb.save(t.path().join("c.png")).unwrap();
    let g = load_gray(&t.path().join("c.png")).unwrap();
    assert_eq!(g.data[0], 255);
    assert_eq!(g.data[1], 0);
    // Green carries most of the luma (Rec. 709: 0.7152).
    assert!((g.data[2] as i32 - 182).abs() <= 2, "{}", g.data[2]);
    assert!(g.view().is_ok());
}
