//! The byte pipe between host and firmware. Every transport moves opaque bytes
//! (already framed by the protocol); reads and writes run on threads behind
//! channels so the session waits with a deadline on any kind of link, in both
//! directions: a firmware that stops reading (a stalled or stopped process, a full
//! pipe) costs a deadline, not a blocked call.
use std::io::{self, Read, Write};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// A bidirectional byte link to a firmware.
pub trait Transport: Send {
    /// Writes bytes (whole packets); buffered until [`Transport::flush`].
    fn send(&mut self, bytes: &[u8]) -> io::Result<()>;
    fn flush(&mut self) -> io::Result<()>;
    /// Bytes that arrived, waiting at most `timeout`; `Ok(None)` on time-out,
    /// an `UnexpectedEof` error when the firmware closed the link.
    fn recv(&mut self, timeout: Duration) -> io::Result<Option<Vec<u8>>>;
    /// Payload rate of the link in bytes per second, when it is limited.
    fn bytes_per_sec(&self) -> Option<f64> {
        None
    }
    /// Longest a [`Transport::flush`] may wait for the firmware to take bytes before
    /// it fails with `TimedOut` (the session sets its link time-out).
    fn set_write_deadline(&mut self, _deadline: Duration) {}
    /// Human-readable description for messages.
    fn describe(&self) -> String;
    /// What a fault injector did to [outgoing, incoming] bytes, when there is one.
    fn fault_counters(&self) -> Option<[super::FaultCounters; 2]> {
        None
    }
}

impl Transport for Box<dyn Transport> {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        (**self).send(bytes)
    }
    fn flush(&mut self) -> io::Result<()> {
        (**self).flush()
    }
    fn recv(&mut self, timeout: Duration) -> io::Result<Option<Vec<u8>>> {
        (**self).recv(timeout)
    }
    fn bytes_per_sec(&self) -> Option<f64> {
        (**self).bytes_per_sec()
    }
    fn set_write_deadline(&mut self, deadline: Duration) {
        (**self).set_write_deadline(deadline)
    }
    fn describe(&self) -> String {
        (**self).describe()
    }
    fn fault_counters(&self) -> Option<[super::FaultCounters; 2]> {
        (**self).fault_counters()
    }
}

/// Incoming bytes pumped by a reader thread.
pub struct Incoming {
    rx: Receiver<io::Result<Vec<u8>>>,
    _thread: JoinHandle<()>,
}

impl Incoming {
    /// Starts a thread reading `source` until end of input or an error.
    pub fn spawn<R: Read + Send + 'static>(mut source: R, name: &str) -> Self {
        let (tx, rx) = mpsc::channel();
        let thread = std::thread::Builder::new()
            .name(format!("link-rx-{name}"))
            .spawn(move || {
                let mut buf = vec![0u8; 64 * 1024];
                loop {
                    match source.read(&mut buf) {
                        Ok(0) => {
                            let _ = tx.send(Err(io::Error::new(
                                io::ErrorKind::UnexpectedEof,
                                "the firmware closed the link",
                            )));
                            return;
                        }
                        Ok(n) => {
                            if tx.send(Ok(buf[..n].to_vec())).is_err() {
                                return;
                            }
                        }
                        Err(e)
                            if matches!(
                                e.kind(),
                                io::ErrorKind::Interrupted
                                    | io::ErrorKind::TimedOut
                                    | io::ErrorKind::WouldBlock
                            ) => {}
                        Err(e) => {
                            let _ = tx.send(Err(e));
                            return;
                        }
                    }
                }
            })
            .expect("spawning a reader thread");
        Incoming {
            rx,
            _thread: thread,
        }
    }

    pub fn recv(&mut self, timeout: Duration) -> io::Result<Option<Vec<u8>>> {
        match self.rx.recv_timeout(timeout) {
            Ok(r) => r.map(Some),
            Err(RecvTimeoutError::Timeout) => Ok(None),
            Err(RecvTimeoutError::Disconnected) => Err(io::Error::new(
                io::ErrorKind::UnexpectedEof,
                "the firmware link is closed",
            )),
        }
    }
}

/// Batches of outgoing bytes in flight to the writer thread; beyond them a flush waits.
const OUTGOING_BATCHES: usize = 16;
/// Bytes the writer thread writes at a time (0.36 s at 115200 baud).
const WRITE_PIECE: usize = 4096;

/// Outgoing bytes written by a thread: [`Outgoing::flush`] hands the buffered bytes
/// over and fails with `TimedOut` once one write has been blocked for the deadline
/// (the firmware takes no bytes), or the batches in flight stay full that long.
pub struct Outgoing {
    tx: Option<SyncSender<Vec<u8>>>,
    pending: Vec<u8>,
    deadline: Duration,
    /// The writer's error, once it stopped on one.
    error: Arc<Mutex<Option<String>>>,
    /// When the write in progress started, while one is.
    writing_since: Arc<Mutex<Option<Instant>>>,
    _thread: JoinHandle<()>,
}

