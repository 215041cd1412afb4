//! Host side of the emulated rig link: transports (in-process, child process,
//! TCP, serial device, the microcontroller image under QEMU), bandwidth limit and fault injection, selected by
//! [`LinkOptions`] (flattened into `phototraverse run`).
pub mod child;
pub mod fault;
pub mod inproc;
pub mod net;
pub mod qemu;
pub mod throttle;
pub mod transport;

pub use fault::{FaultConfig, FaultCounters, Faulty};
pub use transport::Transport;

use anyhow::{bail, Context};
use phototraverse_firmware_sim::Limits;

/// Which link carries the protocol.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LinkKind {
    /// The firmware loop on a thread of this process.
    InProc,
    /// The firmware binary as a child process over its stdin/stdout.
    Child,
    /// TCP: to `ADDR`, or (no address) to a firmware binary started on 127.0.0.1.
    Tcp(Option<String>),
    /// A serial device.
    Serial(String),
    /// The firmware image on a QEMU machine (its UART is the link).
    Qemu(String),
}

/// The QEMU machine `--link qemu` runs.
pub const DEFAULT_QEMU_MACHINE: &str = "mps2-an500";

impl std::str::FromStr for LinkKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Ok(match s {
            "inproc" => LinkKind::InProc,
            "child" => LinkKind::Child,
            "tcp" => LinkKind::Tcp(None),
            "qemu" => LinkKind::Qemu(DEFAULT_QEMU_MACHINE.into()),
            _ => {
                if let Some(a) = s.strip_prefix("tcp:") {
                    LinkKind::Tcp(Some(a.to_string()))
                } else if let Some(d) = s.strip_prefix("serial:") {
                    LinkKind::Serial(d.to_string())
                } else if let Some(m) = s.strip_prefix("qemu:") {
                    LinkKind::Qemu(m.to_string())
                } else {
                    return Err(format!(
                        "unknown link {s:?}: expected inproc, child, tcp, tcp:ADDR, serial:DEV, \
                         qemu or qemu:MACHINE"
                    ));
                }
            }
        })
    }
}

/// What the firmware runs on each epoch.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FirmwareProcessor {
    /// The whole traverse: orientation of every epoch (what `run` needs).
    #[default]
    Traverse,
    /// Reduced SIFT on both images (feature counts and timings only).
    Sift,
    /// Image statistics only (link bring-up).
    Stats,
}

/// Link options of the rig emulation (flatten into a command with `#[command(flatten)]`).
#[derive(clap::Args, Debug, Clone)]
pub struct LinkOptions {
    /// Link to the firmware: inproc, child (this program as `phototraverse firmware` over
    /// pipes; $PHOTOTRAVERSE_FIRMWARE names another firmware binary), tcp (start the
    /// firmware on 127.0.0.1), tcp:ADDR, serial:DEV, qemu (the Cortex-M7 image, built for
    /// the run's configuration, on QEMU's mps2-an500 machine; needs qemu-system-arm and
    /// the Rust target thumbv7em-none-eabihf), qemu:MACHINE.
    #[arg(long, default_value = "child")]
    pub link: LinkKind,
    /// Limit the link to this baud rate (8N1, 10 bits per byte; also the serial device's rate).
    #[arg(long)]
    pub baud: Option<u32>,
    /// Pace epochs at this frame rate (default: as fast as the link goes).
    #[arg(long)]
    pub fps: Option<f64>,
    /// Bit error rate injected on both directions.
    #[arg(long, default_value_t = 0.0)]
    pub fault_ber: f64,
    /// Probability that a packet is dropped (both directions).
    #[arg(long, default_value_t = 0.0)]
    pub fault_drop: f64,
    /// Probability that a single byte is dropped.
    #[arg(long, default_value_t = 0.0)]
    pub fault_drop_byte: f64,
    /// Probability that a packet is truncated.
    #[arg(long, default_value_t = 0.0)]
    pub fault_truncate: f64,
    /// Probability that a packet is duplicated.
    #[arg(long, default_value_t = 0.0)]
    pub fault_duplicate: f64,
    /// Probability that a packet is swapped with the next one.
    #[arg(long, default_value_t = 0.0)]
    pub fault_reorder: f64,
    /// Seed of the fault injection.
    #[arg(long, default_value_t = 1)]
    pub fault_seed: u64,
    /// Working memory of a firmware this link starts, bytes.
    #[arg(long, default_value_t = 32 << 20)]
    pub fw_memory: usize,
    /// Per-epoch processing of a firmware this link starts.
    #[arg(long, value_enum, default_value_t = FirmwareProcessor::Traverse)]
    pub fw_processor: FirmwareProcessor,
    /// Largest frame payload per chunk packet. The session keeps chunks small enough
    /// for the firmware to hold one that arrives after a gap (its capabilities say
    /// how large), and shrinks them on a line that damages packets.
    #[arg(long, default_value_t = crate::session::DEFAULT_CHUNK)]
    pub chunk: usize,
    /// Seconds without any answer, or with a write blocked (a firmware that takes no
    /// bytes), before the firmware is declared unresponsive and the run stops.
    #[arg(long, default_value_t = 5.0)]
    pub link_timeout: f64,
    /// Seconds with epochs outstanding and none completed (a line too noisy to carry
    /// them, with the firmware still answering) before the run stops with the link's
    /// figures and the outputs so far. On a baud-limited link it is at least three
    /// times an epoch's transfer time.
    #[arg(long, default_value_t = 30.0)]
    pub progress_timeout: f64,
}

