//! Benchmark of one window update and a sweep of synthetic problems.
//!
//! `cargo bench -p phototraverse-core --bench adjust_window` writes
//! `bench/adjust/out/problem.json` (8 epochs, 300 points, 4 observations each,
//! 0.3 px noise, perturbed start) and `solution.json` (the adjusted window,
//! the median solve time and the memory budget); `python3
//! bench/adjust/compare.py` then solves the same problem with scipy's
//! `least_squares` and compares solution and time.
//!
//! `... --bench adjust_window -- --sweep` runs the accuracy sweep (2..20 epochs,
//! 50..500 points, clean and with 10 % blunders of 10..50 px) and prints the bars.
use phototraverse_core::adjust::{AdjustConfig, Observation, Robust, Window};
use phototraverse_core::budget::{Arena, MemoryBudget};
use phototraverse_core::camera::{Pose, RelativeOrientation};
use phototraverse_core::testkit::{
    drive, Drive as Scene, DriveObservation, Rng, FOCAL_MM as FOCAL, SIGMA_MM,
};
use std::fmt::Write as _;
use std::time::Instant;

/// The test kit's drive; `span` = epochs a point is seen in (0: as long as it is
/// visible).
fn scene(seed: u64, epochs: usize, n_points: usize, gross: f64, span: usize) -> Scene {
    drive(seed, epochs, n_points, gross, span)
}

/// Perturbed start values (the same for Rust and scipy).
fn start(s: &Scene, seed: u64) -> (Vec<[f64; 6]>, Vec<[f64; 3]>) {
    let mut rng = Rng(seed);
    let poses = s
        .poses
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let start = if k > 0 {
                rng.perturbed(p, 0.01, 0.1)
            } else {
                *p
            };
            start.to_params()
        })
        .collect();
    let points = s
        .points
        .iter()
        .map(|p| {
            [
                p[0] + rng.uniform(-0.2, 0.2),
                p[1] + rng.uniform(-0.2, 0.2),
                p[2] + rng.uniform(-0.2, 0.2),
            ]
        })
        .collect();
    (poses, points)
}

fn load<'a>(
    s: &Scene,
    st: &(Vec<[f64; 6]>, Vec<[f64; 3]>),
    cfg: AdjustConfig,
    arena: &mut Arena<'a>,
) -> (Window<'a>, Vec<u32>) {
    let mut w = Window::new(cfg, &s.rig, arena).expect("window");
    for (k, q) in st.0.iter().enumerate() {
        w.add_epoch(&Pose::from_params(q), 0.2 * k as f64)
            .expect("epoch");
    }
    let ids: Vec<u32> =
        st.1.iter()
            .map(|p| w.add_point(*p).expect("point"))
            .collect();
    let wt = 1.0 / (SIGMA_MM * SIGMA_MM);
    for DriveObservation {
        epoch: e,
        camera: cam,
        point: p,
        xy,
        ..
    } in &s.observations
    {
        w.add_observation(Observation::new(*e as u32, *cam, ids[*p], *xy, [wt, wt]))
            .expect("obs");
    }
    (w, ids)
}

fn budget(cfg: &AdjustConfig) -> usize {
    let mut b = MemoryBudget::new();
    cfg.budget(&mut b);
    b.total()
}

fn json_array(v: &[f64]) -> String {
    let mut s = String::from("[");
    for (i, x) in v.iter().enumerate() {
        if i > 0 {
            s.push(',');
        }
        write!(s, "{x:.17e}").unwrap();
    }
    s.push(']');
    s
}

fn window_update(out: &std::path::Path) {
    let s = scene(2024, 8, 300, 0.0, 2);
    let st = start(&s, 77);
    let cfg = AdjustConfig {
        window: 8,
        max_points: 300,
        max_observations: s.observations.len(),
        robust: Robust::None,
        ..AdjustConfig::default()
    };
    let total = budget(&cfg);
    let mut mem = vec![0u8; total];
    // Warm-up and timing: each run loads the window afresh and solves.
    let reps = 30;
    let mut times = Vec::new();
    let mut last = None;
    let mut used = 0;
    for _ in 0..reps {
        let mut arena = Arena::new(&mut mem);
        let (mut w, ids) = load(&s, &st, cfg, &mut arena);
        used = arena.used();
        let t0 = Instant::now();
        let r = w.solve().expect("solve");
        times.push(t0.elapsed().as_secs_f64());
        let epochs: Vec<f64> = (0..8)
            .flat_map(|e| w.epoch_pose(e).unwrap().to_params())
            .collect();
        let points: Vec<f64> = ids.iter().flat_map(|p| w.point(*p).unwrap()).collect();
        last = Some((r, epochs, points));
    }
    times.sort_by(|a, b| a.total_cmp(b));
    let median = times[reps / 2];
    let (r, epochs, points) = last.unwrap();

    // The problem, in the window's terms (object coordinates; the datum prior on epoch 0).
    let sig = cfg.sigmas;
    let rp = RelativeOrientation::from_rig(&s.rig);
    let mut pj = String::new();
    write!(
        pj,
        "{{\"focal_mm\":[{FOCAL},{FOCAL}],\"rig_angles\":{},\"rig_base\":{},\"datum_sigma\":[{},{}],",
        json_array(&rp.angles),
        json_array(&rp.base),
        sig.datum_angle_rad,
        sig.datum_position_m
    )
    .unwrap();
    let e0: Vec<f64> = st.0.iter().flatten().copied().collect();
    let p0: Vec<f64> = st.1.iter().flatten().copied().collect();
    write!(
        pj,
        "\"epochs\":{},\"points\":{},",
        json_array(&e0),
        json_array(&p0)
    )
    .unwrap();
    let wt = 1.0 / (SIGMA_MM * SIGMA_MM);
    let ob: Vec<f64> = s
        .observations
        .iter()
        .flat_map(|o| {
            let [x, y] = o.xy;
            [
                o.epoch as f64,
                o.camera.index() as f64,
                o.point as f64,
                x,
                y,
                wt,
                wt,
            ]
        })
        .collect();
    write!(pj, "\"observations\":{}}}", json_array(&ob)).unwrap();
    std::fs::write(out.join("problem.json"), pj).expect("write problem");

    let mut sj = String::new();
    write!(
        sj,
        "{{\"epochs\":{},\"points\":{},\"seconds_median\":{median:.9},\"seconds_min\":{:.9},\"reps\":{reps},\
         \"iterations\":{},\"sigma0\":{},\"cost\":{},\"redundancy\":{},\"budget_bytes\":{total},\"arena_used_bytes\":{used}}}",
        json_array(&epochs),
        json_array(&points),
        times[0],
        r.iterations,
        r.sigma0,
        r.cost,
        r.redundancy
    )
    .unwrap();
    std::fs::write(out.join("solution.json"), sj).expect("write solution");
    println!(
        "window update (8 epochs, 300 points, {} observations): median {:.3} ms over {reps} runs, {} iterations, sigma0 {:.4}; memory {} B predicted, {} B used",
        s.observations.len(),
        median * 1e3,
        r.iterations,
        r.sigma0,
        total,
        used
    );
    println!("wrote {}/problem.json and solution.json", out.display());
}

