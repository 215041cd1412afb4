//! The firmware as a child process: its stdin and stdout are the link.
use super::transport::StreamTransport;
use anyhow::{bail, Context};
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// Name of the firmware binary.
pub const FIRMWARE_BIN: &str = "phototraverse-firmware-sim";

/// Where the firmware binary is: `$PHOTOTRAVERSE_FIRMWARE`, else next to the
/// running executable (or one level up, for test binaries in `deps/`).
pub fn firmware_binary() -> anyhow::Result<PathBuf> {
    if let Some(p) = std::env::var_os("PHOTOTRAVERSE_FIRMWARE") {
        return Ok(PathBuf::from(p));
    }
    let exe = std::env::current_exe().context("locating the running executable")?;
    let name = format!("{FIRMWARE_BIN}{}", std::env::consts::EXE_SUFFIX);
    for dir in exe.ancestors().skip(1).take(2) {
        let candidate = dir.join(&name);
        if candidate.is_file() {
            return Ok(candidate);
        }
    }
    bail!(
        "cannot find the firmware binary {name} next to {}; build it (cargo build -p phototraverse-firmware-sim) \
         or set PHOTOTRAVERSE_FIRMWARE",
        exe.display()
    )
}

/// The command that starts the firmware, and its name for messages:
/// `$PHOTOTRAVERSE_FIRMWARE` when set; else this very program as `phototraverse
/// firmware` (the same no_std loop, hosted), which is always the build that runs the
/// host: a dedicated binary found beside it may be older (`cargo build -p
/// phototraverse-host` does not rebuild it) and would answer with its own behaviour
/// without a word; else, from another program (a test binary), the dedicated binary
/// beside it ([`firmware_binary`]).
pub fn firmware_command() -> anyhow::Result<(Command, String)> {
    let exe = std::env::current_exe().context("locating the running executable")?;
    let own = exe.file_stem().and_then(|s| s.to_str()) == Some("phototraverse");
    if own && std::env::var_os("PHOTOTRAVERSE_FIRMWARE").is_none() {
        let mut cmd = Command::new(&exe);
        cmd.arg("firmware");
        return Ok((cmd, format!("{} firmware", exe.display())));
    }
    let bin = firmware_binary()?;
    Ok((Command::new(&bin), bin.display().to_string()))
}

/// Arguments passed to every spawned firmware.
pub fn firmware_args(memory: usize, processor: super::FirmwareProcessor) -> Vec<String> {
    let p = match processor {
        super::FirmwareProcessor::Traverse => "traverse",
        super::FirmwareProcessor::Sift => "sift",
        super::FirmwareProcessor::Stats => "stats",
    };
    vec![
        "--memory".into(),
        memory.to_string(),
        "--processor".into(),
        p.into(),
    ]
}

/// Kills the child when the link is dropped, after closing its input.
pub struct ChildGuard(pub Child);

impl Drop for ChildGuard {
    fn drop(&mut self) {
        // Give the firmware a moment to see end of input, then make sure it is gone.
        for _ in 0..20 {
            if let Ok(Some(_)) = self.0.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The child-process transport.
pub struct ChildLink {
    inner: StreamTransport,
    _child: ChildGuard,
}

impl ChildLink {
    pub fn spawn(memory: usize, processor: super::FirmwareProcessor) -> anyhow::Result<Self> {
        let (mut cmd, bin) = firmware_command()?;
        // In its own process group: Ctrl-C at the terminal goes to the host alone, which
        // stops between epochs and still needs the firmware for the epochs in flight.
        #[cfg(unix)]
        std::os::unix::process::CommandExt::process_group(&mut cmd, 0);
        let mut child = cmd
            .args(firmware_args(memory, processor))
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .with_context(|| format!("starting the firmware {bin}"))?;
        let stdin = child.stdin.take().context("firmware stdin")?;
        let stdout = child.stdout.take().context("firmware stdout")?;
        Ok(ChildLink {
            inner: StreamTransport::spawn(stdin, stdout, "child", format!("child process {bin}")),
            _child: ChildGuard(child),
        })
    }
}

super::transport::delegate_to_inner_stream!(ChildLink);

/// Spawns the firmware listening on TCP (an ephemeral 127.0.0.1 port) and
/// returns the child and the address it printed.
pub fn spawn_tcp_firmware(
    memory: usize,
    processor: super::FirmwareProcessor,
) -> anyhow::Result<(ChildGuard, String)> {
    let (mut cmd, bin) = firmware_command()?;
    let mut child = cmd
        .args(firmware_args(memory, processor))
        .args(["--tcp", "127.0.0.1:0"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .with_context(|| format!("starting the firmware {bin}"))?;
    let stdout = child.stdout.take().context("firmware stdout")?;
    let guard = ChildGuard(child);
    let mut line = String::new();
    BufReader::new(stdout)
        .read_line(&mut line)
        .context("reading the firmware's listening address")?;
    let addr = line
        .trim()
        .strip_prefix("listening ")
        .with_context(|| format!("unexpected firmware output {line:?}"))?;
    Ok((guard, addr.to_string()))
}