impl Outgoing {
    /// Starts a thread writing to `sink` (each batch written and flushed).
    pub fn spawn<W: Write + Send + 'static>(mut sink: W, name: &str) -> Self {
        let (tx, rx) = mpsc::sync_channel::<Vec<u8>>(OUTGOING_BATCHES);
        let error = Arc::new(Mutex::new(None));
        let writing_since = Arc::new(Mutex::new(None));
        let (seen, since) = (Arc::clone(&error), Arc::clone(&writing_since));
        let thread = std::thread::Builder::new()
            .name(format!("link-tx-{name}"))
            .spawn(move || {
                for batch in rx {
                    // Piece by piece, each restarting the clock: the deadline is for a
                    // firmware that takes nothing, not for a slow link (64 KiB take 5.7 s
                    // at 115200 baud).
                    let written = batch.chunks(WRITE_PIECE).try_for_each(|piece| {
                        set(&since, Some(Instant::now()));
                        sink.write_all(piece)
                    });
                    let written = written.and_then(|_| sink.flush());
                    set(&since, None);
                    if let Err(e) = written {
                        set(&seen, Some(e.to_string()));
                        return;
                    }
                }
            })
            .expect("spawning a writer thread");
        Outgoing {
            tx: Some(tx),
            pending: Vec::new(),
            deadline: Duration::from_secs(5),
            error,
            writing_since,
            _thread: thread,
        }
    }

    pub fn send(&mut self, bytes: &[u8]) {
        self.pending.extend_from_slice(bytes);
    }

    pub fn set_deadline(&mut self, deadline: Duration) {
        self.deadline = deadline;
    }

    /// Hands the buffered bytes to the writer. Called with nothing buffered, it still
    /// reports a writer blocked past the deadline: the session polls it so.
    pub fn flush(&mut self) -> io::Result<()> {
        let start = Instant::now();
        self.check_blocked(start)?;
        if self.pending.is_empty() {
            return Ok(());
        }
        let mut batch = std::mem::take(&mut self.pending);
        let tx = self.tx.as_ref().ok_or_else(|| self.stopped())?;
        loop {
            self.check_blocked(start)?;
            match tx.try_send(batch) {
                Ok(()) => return Ok(()),
                Err(TrySendError::Disconnected(_)) => return Err(self.stopped()),
                Err(TrySendError::Full(b)) => {
                    batch = b;
                    std::thread::sleep(Duration::from_millis(1));
                }
            }
        }
    }

    /// `TimedOut` when the write in progress (or this flush, since `start`) has waited
    /// for the deadline.
    fn check_blocked(&self, start: Instant) -> io::Result<()> {
        let blocked = self
            .writing_since
            .lock()
            .ok()
            .and_then(|s| *s)
            .map_or(Duration::ZERO, |t| t.elapsed());
        let waited = blocked.max(start.elapsed());
        if waited >= self.deadline {
            return Err(io::Error::new(
                io::ErrorKind::TimedOut,
                format!(
                    "the firmware took no bytes for {:.1} s (stopped or stalled)",
                    waited.as_secs_f64()
                ),
            ));
        }
        Ok(())
    }

    fn stopped(&self) -> io::Error {
        let why = self.error.lock().ok().and_then(|e| e.clone());
        io::Error::new(
            io::ErrorKind::BrokenPipe,
            why.unwrap_or_else(|| "the link's writer stopped".into()),
        )
    }
}

/// Sets a value shared with the writer thread (a poisoned lock only loses the update).
fn set<T>(slot: &Mutex<T>, value: T) {
    if let Ok(mut s) = slot.lock() {
        *s = value;
    }
}

impl Drop for Outgoing {
    fn drop(&mut self) {
        // Closing the channel ends the writer once it has written what it holds; it is
        // not joined, as it may be blocked on a firmware that stopped reading.
        self.tx.take();
    }
}

/// `impl Transport for $link` by delegating to its `inner` [`StreamTransport`]
/// (the links differ only in how they open the stream and what they keep alive).
macro_rules! delegate_to_inner_stream {
    ($($link:ty),+ $(,)?) => {$(
        impl $crate::link::transport::Transport for $link {
            fn send(&mut self, bytes: &[u8]) -> std::io::Result<()> {
                $crate::link::transport::Transport::send(&mut self.inner, bytes)
            }
            fn flush(&mut self) -> std::io::Result<()> {
                $crate::link::transport::Transport::flush(&mut self.inner)
            }
            fn recv(
                &mut self,
                timeout: std::time::Duration,
            ) -> std::io::Result<Option<Vec<u8>>> {
                $crate::link::transport::Transport::recv(&mut self.inner, timeout)
            }
            fn set_write_deadline(&mut self, deadline: std::time::Duration) {
                $crate::link::transport::Transport::set_write_deadline(&mut self.inner, deadline)
            }
            fn describe(&self) -> String {
                $crate::link::transport::Transport::describe(&self.inner)
            }
        }
    )+};
}
pub(crate) use delegate_to_inner_stream;

/// A transport made of a writer thread and a reader thread.
pub struct StreamTransport {
    pub(crate) outgoing: Outgoing,
    pub(crate) incoming: Incoming,
    pub(crate) name: String,
}

impl StreamTransport {
    /// Threads writing to `sink` and reading from `source`; `name` for messages.
    pub fn spawn<W, R>(sink: W, source: R, kind: &str, name: String) -> Self
    where
        W: Write + Send + 'static,
        R: Read + Send + 'static,
    {
        StreamTransport {
            outgoing: Outgoing::spawn(sink, kind),
            incoming: Incoming::spawn(source, kind),
            name,
        }
    }
}

impl Transport for StreamTransport {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.outgoing.send(bytes);
        Ok(())
    }
    fn flush(&mut self) -> io::Result<()> {
        self.outgoing.flush()
    }
    fn set_write_deadline(&mut self, deadline: Duration) {
        self.outgoing.set_deadline(deadline);
    }
    fn recv(&mut self, timeout: Duration) -> io::Result<Option<Vec<u8>>> {
        self.incoming.recv(timeout)
    }
    fn describe(&self) -> String {
        self.name.clone()
    }
}
