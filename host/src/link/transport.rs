//! The byte pipe between host and firmware. Every transport moves opaque bytes
//! (already framed by the protocol); reads run on a thread feeding a channel so
//! the session can wait with a time-out on any kind of link.
use std::io::{self, Read, Write};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::thread::JoinHandle;
use std::time::Duration;

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
            fn describe(&self) -> String {
                $crate::link::transport::Transport::describe(&self.inner)
            }
        }
    )+};
}
pub(crate) use delegate_to_inner_stream;

/// A transport made of any writer and a reader thread.
pub struct StreamTransport<W: Write + Send> {
    pub(crate) writer: W,
    pub(crate) incoming: Incoming,
    pub(crate) name: String,
}

impl<W: Write + Send> Transport for StreamTransport<W> {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.writer.write_all(bytes)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.writer.flush()
    }
    fn recv(&mut self, timeout: Duration) -> io::Result<Option<Vec<u8>>> {
        self.incoming.recv(timeout)
    }
    fn describe(&self) -> String {
        self.name.clone()
    }
}
