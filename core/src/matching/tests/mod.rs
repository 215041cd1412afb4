//! Matcher tests on synthetic scenes with known correspondences (COLMAP-style: exact
//! truth, exact counts where the scene makes them exact), budget vs arena, bad input.
extern crate std;
use std::vec;
use std::vec::Vec;

use super::config::NONE;
use super::grid::Grid;
use super::refine::{refine_match, Correlator};
use super::synthetic::{SyntheticScene, DISTRACTOR};
use super::*;
use crate::budget::{Arena, MemoryBudget};
use crate::camera::{project_to_pixel, Interior, Pose, Rig};
use crate::features::{Descriptor, Keypoint};
use crate::image::ImageView;

struct Img {
    kps: Vec<Keypoint>,
    desc: Vec<Descriptor>,
    ids: Vec<u32>,
}

impl Img {
    fn render(scene: &SyntheticScene, pose: &Pose, cam: &Interior, tag: u64, cap: usize) -> Img {
        let mut img = Img {
            kps: vec![Keypoint::default(); cap],
            desc: vec![[0; 128]; cap],
            ids: vec![0; cap],
        };
        let n = scene.render(pose, cam, tag, &mut img.kps, &mut img.desc, &mut img.ids);
        img.kps.truncate(n);
        img.desc.truncate(n);
        img.ids.truncate(n);
        img
    }
    fn features(&self) -> Features<'_> {
        Features::new(&self.kps, &self.desc)
    }
}

fn rectified_rig() -> Rig {
    Rig::rectified(Interior::pinhole_px(640, 480, 500.0), 0.5)
}

fn pose_at(y: f64) -> Pose {
    Pose::from_degrees(90.0, 0.0, 0.0, [0.0, y, 0.0])
}

fn config() -> MatchConfig {
    MatchConfig::rectified(640, 480, 1000, 80.0)
}

/// Storage sized exactly by the budget.
fn storage(cfg: &MatchConfig) -> Vec<u8> {
    vec![0u8; cfg.predicted_bytes()]
}

struct Epoch {
    left: Img,
    right: Img,
}

fn epoch(scene: &SyntheticScene, rig: &Rig, pose: &Pose, k: u64) -> Epoch {
    Epoch {
        left: Img::render(scene, pose, &rig.left, 2 * k, 1000),
        right: Img::render(scene, &rig.right_pose(pose), &rig.right, 2 * k + 1, 1000),
    }
}

impl Epoch {
    fn features(&self) -> StereoFeatures<'_> {
        StereoFeatures {
            left: self.left.features(),
            right: self.right.features(),
        }
    }
}

#[test]
fn budget_predicts_arena_use() {
    for cfg in [
        config(),
        MatchConfig {
            max_tracks: 300,
            track_history: 5,
            ..MatchConfig::rectified(1241, 376, 2000, 160.0)
        },
    ] {
        let mut store = storage(&cfg);
        let mut arena = Arena::new(&mut store);
        let _m = Matcher::new(cfg, &mut arena).expect("fits its own budget");
        let predicted = cfg.predicted_bytes();
        assert!(arena.used() <= predicted);
        // Only alignment padding may be unused: a few bytes per slice.
        assert!(
            predicted - arena.used() < 128,
            "predicted {predicted}, used {}",
            arena.used()
        );
        let mut b = MemoryBudget::new();
        cfg.budget(&mut b);
        assert_eq!(b.total(), predicted);
        // One byte less does not fit, and says so.
        let mut small = vec![0u8; arena.used() - 1 - 16];
        let mut arena = Arena::new(&mut small);
        assert!(matches!(
            Matcher::new(cfg, &mut arena),
            Err(MatchError::OutOfMemory(_))
        ));
    }
}

