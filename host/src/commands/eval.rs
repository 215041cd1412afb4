//! `phototraverse eval GT EST [--json OUT] [--common-prefix]`: KITTI-style drift, ATE
//! (unaligned, and aligned rigidly and by a similarity), the relative pose error and the
//! final-position error of an estimated trajectory (see [`crate::eval`]).
use crate::eval::evaluate;
use crate::poses::read_poses;
use anyhow::Context;
use std::path::PathBuf;

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
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&e)?;
        std::fs::write(path, text + "\n")
            .with_context(|| format!("{}: cannot write", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
