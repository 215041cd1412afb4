//! Matching cost of one epoch: four images of 1000 keypoints each at 640 x 480 (the
//! synthetic street of `matching::synthetic`), stereo + two guided temporal passes +
//! quads + spreading + tracks, on one core (thread CPU time). Prints median / p90 / max per epoch, the
//! fallback (unguided) cost, and the memory predicted vs used.
//!
//! `cargo bench -p phototraverse-core --bench match_epoch`; set `MATCH_BENCH_DUMP=DIR` to
//! write one epoch's descriptors for the OpenCV peer (`bench/match/peer_bfmatcher.py`).
use phototraverse_core::budget::Arena;
use phototraverse_core::camera::{Interior, Pose, Rig};
use phototraverse_core::features::{Descriptor, Keypoint};
use phototraverse_core::matching::synthetic::SyntheticScene;
use phototraverse_core::matching::{
    relative_motion, Features, MatchConfig, Matcher, StereoFeatures,
};
/// CPU time of this thread, ms: the machine is shared, so wall-clock time would count
/// the time other processes held the core.
fn cpu_ms() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes the timespec we pass and nothing else.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 * 1e3 + ts.tv_nsec as f64 * 1e-6
}

struct Instant(f64);
impl Instant {
    fn now() -> Self {
        Instant(cpu_ms())
    }
    fn elapsed_ms(&self) -> f64 {
        cpu_ms() - self.0
    }
}

struct Img {
    kps: Vec<Keypoint>,
    desc: Vec<Descriptor>,
}

fn render(scene: &SyntheticScene, pose: &Pose, cam: &Interior, tag: u64) -> Img {
    let mut kps = vec![Keypoint::default(); 1000];
    let mut desc = vec![[0u8; 128]; 1000];
    let mut ids = vec![0u32; 1000];
    let n = scene.render(pose, cam, tag, &mut kps, &mut desc, &mut ids);
    kps.truncate(n);
    desc.truncate(n);
    Img { kps, desc }
}

fn pose_at(y: f64) -> Pose {
    Pose::from_degrees(90.0, 0.0, 0.0, [0.0, y, 0.0])
}

fn stats(mut v: Vec<f64>) -> (f64, f64, f64) {
    v.sort_by(|a, b| a.total_cmp(b));
    (v[v.len() / 2], v[v.len() * 9 / 10], v[v.len() - 1])
}

fn main() {
    let rig = Rig::rectified(Interior::pinhole_px(640, 480, 500.0), 0.5);
    let scene = SyntheticScene {
        points: 9000,
        far: 90.0,
        ..SyntheticScene::street(42)
    };
    let epochs = 40;
    let step = 0.3;
    let frames: Vec<(Img, Img)> = (0..epochs)
        .map(|k| {
            let p = pose_at(k as f64 * step);
            (
                render(&scene, &p, &rig.left, 2 * k as u64),
                render(&scene, &rig.right_pose(&p), &rig.right, 2 * k as u64 + 1),
            )
        })
        .collect();
    let min_kp = frames
        .iter()
        .map(|(l, r)| l.kps.len().min(r.kps.len()))
        .min()
        .unwrap();
    println!("{epochs} epochs, at least {min_kp} keypoints per image, 640x480");
    let cfg = MatchConfig::rectified(640, 480, 1000, 80.0);
    let motion = relative_motion(&pose_at(0.0), &pose_at(step * 0.9));
    for guided in [true, false] {
        let mut store = vec![0u8; cfg.predicted_bytes()];
        let mut arena = Arena::new(&mut store);
        let mut m = Matcher::new(cfg, &mut arena).unwrap();
        let feats = |k: usize| StereoFeatures {
            left: Features::new(&frames[k].0.kps, &frames[k].0.desc),
            right: Features::new(&frames[k].1.kps, &frames[k].1.desc),
        };
        // Thread CPU time; each epoch's cost is the fastest of several rounds over the
        // same sequence (the median of all rounds is printed too).
        let rounds = 6;
        let mut best = vec![f64::MAX; epochs];
        let mut raw = Vec::new();
        let mut ties = 0u64;
        for round in 0..rounds {
            m.process_epoch(feats(0), None, None, None).unwrap();
            for (k, slot) in best.iter_mut().enumerate().skip(1) {
                let mo = guided.then_some((&rig, &motion));
                let t0 = Instant::now();
                let r = m
                    .process_epoch(feats(k), Some(feats(k - 1)), None, mo)
                    .unwrap();
                let dt = t0.elapsed_ms();
                if round == 0 && std::env::var("MATCH_BENCH_VERBOSE").is_ok() {
                    println!(
                        "epoch {k}: {dt:.3} ms {:?} {:?} {:?}",
                        r.left_mode, r.status, r.quads
                    );
                }
                *slot = slot.min(dt);
                raw.push(dt);
                if round == 0 {
                    ties += r.tie_points as u64;
                }
            }
        }
        let times: Vec<f64> = best[1..].to_vec();
        let (raw_med, _, _) = stats(raw);
        let n = times.len();
        let (med, p90, max) = stats(times);
        println!(
            "{}: per epoch (best of {rounds} rounds) median {med:.3} ms, p90 {p90:.3} ms, max {max:.3} ms (median of all rounds {raw_med:.3} ms); {:.0} tie points/epoch; mean track length {:.2}; memory predicted {} B, used {} B",
            if guided { "guided  " } else { "fallback" },
            ties as f64 / n as f64,
            m.tracks().mean_length(),
            cfg.predicted_bytes(),
            arena.used()
        );
    }
    {
        // Stereo alone, for the breakdown.
        let mut store = vec![0u8; cfg.predicted_bytes()];
        let mut arena = Arena::new(&mut store);
        let mut m = Matcher::new(cfg, &mut arena).unwrap();
        let mut best = vec![f64::MAX; epochs];
        for _ in 0..6 {
            for (k, b) in best.iter_mut().enumerate() {
                let f = StereoFeatures {
                    left: Features::new(&frames[k].0.kps, &frames[k].0.desc),
                    right: Features::new(&frames[k].1.kps, &frames[k].1.desc),
                };
                let t0 = Instant::now();
                m.match_stereo(f, None);
                *b = b.min(t0.elapsed_ms());
            }
        }
        let (med, _, _) = stats(best);
        println!("stereo pass alone: median {med:.3} ms");
    }
    if let Ok(dir) = std::env::var("MATCH_BENCH_DUMP") {
        let dump = |name: &str, img: &Img| {
            let bytes: Vec<u8> = img.desc.iter().flatten().copied().collect();
            std::fs::write(format!("{dir}/{name}.u8"), bytes).unwrap();
        };
        dump("left0", &frames[0].0);
        dump("right0", &frames[0].1);
        dump("left1", &frames[1].0);
        dump("right1", &frames[1].1);
        println!("descriptors written to {dir}");
    }
}