#[test]
fn grid_query_equals_brute_force() {
    let scene = SyntheticScene::street(3);
    let img = Img::render(&scene, &pose_at(0.0), &rectified_rig().left, 0, 1000);
    let mut store = vec![0u8; 64 * 1024];
    let mut arena = Arena::new(&mut store);
    let mut grid = Grid::new(&mut arena, 40, 30, 16, 1000).unwrap();
    assert_eq!(grid.build(&img.kps), 0);
    assert_eq!(grid.len(), img.kps.len());
    for (x0, y0, x1, y1) in [
        (10.0, 10.0, 50.0, 20.0),
        (-30.0, 100.0, 700.0, 104.0),
        (600.0, 400.0, 900.0, 900.0),
    ] {
        let mut got = Vec::new();
        grid.query(x0, y0, x1, y1, |i| {
            let k = img.kps[i as usize];
            if k.x >= x0 && k.x <= x1 && k.y >= y0 && k.y <= y1 {
                got.push(i);
            }
            true
        });
        got.sort();
        let want: Vec<u32> = (0..img.kps.len() as u32)
            .filter(|&i| {
                let k = img.kps[i as usize];
                k.x >= x0 && k.x <= x1 && k.y >= y0 && k.y <= y1
            })
            .collect();
        assert_eq!(got, want);
    }
}

#[test]
fn rectified_stereo_exact_on_clean_scene() {
    // Unique descriptors, no noise, no distractors: every point seen in both images
    // (and inside the disparity range) is matched, and nothing else.
    let scene = SyntheticScene {
        distractors: 0,
        position_noise_px: 0.0,
        descriptor_noise: 0,
        prototypes: 100_000,
        points: 900,
        ..SyntheticScene::street(5)
    };
    let rig = rectified_rig();
    let e = epoch(&scene, &rig, &pose_at(0.0), 0);
    let cfg = config();
    let mut store = storage(&cfg);
    let mut arena = Arena::new(&mut store);
    let mut m = Matcher::new(cfg, &mut arena).unwrap();
    let stats = m.match_stereo(e.features(), None);
    let common = e
        .left
        .ids
        .iter()
        .filter(|id| e.right.ids.contains(id))
        .count();
    let matches: Vec<_> = m.stereo_matches(&e.left.kps).collect();
    assert_eq!(stats.pass.matches as usize, matches.len());
    assert_eq!(matches.len(), common);
    for s in &matches {
        assert_eq!(e.left.ids[s.left as usize], e.right.ids[s.right as usize]);
        assert!((s.left_px[1] - s.right_px[1]).abs() < 1e-3);
    }
}

#[test]
fn rectified_stereo_on_noisy_scene_is_right() {
    let scene = SyntheticScene::street(7);
    let rig = rectified_rig();
    let e = epoch(&scene, &rig, &pose_at(0.0), 0);
    let cfg = config();
    let mut store = storage(&cfg);
    let mut arena = Arena::new(&mut store);
    let mut m = Matcher::new(cfg, &mut arena).unwrap();
    let stats = m.match_stereo(e.features(), None);
    let wrong = m
        .stereo_matches(&e.left.kps)
        .filter(|s| e.left.ids[s.left as usize] != e.right.ids[s.right as usize])
        .count();
    let common = e
        .left
        .ids
        .iter()
        .filter(|&&id| id != DISTRACTOR && e.right.ids.contains(&id))
        .count();
    std::println!("stereo: {:?}, common {common}, wrong {wrong}", stats);
    assert!(
        stats.pass.matches as usize > common * 8 / 10,
        "{} of {common}",
        stats.pass.matches
    );
    assert!(wrong * 200 <= stats.pass.matches as usize, "{wrong} wrong");
    // The cost stays bounded: at most max_candidates comparisons per query.
    assert!(stats.pass.comparisons as usize <= e.left.kps.len() * cfg.max_candidates);
}

/// A converging rig with the test camera's distortion: its epipolar curves are bent in
/// pixels.
fn converging_rig() -> Rig {
    let cam = crate::testkit::test_camera();
    Rig {
        left: cam,
        right: cam,
        relative_angles: [0.01, -0.04, 0.02],
        base_m: [0.5, 0.02, -0.01],
    }
}

