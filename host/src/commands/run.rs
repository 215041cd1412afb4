//! `phototraverse run DATASET --out DIR`: orient every image of a stereo sequence.
use crate::dataset::{aiding, Dataset, OpenOptions};
use crate::link::LinkOptions;
use crate::pipeline::{Mode, PipelineSettings};
use crate::runner::{run_dataset, RunOptions, RunOutcome};
use anyhow::{Context, Result};
use std::path::PathBuf;

/// Orient a stereo sequence through the firmware and write poses.txt (KITTI), eop.csv,
/// report.json and report.html into the output directory. The dataset is a KITTI
/// odometry sequence (image_0/, image_1/, calib.txt) or a rig.toml layout (left/,
/// right/, rig.toml); a gt_poses.txt beside it is used for evaluation. Ctrl-C (or
/// SIGTERM) stops the run after the epoch in hand and writes every output for the
/// epochs done (exit status 130); a second Ctrl-C quits at once.
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
    /// GNSS fixes (`time_s X_m Y_m Z_m sigma_m` per line; default: the dataset's gnss.txt).
    #[arg(long, value_name = "FILE", conflicts_with = "gnss_geodetic")]
    pub gnss: Option<PathBuf>,
    /// Geodetic GNSS fixes (`time_s latitude_deg longitude_deg height_m sigma_m`, WGS84),
    /// placed with the dataset's [gnss] table (default: the dataset's gnss_geodetic.txt).
    #[arg(long, value_name = "FILE")]
    pub gnss_geodetic: Option<PathBuf>,
    /// Odometer distances (`time_s distance_m sigma_m` per line; default: the dataset's
    /// odometer.txt).
    #[arg(long, value_name = "FILE")]
    pub odometer: Option<PathBuf>,
    /// Withhold the GNSS fixes of a time span, seconds (repeatable): an outage simulated
    /// on a dataset with GNSS throughout.
    #[arg(long, value_name = "START_S..END_S", value_parser = aiding::parse_span)]
    pub gnss_outage: Vec<(f64, f64)>,
    /// Orient from the images alone: ignore GNSS and odometer.
    #[arg(long, conflicts_with_all = ["gnss", "gnss_geodetic", "odometer", "gnss_outage"])]
    pub images_only: bool,
    /// KITTI: the camera pair, `0,1` (grey) or `2,3` (colour, converted to grey).
    /// Default: the grey pair when image_0/ and image_1/ are there, else the colour pair.
    #[arg(long, value_name = "LEFT,RIGHT", value_parser = parse_cameras)]
    pub cameras: Option<(usize, usize)>,
    /// Ground-truth poses (KITTI format, one line per epoch) for the evaluation, instead
    /// of the dataset's gt_poses.txt or, in a KITTI tree, poses/NN.txt beside sequences/NN.
    #[arg(long, value_name = "FILE")]
    pub gt: Option<PathBuf>,
    #[command(flatten)]
    pub link: LinkOptions,
}

/// `0,1` or `2,3`: KITTI's grey and colour pairs.
fn parse_cameras(s: &str) -> Result<(usize, usize), String> {
    match s.replace(' ', "").as_str() {
        "0,1" => Ok((0, 1)),
        "2,3" => Ok((2, 3)),
        other => Err(format!(
            "`{other}`: KITTI's pairs are 0,1 (grey) and 2,3 (colour)"
        )),
    }
}