/// Fraction of parameters within 3 sigma, sigma0, chi-square, flag counts.
fn sweep() {
    println!(
        "epochs points gross  within3s   sigma0  chi2  blunders caught  good falsely_flagged  ms"
    );
    let (mut tot_ok, mut tot_n, mut tot_b, mut tot_c, mut tot_g, mut tot_f) = (0, 0, 0, 0, 0, 0);
    let mut seed = 1000;
    for &(epochs, points) in &[
        (2usize, 50usize),
        (2, 200),
        (4, 100),
        (5, 300),
        (8, 300),
        (10, 400),
        (15, 500),
        (20, 500),
    ] {
        for &gross in &[0.0, 0.10] {
            for _ in 0..3 {
                seed += 1;
                let s = scene(seed, epochs, points, gross, 0);
                let st = start(&s, seed + 7);
                let cfg = AdjustConfig {
                    window: epochs,
                    max_points: points,
                    max_observations: s.observations.len(),
                    ..AdjustConfig::default()
                };
                let mut mem = vec![0u8; budget(&cfg)];
                let mut arena = Arena::new(&mut mem);
                let (mut w, ids) = load(&s, &st, cfg, &mut arena);
                let t0 = Instant::now();
                let r = match w.solve() {
                    Ok(r) => r,
                    Err(e) => {
                        println!("{epochs:6} {points:6} {gross:5.2} solve failed: {e}");
                        continue;
                    }
                };
                let ms = t0.elapsed().as_secs_f64() * 1e3;
                let (mut ok, mut n) = (0, 0);
                for (e, truth) in s.poses.iter().enumerate() {
                    let est = w.epoch_pose(e).unwrap().to_params();
                    let sd = w.epoch_std(e).unwrap();
                    let t = truth.to_params();
                    for i in 0..6 {
                        n += 1;
                        ok += ((est[i] - t[i]).abs() <= 3.0 * sd[i] + 1e-9) as usize;
                    }
                }
                for (p, truth) in s.points.iter().enumerate() {
                    let (Some(est), Some(sd)) = (w.point(ids[p]), w.point_std(ids[p])) else {
                        continue;
                    };
                    for a in 0..3 {
                        n += 1;
                        ok += ((est[a] - truth[a]).abs() <= 3.0 * sd[a]) as usize;
                    }
                }
                let (mut b, mut c, mut g, mut f) = (0, 0, 0, 0);
                for (i, o) in w.observations().iter().enumerate() {
                    if s.observations[i].blunder {
                        b += 1;
                        c += o.is_flagged() as usize;
                    } else {
                        g += 1;
                        f += o.is_flagged() as usize;
                    }
                }
                println!(
                    "{epochs:6} {points:6} {gross:5.2} {:8.4} {:8.4} {:5} {b:8} {c:6} {g:6} {f:6} {ms:8.1}",
                    ok as f64 / n as f64,
                    r.sigma0,
                    if r.chi2.passed { "pass" } else { "FAIL" }
                );
                tot_ok += ok;
                tot_n += n;
                tot_b += b;
                tot_c += c;
                tot_g += g;
                tot_f += f;
            }
        }
    }
    println!(
        "TOTAL within 3 sigma {:.4} ({tot_ok}/{tot_n}); blunders flagged {:.4} ({tot_c}/{tot_b}); good flagged {:.4} ({tot_f}/{tot_g})",
        tot_ok as f64 / tot_n as f64,
        tot_c as f64 / tot_b.max(1) as f64,
        tot_f as f64 / tot_g as f64
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.iter().any(|a| a == "--sweep") {
        sweep();
        return;
    }
    let out = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../bench/adjust/out");
    std::fs::create_dir_all(&out).expect("create bench/adjust/out");
    window_update(&out);
}
