//! Per-epoch time and accuracy of the core traverse on one core, without the link.
//!
//! `cargo bench -p phototraverse-host --bench traverse_epoch -- DATASET [KEY=VALUE ...]`
//!
//! Runs `Traverse::process` on every epoch of DATASET in this thread, timing each
//! stage with the thread's CPU clock (so a loaded machine slows the wall clock, not
//! the figures), and prints the median and 90th percentile per stage, the tie points
//! per epoch and, when the dataset has `gt_poses.txt`, the KITTI drift. The OpenCV
//! stereo-odometry peer of `bench/traverse/` runs on the same datasets.
//!
//! KEY=VALUE overrides the traverse configuration for experiments (keys listed by
//! `--help`; `poses=FILE` writes the estimated KITTI poses); without them it runs the firmware's defaults for the dataset's rig.
use phototraverse_core::budget::{Arena, MemoryBudget};
use phototraverse_core::camera::kitti_from_pose;
use phototraverse_core::traverse::{flags, CalibrationCheck, Clock, Traverse, TraverseConfig};
use phototraverse_host::dataset::Dataset;
use phototraverse_host::eval::evaluate;
use std::path::PathBuf;

/// Thread CPU time in microseconds.
struct ThreadClock;

impl Clock for ThreadClock {
    fn now_us(&self) -> u64 {
        let mut ts = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: clock_gettime writes the timespec we own.
        unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
        ts.tv_sec as u64 * 1_000_000 + ts.tv_nsec as u64 / 1000
    }
}

/// The configuration keys: each sets its part of the configuration from the value.
type Setter = fn(&mut TraverseConfig, f64);
const SETTERS: &[(&str, Setter)] = &[
    ("keypoints", |c, v| {
        c.sift.max_keypoints = v as usize;
        c.matching.max_keypoints = v as usize;
    }),
    ("contrast", |c, v| c.sift.contrast_threshold = v as f32),
    ("window", |c, v| {
        c.adjust.window = v as usize;
        c.matching.track_history = c.adjust.window;
    }),
    ("sigma_px", |c, v| c.sigma_px = v),
    ("max_iterations", |c, v| {
        c.adjust.max_iterations = v as usize
    }),
    ("tolerance", |c, v| c.adjust.tolerance = v),
    ("step_angle", |c, v| c.adjust.step_tolerance[0] = v),
    ("step_position", |c, v| c.adjust.step_tolerance[1] = v),
    ("robust_rounds", |c, v| {
        c.adjust.max_robust_rounds = v as usize
    }),
    ("ratio", |c, v| c.matching.ratio = v as f32),
    ("tie_points", |c, v| c.matching.max_tie_points = v as usize),
    ("keep_exclusions", |c, v| {
        c.adjust.keep_exclusions = v != 0.0
    }),
    ("fine_octave", |c, v| c.sift.fine_octave = v != 0.0),
    ("levels", |c, v| c.sift.levels = v as usize),
    ("edge", |c, v| c.sift.edge_threshold = v as f32),
    ("velocity_sigma", |c, v| {
        c.adjust.sigmas.velocity_change_mps = v
    }),
    ("robust", |c, v| {
        c.adjust.robust = if v == 0.0 {
            phototraverse_core::adjust::Robust::None
        } else {
            phototraverse_core::adjust::Robust::snooping()
        }
    }),
    ("max_depth", |c, v| c.max_depth_m = v),
    ("min_ray_angle_deg", |c, v| {
        c.min_ray_angle_rad = v.to_radians()
    }),
    ("refine", |c, v| {
        c.matching.refine = (v != 0.0).then(|| phototraverse_core::matching::RefineConfig {
            rows_only: matches!(
                c.matching.stereo,
                phototraverse_core::matching::StereoGeometry::Rectified { .. }
            ),
            ..Default::default()
        })
    }),
    ("temporal_refine", |c, v| c.temporal_refine = v != 0.0),
    ("rows_only", |c, v| {
        if let Some(r) = c.matching.refine.as_mut() {
            r.rows_only = v != 0.0;
        }
    }),
    ("min_ncc", |c, v| {
        if let Some(r) = c.matching.refine.as_mut() {
            r.min_ncc = v as f32;
        }
    }),
    ("back_check", |c, v| {
        if let Some(r) = c.matching.refine.as_mut() {
            r.back_check_px = v as f32;
        }
    }),
    ("area", |c, v| {
        c.max_area_ties = v as usize;
        c.fit_capacities();
    }),
    ("fixed_epochs", |c, v| {
        c.adjust.fixed_epochs = v as usize;
        c.fit_capacities();
    }),
    ("prior_inflation", |c, v| {
        c.adjust.carried_prior_inflation = v
    }),
    ("anchor_scale", |c, v| c.max_anchor_scale = v as f32),
    ("estimate_rig", |c, v| *c = c.with_rig_estimation(v != 0.0)),
    ("check_calibration", |c, v| {
        *c = c.with_calibration_check((v != 0.0).then(CalibrationCheck::default))
    }),
    ("desc_grid", |c, v| c.sift.descriptor_grid = v as usize),
    ("ori_radius", |c, v| c.sift.orientation_radius = v as f32),
    ("ori_stride", |c, v| {
        c.sift.orientation_stride_sigma = v as f32
    }),
    ("soft_orientation", |c, v| {
        c.sift.soft_orientation = v != 0.0
    }),
    ("octaves", |c, v| c.sift.octaves = v as usize),
    ("grid_cols", |c, v| c.sift.grid_cols = v as usize),
    ("grid_rows", |c, v| c.sift.grid_rows = v as usize),
];