/// [`config`] with the stereo search of a general `rig` (2 px band, depths from 2 m).
fn rig_config(rig: Rig) -> MatchConfig {
    MatchConfig {
        stereo: StereoGeometry::Rig {
            rig,
            tolerance_px: 2.0,
            min_depth_m: 2.0,
            max_depth_m: f64::INFINITY,
        },
        ..config()
    }
}

#[test]
fn general_rig_with_distortion_and_rotation() {
    let rig = converging_rig();
    let scene = SyntheticScene::street(11);
    let e = epoch(&scene, &rig, &pose_at(0.0), 0);
    let cfg = rig_config(rig);
    let mut store = storage(&cfg);
    let mut arena = Arena::new(&mut store);
    let mut m = Matcher::new(cfg, &mut arena).unwrap();
    let stats = m.match_stereo(e.features(), None);
    let wrong = m
        .stereo_matches(&e.left.kps)
        .filter(|s| e.left.ids[s.left as usize] != e.right.ids[s.right as usize])
        .count();
    let common = e
        .left
        .ids
        .iter()
        .filter(|&&id| id != DISTRACTOR && e.right.ids.contains(&id))
        .count();
    std::println!("rig stereo: {:?}, common {common}, wrong {wrong}", stats);
    assert!(stats.pass.matches as usize > common * 8 / 10);
    assert!(wrong * 200 <= stats.pass.matches as usize);
    // Without the relative rotation in the model the band misses most true matches.
    let wrong_rig = Rig {
        relative_angles: [0.0; 3],
        ..rig
    };
    let cfg2 = MatchConfig {
        stereo: StereoGeometry::Rig {
            rig: wrong_rig,
            tolerance_px: 2.0,
            min_depth_m: 2.0,
            max_depth_m: f64::INFINITY,
        },
        ..cfg
    };
    let mut store2 = storage(&cfg2);
    let mut arena2 = Arena::new(&mut store2);
    let mut m2 = Matcher::new(cfg2, &mut arena2).unwrap();
    let bad = m2.match_stereo(e.features(), None);
    assert!(
        bad.pass.matches * 3 < stats.pass.matches,
        "{} vs {}",
        bad.pass.matches,
        stats.pass.matches
    );
}

/// The offset of a pair from its epipolar lines, measured in a wider band than the
/// search's: exact (to the median's bin) on a shifted right image, zero on the true
/// geometry, none for a rectified search.
#[test]
fn epipolar_offset_measures_a_shifted_right_image() {
    let rig = converging_rig();
    let scene = SyntheticScene::street(11);
    let mut e = epoch(&scene, &rig, &pose_at(0.0), 0);
    let cfg = rig_config(rig);
    let mut store = storage(&cfg);
    let mut arena = Arena::new(&mut store);
    let mut m = Matcher::new(cfg, &mut arena).unwrap();
    let true_geometry = m.epipolar_offset(e.features(), 3.0, 30).unwrap();
    assert!(true_geometry.matches > 100, "{true_geometry:?}");
    assert!(true_geometry.median_px.abs() < 0.1, "{true_geometry:?}");
    // The right camera's principal point 2.5 px off vertically: every right point moves
    // down the image (photo-coordinates have y up), across lines along the rows.
    for k in &mut e.right.kps {
        k.y += 2.5;
    }
    let shifted = m.epipolar_offset(e.features(), 3.0, 30).unwrap();
    assert!(shifted.normal[1].abs() > 0.99, "{shifted:?}");
    let down = -shifted.median_px * shifted.normal[1];
    assert!((down - 2.5).abs() < 0.1, "{shifted:?}");
    assert!(
        shifted.matches * 10 > true_geometry.matches * 9,
        "{shifted:?}"
    );
    // The search band (2 px) keeps none of these noise-free points.
    let kept = m.match_stereo(e.features(), None).pass.matches;
    assert!(kept * 10 < shifted.matches, "{kept} of {shifted:?}");
    // Too few matches, or a rectified search: nothing measured.
    assert_eq!(m.epipolar_offset(e.features(), 3.0, 10_000), None);
    let mut rect_store = storage(&config());
    let mut rect_arena = Arena::new(&mut rect_store);
    let mut rect = Matcher::new(config(), &mut rect_arena).unwrap();
    assert_eq!(rect.epipolar_offset(e.features(), 3.0, 30), None);
}