/// Replaces, withholds or drops the dataset's aiding observations as the options say,
/// and tells what the run will use.
fn apply_aiding(ds: &mut Dataset, args: &Args) -> Result<()> {
    if args.images_only {
        ds.gnss.clear();
        ds.odometer.clear();
        return Ok(());
    }
    if let Some(p) = &args.gnss {
        ds.gnss = aiding::read_gnss(p)?;
    }
    if let Some(p) = &args.gnss_geodetic {
        ds.gnss = aiding::read_gnss_geodetic(p, &ds.gnss_setup)?;
    }
    if let Some(p) = &args.odometer {
        ds.odometer = aiding::read_odometer(p)?;
    }
    let all = ds.gnss.len();
    ds.gnss = aiding::withhold(&ds.gnss, &args.gnss_outage);
    ds.gnss_outages = args.gnss_outage.clone();
    let (t0, t1) = (ds.time_of(0), ds.time_of(ds.len().saturating_sub(1)));
    let outside = ds
        .gnss
        .iter()
        .filter(|f| {
            f.time < t0 - aiding::GNSS_SAME_TIME_S || f.time > t1 + aiding::GNSS_SAME_TIME_S
        })
        .count();
    if all > 0 {
        eprintln!(
            "GNSS: {} fixes, {} withheld by --gnss-outage, {outside} outside the sequence's \
             {t0}..{t1} s (ignored)",
            all,
            all - ds.gnss.len()
        );
    }
    if !ds.odometer.is_empty() {
        eprintln!("odometer: {} readings", ds.odometer.len());
    }
    Ok(())
}

pub fn run(args: Args) -> Result<()> {
    let open = OpenOptions {
        kitti_cameras: args.cameras,
        ground_truth: args.gt.clone(),
    };
    let mut ds = Dataset::open_with(&args.dataset, &open)
        .with_context(|| format!("cannot open the dataset {}", args.dataset.display()))?;
    apply_aiding(&mut ds, &args)?;
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
    crate::interrupt::install();
    let outcome = run_dataset(&ds, &args.out, &opts)?;
    print!("{}", summary(&outcome));
    println!("outputs in {}", args.out.display());
    let planned = opts.max_epochs.map_or(ds.len(), |m| m.min(ds.len()));
    crate::interrupt::exit_if_interrupted(&outcome, planned);
    Ok(())
}

/// A few lines that say how the run went.
pub fn summary(o: &RunOutcome) -> String {
    let r = &o.report;
    // On QEMU the firmware's clock runs on instructions, not on time.
    let clock = if r.target.is_some() {
        " (QEMU's virtual time)"
    } else {
        ""
    };
    let end_to_end = r
        .wall_ms_per_epoch
        .map_or(String::new(), |w| format!(", {w:.1} ms end to end"));
    let mut s = format!(
        "mode {}: {} epochs, {} flagged, median {:.1} ms per epoch in the firmware{clock}{end_to_end}\n",
        r.mode,
        r.epochs.len(),
        r.flagged_epochs(),
        o.median_epoch_ms
    );
    if let Some(q) = &r.quality {
        s += &format!(
            "sigma0 median {:.3} (max {:.3}); {}\n",
            q.sigma0_median,
            q.sigma0_max,
            q.test_reading()
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
    if let Some(m) = &r.smoothing {
        s += &format!(
            "GNSS: positions smoothed over {} fixes (the images' step estimated at {:.1} mm); \
             moved {:.3} m RMS, {:.3} m at most from the on-board ones\n",
            m.fixes,
            m.step_sd_m * 1e3,
            m.rms_shift_m,
            m.largest_shift_m
        );
    }
    if let Some(total) = r.memory.iter().find(|m| m.name.starts_with("total")) {
        s += &format!(
            "memory: {:.1} KiB predicted, {} carved from the firmware's arena\n",
            total.predicted_bytes as f64 / 1024.0,
            total
                .measured_bytes
                .map_or("-".to_string(), |m| format!("{:.1} KiB", m as f64 / 1024.0))
        );
    }
    if !r.capacities.is_empty() {
        let peaks: Vec<String> = r
            .capacities
            .iter()
            .map(|c| format!("{} {}/{}", c.name, c.peak, c.reserved))
            .collect();
        s += &format!("capacities, peak/reserved: {}\n", peaks.join(", "));
    }
    if let Some(t) = &r.target {
        s += &t.summary();
    }
    if let Some(e) = &o.evaluation {
        s += &e.summary();
    }
    if !o.unreadable.is_empty() {
        s += &format!("unreadable epochs (pose predicted): {:?}\n", o.unreadable);
    }
    s
}