fn keys() -> String {
    SETTERS
        .iter()
        .map(|(k, _)| *k)
        .collect::<Vec<_>>()
        .join(" ")
}

fn apply(cfg: &mut TraverseConfig, key: &str, value: &str) -> Result<(), String> {
    let Some((_, set)) = SETTERS.iter().find(|(k, _)| *k == key) else {
        return Err(format!("unknown key {key}; keys: {}", keys()));
    };
    let v = value
        .parse::<f64>()
        .map_err(|e| format!("{key}={value}: {e}"))?;
    set(cfg, v);
    Ok(())
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

fn main() -> Result<(), String> {
    // cargo bench passes --bench; the dataset is the first other argument.
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    if args.is_empty() || args[0] == "--help" {
        println!(
            "usage: traverse_epoch DATASET [KEY=VALUE ...]\nkeys: {}",
            keys()
        );
        return Ok(());
    }
    let ds = Dataset::open(&PathBuf::from(&args[0])).map_err(|e| e.to_string())?;
    let mut cfg = TraverseConfig::for_rig(ds.rig, ds.datum);
    let mut poses_out = None;
    for kv in &args[1..] {
        let (k, v) = kv
            .split_once('=')
            .ok_or(format!("{kv}: expected KEY=VALUE"))?;
        if k == "poses" {
            poses_out = Some(PathBuf::from(v));
        } else {
            apply(&mut cfg, k, v)?;
        }
    }
    let mut budget = MemoryBudget::new();
    cfg.budget(&mut budget).map_err(|e| format!("{e:?}"))?;
    let mut store = vec![0u8; budget.total()];
    let mut arena = Arena::new(&mut store);
    let mut trav = Traverse::new(cfg, &mut arena).map_err(|e| e.to_string())?;

    let names = [
        "sift_left",
        "sift_right",
        "matching",
        "initial",
        "adjust",
        "total",
    ];
    let mut stages: [Vec<f64>; 6] = Default::default();
    let (mut ties, mut flagged) = (Vec::new(), 0usize);
    let (mut iters, mut obs) = (Vec::new(), Vec::new());
    let mut flag_list = Vec::new();
    let (mut kps, mut stereo) = (Vec::new(), Vec::new());
    let mut poses = Vec::new();
    let mut smoothed = Vec::new();
    for i in 0..ds.len() {
        let (l, r) = ds.load_pair(i).map_err(|e| e.to_string())?;
        let (lv, rv) = (l.view().unwrap(), r.view().unwrap());
        let out = trav.process(
            &lv,
            &rv,
            // As the link carries it: whole microseconds (runner.rs).
            ((ds.epochs[i].time.unwrap_or(i as f64 * 0.1) * 1e6).max(0.0) as u64) as f64 * 1e-6,
            &ThreadClock,
        );
        let t = out.times;
        let us = [
            t.sift_left_us,
            t.sift_right_us,
            t.matching_us,
            t.initial_us,
            t.adjust_us,
            t.total_us,
        ];
        for (s, v) in stages.iter_mut().zip(us) {
            s.push(v as f64 / 1000.0);
        }
        if std::env::var_os("PT_RESID_DEBUG").is_some() && i % 10 == 9 {
            // mean residual per camera and axis, and per image quadrant (left camera)
            let mut acc = [[0f64; 3]; 6];
            for j in 0..trav.window_observation_count() {
                let (Some(o), Some((px, Some(r)))) = (
                    trav.window_observation(j),
                    trav.window_observation_pixels(j),
                ) else {
                    continue;
                };
                if o.flagged {
                    continue;
                }
                let c = o.camera as usize;
                acc[c][0] += r[0];
                acc[c][1] += r[1];
                acc[c][2] += 1.0;
                if c == 0 {
                    let q = 2 + (px[0] > 320.0) as usize + 2 * (px[1] > 240.0) as usize;
                    acc[q][0] += r[0];
                    acc[q][1] += r[1];
                    acc[q][2] += 1.0;
                }
            }
            let m: Vec<String> = acc
                .iter()
                .map(|a| {
                    format!(
                        "({:+.3},{:+.3} n{})",
                        a[0] / a[2].max(1.0),
                        a[1] / a[2].max(1.0),
                        a[2]
                    )
                })
                .collect();
            eprintln!(
                "{i}: L {} R {} | TL {} TR {} BL {} BR {}",
                m[0], m[1], m[2], m[3], m[4], m[5]
            );
        }
        if out.flags & flags::SOLVE_FAILED != 0 {
            eprintln!("{i}: solve failed: {:?}", trav.last_solve_error());
        }
        if std::env::var_os("PT_OBS_DEBUG").is_some() {
            let mut seen = std::collections::BTreeMap::new();
            for j in 0..trav.window_observation_count() {
                if let Some(o) = trav.window_observation(j) {
                    seen.entry((o.point, 0))
                        .or_insert_with(Vec::new)
                        .push((o.camera, o.track_id, j));
                }
            }
            for ((p, e), v) in &seen {
                let tags: std::collections::BTreeSet<u32> = v.iter().map(|x| x.1).collect();
                let cams: Vec<u8> = v.iter().map(|x| x.0).collect();
                if tags.len() > 1 || cams.len() < 2 {
                    eprintln!("{i}: point {p} epoch {e}: {v:?}");
                }
            }
        }
        if std::env::var_os("PT_MATCH_DEBUG").is_some() {
            eprintln!("{i}: {:?}", trav.match_report());
        }
        ties.push(out.tie_points as f64);
        iters.push(out.iterations as f64);
        kps.push(out.keypoints[0] as f64);
        stereo.push(out.stereo_matches as f64);
        obs.push(out.observations as f64);
        if out.flags != 0 {
            flagged += 1;
            flag_list.push(format!("{i}:{:#x}", out.flags));
        }
        poses.push(kitti_from_pose(&ds.datum, &out.left));
        // The window's refinements of earlier epochs (the last one is final).
        for (input, pose, _) in trav.window_epochs() {
            let k = input as usize;
            if k < smoothed.len() {
                smoothed[k] = kitti_from_pose(&ds.datum, &pose);
            } else if k == smoothed.len() {
                smoothed.push(kitti_from_pose(&ds.datum, &pose));
            }
        }
        while smoothed.len() < poses.len() {
            smoothed.push(poses[smoothed.len()]);
        }
    }
    println!("{} epochs of {}, one thread (CPU time)", ds.len(), args[0]);
    println!("{:<12} {:>9} {:>9}", "stage", "median ms", "p90 ms");
    for (n, s) in names.iter().zip(stages.iter_mut()) {
        let (m, p) = (percentile(s, 0.5), percentile(s, 0.9));
        println!("{n:<12} {m:>9.2} {p:>9.2}");
    }
    println!(
        "per epoch (median): {:.0} left keypoints, {:.0} stereo matches, {:.0} tie points, {:.0} window observations, {:.0} \
         iterations; epochs with flags: {flagged}",
        percentile(&mut kps, 0.5),
        percentile(&mut stereo, 0.5),
        percentile(&mut ties, 0.5),
        percentile(&mut obs, 0.5),
        percentile(&mut iters, 0.5),
    );
    if !flag_list.is_empty() {
        println!(
            "flags (epoch:bits, see traverse::flags): {}",
            flag_list.join(" ")
        );
    }
    if let Some(path) = poses_out {
        phototraverse_host::poses::write_poses(&path, &poses).map_err(|e| e.to_string())?;
    }
    if let Some(gt) = &ds.ground_truth {
        let e = evaluate(gt, &smoothed).map_err(|e| e.to_string())?;
        println!("window-refined poses:");
        print!("{}", e.summary());
        println!("poses as output at their epoch:");
        let e = evaluate(gt, &poses).map_err(|e| e.to_string())?;
        print!("{}", e.summary());
    }
    Ok(())
}
