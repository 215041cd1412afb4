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
use phototraverse_core::adjust::geometry::project_rig;
use phototraverse_core::adjust::{AdjustConfig, Observation, Robust, Window};
use phototraverse_core::budget::{Arena, MemoryBudget};
use phototraverse_core::camera::{Camera, RelativeOrientation};
use phototraverse_core::camera::{DistortionModel, Interior, Pose, Rig};
use std::fmt::Write as _;
use std::time::Instant;

const PIXEL_MM: f64 = 0.005;
const SIGMA_MM: f64 = 0.3 * PIXEL_MM;
const FOCAL: f64 = 8.0;

struct Rng(u64);
impl Rng {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        lo + (hi - lo) * ((self.0 >> 11) as f64 / (1u64 << 53) as f64)
    }
    fn normal(&mut self) -> f64 {
        let u1 = self.uniform(1e-12, 1.0);
        let u2 = self.uniform(0.0, 1.0);
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

struct Scene {
    rig: Rig,
    poses: Vec<Pose>,
    points: Vec<[f64; 3]>,
    /// (epoch, camera, point, observed xy, blunder)
    obs: Vec<(usize, u8, usize, [f64; 2], bool)>,
}

fn rig() -> Rig {
    let cam = Interior {
        width_px: 1280,
        height_px: 960,
        pixel_size_mm: [PIXEL_MM, PIXEL_MM],
        focal_mm: FOCAL,
        principal_point_mm: [0.0, 0.0],
        radial: [0.0, 0.0, 0.0],
        decentering: [0.0, 0.0],
        distortion_model: DistortionModel::Correction,
    };
    let mut rig = Rig::rectified(cam, 0.5);
    rig.relative_angles = [0.002, -0.004, 0.001];
    rig.base_m = [0.5, 0.003, -0.002];
    rig
}

/// Random drive; `span` = epochs a point is seen in (0: as long as it is visible).
fn scene(seed: u64, epochs: usize, n_points: usize, gross: f64, span: usize) -> Scene {
    let mut rng = Rng(seed);
    let rig = rig();
    let rp = RelativeOrientation::from_rig(&rig);
    let mut poses = Vec::new();
    let (mut x, mut y) = (0.0, 0.0);
    for k in 0..epochs {
        if k > 0 {
            y += rng.uniform(0.8, 1.2);
            x += rng.uniform(-0.1, 0.1);
        }
        poses.push(Pose::from_degrees(
            90.0 + rng.uniform(-2.0, 2.0),
            rng.uniform(-2.0, 2.0),
            rng.uniform(-2.0, 2.0),
            [x, y, 1.5 + rng.uniform(-0.05, 0.05)],
        ));
    }
    let mut points = Vec::new();
    let mut obs = Vec::new();
    while points.len() < n_points {
        let p = [
            rng.uniform(-8.0, 8.0),
            rng.uniform(4.0, y + 25.0),
            rng.uniform(-1.0, 6.0),
        ];
        let first = if span > 0 {
            rng.below(epochs + 1 - span)
        } else {
            0
        };
        let last = if span > 0 { first + span } else { epochs };
        let mut seen = Vec::new();
        for (e, pose) in poses.iter().enumerate().take(last).skip(first) {
            for cam in [Camera::Left, Camera::Right] {
                if let Ok(pr) = project_rig(pose, &rp, cam, FOCAL, &p) {
                    if pr.xy[0].abs() < 3.19
                        && pr.xy[1].abs() < 2.39
                        && pose.to_camera(&p)[2] < -3.0
                    {
                        seen.push((e, cam as u8, pr.xy));
                    }
                }
            }
        }
        let mut eps: Vec<usize> = seen.iter().map(|s| s.0).collect();
        eps.dedup();
        let complete = if span > 0 {
            seen.len() == 2 * span
        } else {
            eps.len() >= 2 && seen.len() >= 4
        };
        if !complete {
            continue;
        }
        let id = points.len();
        points.push(p);
        for (e, c, xy) in seen {
            let mut m = [
                xy[0] + SIGMA_MM * rng.normal(),
                xy[1] + SIGMA_MM * rng.normal(),
            ];
            let blunder = rng.uniform(0.0, 1.0) < gross;
            if blunder {
                let mag = rng.uniform(10.0, 50.0) * PIXEL_MM;
                let ang = rng.uniform(0.0, 2.0 * std::f64::consts::PI);
                m[0] += mag * ang.cos();
                m[1] += mag * ang.sin();
            }
            obs.push((e, c, id, m, blunder));
        }
    }
    Scene {
        rig,
        poses,
        points,
        obs,
    }
}

impl Rng {
    fn below(&mut self, n: usize) -> usize {
        (self.uniform(0.0, n as f64) as usize).min(n - 1)
    }
}

/// Perturbed start values (the same for Rust and scipy).
fn start(s: &Scene, seed: u64) -> (Vec<[f64; 6]>, Vec<[f64; 3]>) {
    let mut rng = Rng(seed);
    let poses = s
        .poses
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let mut q = p.to_params();
            if k > 0 {
                for (i, qi) in q.iter_mut().enumerate() {
                    *qi += if i < 3 {
                        rng.uniform(-0.01, 0.01)
                    } else {
                        rng.uniform(-0.1, 0.1)
                    };
                }
            }
            q
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
    for (e, c, p, xy, _) in &s.obs {
        let cam = if *c == 0 { Camera::Left } else { Camera::Right };
        w.add_observation(Observation::new(*e as u32, cam, ids[*p], *xy, [wt, wt]))
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
        max_observations: s.obs.len(),
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
        .obs
        .iter()
        .flat_map(|(e, c, p, xy, _)| [*e as f64, *c as f64, *p as f64, xy[0], xy[1], wt, wt])
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
        s.obs.len(),
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
                    max_observations: s.obs.len(),
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
                    if s.obs[i].4 {
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
