//! The firmware image on an emulated microcontroller: QEMU runs it, the board's UART
//! on QEMU's stdin and stdout is the link, as the child process's pipes are for the
//! hosted firmware. The image is built for the configuration of the run
//! ([`crate::mcu::build_image`]).
use super::child::ChildGuard;
use super::transport::{StreamTransport, Transport};
use crate::mcu::TargetImage;
use anyhow::{bail, Context};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

/// The QEMU program for Arm machines, and the Debian package that has it.
pub const QEMU_BIN: &str = "qemu-system-arm";
pub const QEMU_PACKAGE: &str = "qemu-system-arm";

/// Bytes per second the emulated UART moves, for the retransmission time-outs. QEMU
/// hands its CMSDK UART one byte per turn of its event loop (15-20 kB/s measured);
/// the time-outs are set for the slower end.
const UART_BYTES_PER_SEC: f64 = 10_000.0;

/// The QEMU command line that runs `image` on `machine`, the UART on stdin/stdout.
pub fn qemu_command(machine: &str, image: &Path) -> Command {
    let mut cmd = Command::new(QEMU_BIN);
    cmd.args(["-machine", machine, "-display", "none", "-monitor", "none"])
        .args(["-serial", "stdio"])
        // A panic or a fault is printed by semihosting, on stderr (appended: a
        // redirected stderr is not truncated), and ends QEMU with a failure.
        .args([
            "-chardev",
            "file,id=semihosting,path=/dev/stderr,append=on",
            "-semihosting-config",
            "enable=on,target=native,chardev=semihosting",
        ])
        // One instruction per virtual nanosecond: the firmware's timer counts instructions.
        .args(["-icount", "shift=0"])
        .arg("-kernel")
        .arg(image);
    cmd
}

/// The firmware image under QEMU.
pub struct QemuLink {
    inner: StreamTransport,
    _qemu: ChildGuard,
}

impl QemuLink {
    /// Starts the machine of the image's part on the image.
    pub fn spawn(image: &TargetImage) -> anyhow::Result<Self> {
        let Some(machine) = image.part.qemu_machine else {
            bail!("the part {} has no QEMU machine to run on", image.part.name);
        };
        let image = &image.path;
        let mut cmd = qemu_command(machine, image);
        // Its own process group: Ctrl-C goes to the host, which finishes the epochs in flight.
        #[cfg(unix)]
        std::os::unix::process::CommandExt::process_group(&mut cmd, 0);
        let mut child = match cmd
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
        {
            Ok(c) => c,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => bail!(
                "{QEMU_BIN} is not installed: install Debian's package {QEMU_PACKAGE} \
                 (apt-get install {QEMU_PACKAGE}, or scripts/install-qemu.sh)"
            ),
            Err(e) => return Err(e).with_context(|| format!("starting {QEMU_BIN}")),
        };
        let stdin = child.stdin.take().context("QEMU's stdin")?;
        let stdout = child.stdout.take().context("QEMU's stdout")?;
        let name = format!("{QEMU_BIN} -machine {machine} ({})", image.display());
        Ok(QemuLink {
            inner: StreamTransport::spawn(stdin, stdout, "qemu", name),
            _qemu: ChildGuard(child),
        })
    }
}

impl Transport for QemuLink {
    fn send(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.inner.send(bytes)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
    fn recv(&mut self, timeout: Duration) -> std::io::Result<Option<Vec<u8>>> {
        self.inner.recv(timeout)
    }
    fn bytes_per_sec(&self) -> Option<f64> {
        Some(UART_BYTES_PER_SEC)
    }
    fn set_write_deadline(&mut self, deadline: Duration) {
        self.inner.set_write_deadline(deadline)
    }
    fn describe(&self) -> String {
        self.inner.describe()
    }
}
