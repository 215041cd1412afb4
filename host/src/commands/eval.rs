//! `phototraverse eval GT EST [--json OUT] [--common-prefix]`: KITTI-style drift, ATE
//! (unaligned, and aligned rigidly and by a similarity), the relative pose error and the
//! final-position error of an estimated trajectory (see [`crate::eval`]).
use crate::eval::{evaluate, trajectory_distances, Evaluation};
use crate::poses::{read_poses, KittiPose};
use crate::report::html::{drift_per_length_charts, line_chart, Series};
use anyhow::Context;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Ground-truth poses (KITTI format).
    pub gt: PathBuf,
    /// Estimated poses (KITTI format), one per ground-truth pose.
    pub est: PathBuf,
    /// Also write the evaluation as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Evaluate the poses both files have (the first min(n_gt, n_est)), for an estimate
    /// of part of a sequence (a run stopped early, `--max-epochs`).
    #[arg(long)]
    pub common_prefix: bool,
    /// Write SVG plots into this directory: the trajectories from above, the position
    /// error along the path, and the KITTI drift against segment length.
    #[arg(long, value_name = "DIR")]
    pub plots: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut gt = read_poses(&args.gt)?;
    let mut est = read_poses(&args.est)?;
    if args.common_prefix && gt.len() != est.len() {
        let n = gt.len().min(est.len());
        println!(
            "evaluating the first {n} poses ({} in {}, {} in {})",
            gt.len(),
            args.gt.display(),
            est.len(),
            args.est.display()
        );
        gt.truncate(n);
        est.truncate(n);
    }
    let e = evaluate(&gt, &est)
        .with_context(|| format!("{} vs {}", args.gt.display(), args.est.display()))?;
    print!("{}", e.summary());
    if let Some(dir) = &args.plots {
        write_plots(dir, &gt, &est, &e)?;
        println!(
            "wrote trajectory.svg, error.svg, drift_translation.svg, drift_rotation.svg in {}",
            dir.display()
        );
    }
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&e)?;
        std::fs::write(path, text + "\n")
            .with_context(|| format!("{}: cannot write", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// The plots of `eval --plots`.
fn write_plots(
    dir: &Path,
    gt: &[KittiPose],
    est: &[KittiPose],
    e: &Evaluation,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let write = |name: &str, svg: String| {
        let path = dir.join(name);
        std::fs::write(&path, svg).with_context(|| format!("cannot write {}", path.display()))
    };
    // KITTI's camera frame: x right, z forward; from above.
    let top = |p: &[KittiPose]| p.iter().map(|q| (q[0][3], q[2][3])).collect();
    let trajectories = [
        Series {
            name: "ground truth".into(),
            points: top(gt),
        },
        Series {
            name: "estimate".into(),
            points: top(est),
        },
    ];
    write(
        "trajectory.svg",
        line_chart(
            "Trajectories from above",
            "x (m)",
            "z (m)",
            &trajectories,
            true,
        )?,
    )?;
    let distance = trajectory_distances(gt);
    let error = [Series {
        name: "position error (no alignment)".into(),
        points: gt
            .iter()
            .zip(est)
            .zip(&distance)
            .map(|((g, q), d)| {
                let err: f64 = (0..3)
                    .map(|k| (g[k][3] - q[k][3]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                (*d, err)
            })
            .collect(),
    }];
    write(
        "error.svg",
        line_chart(
            "Position error along the path",
            "distance (m)",
            "error (m)",
            &error,
            false,
        )?,
    )?;
    let per_length: Vec<serde_json::Value> = e
        .per_length
        .iter()
        .map(serde_json::to_value)
        .collect::<Result<_, _>>()?;
    let [translation, rotation] = drift_per_length_charts(&per_length)?;
    write("drift_translation.svg", translation)?;
    write("drift_rotation.svg", rotation)
}