/// Measuring the offset uses the current epoch's buffers as scratch: the epoch matched
/// after it, and the next one, are the same as without it.
#[test]
fn epipolar_offset_leaves_the_matching_as_it_was() {
    let rig = converging_rig();
    let scene = SyntheticScene::street(11);
    let epochs = [0.0, 1.0].map(|y| epoch(&scene, &rig, &pose_at(y), y as u64));
    let cfg = rig_config(rig);
    let run = |probe: bool| {
        let mut store = storage(&cfg);
        let mut arena = Arena::new(&mut store);
        let mut m = Matcher::new(cfg, &mut arena).unwrap();
        let mut seen = Vec::new();
        for (k, e) in epochs.iter().enumerate() {
            if probe {
                assert!(m.epipolar_offset(e.features(), 3.0, 30).is_some());
            }
            let prev = (k > 0).then(|| epochs[k - 1].features());
            let report = m.process_epoch(e.features(), prev, None, None).unwrap();
            let stereo: Vec<_> = m
                .stereo_matches(&e.left.kps)
                .map(|s| (s.left, s.right))
                .collect();
            let ties: Vec<_> = m.tie_points().map(|t| (t.track_id, t.cur.left)).collect();
            seen.push((report.stereo.pass.matches, report.tie_points, stereo, ties));
        }
        seen
    };
    let (plain, probed) = (run(false), run(true));
    assert!(plain[1].1 > 100, "{} tie points", plain[1].1);
    assert_eq!(plain, probed);
}

#[test]
fn triangulate_and_predict_are_exact() {
    let rig = Rig {
        relative_angles: [0.01, -0.02, 0.005],
        ..rectified_rig()
    };
    let prev = pose_at(0.0);
    let cur = Pose::from_degrees(90.5, 0.3, -0.2, [0.1, 1.0, 0.02]);
    let motion = relative_motion(&prev, &cur);
    let p = [1.5, 12.0, 0.7];
    let l = project_to_pixel(&prev, &rig.left, &p).unwrap();
    let r = project_to_pixel(&rig.right_pose(&prev), &rig.right, &p).unwrap();
    let x = triangulate(&rig, l, r).unwrap();
    let in_cam = prev.to_camera(&p);
    assert!((x - in_cam).norm() < 1e-9);
    let kp = |c: [f64; 2]| Keypoint {
        x: c[0] as f32,
        y: c[1] as f32,
        ..Default::default()
    };
    let (mut pl, mut pr) = ([[0f32; 2]; 2], [[0f32; 2]; 1]);
    let n = predict_positions(
        &rig,
        &motion,
        &[kp(l), kp([5.0, 5.0])],
        &[kp(r)],
        &[0, NONE],
        &mut pl,
        &mut pr,
    );
    assert_eq!(n, 1);
    let lk = project_to_pixel(&cur, &rig.left, &p).unwrap();
    let rk = project_to_pixel(&rig.right_pose(&cur), &rig.right, &p).unwrap();
    assert!((pl[0][0] as f64 - lk[0]).abs() < 0.02 && (pl[0][1] as f64 - lk[1]).abs() < 0.02);
    assert!((pr[0][0] as f64 - rk[0]).abs() < 0.02 && (pr[0][1] as f64 - rk[1]).abs() < 0.02);
    assert!(pl[1][0].is_nan());
}

