//! TCP and serial-port transports.
use super::child::{spawn_tcp_firmware, ChildGuard};
use super::transport::StreamTransport;
use anyhow::Context;
use std::io;
use std::net::TcpStream;
use std::time::Duration;

/// A TCP connection to a firmware (optionally one this link started).
pub struct TcpLink {
    inner: StreamTransport,
    _child: Option<ChildGuard>,
}

impl TcpLink {
    /// Connects to a firmware listening at `addr`.
    pub fn connect(addr: &str) -> anyhow::Result<Self> {
        Self::connect_with(addr, None)
    }

    /// Starts the firmware binary listening on 127.0.0.1 and connects to it.
    pub fn spawn(memory: usize, processor: super::FirmwareProcessor) -> anyhow::Result<Self> {
        let (child, addr) = spawn_tcp_firmware(memory, processor)?;
        Self::connect_with(&addr, Some(child))
    }

    fn connect_with(addr: &str, child: Option<ChildGuard>) -> anyhow::Result<Self> {
        let stream = TcpStream::connect(addr)
            .with_context(|| format!("connecting to the firmware at {addr}"))?;
        stream.set_nodelay(true)?;
        let reader = stream.try_clone()?;
        Ok(TcpLink {
            inner: StreamTransport::spawn(stream, reader, "tcp", format!("tcp {addr}")),
            _child: child,
        })
    }
}

super::transport::delegate_to_inner_stream!(TcpLink);

/// A serial device (UART, USB CDC, pseudo-terminal) through the `serialport` crate.
pub struct SerialLink {
    inner: StreamTransport,
}

impl SerialLink {
    pub fn open(device: &str, baud: u32) -> anyhow::Result<Self> {
        let port = serialport::new(device, baud)
            .timeout(Duration::from_millis(50))
            .open()
            .with_context(|| format!("opening the serial device {device}"))?;
        let reader = port
            .try_clone()
            .context("cloning the serial port for reading")?;
        Ok(SerialLink {
            inner: StreamTransport::spawn(
                port,
                reader,
                "serial",
                format!("serial {device} at {baud} baud"),
            ),
        })
    }
}

super::transport::delegate_to_inner_stream!(SerialLink);

/// A pseudo-terminal pair: the master end as a file and the slave's device path
/// (a serial device for tests without hardware).
pub struct Pty {
    pub master: std::fs::File,
    pub slave_path: std::path::PathBuf,
    /// Kept open so the pair survives until the serial side opens the path.
    _slave: std::fs::File,
}

impl Pty {
    pub fn open() -> anyhow::Result<Self> {
        use std::os::fd::FromRawFd;
        let mut master: libc::c_int = -1;
        let mut slave: libc::c_int = -1;
        let mut name = [0 as libc::c_char; 128];
        // SAFETY: openpty writes two descriptors and a NUL-terminated name into
        // the buffers given; the termios and winsize pointers may be null.
        let rc = unsafe {
            libc::openpty(
                &mut master,
                &mut slave,
                name.as_mut_ptr(),
                std::ptr::null(),
                std::ptr::null(),
            )
        };
        if rc != 0 {
            return Err(io::Error::last_os_error()).context("openpty");
        }
        // SAFETY: openpty succeeded, so both descriptors are open and owned by us,
        // and `name` holds a NUL-terminated path.
        let (master, slave, path) = unsafe {
            (
                std::fs::File::from_raw_fd(master),
                std::fs::File::from_raw_fd(slave),
                std::ffi::CStr::from_ptr(name.as_ptr())
                    .to_string_lossy()
                    .into_owned(),
            )
        };
        Ok(Pty {
            master,
            slave_path: path.into(),
            _slave: slave,
        })
    }
}