impl Default for LinkOptions {
    fn default() -> Self {
        LinkOptions {
            link: LinkKind::InProc,
            baud: None,
            fps: None,
            fault_ber: 0.0,
            fault_drop: 0.0,
            fault_drop_byte: 0.0,
            fault_truncate: 0.0,
            fault_duplicate: 0.0,
            fault_reorder: 0.0,
            fault_seed: 1,
            fw_memory: 32 << 20,
            fw_processor: FirmwareProcessor::Traverse,
            chunk: crate::session::DEFAULT_CHUNK,
            link_timeout: 5.0,
            progress_timeout: 30.0,
        }
    }
}

impl LinkOptions {
    pub fn faults(&self) -> FaultConfig {
        FaultConfig {
            ber: self.fault_ber,
            drop_byte: self.fault_drop_byte,
            drop_packet: self.fault_drop,
            truncate: self.fault_truncate,
            duplicate: self.fault_duplicate,
            reorder: self.fault_reorder,
            seed: self.fault_seed,
        }
    }

    /// For a QEMU link, the part it emulates and the image built for `configure`.
    pub fn target_image(
        &self,
        configure: &phototraverse_core::protocol::messages::Configure,
    ) -> anyhow::Result<Option<crate::mcu::TargetImage>> {
        let LinkKind::Qemu(machine) = &self.link else {
            return Ok(None);
        };
        let part = crate::mcu::Part::for_qemu_machine(machine)?;
        crate::mcu::TargetImage::build(part, configure).map(Some)
    }

    /// Opens the transport with its limiter and injector.
    pub fn open(&self) -> anyhow::Result<Box<dyn Transport>> {
        self.open_with_image(None)
    }

    /// Opens the transport; a QEMU link runs `image` ([`LinkOptions::target_image`]).
    pub fn open_with_image(
        &self,
        image: Option<&crate::mcu::TargetImage>,
    ) -> anyhow::Result<Box<dyn Transport>> {
        for (name, p) in [
            ("--fault-ber", self.fault_ber),
            ("--fault-drop", self.fault_drop),
            ("--fault-drop-byte", self.fault_drop_byte),
            ("--fault-truncate", self.fault_truncate),
            ("--fault-duplicate", self.fault_duplicate),
            ("--fault-reorder", self.fault_reorder),
        ] {
            if !(0.0..=1.0).contains(&p) {
                bail!("{name} must be a probability in [0, 1], got {p}");
            }
        }
        let base: Box<dyn Transport> = match &self.link {
            LinkKind::InProc => Box::new(inproc::InProc::spawn(
                self.fw_memory,
                Limits::default(),
                self.fw_processor,
            )),
            LinkKind::Child => {
                Box::new(child::ChildLink::spawn(self.fw_memory, self.fw_processor)?)
            }
            LinkKind::Tcp(None) => {
                Box::new(net::TcpLink::spawn(self.fw_memory, self.fw_processor)?)
            }
            LinkKind::Tcp(Some(addr)) => Box::new(net::TcpLink::connect(addr)?),
            LinkKind::Serial(dev) => Box::new(
                net::SerialLink::open(dev, self.baud.unwrap_or(921_600)).context("serial link")?,
            ),
            LinkKind::Qemu(machine) => {
                let Some(image) = image else {
                    bail!(
                        "the QEMU link ({machine}) runs an image built for the run's \
                         configuration: use it with `run` or `demo`"
                    );
                };
                Box::new(qemu::QemuLink::spawn(image)?)
            }
        };
        let limited: Box<dyn Transport> = match self.baud {
            Some(b) if b > 0 => Box::new(throttle::Throttled::new(base, b)),
            _ => base,
        };
        let faults = self.faults();
        Ok(if faults.is_clean() {
            limited
        } else {
            Box::new(Faulty::new(limited, faults))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn link_kinds_parse() {
        assert_eq!("inproc".parse::<LinkKind>(), Ok(LinkKind::InProc));
        assert_eq!("child".parse::<LinkKind>(), Ok(LinkKind::Child));
        assert_eq!("tcp".parse::<LinkKind>(), Ok(LinkKind::Tcp(None)));
        assert_eq!(
            "qemu".parse::<LinkKind>(),
            Ok(LinkKind::Qemu("mps2-an500".into()))
        );
        assert_eq!(
            "qemu:mps2-an386".parse::<LinkKind>(),
            Ok(LinkKind::Qemu("mps2-an386".into()))
        );
        assert_eq!(
            "tcp:127.0.0.1:7000".parse::<LinkKind>(),
            Ok(LinkKind::Tcp(Some("127.0.0.1:7000".into())))
        );
        assert_eq!(
            "serial:/dev/ttyUSB0".parse::<LinkKind>(),
            Ok(LinkKind::Serial("/dev/ttyUSB0".into()))
        );
        assert!("udp"
            .parse::<LinkKind>()
            .unwrap_err()
            .contains("unknown link"));
    }

    #[test]
    fn options_flatten_into_a_command() {
        use clap::Parser;
        #[derive(Parser)]
        struct Cmd {
            #[command(flatten)]
            link: LinkOptions,
        }
        let c = Cmd::parse_from([
            "x",
            "--link",
            "tcp:1.2.3.4:5",
            "--baud",
            "921600",
            "--fault-ber",
            "1e-4",
            "--fault-seed",
            "3",
        ]);
        assert_eq!(c.link.link, LinkKind::Tcp(Some("1.2.3.4:5".into())));
        assert_eq!(c.link.baud, Some(921_600));
        assert_eq!(c.link.faults().ber, 1e-4);
        assert_eq!(c.link.faults().seed, 3);
        let bad = LinkOptions {
            fault_drop: 1.5,
            ..LinkOptions::default()
        };
        assert!(bad
            .open()
            .err()
            .unwrap()
            .to_string()
            .contains("--fault-drop"));
    }
}
