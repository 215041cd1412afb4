//! `phototraverse eval GT EST [--json OUT]`: KITTI-style drift, ATE RMSE and
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
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let gt = read_poses(&args.gt)?;
    let est = read_poses(&args.est)?;
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