/// Runs a traverse and returns (tie points, off by > 2 px, tie points per epoch, mean track length).
fn run_traverse(
    cfg: MatchConfig,
    scene: &SyntheticScene,
    epochs: usize,
    step: f64,
    guided: bool,
) -> (usize, usize, Vec<EpochReport>, f64) {
    let rig = rectified_rig();
    let mut store = storage(&cfg);
    let mut arena = Arena::new(&mut store);
    let mut m = Matcher::new(cfg, &mut arena).unwrap();
    let poses: Vec<Pose> = (0..epochs).map(|k| pose_at(k as f64 * step)).collect();
    let frames: Vec<Epoch> = poses
        .iter()
        .enumerate()
        .map(|(k, p)| epoch(scene, &rig, p, k as u64))
        .collect();
    let (mut total, mut off) = (0usize, 0usize);
    let mut reports = Vec::new();
    for k in 0..epochs {
        let prev = (k > 0).then(|| frames[k - 1].features());
        // A constant-velocity prediction that is 15% short of the true step.
        let motion = (k > 0).then(|| relative_motion(&pose_at(0.0), &pose_at(0.85 * step)));
        let motion_ref = if guided {
            motion.as_ref().map(|m| (&rig, m))
        } else {
            None
        };
        let rep = m
            .process_epoch(frames[k].features(), prev, None, motion_ref)
            .unwrap();
        if k == 0 {
            assert_eq!(rep.status, MatchOutcome::FirstEpoch);
            continue;
        }
        let (pf, cf) = (&frames[k - 1], &frames[k]);
        for (q, t) in m.quads().iter().zip(m.tie_points()) {
            total += 1;
            let id = pf.left.ids[q.prev_left as usize];
            if id == DISTRACTOR {
                off += 1;
                continue;
            }
            let p = scene.point(id);
            let truth = [
                project_to_pixel(&poses[k - 1], &rig.left, &p),
                project_to_pixel(&rig.right_pose(&poses[k - 1]), &rig.right, &p),
                project_to_pixel(&poses[k], &rig.left, &p),
                project_to_pixel(&rig.right_pose(&poses[k]), &rig.right, &p),
            ];
            let obs = [t.prev.left, t.prev.right, t.cur.left, t.cur.right];
            let bad = truth.iter().zip(obs.iter()).any(|(tr, o)| match tr {
                Ok(tp) => (tp[0] - o[0] as f64).hypot(tp[1] - o[1] as f64) > 2.0,
                Err(_) => true,
            });
            off += bad as usize;
            assert_eq!(
                t.cur.left,
                [
                    cf.left.kps[q.cur_left as usize].x,
                    cf.left.kps[q.cur_left as usize].y
                ]
            );
        }
        reports.push(rep);
    }
    (total, off, reports, m.tracks().mean_length())
}

#[test]
fn guided_traverse_quads_are_right() {
    let scene = SyntheticScene::street(21);
    let (total, off, reports, mean_len) = run_traverse(config(), &scene, 6, 0.8, true);
    let per_epoch = total as f64 / reports.len() as f64;
    std::println!("quads: {total} tie points, {off} off by > 2 px, {per_epoch:.0} per epoch, mean track length {mean_len:.2}");
    for r in &reports {
        std::println!("{r:?}");
        assert_eq!(r.status, MatchOutcome::Ok);
        assert_eq!(r.left_mode, TemporalMode::Guided);
        assert_eq!(r.right_mode, TemporalMode::Guided);
        let q = r.quads;
        assert_eq!(
            q.candidates,
            q.no_left_temporal + q.no_right_temporal + q.no_current_stereo + q.loop_open + q.closed
        );
    }
    assert!(per_epoch > 300.0);
    assert!(off * 100 <= total, "{off} of {total} off by > 2 px");
    assert!(mean_len > 3.0);
}

#[test]
fn fallback_without_prediction() {
    let scene = SyntheticScene::street(22);
    let (total, off, reports, _) = run_traverse(config(), &scene, 3, 0.5, false);
    for r in &reports {
        assert_eq!(r.left_mode, TemporalMode::Fallback);
        assert_eq!(r.status, MatchOutcome::Ok);
    }
    assert!(total > 200);
    assert!(off * 100 <= total, "{off} of {total}");
}

