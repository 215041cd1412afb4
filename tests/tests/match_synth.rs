//! The synthetic-sequence bar of the matcher: a rendered street (`synth --depth`) goes
//! through our extractor and the per-epoch matcher (stereo, guided temporal with a
//! constant-velocity prediction, quads, spreading, tracks); every tie point is checked
//! against the renderer's depth: the previous left observation is back-projected with
//! its depth and projected into the other three images with the true poses and rig.
//! Prints the share off by more than 2 px, tie points per epoch and mean track length.
//!
//! `MATCH_SYNTH_FRAMES=N` (default 5) and `MATCH_SYNTH_SCENE` (default `straight`)
//! make a longer measurement.
use phototraverse_core::budget::Arena;
use phototraverse_core::camera::{pose_from_kitti, project_to_pixel, Pose, Rig};
use phototraverse_core::features::{Descriptor, Keypoint};
use phototraverse_core::matching::{
    relative_motion, Features, MatchConfig, MatchOutcome, Matcher, RefineConfig, StereoFeatures,
    StereoGeometry,
};
use phototraverse_core::sift::SiftConfig;
use phototraverse_host::commands::features::extract_with;
use phototraverse_host::dataset::{read_rig, Dataset};
use phototraverse_host::synth::writer::read_pfm;
use phototraverse_host::synth::{generate, SynthOptions};

struct Frame {
    kps: [Vec<Keypoint>; 2],
    desc: [Vec<Descriptor>; 2],
    images: [phototraverse_host::dataset::GrayImage; 2],
    depth: (usize, usize, Vec<f32>),
}

impl Frame {
    fn features(&self) -> StereoFeatures<'_> {
        StereoFeatures {
            left: Features::new(&self.kps[0], &self.desc[0]),
            right: Features::new(&self.kps[1], &self.desc[1]),
        }
    }
}

fn extract(img: &phototraverse_host::dataset::GrayImage) -> (Vec<Keypoint>, Vec<Descriptor>) {
    let (w, h) = (img.width as usize, img.height as usize);
    let cfg = SiftConfig {
        max_width: w,
        max_height: h,
        max_keypoints: 1000,
        // The rendered facades are smooth: a lower contrast threshold than Lowe's
        // keeps enough keypoints for the quads to be counted meaningfully.
        contrast_threshold: 0.02,
        ..SiftConfig::default()
    };
    let mut out = (Vec::new(), Vec::new());
    extract_with(cfg, &img.data, w, h, 1, |set| {
        out = (set.keypoints().to_vec(), set.descriptors().to_vec());
        Ok(())
    })
    .unwrap();
    out
}

