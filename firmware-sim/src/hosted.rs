//! The firmware hosted on a computer: the same no_std loop, its link on
//! stdin/stdout (default), a TCP socket (`--tcp ADDR`, listening) or a serial
//! device (`--serial DEV --baud N`). Used by the `phototraverse-firmware-sim`
//! binary and by `phototraverse firmware` (so the host binary alone can play
//! both ends of the link).
extern crate std;

use crate::{
    Clock, Firmware, ImageStatsFactory, Limits, LinkBuffers, SiftFactory, TraverseFactory,
};
use std::boxed::Box;
use std::format;
use std::string::{String, ToString};
use std::vec;
use std::vec::Vec;
use std::{eprintln, println};

/// What the firmware runs on each epoch.
#[derive(Clone, Copy)]
enum Processor {
    Traverse,
    Sift,
    Stats,
}
use std::io::{Read, Write};
use std::time::Instant;

const USAGE: &str = "usage: phototraverse-firmware-sim [--tcp ADDR | --serial DEV [--baud N]] \
[--memory BYTES] [--max-width W] [--max-height H] [--processor traverse|sift|stats] \
[--die-after-bytes N (fault injection: the process exits after reading N bytes)] \
[--stop-after-bytes N (fault injection: the process stops itself, SIGSTOP, after reading N bytes)]";

struct Options {
    tcp: Option<String>,
    serial: Option<String>,
    baud: u32,
    memory: usize,
    limits: Limits,
    /// Image statistics instead of SIFT (bring-up).
    processor: Processor,
    /// Fault injection for tests: exit abruptly, or stop (a hung firmware), once this
    /// many bytes were read.
    fault_after_bytes: Option<(u64, Fault)>,
}

/// What an injected fault does to the process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Fault {
    Exit,
    Stop,
}

fn parse_args(argv: Vec<String>) -> Result<Options, String> {
    let mut o = Options {
        tcp: None,
        serial: None,
        baud: 921_600,
        memory: 32 << 20,
        limits: Limits::default(),
        processor: Processor::Traverse,
        fault_after_bytes: None,
    };
    let mut args = argv.into_iter();
    while let Some(a) = args.next() {
        let mut value = || {
            args.next()
                .ok_or_else(|| format!("{a} needs a value\n{USAGE}"))
        };
        match a.as_str() {
            "--tcp" => o.tcp = Some(value()?),
            "--serial" => o.serial = Some(value()?),
            "--baud" => o.baud = value()?.parse().map_err(|e| format!("--baud: {e}"))?,
            "--memory" => o.memory = value()?.parse().map_err(|e| format!("--memory: {e}"))?,
            "--max-width" => {
                o.limits.max_width = value()?.parse().map_err(|e| format!("--max-width: {e}"))?
            }
            "--max-height" => {
                o.limits.max_height = value()?.parse().map_err(|e| format!("--max-height: {e}"))?
            }
            "--processor" => {
                o.processor = match value()?.as_str() {
                    "traverse" => Processor::Traverse,
                    "sift" => Processor::Sift,
                    "stats" => Processor::Stats,
                    other => {
                        return Err(format!(
                            "--processor: unknown {other:?} (traverse, sift or stats)"
                        ))
                    }
                }
            }
            "--die-after-bytes" | "--stop-after-bytes" => {
                let n = value()?.parse().map_err(|e| format!("{a}: {e}"))?;
                let fault = if a == "--die-after-bytes" {
                    Fault::Exit
                } else {
                    Fault::Stop
                };
                o.fault_after_bytes = Some((n, fault));
            }
            "-h" | "--help" => return Err(USAGE.to_string()),
            other => return Err(format!("unknown argument {other}\n{USAGE}")),
        }
    }
    Ok(o)
}

/// `std::io` reader and writer as an `embedded_io` port. Read time-outs (serial
/// devices) are waited through: the firmware loop blocks like a UART driver.
struct Port<R, W> {
    rx: R,
    tx: W,
    /// Bytes left before the injected fault, if one is configured.
    fault_after: Option<(u64, Fault)>,
}

impl<R, W> embedded_io::ErrorType for Port<R, W> {
    type Error = std::io::Error;
}