#[test]
fn tracks_capacity_keeps_spread_and_counts_dropped() {
    let scene = SyntheticScene::street(23);
    let cfg = MatchConfig {
        max_tracks: 60,
        max_tie_points: 1000,
        ..config()
    };
    let (total, off, reports, _) = run_traverse(cfg, &scene, 4, 0.8, true);
    let first = reports[0];
    assert_eq!(first.tracks.started, 60);
    assert_eq!(first.tie_points, 60);
    let kept = first.quads.closed - first.quads.motion_outliers;
    assert_eq!(first.tracks.dropped, kept - 60);
    assert!(reports.iter().all(|r| r.tracks.live <= 60));
    // Later epochs continue the old tracks first.
    assert!(reports[1].tracks.continued > 40, "{:?}", reports[1].tracks);
    assert!(off * 100 <= total);
}

#[test]
fn spreading_covers_every_region() {
    let scene = SyntheticScene::street(24);
    let rig = rectified_rig();
    let cfg = MatchConfig {
        max_tie_points: 48,
        spread_cols: 4,
        spread_rows: 3,
        ..config()
    };
    let mut store = storage(&cfg);
    let mut arena = Arena::new(&mut store);
    let mut m = Matcher::new(cfg, &mut arena).unwrap();
    let e0 = epoch(&scene, &rig, &pose_at(0.0), 0);
    let e1 = epoch(&scene, &rig, &pose_at(0.5), 1);
    m.process_epoch(e0.features(), None, None, None).unwrap();
    let motion = relative_motion(&pose_at(0.0), &pose_at(0.5));
    let rep = m
        .process_epoch(
            e1.features(),
            Some(e0.features()),
            None,
            Some((&rig, &motion)),
        )
        .unwrap();
    assert_eq!(rep.tie_points, 48);
    assert_eq!(
        rep.spread_dropped,
        rep.quads.closed - rep.quads.motion_outliers - 48
    );
    let mut per_region = [0u32; 12];
    for t in m.tie_points() {
        per_region[spread::region_of(t.cur.left[0], t.cur.left[1], 640, 480, 4, 3) as usize] += 1;
    }
    // Every region with enough candidates gets its share (4 each when all have >= 4).
    std::println!("per region {per_region:?}");
    assert!(
        per_region.iter().filter(|&&c| c >= 3).count() >= 10,
        "{per_region:?}"
    );
}

