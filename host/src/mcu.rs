//! The firmware as a microcontroller image: the `firmware-mcu` crate built for a part's
//! memory map, its storage sized from a configuration at build time (so a
//! configuration that does not fit fails to link), and what the image and a run on the
//! emulated part measure: the ELF's sections, the stack, the instructions per stage.
use crate::runner::median;
use anyhow::{bail, Context, Result};
use phototraverse_core::budget::{ComponentKind, MemoryBudget};
use phototraverse_core::protocol::messages::{stage, Configure};
use phototraverse_firmware_sim::{configuration_budget, TraverseFactory};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The Rust target of every part.
pub const RUST_TARGET: &str = "thumbv7em-none-eabihf";
/// The image's binary name.
const IMAGE_BIN: &str = "phototraverse-firmware-mcu";

/// A microcontroller the firmware can be linked for; its memory map is
/// `firmware-mcu/parts/<name>.x`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Part {
    pub name: &'static str,
    pub description: &'static str,
    /// The QEMU machine that runs the image, when one does.
    pub qemu_machine: Option<&'static str>,
}

/// The parts, the emulated board first (the default).
pub const PARTS: [Part; 2] = [
    Part {
        name: "mps2-an500",
        description: "Arm MPS2 board with the AN500 image: Cortex-M7 with a double-precision FPU, \
                      4 MiB code and 4 MiB data SSRAM, 16 MiB PSRAM (runs under QEMU)",
        qemu_machine: Some("mps2-an500"),
    },
    Part {
        name: "stm32h743",
        description: "STM32H743: Cortex-M7 with a double-precision FPU, 2 MiB flash, 1 MiB SRAM \
                      in blocks (128 KiB DTCM for the statics and stack, 512 KiB AXI SRAM for the \
                      arena, 288 KiB SRAM1-3 for the frames); linked to check the fit, not run",
        qemu_machine: None,
    },
];

impl Part {
    pub fn named(name: &str) -> Result<Part> {
        PARTS
            .iter()
            .copied()
            .find(|p| p.name == name)
            .with_context(|| {
                let names: Vec<_> = PARTS.iter().map(|p| p.name).collect();
                format!(
                    "unknown part {name:?}: expected one of {}",
                    names.join(", ")
                )
            })
    }

    /// The part a QEMU machine emulates.
    pub fn for_qemu_machine(machine: &str) -> Result<Part> {
        PARTS
            .iter()
            .copied()
            .find(|p| p.qemu_machine == Some(machine))
            .with_context(|| {
                let names: Vec<_> = PARTS.iter().filter_map(|p| p.qemu_machine).collect();
                format!(
                    "no firmware image for the QEMU machine {machine:?}: supported {}",
                    names.join(", ")
                )
            })
    }
}

/// What the image's statics reserve for a configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct StorageSizes {
    /// Everything the configuration carves but the frames: the firmware's arena.
    pub arena_bytes: usize,
    /// One frame buffer (the image holds two).
    pub frame_bytes: usize,
}

impl StorageSizes {
    /// The firmware's own prediction for `configure` (the budget it checks before carving).
    pub fn for_configuration(configure: &Configure) -> Result<Self> {
        let mut budget = MemoryBudget::new();
        configuration_budget(&TraverseFactory, configure, &mut budget)
            .map_err(|e| anyhow::anyhow!("configuration: {e:?}"))?;
        let frames = budget.total_of(ComponentKind::Frame);
        Ok(StorageSizes {
            arena_bytes: budget.total() - frames,
            frame_bytes: frames / 2,
        })
    }
}

/// Where the `firmware-mcu` crate is: `$PHOTOTRAVERSE_MCU_DIR`, else beside this
/// crate in the source tree.
pub fn crate_dir() -> PathBuf {
    std::env::var_os("PHOTOTRAVERSE_MCU_DIR").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("../firmware-mcu"),
        PathBuf::from,
    )
}