impl<R: Read, W> embedded_io::Read for Port<R, W> {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        loop {
            let n = match self.fault_after {
                // Never read past the fault: what follows it is never seen.
                Some((left, _)) => buf.len().min(left.max(1) as usize),
                None => buf.len(),
            };
            let buf = &mut buf[..n];
            let got = self.rx.read(buf);
            if let (Ok(k), Some((left, fault))) = (&got, self.fault_after.as_mut()) {
                *left = left.saturating_sub(*k as u64);
                if *left == 0 {
                    inject(*fault);
                    self.fault_after = None;
                }
            }
            match got {
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::TimedOut | std::io::ErrorKind::Interrupted
                    ) => {}
                // A peer that hung up ends the session like end of input.
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => return Ok(0),
                other => return other,
            }
        }
    }
}

impl<R, W: Write> embedded_io::Write for Port<R, W> {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        self.tx.write(buf)
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        self.tx.flush()
    }
}

/// The injected fault: the process exits, or stops itself as a hung firmware would.
fn inject(fault: Fault) {
    match fault {
        Fault::Exit => {
            eprintln!(
                "phototraverse-firmware-sim: injected fault: exiting after the configured bytes"
            );
            std::process::exit(3);
        }
        Fault::Stop => {
            eprintln!(
                "phototraverse-firmware-sim: injected fault: stopping after the configured bytes"
            );
            // SAFETY: raise only sends a signal to this process; SIGSTOP cannot be caught.
            unsafe {
                libc::raise(libc::SIGSTOP);
            }
        }
    }
}

struct StdClock(Instant);

impl Clock for StdClock {
    fn now_us(&self) -> u64 {
        self.0.elapsed().as_micros() as u64
    }
}

fn serve<R: Read, W: Write>(o: &Options, rx: R, tx: W) -> std::io::Result<()> {
    let mut work = vec![0u8; o.memory];
    let mut buffers = Box::new(LinkBuffers::new());
    let mut port = Port {
        rx,
        tx,
        fault_after: o.fault_after_bytes,
    };
    let clock = StdClock(Instant::now());
    match o.processor {
        Processor::Traverse => {
            Firmware::new(&mut work, TraverseFactory, clock, o.limits).run(&mut port, &mut buffers)
        }
        Processor::Sift => {
            Firmware::new(&mut work, SiftFactory, clock, o.limits).run(&mut port, &mut buffers)
        }
        Processor::Stats => Firmware::new(&mut work, ImageStatsFactory, clock, o.limits)
            .run(&mut port, &mut buffers),
    }
}

/// Runs the firmware with command-line arguments (without the program name);
/// returns the process exit code.
pub fn main_with_args(argv: Vec<String>) -> i32 {
    let o = match parse_args(argv) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("{e}");
            return 2;
        }
    };
    let result = if let Some(addr) = &o.tcp {
        serve_tcp(&o, addr)
    } else if let Some(dev) = &o.serial {
        serialport::new(dev, o.baud)
            .timeout(std::time::Duration::from_secs(3600))
            .open()
            .map_err(std::io::Error::from)
            .and_then(|p| {
                let rx = p.try_clone().map_err(std::io::Error::from)?;
                serve(&o, rx, p)
            })
    } else {
        serve(&o, std::io::stdin().lock(), std::io::stdout().lock())
    };
    match result {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("phototraverse-firmware-sim: {e}");
            1
        }
    }
}

/// Listens on `addr` (port 0 picks one) and serves one connection after another;
/// the chosen address is printed on stdout first so a parent can connect.
fn serve_tcp(o: &Options, addr: &str) -> std::io::Result<()> {
    let listener = std::net::TcpListener::bind(addr)?;
    println!("listening {}", listener.local_addr()?);
    std::io::stdout().flush()?;
    for stream in listener.incoming() {
        let stream = stream?;
        stream.set_nodelay(true)?;
        let rx = stream.try_clone()?;
        if let Err(e) = serve(o, rx, std::io::BufWriter::with_capacity(64 * 1024, stream)) {
            eprintln!("phototraverse-firmware-sim: connection ended: {e}");
        }
    }
    Ok(())
}
