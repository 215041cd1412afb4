//! Property tests of the text parsers: never a panic on any input, exact round trips.
use phototraverse_host::dataset::kitti::{calib_text, pair_rows, parse_calib, rig_from_calib};
use phototraverse_host::dataset::rigfile::{parse_rig, rig_toml_text};
use phototraverse_host::poses::{format_pose, parse_poses, KittiPose};
use phototraverse_host::synth::realism::CalibError;
use proptest::prelude::*;
use std::path::Path;

fn finite() -> impl Strategy<Value = f64> {
    prop_oneof![
        -1e6f64..1e6,
        -1.0f64..1.0,
        Just(0.0),
        Just(-0.0),
        Just(1e-300)
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn pose_parser_never_panics(text in "\\PC{0,400}") {
        let _ = parse_poses(&text, Path::new("x"));
    }

    #[test]
    fn pose_lines_round_trip(values in proptest::collection::vec(finite(), 12)) {
        let mut p: KittiPose = [[0.0; 4]; 3];
        for (k, v) in values.iter().enumerate() {
            p[k / 4][k % 4] = *v;
        }
        let back = parse_poses(&format_pose(&p), Path::new("x")).unwrap();
        prop_assert_eq!(back, vec![p]);
    }

    #[test]
    fn calib_parser_never_panics(text in "(P[0-3]: ?)?[-0-9. e+a-z]{0,200}(\n[-0-9. e+P:]{0,120}){0,3}") {
        if let Ok(rows) = parse_calib(&text, Path::new("calib.txt")) {
            for pair in [(0, 1), (2, 3)] {
                if let Ok((l, r)) = pair_rows(&rows, pair, Path::new("calib.txt")) {
                    let _ = rig_from_calib(&l, &r, 64, 48, Path::new("calib.txt"));
                }
            }
        }
    }

    #[test]
    fn calib_round_trips(f in 100.0f64..2000.0, aspect in 0.8f64..1.25, cx in 0.0f64..640.0, cy in 0.0f64..480.0, b in 0.05f64..2.0) {
        let text = format!("P0: {f} 0 {cx} 0 0 {} {cy} 0 0 0 1 0\nP1: {f} 0 {cx} {} 0 {} {cy} 0 0 0 1 0\n", f * aspect, -f * b, f * aspect);
        let grey = |t: &str| pair_rows(&parse_calib(t, Path::new("c")).unwrap(), (0, 1), Path::new("c")).unwrap();
        let (p0, p1) = grey(&text);
        let rig = rig_from_calib(&p0, &p1, 640, 480, Path::new("c")).unwrap();
        let (q0, q1) = grey(&calib_text(&rig));
        let back = rig_from_calib(&q0, &q1, 640, 480, Path::new("c")).unwrap();
        prop_assert!((back.base_length() - b).abs() < 1e-9 * b.max(1.0));
        for i in 0..2 {
            prop_assert!((back.left.principal_point_mm[i] - rig.left.principal_point_mm[i]).abs() < 1e-9);
            prop_assert!((back.left.pixel_size_mm[i] - rig.left.pixel_size_mm[i]).abs() < 1e-12);
        }
    }

    #[test]
    fn rig_parser_never_panics(text in "(\\[[a-z_]{0,16}\\]\n)?([a-z_]{1,20} = [-0-9.e\\[\\], \"]{0,30}\n){0,12}") {
        let _ = parse_rig(&text, Path::new("rig.toml"));
    }

    #[test]
    fn calib_error_parser_never_panics(text in "[a-z_=0-9.,-]{0,60}") {
        let _ = CalibError::parse(&text);
    }
}

#[test]
fn rig_text_survives_arbitrary_values() {
    // Writing then reading keeps every camera value exactly.
    use phototraverse_core::camera::{DistortionModel, Interior, Pose, Rig};
    let mut runner = proptest::test_runner::TestRunner::default();
    runner
        .run(
            &(1.0f64..100.0, -1.0f64..1.0, -1e-4f64..1e-4, 0.1f64..2.0),
            |(f, pp, k, b)| {
                let cam = Interior {
                    width_px: 640,
                    height_px: 480,
                    pixel_size_mm: [0.01, 0.012],
                    focal_mm: f,
                    principal_point_mm: [pp, -pp],
                    radial: [k, k * 1e-3, 0.0],
                    decentering: [k, -k],
                    distortion_model: DistortionModel::Correction,
                };
                let rig = Rig {
                    left: cam,
                    right: cam,
                    relative_angles: [0.001, -0.002, 0.003],
                    base_m: [b, 0.01, 0.0],
                };
                let (back, _) =
                    parse_rig(&rig_toml_text(&rig, &Pose::default()), Path::new("r")).unwrap();
                prop_assert_eq!(back.left, rig.left);
                prop_assert!((back.base_m[0] - b).abs() < 1e-12);
                Ok(())
            },
        )
        .unwrap();
}
