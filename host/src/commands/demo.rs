//! `phototraverse demo`: the whole product in one command. Synthesizes the
//! `straight` street with ground truth, streams it through the emulated rig link
//! to the firmware (a child process by default), which runs the core traverse,
//! then evaluates the orientations against the ground truth and writes the report.
use crate::commands::run::summary;
use crate::dataset::Dataset;
use crate::link::{LinkKind, LinkOptions};
use crate::pipeline::{Mode, PipelineSettings};
use crate::runner::{run_dataset, RunOptions};
use crate::synth::{generate, SynthOptions};
use anyhow::Context;
use std::io::IsTerminal;
use std::path::PathBuf;

/// Synthesize a street sequence, orient it through the firmware over the framing
/// protocol, evaluate against the ground truth and write the report.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Where to write the dataset (OUT/straight) and the results (OUT/run); default: the
    /// system temporary directory's `phototraverse-demo`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Number of epochs to synthesize (default 40; 8 on the emulated microcontroller,
    /// whose UART takes about 10 s per 320x240 epoch).
    #[arg(long)]
    pub frames: Option<usize>,
    /// Image size WxH (default: the scene's; 320x240 with `--link qemu`).
    #[arg(long, value_parser = crate::commands::synth::parse_size)]
    pub size: Option<(u32, u32)>,
    /// Pipeline settings (TOML; default: the defaults, or with `--link qemu` the
    /// embedded profile, configs/embedded-320x240.toml).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Scene to synthesize (straight, curves, seed2014, seed2006, hard).
    #[arg(long, default_value = "straight")]
    pub scene: String,
    /// Adjustment procedure.
    #[arg(long, value_enum, default_value = "window")]
    pub mode: Mode,
    /// Estimate the rig's relative orientation and base in the adjustment.
    #[arg(long)]
    pub estimate_rig: bool,
    #[command(flatten)]
    pub link: LinkOptions,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let out = a
        .out
        .unwrap_or_else(|| std::env::temp_dir().join("phototraverse-demo"));
    let dataset = out.join(&a.scene);
    // On the emulated microcontroller the defaults are the microcontroller's: the
    // embedded profile at its image size, and fewer epochs.
    let on_mcu = matches!(a.link.link, LinkKind::Qemu(_));
    let mut opts = SynthOptions::new(&a.scene, dataset.clone());
    opts.frames = Some(a.frames.unwrap_or(if on_mcu { 8 } else { 40 }).max(3));
    opts.size = a.size.or(on_mcu.then_some((320, 240)));
    let mut settings = match &a.config {
        Some(path) => PipelineSettings::from_file(path)?,
        None if on_mcu => PipelineSettings::embedded(),
        None => PipelineSettings::default(),
    };
    settings.mode = a.mode;
    settings.estimate_rig |= a.estimate_rig;
    opts.progress = std::io::stderr().is_terminal();
    let s = generate(&opts)?;
    println!(
        "synthesized `{}`: {} epochs {}x{} into {} ({:.0} ms per image)",
        a.scene,
        s.frames,
        s.width,
        s.height,
        dataset.display(),
        s.render_ms_mean
    );
    let ds = Dataset::open(&dataset).context("opening the synthesized dataset")?;
    let results = out.join("run");
    let run = RunOptions {
        link: a.link,
        settings,
        max_epochs: None,
        progress: std::io::stderr().is_terminal(),
    };
    println!(
        "orienting it through the firmware over the {:?} link ...",
        run.link.link
    );
    crate::interrupt::install();
    let outcome = run_dataset(&ds, &results, &run)?;
    print!("{}", summary(&outcome));
    println!(
        "wrote poses.txt, eop.csv, points.ply, efoto/, colmap/, report.json and report.html in {}",
        results.display()
    );
    crate::interrupt::exit_if_interrupted(&outcome, ds.len());
    Ok(())
}
