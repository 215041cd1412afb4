//! `phototraverse budget`: the firmware's memory for a configuration and image size.
use crate::pipeline::PipelineSettings;
use anyhow::{Context, Result};
use phototraverse_core::budget::{ComponentKind, MemoryBudget};
use phototraverse_core::camera::{Interior, Rig};
use phototraverse_firmware_sim::{configuration_budget, LinkBuffers, TraverseFactory};
use serde::Serialize;
use std::path::PathBuf;

/// Print the memory budget of the firmware, component by component, as predicted from the
/// configuration before anything runs; with --ram, whether it fits that RAM. The working
/// memory excludes the two frame buffers (the figure to compare across image sizes).
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Image width, pixels.
    #[arg(long, default_value_t = 640)]
    pub width: u32,
    /// Image height, pixels.
    #[arg(long, default_value_t = 480)]
    pub height: u32,
    /// Pipeline settings (TOML).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// RAM available on the target, bytes (suffixes K, M accepted: 512K, 2M). The command
    /// exits with status 1 when the memory without the frame buffers does not fit (the
    /// frames may live in other memory: whether they fit too is printed).
    #[arg(long)]
    pub ram: Option<String>,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Serialize)]
struct Line {
    name: String,
    kind: String,
    bytes: usize,
}

#[derive(Debug, Serialize)]
pub struct BudgetReport {
    width: u32,
    height: u32,
    components: Vec<Line>,
    frame_bytes: usize,
    working_bytes: usize,
    storage_bytes: usize,
    link_bytes: usize,
    /// Everything but the two frame buffers: working, storage and link buffers.
    working_excluding_frames: usize,
    total_bytes: usize,
    ram_bytes: Option<usize>,
    /// Everything, frames included, fits `ram_bytes`.
    fits: Option<bool>,
    /// The working memory without the frame buffers fits `ram_bytes` (frames held elsewhere,
    /// e.g. in the camera interface's own memory).
    fits_excluding_frames: Option<bool>,
}

fn parse_bytes(s: &str) -> Result<usize> {
    let t = s.trim();
    let (num, mult) = match t.chars().last() {
        Some('K' | 'k') => (&t[..t.len() - 1], 1024),
        Some('M' | 'm') => (&t[..t.len() - 1], 1024 * 1024),
        _ => (t, 1),
    };
    let n: usize = num
        .trim()
        .parse()
        .with_context(|| format!("--ram: {s:?} is not a byte count"))?;
    Ok(n * mult)
}

/// The budget of the firmware for `settings` at `width` x `height`.
pub fn budget_for(width: u32, height: u32, settings: &PipelineSettings) -> Result<MemoryBudget> {
    anyhow::ensure!(
        width >= 16 && height >= 16,
        "image size {width}x{height} is too small"
    );
    let rig = Rig::rectified(Interior::pinhole_px(width, height, width as f64), 0.5);
    let configure = settings.configure(&rig);
    let mut budget = MemoryBudget::new();
    configuration_budget(&TraverseFactory, &configure, &mut budget)
        .map_err(|e| anyhow::anyhow!("configuration: {e:?}"))?;
    Ok(budget)
}

pub fn report(args: &Args) -> Result<BudgetReport> {
    let settings = PipelineSettings::load(args.config.as_deref())?;
    let b = budget_for(args.width, args.height, &settings)?;
    let ram = args.ram.as_deref().map(parse_bytes).transpose()?;
    let link = LinkBuffers::BYTES;
    let frames = b.total_of(ComponentKind::Frame);
    let total = b.total() + link;
    Ok(BudgetReport {
        width: args.width,
        height: args.height,
        components: b
            .components()
            .iter()
            .map(|c| Line {
                name: c.name.into(),
                kind: format!("{:?}", c.kind).to_lowercase(),
                bytes: c.bytes,
            })
            .collect(),
        frame_bytes: frames,
        working_bytes: b.total_of(ComponentKind::Working),
        storage_bytes: b.total_of(ComponentKind::Storage),
        link_bytes: link,
        working_excluding_frames: total - frames,
        total_bytes: total,
        ram_bytes: ram,
        fits: ram.map(|r| total <= r),
        fits_excluding_frames: ram.map(|r| total - frames <= r),
    })
}

pub fn run(args: Args) -> Result<()> {
    let r = report(&args)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print_table(&r);
    }
    match (r.ram_bytes, r.fits_excluding_frames) {
        (Some(ram), Some(false)) => anyhow::bail!(
            "the configuration needs {} bytes besides the frames: it does not fit in {ram} bytes of RAM",
            r.working_excluding_frames
        ),
        _ => Ok(()),
    }
}

fn print_table(r: &BudgetReport) {
    println!("memory budget at {}x{} (bytes)", r.width, r.height);
    for c in &r.components {
        println!("  {:<36} {:<8} {:>10}", c.name, c.kind, c.bytes);
    }
    println!(
        "  {:<36} {:<8} {:>10}",
        "firmware.link_buffers", "working", r.link_bytes
    );
    println!("frames (two buffers)          {:>10}", r.frame_bytes);
    println!(
        "working                       {:>10}",
        r.working_bytes + r.link_bytes
    );
    println!("storage                       {:>10}", r.storage_bytes);
    println!(
        "excluding frames              {:>10}  ({:.1} KiB)",
        r.working_excluding_frames,
        r.working_excluding_frames as f64 / 1024.0
    );
    println!(
        "total                         {:>10}  ({:.1} KiB)",
        r.total_bytes,
        r.total_bytes as f64 / 1024.0
    );
    if let Some(ram) = r.ram_bytes {
        let verdict = |fits: bool| if fits { "fits" } else { "does NOT fit" };
        println!(
            "excluding frames: {} in {ram} bytes of RAM ({:+} bytes spare)",
            verdict(r.working_excluding_frames <= ram),
            ram as i64 - r.working_excluding_frames as i64
        );
        println!(
            "with the frames:  {} in {ram} bytes of RAM ({:+} bytes spare)",
            verdict(r.total_bytes <= ram),
            ram as i64 - r.total_bytes as i64
        );
    }
}
