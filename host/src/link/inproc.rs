//! In-process link: the firmware loop on a thread, bytes through channels —
//! still every byte through the protocol, only the wire is memory.
use super::transport::Transport;
use super::FirmwareProcessor;
use phototraverse_firmware_sim::{
    Clock, Firmware, ImageStatsFactory, Limits, LinkBuffers, SiftFactory, TraverseFactory,
};
use std::io;
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The firmware's end: an `embedded_io` port over two channels.
struct ChannelPort {
    rx: Receiver<Vec<u8>>,
    tx: Sender<Vec<u8>>,
    pending: Vec<u8>,
    pos: usize,
    out: Vec<u8>,
}

impl embedded_io::ErrorType for ChannelPort {
    type Error = std::io::Error;
}

impl embedded_io::Read for ChannelPort {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        if self.pos == self.pending.len() {
            match self.rx.recv() {
                Ok(v) => {
                    self.pending = v;
                    self.pos = 0;
                }
                Err(_) => return Ok(0),
            }
        }
        let n = buf.len().min(self.pending.len() - self.pos);
        buf[..n].copy_from_slice(&self.pending[self.pos..self.pos + n]);
        self.pos += n;
        Ok(n)
    }
}

impl embedded_io::Write for ChannelPort {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        self.out.extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        if !self.out.is_empty() {
            let v = std::mem::take(&mut self.out);
            // A host that went away is not the firmware's error.
            let _ = self.tx.send(v);
        }
        Ok(())
    }
}

struct StdClock(Instant);

impl Clock for StdClock {
    fn now_us(&self) -> u64 {
        self.0.elapsed().as_micros() as u64
    }
}

/// Host end of the in-process link.
pub struct InProc {
    tx: Option<Sender<Vec<u8>>>,
    rx: Receiver<Vec<u8>>,
    out: Vec<u8>,
    thread: Option<JoinHandle<()>>,
}

impl InProc {
    /// Starts the firmware loop with `memory` bytes of working storage.
    pub fn spawn(memory: usize, limits: Limits, processor: FirmwareProcessor) -> Self {
        let (host_tx, fw_rx) = mpsc::channel::<Vec<u8>>();
        let (fw_tx, host_rx) = mpsc::channel::<Vec<u8>>();
        let thread = std::thread::Builder::new()
            .name("firmware-inproc".into())
            .spawn(move || {
                let mut work = vec![0u8; memory];
                let mut buffers = Box::new(LinkBuffers::new());
                let mut port = ChannelPort {
                    rx: fw_rx,
                    tx: fw_tx,
                    pending: Vec::new(),
                    pos: 0,
                    out: Vec::new(),
                };
                let clock = StdClock(Instant::now());
                // The loop ends at end of input; a port error means the host went away.
                let _ = match processor {
                    FirmwareProcessor::Traverse => {
                        Firmware::new(&mut work, TraverseFactory, clock, limits)
                            .run(&mut port, &mut buffers)
                    }
                    FirmwareProcessor::Sift => Firmware::new(&mut work, SiftFactory, clock, limits)
                        .run(&mut port, &mut buffers),
                    FirmwareProcessor::Stats => {
                        Firmware::new(&mut work, ImageStatsFactory, clock, limits)
                            .run(&mut port, &mut buffers)
                    }
                };
            })
            .expect("spawning the in-process firmware");
        InProc {
            tx: Some(host_tx),
            rx: host_rx,
            out: Vec::new(),
            thread: Some(thread),
        }
    }
}

impl Transport for InProc {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.out.extend_from_slice(bytes);
        Ok(())
    }
    fn flush(&mut self) -> io::Result<()> {
        if self.out.is_empty() {
            return Ok(());
        }
        let v = std::mem::take(&mut self.out);
        self.tx
            .as_ref()
            .and_then(|t| t.send(v).ok())
            .ok_or_else(|| {
                io::Error::new(io::ErrorKind::BrokenPipe, "the in-process firmware stopped")
            })
    }
    fn recv(&mut self, timeout: Duration) -> io::Result<Option<Vec<u8>>> {
        match self.rx.recv_timeout(timeout) {
            Ok(v) => Ok(Some(v)),
            Err(RecvTimeoutError::Timeout) => Ok(None),
            Err(RecvTimeoutError::Disconnected) => Err(io::Error::new(
                io::ErrorKind::UnexpectedEof,
                "the in-process firmware stopped",
            )),
        }
    }
    fn describe(&self) -> String {
        "in-process".into()
    }
}

impl Drop for InProc {
    fn drop(&mut self) {
        // Closing the channel is end of input for the firmware loop.
        self.tx.take();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