/// Depth at (x, y) when the 3x3 neighbourhood is one surface (within 3 %), else None.
fn depth_at(depth: &(usize, usize, Vec<f32>), x: f32, y: f32) -> Option<f64> {
    let (w, h, d) = depth;
    let (c, r) = (x.round() as isize, y.round() as isize);
    let (mut lo, mut hi) = (f32::MAX, f32::MIN);
    for dr in -1..=1 {
        for dc in -1..=1 {
            let (cc, rr) = (c + dc, r + dr);
            if cc < 0 || rr < 0 || cc >= *w as isize || rr >= *h as isize {
                return None;
            }
            let v = d[rr as usize * w + cc as usize];
            if !v.is_finite() {
                return None;
            }
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    (hi <= lo * 1.03).then(|| d[r as usize * w + c as usize] as f64)
}

fn back_project(rig: &Rig, pose: &Pose, px: [f32; 2], z: f64) -> [f64; 3] {
    let [xc, yc] = rig.left.pixel_to_corrected(px[0] as f64, px[1] as f64);
    let f = rig.left.focal_mm;
    let d = pose.rotation().transpose() * nalgebra::Vector3::new(xc, yc, -f) * (z / f);
    [
        pose.centre[0] + d[0],
        pose.centre[1] + d[1],
        pose.centre[2] + d[2],
    ]
}

#[test]
fn synthetic_quads_are_right() {
    let frames: usize = std::env::var("MATCH_SYNTH_FRAMES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(5);
    let scene = std::env::var("MATCH_SYNTH_SCENE").unwrap_or_else(|_| "straight".into());
    let dir = tempfile::tempdir().unwrap();
    let mut opts = SynthOptions::new(&scene, dir.path().to_path_buf());
    opts.frames = Some(frames);
    opts.depth = true;
    generate(&opts).unwrap();
    let ds = Dataset::open(dir.path()).unwrap();
    let (truth, datum) = read_rig(&dir.path().join("truth_rig.toml")).unwrap();
    let gt: Vec<Pose> = ds
        .ground_truth
        .as_ref()
        .unwrap()
        .iter()
        .map(|m| pose_from_kitti(&datum, m))
        .collect();
    let load = |k: usize| {
        let (l, r) = ds.load_pair(k).unwrap();
        let (kl, dl) = extract(&l);
        let (kr, dr) = extract(&r);
        let depth = read_pfm(
            &dir.path()
                .join(format!("depth_0/{}.pfm", ds.epochs[k].name)),
        )
        .unwrap();
        Frame {
            kps: [kl, kr],
            desc: [dl, dr],
            images: [l, r],
            depth,
        }
    };
    let data: Vec<Frame> = (0..ds.epochs.len()).map(load).collect();
    let (w, h) = (ds.rig.left.width_px, ds.rig.left.height_px);
    let geometry = if ds.rig.relative_angles == [0.0; 3] && ds.rig.left.radial == [0.0; 3] {
        StereoGeometry::Rectified {
            row_tolerance_px: 1.5,
            min_disparity_px: 0.0,
            max_disparity_px: 160.0,
        }
    } else {
        StereoGeometry::Rig {
            rig: ds.rig,
            tolerance_px: 2.0,
            min_depth_m: 1.0,
            max_depth_m: f64::INFINITY,
        }
    };
    let cfg = MatchConfig {
        stereo: geometry,
        refine: Some(RefineConfig {
            rows_only: matches!(geometry, StereoGeometry::Rectified { .. }),
            min_ncc: 0.9,
            half_window: 3,
            ..RefineConfig::default()
        }),
        ..MatchConfig::rectified(w, h, 1000, 160.0)
    };
    let mut store = vec![0u8; cfg.predicted_bytes()];
    let mut arena = Arena::new(&mut store);
    let mut m = Matcher::new(cfg, &mut arena).unwrap();
    let (mut total, mut off, mut unknown) = (0usize, 0usize, 0usize);
    // Per image (prev left, prev right, cur left, cur right): signed errors of good quads.
    let mut signed: [Vec<[f64; 2]>; 4] = Default::default();
    let mut per_epoch = Vec::new();
    for k in 0..data.len() {
        let f = &data[k];
        let views = Some((f.images[0].view().unwrap(), f.images[1].view().unwrap()));
        let prev = (k > 0).then(|| data[k - 1].features());
        // Constant velocity: the last true motion predicts the next one.
        let motion = (k >= 2).then(|| relative_motion(&gt[k - 2], &gt[k - 1]));
        let r = m
            .process_epoch_with(f.features(), prev, views, Some(&ds.rig), motion.as_ref())
            .unwrap();
        if k == 0 {
            assert_eq!(r.status, MatchOutcome::FirstEpoch);
            continue;
        }
        println!(
            "epoch {k}: {:?}, {} tie points, stereo {}, temporal {}/{} ({:?}), quads {:?}",
            r.status,
            r.tie_points,
            r.stereo.pass.matches,
            r.left_temporal.matches,
            r.right_temporal.matches,
            r.left_mode,
            r.quads
        );
        per_epoch.push(r.tie_points);
        let poses = [
            gt[k - 1],
            truth.right_pose(&gt[k - 1]),
            gt[k],
            truth.right_pose(&gt[k]),
        ];
        let cams = [truth.left, truth.right, truth.left, truth.right];
        for t in m.tie_points() {
            total += 1;
            let Some(z) = depth_at(&data[k - 1].depth, t.prev.left[0], t.prev.left[1]) else {
                unknown += 1;
                continue;
            };
            let p = back_project(&truth, &gt[k - 1], t.prev.left, z);
            let obs = [t.prev.left, t.prev.right, t.cur.left, t.cur.right];
            let diffs: Vec<Option<[f64; 2]>> = (0..4)
                .map(|i| {
                    project_to_pixel(&poses[i], &cams[i], &p)
                        .ok()
                        .map(|q| [obs[i][0] as f64 - q[0], obs[i][1] as f64 - q[1]])
                })
                .collect();
            let errs: Vec<f64> = diffs
                .iter()
                .map(|d| d.map_or(f64::INFINITY, |d| d[0].hypot(d[1])))
                .collect();
            if errs.iter().all(|&e| e <= 2.0) {
                for (i, d) in diffs.iter().enumerate() {
                    let d = d.unwrap();
                    signed[i].push(d);
                }
            }
            let bad = errs.iter().any(|&e| e > 2.0);
            if bad && std::env::var("MATCH_SYNTH_VERBOSE").is_ok() {
                println!(
                    "  off: track {} len {} errors {errs:.2?} at {:?} depth {z:.2}",
                    t.track_id, t.length, t.prev.left
                );
            }
            off += bad as usize;
        }
    }
    let checked = total - unknown;
    let mean_per_epoch = total as f64 / per_epoch.len() as f64;
    println!(
        "synthetic `{scene}`, {} epochs: {total} tie points ({mean_per_epoch:.0} per epoch), {checked} with a \
         usable depth, {off} off by > 2 px = {:.2} %; mean track length {:.2}",
        data.len(),
        100.0 * off as f64 / checked.max(1) as f64,
        m.tracks().mean_length()
    );
    for (name, d) in ["prev left", "prev right", "cur left", "cur right"]
        .iter()
        .zip(&signed)
    {
        let n = d.len().max(1) as f64;
        let mean = [
            d.iter().map(|v| v[0]).sum::<f64>() / n,
            d.iter().map(|v| v[1]).sum::<f64>() / n,
        ];
        let mut abs: Vec<f64> = d.iter().map(|v| v[0].hypot(v[1])).collect();
        abs.sort_by(f64::total_cmp);
        let median = abs.get(abs.len() / 2).copied().unwrap_or(0.0);
        println!(
            "  {name}: mean error ({:+.3}, {:+.3}) px, median |error| {median:.3} px",
            mean[0], mean[1]
        );
        // A bias (half-pixel convention, refinement skew) would scale the traverse.
        assert!(mean[0].abs() < 0.1 && mean[1].abs() < 0.1, "{name} biased");
        assert!(median < 0.4, "{name}: median error {median:.3} px");
    }
    assert!(mean_per_epoch >= 50.0);
    assert!(off * 100 <= checked, "{off} of {checked} off by > 2 px");
}