/// Builds the image for `part` with `sizes` and returns the ELF's path. Cargo rebuilds
/// only what the sizes change (the last crate and the link). A configuration that
/// does not fit the part's map fails here, with the linker's words.
pub fn build_image(part: &Part, sizes: &StorageSizes) -> Result<PathBuf> {
    let dir = crate_dir();
    anyhow::ensure!(
        dir.join("Cargo.toml").is_file(),
        "the firmware image's sources are not at {} (set PHOTOTRAVERSE_MCU_DIR to the \
         repository's firmware-mcu directory)",
        dir.display()
    );
    let target_dir = dir.join("target").join(part.name);
    eprintln!(
        "building the firmware image for {} (arena {} bytes, two frames of {} bytes) ...",
        part.name, sizes.arena_bytes, sizes.frame_bytes
    );
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let out = Command::new(cargo)
        .current_dir(&dir)
        .args([
            "build",
            "--release",
            "--target",
            RUST_TARGET,
            "--target-dir",
        ])
        .arg(&target_dir)
        // The image's own flags (linker script, the M7's FPU) are in its
        // .cargo/config.toml; flags from the environment would replace them.
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS")
        .env_remove("CARGO_BUILD_TARGET")
        .env("PHOTOTRAVERSE_PART", part.name)
        .env("PHOTOTRAVERSE_ARENA_BYTES", sizes.arena_bytes.to_string())
        .env("PHOTOTRAVERSE_FRAME_BYTES", sizes.frame_bytes.to_string())
        .output()
        .context("running cargo to build the firmware image")?;
    if !out.status.success() {
        let stderr = String::from_utf8_lossy(&out.stderr);
        bail!("{}", build_failure(part, sizes, &stderr));
    }
    Ok(target_dir.join(RUST_TARGET).join("release").join(IMAGE_BIN))
}

/// An image built for a part, with the storage sizes it was linked with.
#[derive(Debug, Clone)]
pub struct TargetImage {
    pub part: Part,
    pub path: PathBuf,
    pub sizes: StorageSizes,
}

impl TargetImage {
    /// Builds the image for `part` with the storage `configure` needs.
    pub fn build(part: Part, configure: &Configure) -> Result<Self> {
        let sizes = StorageSizes::for_configuration(configure)?;
        let path = build_image(&part, &sizes)?;
        Ok(TargetImage { part, path, sizes })
    }
}

/// What a failed image build means, from cargo's output.
fn build_failure(part: &Part, sizes: &StorageSizes, stderr: &str) -> String {
    let overflow: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("will not fit in region") || l.contains("overflowed by"))
        .map(|l| {
            let l = l.trim_start_matches(|c: char| !c.is_alphanumeric());
            l.strip_prefix("note: ").unwrap_or(l)
        })
        .collect();
    if !overflow.is_empty() {
        return format!(
            "the configuration does not fit the {} memory map (arena {} bytes, two frames of {} \
             bytes): the link failed:\n  {}",
            part.name,
            sizes.arena_bytes,
            sizes.frame_bytes,
            overflow.join("\n  ")
        );
    }
    if stderr.contains("target may not be installed")
        || stderr.contains("can't find crate for `core`")
    {
        return format!(
            "the Rust target {RUST_TARGET} is not installed: rustup target add {RUST_TARGET}"
        );
    }
    format!(
        "building the firmware image for {} failed:\n{stderr}",
        part.name
    )
}

/// An allocated section of the image.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Section {
    pub name: String,
    pub address: u64,
    pub bytes: u64,
}

/// What the linked ELF says: its allocated sections (code, constants, statics, the
/// arena and the frames) in address order, and the bytes left for the stack.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ElfFigures {
    pub sections: Vec<Section>,
    /// From the end of the statics in RAM to the top of the stack (cortex-m-rt's
    /// `__euninit` and `_stack_start`).
    pub stack_reserved_bytes: u64,
}

/// Reads and parses the image once for all its figures.
pub fn read_elf(image: &Path) -> Result<ElfFigures> {
    use object::{Object, ObjectSection, ObjectSymbol, SectionFlags};
    let data = std::fs::read(image)
        .with_context(|| format!("cannot read the image {}", image.display()))?;
    let file = object::File::parse(&*data)
        .with_context(|| format!("{} is not an ELF image", image.display()))?;
    const SHF_ALLOC: u64 = 0x2;
    let mut sections: Vec<Section> = file
        .sections()
        .filter(
            |s| matches!(s.flags(), SectionFlags::Elf { sh_flags } if sh_flags & SHF_ALLOC != 0),
        )
        .filter(|s| s.size() > 0)
        .filter_map(|s| {
            Some(Section {
                name: s.name().ok()?.to_string(),
                address: s.address(),
                bytes: s.size(),
            })
        })
        .collect();
    sections.sort_by_key(|s| s.address);
    let symbol = |name: &str| {
        file.symbols()
            .find(|s| s.name() == Ok(name))
            .map(|s| s.address())
            .with_context(|| format!("{} has no symbol {name}", image.display()))
    };
    let stack_reserved_bytes = symbol("_stack_start")?.saturating_sub(symbol("__euninit")?);
    Ok(ElfFigures {
        sections,
        stack_reserved_bytes,
    })
}

/// Bytes of the named section, 0 when the image has none.
pub fn section_bytes(sections: &[Section], name: &str) -> u64 {
    sections
        .iter()
        .filter(|s| s.name == name)
        .map(|s| s.bytes)
        .sum()
}

