//! `phototraverse budget`: the firmware's memory for a configuration and image size.
use crate::mcu::{read_elf, section_bytes, Part, Section, StorageSizes, TargetImage, TargetReport};
use crate::pipeline::PipelineSettings;
use crate::report::{CapacityLine, MemoryLine, RunReport};
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
    /// Link the firmware image for this microcontroller (mps2-an500, stm32h743) with its
    /// storage sized from the configuration, and show the image's sections beside the
    /// prediction. The command exits with status 1 when the link fails: the
    /// configuration does not fit the part's memory map (the linker names the region
    /// and the overflow). Needs the Rust target thumbv7em-none-eabihf.
    #[arg(long)]
    pub part: Option<String>,
    /// A run's report.json: show what the run measured (each stage's memory carved by
    /// the firmware, the capacities' peaks and, for a run on the emulated
    /// microcontroller, its sections and stack) beside the prediction.
    #[arg(long)]
    pub measured: Option<PathBuf>,
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

/// A rig of the image size (the budget depends on nothing else of it).
fn rig_of_size(width: u32, height: u32) -> Rig {
    Rig::rectified(Interior::pinhole_px(width, height, width as f64), 0.5)
}

/// The budget of the firmware for `settings` at `width` x `height`.
pub fn budget_for(width: u32, height: u32, settings: &PipelineSettings) -> Result<MemoryBudget> {
    anyhow::ensure!(
        width >= 16 && height >= 16,
        "image size {width}x{height} is too small"
    );
    let configure = settings.configure(&rig_of_size(width, height));
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
    if !args.json {
        print_table(&r);
    }
    // Linked after the table is out: a configuration that does not fit still shows
    // where its bytes go.
    let image = args
        .part
        .as_deref()
        .map(|p| link_image(p, &args))
        .transpose()?;
    let measured = args.measured.as_deref().map(read_measured).transpose()?;
    if args.json {
        let all = serde_json::json!({
            "budget": r,
            "image": image,
            "measured": measured,
        });
        println!("{}", serde_json::to_string_pretty(&all)?);
    } else {
        if let Some(i) = &image {
            print_image(i);
        }
        if let Some(m) = &measured {
            print_measured(m);
        }
    }
    match (r.ram_bytes, r.fits_excluding_frames) {
        (Some(ram), Some(false)) => anyhow::bail!(
            "the configuration needs {} bytes besides the frames: it does not fit in {ram} bytes of RAM",
            r.working_excluding_frames
        ),
        _ => Ok(()),
    }
}

/// The image linked for a part, beside the prediction it was sized from.
#[derive(Debug, Serialize)]
struct ImageFit {
    part: String,
    image: String,
    predicted: StorageSizes,
    /// The link buffers, a static of the image (in the budget above).
    predicted_link_bytes: usize,
    sections: Vec<Section>,
    stack_reserved_bytes: u64,
}

/// Links the image for `part` at the configuration's sizes; a failed link is the error.
fn link_image(part: &str, args: &Args) -> Result<ImageFit> {
    let part = Part::named(part)?;
    let settings = PipelineSettings::load(args.config.as_deref())?;
    let configure = settings.configure(&rig_of_size(args.width, args.height));
    let image = TargetImage::build(part, &configure)?;
    let elf = read_elf(&image.path)?;
    Ok(ImageFit {
        part: part.name.into(),
        image: image.path.display().to_string(),
        predicted: image.sizes,
        predicted_link_bytes: LinkBuffers::BYTES,
        sections: elf.sections,
        stack_reserved_bytes: elf.stack_reserved_bytes,
    })
}

fn print_image(i: &ImageFit) {
    println!(
        "\nfirmware image for {} (linked: the configuration fits)",
        i.part
    );
    println!("  {:<14} {:>12} {:>12}", "section", "predicted", "linked");
    let linked = |n: &str| section_bytes(&i.sections, n);
    let rows: [(&str, Option<usize>, u64); 5] = [
        (".text", None, linked(".text") + linked(".vector_table")),
        (".rodata", None, linked(".rodata")),
        (
            ".data + .bss",
            Some(i.predicted_link_bytes),
            linked(".data") + linked(".bss"),
        ),
        (".arena", Some(i.predicted.arena_bytes), linked(".arena")),
        (
            ".frames",
            Some(2 * i.predicted.frame_bytes),
            linked(".frames"),
        ),
    ];
    for (name, predicted, bytes) in rows {
        let p = predicted.map_or("-".to_string(), |p| p.to_string());
        println!("  {name:<14} {p:>12} {bytes:>12}");
    }
    println!(
        "  {:<14} {:>12} {:>12}  (reserved; the high-water mark comes from a run: --link qemu)",
        "stack", "-", i.stack_reserved_bytes
    );
    println!("  image: {}", i.image);
}

/// What a run measured, from its report.json.
#[derive(Debug, Serialize)]
struct Measured {
    report: String,
    /// Each stage's total and the whole's: predicted by the run, carved by its firmware.
    memory: Vec<MemoryLine>,
    capacities: Vec<CapacityLine>,
    target: Option<TargetReport>,
}

fn read_measured(path: &std::path::Path) -> Result<Measured> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let r: RunReport = serde_json::from_str(&text)
        .with_context(|| format!("{} is not a run's report.json", path.display()))?;
    Ok(Measured {
        report: path.display().to_string(),
        memory: r
            .memory
            .into_iter()
            .filter(|l| l.measured_bytes.is_some())
            .collect(),
        capacities: r.capacities,
        target: r.target,
    })
}

fn print_measured(m: &Measured) {
    println!("\nmeasured by the run {}", m.report);
    if !m.memory.is_empty() {
        println!("  {:<22} {:>10} {:>10}", "memory", "predicted", "carved");
        for l in &m.memory {
            let carved = l.measured_bytes.map_or("-".into(), |b| b.to_string());
            println!("  {:<22} {:>10} {:>10}", l.name, l.predicted_bytes, carved);
        }
    }
    println!("  {:<22} {:>10} {:>10}", "capacity", "reserved", "peak");
    for c in &m.capacities {
        println!("  {:<22} {:>10} {:>10}", c.name, c.reserved, c.peak);
    }
    if let Some(t) = &m.target {
        print!("  {}", t.summary().replace('\n', "\n  ").trim_end());
        println!();
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
