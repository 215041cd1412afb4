//! `phototraverse demo [--out DIR]`: interim end-to-end demonstration.
//!
//! The traverse is not wired yet: the demo synthesizes the `straight` scene,
//! builds a constant-velocity dead-reckoning estimate (the first ground-truth
//! step, as an odometer would give at the start, repeated) and evaluates it
//! against the ground truth. The numbers are a baseline any real traverse must
//! beat.
use crate::eval::evaluate;
use crate::poses::{read_poses, write_poses, KittiPose};
use crate::synth::{generate, SynthOptions};
use anyhow::Context;
use nalgebra::Matrix4;
use std::io::IsTerminal;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Where to write the synthetic dataset and the baseline (default: the
    /// system temporary directory's `phototraverse-demo`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Number of epochs to synthesize.
    #[arg(long, default_value_t = 30)]
    pub frames: usize,
}

fn to_m(p: &KittiPose) -> Matrix4<f64> {
    Matrix4::from_fn(|i, j| {
        if i < 3 {
            p[i][j]
        } else if j == 3 {
            1.0
        } else {
            0.0
        }
    })
}

fn from_m(m: &Matrix4<f64>) -> KittiPose {
    let mut p = [[0.0; 4]; 3];
    for (i, row) in p.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = m[(i, j)];
        }
    }
    p
}

/// Constant-velocity dead reckoning: the relative motion between the first two
/// poses, composed over and over.
pub fn constant_velocity(first: &KittiPose, second: &KittiPose, n: usize) -> Vec<KittiPose> {
    let a = to_m(first);
    let step = a.try_inverse().unwrap_or_else(Matrix4::identity) * to_m(second);
    let mut out = Vec::with_capacity(n);
    let mut cur = a;
    for _ in 0..n {
        out.push(from_m(&cur));
        cur *= step;
    }
    out
}

pub fn run(a: Args) -> anyhow::Result<()> {
    println!("phototraverse demo: the photogrammetric traverse is NOT wired yet.");
    println!("This synthesizes the `straight` street and evaluates a trivial constant-velocity");
    println!("dead-reckoning estimate against its ground truth: a baseline, not a result.\n");
    let out = a
        .out
        .unwrap_or_else(|| std::env::temp_dir().join("phototraverse-demo"));
    let dataset = out.join("straight");
    let mut opts = SynthOptions::new("straight", dataset.clone());
    opts.frames = Some(a.frames.max(2));
    opts.progress = std::io::stderr().is_terminal();
    let s = generate(&opts)?;
    println!(
        "synthesized {} epochs {}x{} into {} ({:.1} ms per image)",
        s.frames,
        s.width,
        s.height,
        dataset.display(),
        s.render_ms_mean
    );
    let gt = read_poses(&dataset.join("gt_poses.txt"))?;
    let est = constant_velocity(&gt[0], &gt[1], gt.len());
    let est_path = out.join("baseline_poses.txt");
    write_poses(&est_path, &est)?;
    let e = evaluate(&gt, &est)?;
    println!("\nbaseline (constant velocity from the first step) vs ground truth:");
    print!("{}", e.summary());
    let json = out.join("baseline_eval.json");
    std::fs::write(&json, serde_json::to_string_pretty(&e)? + "\n")
        .with_context(|| json.display().to_string())?;
    println!("\nwrote {} and {}", est_path.display(), json.display());
    Ok(())
}
