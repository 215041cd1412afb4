//! `phototraverse run DATASET --out DIR`: orient every image of a stereo sequence.
use crate::dataset::Dataset;
use crate::link::LinkOptions;
use crate::pipeline::PipelineSettings;
use crate::runner::{run_dataset, RunOptions, RunOutcome};
use anyhow::{Context, Result};
use std::path::PathBuf;

/// Orient a stereo sequence through the firmware and write poses.txt (KITTI), eop.csv,
/// report.json and report.html into the output directory. The dataset is a KITTI
/// odometry sequence (image_0/, image_1/, calib.txt) or a rig.toml layout (left/,
/// right/, rig.toml); a gt_poses.txt beside it is used for evaluation.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Dataset directory.
    pub dataset: PathBuf,
    /// Output directory (created).
    #[arg(long, default_value = "out/run")]
    pub out: PathBuf,
    /// Pipeline settings (TOML; see docs/configuration.md).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Process only the first N epochs.
    #[arg(long)]
    pub max_epochs: Option<usize>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    #[command(flatten)]
    pub link: LinkOptions,
}

pub fn run(args: Args) -> Result<()> {
    let ds = Dataset::open(&args.dataset)
        .with_context(|| format!("cannot open the dataset {}", args.dataset.display()))?;
    let opts = RunOptions {
        link: args.link.clone(),
        settings: PipelineSettings::load(args.config.as_deref())?,
        max_epochs: args.max_epochs,
        progress: !args.quiet,
    };
    let outcome = run_dataset(&ds, &args.out, &opts)?;
    print!("{}", summary(&outcome));
    println!("outputs in {}", args.out.display());
    Ok(())
}

/// A few lines that say how the run went.
pub fn summary(o: &RunOutcome) -> String {
    let r = &o.report;
    let mut s = format!(
        "{} epochs, {} flagged, median {:.1} ms per epoch in the firmware\n",
        r.epochs.len(),
        r.flagged_epochs(),
        o.median_epoch_ms
    );
    if let Some(total) = r.memory.iter().find(|m| m.name.starts_with("total")) {
        s += &format!(
            "memory: {:.1} KiB predicted, {} measured\n",
            total.predicted_bytes as f64 / 1024.0,
            total
                .measured_bytes
                .map_or("-".to_string(), |m| format!("{:.1} KiB", m as f64 / 1024.0))
        );
    }
    if let Some(e) = &o.evaluation {
        s += &e.summary();
    }
    if !o.unreadable.is_empty() {
        s += &format!("unreadable epochs (pose predicted): {:?}\n", o.unreadable);
    }
    s
}
