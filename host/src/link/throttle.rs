//! Link bandwidth limit: paces outgoing bytes as a UART would send them
//! (8N1: 10 bit times per byte), so epoch times at a baud rate are measured,
//! not only computed.
use super::transport::Transport;
use std::io;
use std::time::{Duration, Instant};

pub struct Throttled<T> {
    inner: T,
    bytes_per_sec: f64,
    /// When the wire is free again.
    free_at: Instant,
}

impl<T: Transport> Throttled<T> {
    pub fn new(inner: T, baud: u32) -> Self {
        Throttled {
            inner,
            bytes_per_sec: baud as f64 / 10.0,
            free_at: Instant::now(),
        }
    }
}

impl<T: Transport> Transport for Throttled<T> {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        let now = Instant::now();
        let start = self.free_at.max(now);
        self.free_at = start + Duration::from_secs_f64(bytes.len() as f64 / self.bytes_per_sec);
        // Hand bytes on when the wire would have delivered them.
        self.inner.send(bytes)?;
        self.inner.flush()?;
        let wait = self.free_at.saturating_duration_since(Instant::now());
        if wait > Duration::from_micros(200) {
            std::thread::sleep(wait);
        }
        Ok(())
    }
    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
    fn recv(&mut self, timeout: Duration) -> io::Result<Option<Vec<u8>>> {
        self.inner.recv(timeout)
    }
    fn bytes_per_sec(&self) -> Option<f64> {
        Some(self.bytes_per_sec)
    }
    fn set_write_deadline(&mut self, deadline: Duration) {
        self.inner.set_write_deadline(deadline)
    }
    fn fault_counters(&self) -> Option<[super::FaultCounters; 2]> {
        self.inner.fault_counters()
    }
    fn describe(&self) -> String {
        format!(
            "{} limited to {:.0} baud",
            self.inner.describe(),
            self.bytes_per_sec * 10.0
        )
    }
}