#[test]
fn bad_input_gives_status_not_panic() {
    let scene = SyntheticScene::street(31);
    let rig = rectified_rig();
    let cfg = config();
    let mut store = storage(&cfg);
    let mut arena = Arena::new(&mut store);
    let mut m = Matcher::new(cfg, &mut arena).unwrap();
    let e0 = epoch(&scene, &rig, &pose_at(0.0), 0);
    let motion = relative_motion(&pose_at(0.0), &pose_at(0.8));
    let mo = Some((&rig, &motion));

    // No keypoints.
    let empty = StereoFeatures {
        left: Features::new(&[], &[]),
        right: Features::new(&[], &[]),
    };
    let r = m.process_epoch(empty, None, None, None).unwrap();
    assert_eq!(r.status, MatchOutcome::NoKeypoints);
    let r = m
        .process_epoch(e0.features(), Some(empty), None, mo)
        .unwrap();
    assert_eq!((r.status, r.tie_points), (MatchOutcome::Lost, 0));

    // All keypoints identical (position and descriptor).
    let same_k = vec![
        Keypoint {
            x: 100.0,
            y: 100.0,
            sigma: 2.0,
            ..Default::default()
        };
        500
    ];
    let same_d = vec![[7u8; 128]; 500];
    let same = StereoFeatures {
        left: Features::new(&same_k, &same_d),
        right: Features::new(&same_k, &same_d),
    };
    let r = m.process_epoch(same, None, None, None).unwrap();
    assert_eq!(r.status, MatchOutcome::NoStereoMatches);
    assert_eq!(m.stereo_matches(&same_k).count(), 0);
    let r = m
        .process_epoch(e0.features(), Some(same), None, mo)
        .unwrap();
    assert_eq!((r.status, r.tie_points), (MatchOutcome::Lost, 0));

    // A repeated frame: ignored, state unchanged, the traverse goes on.
    let r = m
        .process_epoch(e0.features(), Some(e0.features()), None, mo)
        .unwrap();
    assert_eq!((r.status, r.tie_points), (MatchOutcome::RepeatedFrame, 0));
    let e1 = epoch(&scene, &rig, &pose_at(0.8), 1);
    let r = m
        .process_epoch(e1.features(), Some(e0.features()), None, mo)
        .unwrap();
    assert_eq!(r.status, MatchOutcome::Ok);
    assert!(r.tie_points > 300);

    // A frame from another place.
    let other = SyntheticScene::street(999);
    let e2 = epoch(&other, &rig, &pose_at(0.0), 2);
    let r = m
        .process_epoch(e2.features(), Some(e1.features()), None, mo)
        .unwrap();
    std::println!("another place: {r:?}");
    assert_eq!(r.status, MatchOutcome::Lost);
    assert!(r.tie_points < 10, "{}", r.tie_points);
    assert_eq!(r.left_mode, TemporalMode::Fallback);

    // Wrong previous features, mismatched lengths, NaN coordinates.
    assert_eq!(
        m.process_epoch(e1.features(), Some(e1.features()), None, mo)
            .unwrap_err(),
        MatchError::PreviousMismatch
    );
    let short = StereoFeatures {
        left: Features::new(&e0.left.kps, &e0.left.desc[..10]),
        right: e0.right.features(),
    };
    assert_eq!(
        m.process_epoch(short, None, None, None).unwrap_err(),
        MatchError::LengthMismatch
    );
    let mut nan = e0.left.kps.clone();
    for k in nan.iter_mut().step_by(2) {
        k.x = f32::NAN;
    }
    let nanf = StereoFeatures {
        left: Features::new(&nan, &e0.left.desc),
        right: e0.right.features(),
    };
    let r = m.process_epoch(nanf, None, None, None).unwrap();
    assert_eq!(r.status, MatchOutcome::FirstEpoch);
    // More keypoints than the capacity: the rest are ignored and counted.
    let big = SyntheticScene {
        points: 8000,
        ..scene
    };
    let l = Img::render(&big, &pose_at(0.0), &rig.left, 0, 1500);
    let rr = Img::render(&big, &rig.right_pose(&pose_at(0.0)), &rig.right, 1, 1500);
    let r = m
        .process_epoch(
            StereoFeatures {
                left: l.features(),
                right: rr.features(),
            },
            None,
            None,
            None,
        )
        .unwrap();
    assert_eq!(r.stereo.ignored_keypoints, 1000);
}

#[test]
fn config_is_validated() {
    let mut store = vec![0u8; 1 << 20];
    for bad in [
        MatchConfig {
            max_keypoints: 0,
            ..config()
        },
        MatchConfig {
            ratio: f32::NAN,
            ..config()
        },
        MatchConfig {
            track_history: 1,
            ..config()
        },
        MatchConfig {
            refine: Some(RefineConfig {
                half_window: 30,
                ..Default::default()
            }),
            ..config()
        },
        MatchConfig {
            stereo: StereoGeometry::Rectified {
                row_tolerance_px: 1.0,
                min_disparity_px: 10.0,
                max_disparity_px: 1.0,
            },
            ..config()
        },
    ] {
        let mut arena = Arena::new(&mut store);
        assert_eq!(
            Matcher::new(bad, &mut arena).err(),
            Some(MatchError::BadConfig)
        );
    }
}

mod correlation;
mod lsm;