/// QEMU runs the image with `-icount shift=0`: each instruction advances the virtual
/// clock by one nanosecond, so the firmware's microseconds (its timer runs on that
/// clock) are thousands of instructions.
pub const INSTRUCTIONS_PER_US: f64 = 1000.0;

/// The clock and cycles per instruction of the time estimate: an STM32H743's Cortex-M7
/// at its top clock. The cycles per instruction are assumed, not measured: the M7
/// issues two instructions per cycle at best, and this workload loses cycles on cache
/// misses over buffers larger than its 16 KiB data cache and on f64 divisions and
/// square roots (14 to 30 cycles each).
pub const ESTIMATE_CLOCK_HZ: f64 = 480e6;
pub const ESTIMATE_CPI: f64 = 1.2;
pub const ESTIMATE_PART: &str = "STM32H743 (Cortex-M7)";

/// Instructions per stage on the emulated core, and the time they would take on a part.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TargetTime {
    /// How the instructions were counted.
    pub method: String,
    pub epochs: usize,
    /// Median instructions per epoch over the processing stages (frame assembly, which
    /// waits on the link, excluded).
    pub instructions_per_epoch_median: f64,
    pub instructions_per_epoch_max: f64,
    /// Median instructions per epoch of each stage, with its share of the processing.
    pub stages: Vec<StageInstructions>,
    /// The time estimate: `instructions x cpi / clock`.
    pub estimate: TimeEstimate,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageInstructions {
    pub stage: String,
    pub instructions_median: f64,
    pub share: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TimeEstimate {
    /// Labelled: this is not a measurement.
    pub kind: String,
    pub part: String,
    pub clock_hz: f64,
    pub cycles_per_instruction: f64,
    pub ms_per_epoch_median: f64,
    pub ms_per_epoch_max: f64,
}

/// The processing stages (everything between a complete frame pair and its result).
const PROCESSING: [usize; 6] = [
    stage::SIFT_LEFT,
    stage::SIFT_RIGHT,
    stage::STEREO_MATCH,
    stage::TEMPORAL_MATCH,
    stage::INITIAL_VALUES,
    stage::ADJUST,
];

/// The instruction counts of a run on the emulated core, from its per-epoch timings.
pub fn target_time(timings_us: &[[u32; stage::COUNT]]) -> TargetTime {
    let insns = |t: &[u32; stage::COUNT], s: usize| t[s] as f64 * INSTRUCTIONS_PER_US;
    let mut per_epoch: Vec<f64> = timings_us
        .iter()
        .map(|t| PROCESSING.iter().map(|&s| insns(t, s)).sum())
        .collect();
    let epoch_max = per_epoch.iter().copied().fold(0.0, f64::max);
    let epoch_median = median(&mut per_epoch);
    let stages = PROCESSING
        .iter()
        .map(|&s| {
            let m = median(&mut timings_us.iter().map(|t| insns(t, s)).collect::<Vec<_>>());
            StageInstructions {
                stage: stage::NAMES[s].to_string(),
                instructions_median: m,
                share: if epoch_median > 0.0 {
                    m / epoch_median
                } else {
                    0.0
                },
            }
        })
        .collect();
    let ms = |i: f64| i * ESTIMATE_CPI / ESTIMATE_CLOCK_HZ * 1e3;
    TargetTime {
        method: "QEMU -icount shift=0 (one instruction per virtual nanosecond), read by the \
                 firmware's timer at each stage"
            .into(),
        epochs: timings_us.len(),
        instructions_per_epoch_median: epoch_median,
        instructions_per_epoch_max: epoch_max,
        stages,
        estimate: TimeEstimate {
            kind: "estimate (instructions x assumed cycles per instruction / clock)".into(),
            part: ESTIMATE_PART.into(),
            clock_hz: ESTIMATE_CLOCK_HZ,
            cycles_per_instruction: ESTIMATE_CPI,
            ms_per_epoch_median: ms(epoch_median),
            ms_per_epoch_max: ms(epoch_max),
        },
    }
}

/// What a run on the emulated part measured, beside what the configuration predicts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TargetReport {
    pub part: String,
    pub description: String,
    pub qemu_machine: Option<String>,
    pub image: String,
    /// The image's allocated sections, from its ELF.
    pub sections: Vec<Section>,
    /// The arena and frames the statics were sized to: the configuration's prediction.
    pub predicted: StorageSizes,
    /// The stack's high-water mark (painted at start, read after each epoch).
    pub stack: Option<StackReport>,
    pub time: TargetTime,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct StackReport {
    pub used_bytes: u32,
    pub reserved_bytes: u32,
}

impl TargetReport {
    /// The report of a run of `image`, from the firmware's statistics.
    pub fn new(
        image: &TargetImage,
        stats: &[phototraverse_core::protocol::messages::Stats],
    ) -> Result<Self> {
        let timings: Vec<_> = stats.iter().map(|s| s.timings_us).collect();
        let part = &image.part;
        Ok(TargetReport {
            part: part.name.into(),
            description: part.description.into(),
            qemu_machine: part.qemu_machine.map(Into::into),
            image: image.path.display().to_string(),
            sections: read_elf(&image.path)?.sections,
            predicted: image.sizes,
            stack: stats
                .iter()
                .rev()
                .find_map(|s| s.stack)
                .map(|s| StackReport {
                    used_bytes: s.used,
                    reserved_bytes: s.reserved,
                }),
            time: target_time(&timings),
        })
    }

    /// Lines for the terminal: instructions, the time estimate, the memory.
    pub fn summary(&self) -> String {
        let t = &self.time;
        let mut stages: Vec<&StageInstructions> = t
            .stages
            .iter()
            .filter(|s| s.instructions_median > 0.0)
            .collect();
        stages.sort_by(|a, b| b.instructions_median.total_cmp(&a.instructions_median));
        let shares: Vec<String> = stages
            .iter()
            .map(|s| format!("{} {:.0} %", s.stage, 100.0 * s.share))
            .collect();
        let kib = |b: u64| format!("{:.1} KiB", b as f64 / 1024.0);
        let sections: Vec<String> = [".text", ".rodata", ".data", ".bss", ".arena", ".frames"]
            .iter()
            .map(|n| format!("{n} {}", kib(section_bytes(&self.sections, n))))
            .collect();
        let mut s = format!(
            "on the emulated {} ({}): median {:.1} M instructions per epoch ({})
",
            self.part,
            t.method.split(' ').next().unwrap_or("QEMU"),
            t.instructions_per_epoch_median / 1e6,
            shares.join(", ")
        );
        s += &format!(
            "estimate, not a measurement: {:.0} ms per epoch (largest {:.0} ms) on an {} at {:.0} \
             MHz and {} cycles per instruction\n",
            t.estimate.ms_per_epoch_median,
            t.estimate.ms_per_epoch_max,
            t.estimate.part,
            t.estimate.clock_hz / 1e6,
            t.estimate.cycles_per_instruction
        );
        s += &format!("image: {}", sections.join(", "));
        if let Some(st) = &self.stack {
            s += &format!(
                "; stack high-water {} of {}",
                kib(st.used_bytes as u64),
                kib(st.reserved_bytes as u64)
            );
        }
        s + "\n"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parts_are_found_by_name_and_by_machine() {
        assert_eq!(Part::named("stm32h743").unwrap().qemu_machine, None);
        assert_eq!(
            Part::for_qemu_machine("mps2-an500").unwrap().name,
            "mps2-an500"
        );
        let e = Part::named("stm32f4").unwrap_err().to_string();
        assert!(e.contains("mps2-an500, stm32h743"), "{e}");
        assert!(Part::for_qemu_machine("mps2-an385").is_err());
    }

    #[test]
    fn every_part_has_a_memory_map() {
        for p in PARTS {
            let map = crate_dir().join("parts").join(format!("{}.x", p.name));
            assert!(map.is_file(), "{}", map.display());
        }
    }

    #[test]
    fn the_linker_overflow_is_quoted_by_name() {
        let stderr = "  = note: rust-lld: error: section '.arena' will not fit in region 'AXISRAM': overflowed by 1234 bytes\n";
        let sizes = StorageSizes {
            arena_bytes: 525_522,
            frame_bytes: 76_800,
        };
        let m = build_failure(&PARTS[1], &sizes, stderr);
        assert!(m.contains("stm32h743"), "{m}");
        assert!(
            m.contains(
                "section '.arena' will not fit in region 'AXISRAM': overflowed by 1234 bytes"
            ),
            "{m}"
        );
    }

    #[test]
    fn instructions_are_the_virtual_microseconds_times_a_thousand() {
        let mut t = [0u32; stage::COUNT];
        t[stage::SIFT_LEFT] = 3_000;
        t[stage::SIFT_RIGHT] = 3_000;
        t[stage::ADJUST] = 4_000;
        t[stage::ASSEMBLE] = 99_000; // waiting on the link: not processing
        let time = target_time(&[t, t, t]);
        assert_eq!(time.instructions_per_epoch_median, 10_000_000.0);
        let adjust = time.stages.iter().find(|s| s.stage == "adjust").unwrap();
        assert!((adjust.share - 0.4).abs() < 1e-12);
        let ms = 10e6 * ESTIMATE_CPI / ESTIMATE_CLOCK_HZ * 1e3;
        assert!((time.estimate.ms_per_epoch_median - ms).abs() < 1e-9);
    }
}
