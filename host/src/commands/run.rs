//! `phototraverse run DATASET --out DIR`: orient every image of a stereo sequence.
use crate::dataset::Dataset;
use crate::link::LinkOptions;
use crate::pipeline::{Mode, PipelineSettings};
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
    /// Adjustment procedure (overrides the settings file's `mode`).
    #[arg(long, value_enum)]
    pub mode: Option<Mode>,
    /// Estimate the rig's relative orientation and base in the adjustment.
    #[arg(long)]
    pub estimate_rig: bool,
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
    let mut settings = PipelineSettings::load(args.config.as_deref())?;
    if let Some(m) = args.mode {
        settings.mode = m;
    }
    settings.estimate_rig |= args.estimate_rig;
    let opts = RunOptions {
        link: args.link.clone(),
        settings,
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
        "mode {}: {} epochs, {} flagged, median {:.1} ms per epoch in the firmware\n",
        r.mode,
        r.epochs.len(),
        r.flagged_epochs(),
        o.median_epoch_ms
    );
    if let Some(q) = &r.quality {
        s += &format!(
            "sigma0 median {:.3} (max {:.3}); chi-square over {} adjusted epochs: {} passed, \
             {} failed (above), {} below the lower bound\n",
            q.sigma0_median, q.sigma0_max, q.adjusted, q.chi2_passed, q.chi2_failed, q.chi2_below
        );
    }
    if let Some(g) = &r.rig {
        let a = g.relative_angles_deg;
        let b = g.base_m;
        s += &format!(
            "rig as adjusted (estimated, or corrected by the calibration check): angles \
             [{:.4}, {:.4}, {:.4}] deg (+- [{:.4}, {:.4}, {:.4}]), \
             base [{:.5}, {:.5}, {:.5}] m (+- [{:.5}, {:.5}, {:.5}])\n",
            a[0],
            a[1],
            a[2],
            g.std[0],
            g.std[1],
            g.std[2],
            b[0],
            b[1],
            b[2],
            g.std[3],
            g.std[4],
            g.std[5]
        );
    }
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
