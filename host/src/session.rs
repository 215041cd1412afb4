//! The host side of a firmware session: hello, configuration, epochs streamed
//! as frame begin/chunk/end per camera, results and statistics collected, with
//! go-back-N retransmission, acknowledgements and time-outs.
use crate::link::{FaultCounters, LinkOptions, Transport};
use phototraverse_core::protocol::crc::crc32;
use phototraverse_core::protocol::messages::{
    nack_reason, Ack, Aux, Camera, Capabilities, ConfigAccepted, Configure, EpochResult,
    EpochStatus, ErrorCode, FrameBegin, FrameChunk, FrameEnd, Hello, Message, MessageType, Nack,
    PixelFormat, Points, PointsRequest, Reset, Stats, CHUNK_HEADER_LEN,
};
use phototraverse_core::protocol::window::{seq_diff, Accept, RxSequence};
use phototraverse_core::protocol::{
    wire_len, DecodeError, Decoder, Header, PacketBuffers, PacketError,
};
use phototraverse_core::protocol::{MAX_ENCODED, MAX_PAYLOAD, PROTOCOL_VERSION};
use std::collections::{BTreeMap, VecDeque};
use std::time::{Duration, Instant};

/// Session tuning.
#[derive(Debug, Clone)]
pub struct SessionOptions {
    /// Frame bytes per chunk packet.
    pub chunk: usize,
    /// Most packets in flight unacknowledged (also bounded by the firmware's window).
    pub window: usize,
    /// No answer for this long: the firmware is declared unresponsive.
    pub timeout: Duration,
    /// Retransmission time-out (raised for slow links).
    pub rto: Duration,
    /// Epochs paced at this rate; `None`: as fast as the link goes.
    pub fps: Option<f64>,
}

impl Default for SessionOptions {
    fn default() -> Self {
        SessionOptions {
            chunk: 1024,
            window: 32,
            timeout: Duration::from_secs(5),
            rto: Duration::from_millis(200),
            fps: None,
        }
    }
}

impl SessionOptions {
    pub fn from_link(o: &LinkOptions) -> Self {
        SessionOptions {
            chunk: o.chunk,
            timeout: Duration::from_secs_f64(o.link_timeout.max(0.01)),
            fps: o.fps,
            ..Default::default()
        }
    }
}

/// One stereo epoch to send.
#[derive(Debug, Clone, Copy)]
pub struct EpochFrames<'a> {
    pub epoch: u32,
    pub timestamp_us: u64,
    pub width: u16,
    pub height: u16,
    pub format: PixelFormat,
    pub left: &'a [u8],
    pub right: &'a [u8],
    pub aux: Option<Aux>,
}

impl<'a> EpochFrames<'a> {
    /// A stereo pair of 8-bit images (the datasets' format), without auxiliary data.
    pub fn gray8(
        epoch: u32,
        timestamp_us: u64,
        left: &'a crate::dataset::GrayImage,
        right: &'a crate::dataset::GrayImage,
    ) -> Self {
        EpochFrames {
            epoch,
            timestamp_us,
            width: left.width as u16,
            height: left.height as u16,
            format: PixelFormat::Gray8,
            left: &left.data,
            right: &right.data,
            aux: None,
        }
    }
}

/// An Error message from the firmware (or a host-side link error), owned.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FirmwareError {
    pub code: String,
    pub epoch: Option<u32>,
    pub text: String,
}

/// Link figures of a session (host side; the firmware's are in its Stats).
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct LinkStats {
    pub bytes_sent: u64,
    pub bytes_received: u64,
    pub packets_sent: u64,
    /// Frame pixel bytes handed to the link.
    pub frame_bytes: u64,
    pub retransmitted_packets: u64,
    pub retransmission_timeouts: u64,
    pub nacks_received: u64,
    pub nacks_sent: u64,
    pub packets_received: u64,
    pub crc_errors: u64,
    pub framing_errors: u64,
    pub oversized: u64,
    pub version_errors: u64,
    pub duplicates: u64,
    pub gaps: u64,
    pub faults: Option<[FaultCounters; 2]>,
}

impl LinkStats {
    /// One line for people: what the link did, to say why a run stopped.
    pub fn summary(&self) -> String {
        format!(
            "{} packets sent ({} retransmitted, {} retransmission time-outs, {} NACKs received), \
             {} received ({} CRC errors, {} framing errors, {} oversized, {} gaps)",
            self.packets_sent,
            self.retransmitted_packets,
            self.retransmission_timeouts,
            self.nacks_received,
            self.packets_received,
            self.crc_errors,
            self.framing_errors,
            self.oversized,
            self.gaps,
        )
    }
}

/// Why a session call failed.
/// MORE answers without a point before [`Session::pull_points`] gives up.
const MAX_EMPTY_POINTS_ROUNDS: u32 = 8;

#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    #[error("the firmware did not answer for {secs:.1} s over {link} while waiting for {what}")]
    Timeout {
        secs: f64,
        link: String,
        what: String,
    },
    // The I/O error is part of the text and deliberately not a `source`: an
    // `{:#}` chain would print it twice.
    #[error("link error over {link}: {error}")]
    Io { link: String, error: std::io::Error },
    #[error("the firmware rejected the configuration ({code}): {text}")]
    ConfigRejected { code: String, text: String },
    #[error("the firmware speaks protocol version {firmware}, this host speaks {host}")]
    Version { firmware: u8, host: u8 },
    #[error("cannot encode a {0:?} message")]
    Encode(MessageType),
    #[error(
        "the firmware keeps announcing more tie points without sending any ({rounds} requests)"
    )]
    PointsStalled { rounds: u32 },
}

/// Everything a session collected.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SessionReport {
    pub results: Vec<EpochResultRecord>,
    pub stats: Vec<StatsRecord>,
    pub errors: Vec<FirmwareError>,
    pub link: LinkStats,
    pub elapsed_s: f64,
}

/// A result with the time from the epoch's first byte sent to its result.
#[derive(Debug, Clone, serde::Serialize)]
pub struct EpochResultRecord {
    pub epoch: u32,
    /// The wire's status code (`docs/protocol.md`, Result).
    pub status: u8,
    pub pose: [f64; 6],
    pub sigma: [f64; 6],
    /// The wire's flag bits.
    pub flags: u32,
    pub keypoints: [u32; 2],
    pub stereo_matches: u32,
    pub tie_points: u32,
    pub window_points: u32,
    pub observations: u32,
    pub new_points: u32,
    pub dropped: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub adjustment: Option<AdjustmentRecord>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sift: Option<SiftRecord>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub image_stats: Option<ImageStatsRecord>,
    pub latency_s: f64,
}

/// The adjustment figures of a result.
#[derive(Debug, Clone, serde::Serialize)]
pub struct AdjustmentRecord {
    pub sigma0: f64,
    pub rms_px: f64,
    pub chi2: f64,
    pub redundancy: u32,
}

/// The feature extractor's figures of a result (left, right).
#[derive(Debug, Clone, serde::Serialize)]
pub struct SiftRecord {
    pub extrema: [u32; 2],
    pub refined: [u32; 2],
}

/// The image statistics of a result (left, right).
#[derive(Debug, Clone, serde::Serialize)]
pub struct ImageStatsRecord {
    pub mean: [f64; 2],
    pub gradient_energy: [f64; 2],
    pub median: [u8; 2],
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct StatsRecord {
    pub epoch: u32,
    pub timings_us: [u32; 8],
    pub memory_predicted: u32,
    pub memory_high_water: u32,
    pub memory_capacity: u32,
    pub firmware_crc_errors: u32,
    pub firmware_retransmissions: u32,
}

/// A firmware message owned by the host.
enum Incoming {
    Capabilities(Capabilities),
    Accepted(ConfigAccepted),
    Result(EpochResult),
    Stats(Stats),
    Points(Box<Points>),
    Error(FirmwareError, ErrorCode),
    Ack(Ack),
    Nack(Nack),
    Other(MessageType),
}

impl Incoming {
    fn from_message(m: Message) -> Self {
        match m {
            Message::Capabilities(c) => Incoming::Capabilities(c),
            Message::ConfigAccepted(c) => Incoming::Accepted(c),
            Message::Result(r) => Incoming::Result(r),
            Message::Stats(s) => Incoming::Stats(s),
            Message::Points(p) => Incoming::Points(Box::new(p)),
            Message::Error(e) => Incoming::Error(
                FirmwareError {
                    code: format!("{:?}", e.code),
                    epoch: (e.epoch != u32::MAX).then_some(e.epoch),
                    text: e.text.to_string(),
                },
                e.code,
            ),
            Message::Ack(a) => Incoming::Ack(a),
            Message::Nack(n) => Incoming::Nack(n),
            other => Incoming::Other(other.message_type()),
        }
    }
}

// Short-lived (one per decoded packet): the size of a Result with its rig block is fine.
#[allow(clippy::large_enum_variant)]
enum Event {
    Packet(u16, MessageType, Incoming),
    Malformed(u16),
    Fault(DecodeError),
}

/// The host side of one session over a transport.
pub struct Session<T: Transport> {
    t: T,
    opts: SessionOptions,
    decoder: Decoder<Vec<u8>>,
    bufs: Box<PacketBuffers>,
    window: VecDeque<(u16, Vec<u8>)>,
    next_seq: u16,
    rx: RxSequence,
    delivered_unacked: u32,
    unflushed: usize,
    last_progress: Instant,
    last_heard: Instant,
    started: Instant,
    rto: Duration,
    /// Current retransmission time-out: `rto`, doubled on each time-out.
    backoff: Duration,
    /// Congestion window (packets): halved on every loss, grown by one per
    /// window of acknowledgements, so a noisy link wastes less on go-back-N.
    cwnd: f64,
    capabilities: Option<Capabilities>,
    accepted: Option<ConfigAccepted>,
    config_error: Option<FirmwareError>,
    results: BTreeMap<u32, EpochResult>,
    result_at: BTreeMap<u32, Instant>,
    stats: BTreeMap<u32, Stats>,
    errors: Vec<FirmwareError>,
    sent_epochs: Vec<(u32, Instant)>,
    link: LinkStats,
    /// Tie point reports received and not yet taken.
    points: Vec<Points>,
    /// The answer to the last PointsRequest is complete; whether more is pending.
    points_answered: bool,
    points_more: bool,
}

impl<T: Transport> Session<T> {
    /// Says hello and waits for the firmware's capabilities.
    pub fn open(mut t: T, opts: SessionOptions) -> Result<Self, SessionError> {
        let now = Instant::now();
        t.set_write_deadline(opts.timeout);
        let chunk = opts.chunk.clamp(1, MAX_PAYLOAD - CHUNK_HEADER_LEN);
        let mut rto = opts.rto;
        if let Some(rate) = t.bytes_per_sec() {
            // A full window must fit through the wire before retransmitting it.
            let window_bytes = (opts.window * wire_len(chunk + CHUNK_HEADER_LEN)) as f64;
            rto = rto.max(Duration::from_secs_f64(2.0 * window_bytes / rate));
        }
        let mut s = Session {
            t,
            opts: SessionOptions { chunk, ..opts },
            decoder: Decoder::new(vec![0u8; MAX_ENCODED]),
            bufs: Box::default(),
            window: VecDeque::new(),
            next_seq: 0,
            rx: RxSequence::new(16),
            delivered_unacked: 0,
            unflushed: 0,
            last_progress: now,
            last_heard: now,
            started: now,
            rto,
            backoff: rto,
            cwnd: opts.window as f64,
            capabilities: None,
            accepted: None,
            config_error: None,
            results: BTreeMap::new(),
            result_at: BTreeMap::new(),
            stats: BTreeMap::new(),
            errors: Vec::new(),
            sent_epochs: Vec::new(),
            link: LinkStats::default(),
            points: Vec::new(),
            points_answered: false,
            points_more: false,
        };
        let session = rand::random::<u32>();
        let version = env!("CARGO_PKG_VERSION")
            .split('.')
            .map(|v| v.parse().unwrap_or(0))
            .collect::<Vec<u8>>();
        let host_version = [
            version[0],
            *version.get(1).unwrap_or(&0),
            *version.get(2).unwrap_or(&0),
        ];
        s.send_message(&Message::Hello(Hello {
            session,
            host_version,
        }))?;
        s.wait_for("the firmware's capabilities", |s| s.capabilities.is_some())?;
        let caps = s.capabilities.expect("waited for");
        if caps.protocol_version != PROTOCOL_VERSION {
            return Err(SessionError::Version {
                firmware: caps.protocol_version,
                host: PROTOCOL_VERSION,
            });
        }
        Ok(s)
    }

    pub fn capabilities(&self) -> Capabilities {
        self.capabilities
            .expect("open() waits for the capabilities")
    }

    pub fn describe(&self) -> String {
        self.t.describe()
    }

    /// Sends a configuration; the firmware's acceptance, or its error as `ConfigRejected`.
    pub fn configure(&mut self, config: &Configure) -> Result<ConfigAccepted, SessionError> {
        self.accepted = None;
        self.config_error = None;
        self.send_message(&Message::Configure(*config))?;
        self.wait_for("the configuration's answer", |s| {
            s.accepted.is_some() || s.config_error.is_some()
        })?;
        match (self.accepted, self.config_error.take()) {
            (Some(a), _) => Ok(a),
            (None, Some(e)) => Err(SessionError::ConfigRejected {
                code: e.code,
                text: e.text,
            }),
            (None, None) => unreachable!("waited for one of them"),
        }
    }

    /// Asks the firmware to drop its configuration; waits for its capabilities.
    pub fn reset(&mut self) -> Result<(), SessionError> {
        self.capabilities = None;
        self.send_message(&Message::Reset(Reset { reason: 0 }))?;
        self.wait_for("the capabilities after a reset", |s| {
            s.capabilities.is_some()
        })
    }

    /// Streams one epoch: auxiliary data, then for each camera FrameBegin,
    /// chunks and FrameEnd with the whole-frame CRC. Returns when everything is
    /// handed to the link (results arrive later; see [`Session::finish`]).
    pub fn send_epoch(&mut self, f: &EpochFrames) -> Result<(), SessionError> {
        if let Some(fps) = self.opts.fps.filter(|r| *r > 0.0) {
            // Epoch k leaves k frame intervals after the first one, like a camera's trigger.
            let origin = self.sent_epochs.first().map_or_else(Instant::now, |e| e.1);
            let due = origin + Duration::from_secs_f64(self.sent_epochs.len() as f64 / fps);
            while Instant::now() < due {
                self.service(
                    due.saturating_duration_since(Instant::now())
                        .min(Duration::from_millis(20)),
                )?;
            }
        }
        self.sent_epochs.push((f.epoch, Instant::now()));
        if let Some(aux) = f.aux {
            self.send_message(&Message::Aux(aux))?;
        }
        for (camera, data) in [(Camera::Left, f.left), (Camera::Right, f.right)] {
            let begin = FrameBegin {
                epoch: f.epoch,
                camera,
                format: f.format,
                width: f.width,
                height: f.height,
                timestamp_us: f.timestamp_us,
            };
            self.send_message(&Message::FrameBegin(begin))?;
            for (k, part) in data.chunks(self.opts.chunk).enumerate() {
                let offset = (k * self.opts.chunk) as u32;
                self.send_message(&Message::FrameChunk(FrameChunk {
                    epoch: f.epoch,
                    camera,
                    offset,
                    data: part,
                }))?;
                self.link.frame_bytes += part.len() as u64;
            }
            let end = FrameEnd {
                epoch: f.epoch,
                camera,
                total_bytes: data.len() as u32,
                crc32: crc32(data),
            };
            self.send_message(&Message::FrameEnd(end))?;
        }
        self.flush()
    }

    /// Waits until every epoch sent has its result (processed or lost) and
    /// every processed epoch its statistics.
    pub fn finish(&mut self) -> Result<(), SessionError> {
        self.flush()?;
        let pending: Vec<u32> = self.sent_epochs.iter().map(|e| e.0).collect();
        self.wait_for("the results of the epochs sent", |s| {
            pending.iter().all(|e| match s.results.get(e) {
                Some(r) => r.status == EpochStatus::Lost || s.stats.contains_key(e),
                None => false,
            })
        })
    }

    /// Pulls the firmware's tie point report: requests until the report is
    /// complete and returns its messages. `flush`: the sequence ended, the
    /// firmware makes its whole window final first.
    pub fn pull_points(&mut self, flush: bool) -> Result<Vec<Points>, SessionError> {
        let mut flush = flush;
        // Each MORE answer must bring points: a firmware that keeps announcing more
        // without sending any would otherwise hold the host forever.
        let mut stalled = 0u32;
        loop {
            let before = self.point_records();
            self.points_answered = false;
            self.send_message(&Message::PointsRequest(PointsRequest {
                flush: flush as u8,
            }))?;
            flush = false;
            self.wait_for("the tie point report", |s| s.points_answered)?;
            if !self.points_more {
                return Ok(std::mem::take(&mut self.points));
            }
            stalled = if self.point_records() > before {
                0
            } else {
                stalled + 1
            };
            if stalled >= MAX_EMPTY_POINTS_ROUNDS {
                return Err(SessionError::PointsStalled { rounds: stalled });
            }
        }
    }

    /// Points and observations received so far by [`Session::pull_points`].
    fn point_records(&self) -> usize {
        self.points
            .iter()
            .map(|p| p.n_points as usize + p.n_obs as usize)
            .sum()
    }

    /// The result of an epoch, if it arrived.
    pub fn result(&self, epoch: u32) -> Option<&EpochResult> {
        self.results.get(&epoch)
    }

    pub fn stats(&self, epoch: u32) -> Option<&Stats> {
        self.stats.get(&epoch)
    }

    pub fn errors(&self) -> &[FirmwareError] {
        &self.errors
    }

    pub fn link_stats(&self) -> LinkStats {
        let d = self.decoder.counters();
        LinkStats {
            packets_received: d.packets as u64,
            crc_errors: d.crc_errors as u64,
            framing_errors: (d.framing_errors + d.truncated) as u64,
            oversized: d.oversized as u64,
            version_errors: d.version_errors as u64,
            bytes_received: d.bytes,
            faults: self.t.fault_counters(),
            ..self.link.clone()
        }
    }

    /// Results, statistics, errors and link figures so far.
    pub fn report(&self) -> SessionReport {
        let sent: BTreeMap<u32, Instant> = self.sent_epochs.iter().copied().collect();
        let results = self
            .results
            .values()
            .map(|r| {
                let latency_s = match (sent.get(&r.epoch), self.result_at.get(&r.epoch)) {
                    (Some(a), Some(b)) => b.saturating_duration_since(*a).as_secs_f64(),
                    _ => 0.0,
                };
                let c = &r.counts;
                EpochResultRecord {
                    epoch: r.epoch,
                    status: r.status.code(),
                    pose: r.pose,
                    sigma: r.sigma,
                    flags: r.flags.bits(),
                    keypoints: c.keypoints,
                    stereo_matches: c.stereo_matches,
                    tie_points: c.tie_points,
                    window_points: c.window_points,
                    observations: c.observations,
                    new_points: c.new_points,
                    dropped: c.dropped,
                    adjustment: r.adjustment().map(|a| AdjustmentRecord {
                        sigma0: a.sigma0,
                        rms_px: a.rms_px,
                        chi2: a.chi2,
                        redundancy: a.redundancy,
                    }),
                    sift: r.sift().map(|s| SiftRecord {
                        extrema: s.extrema,
                        refined: s.refined,
                    }),
                    image_stats: r.image_stats().map(|s| ImageStatsRecord {
                        mean: s.mean,
                        gradient_energy: s.gradient_energy,
                        median: s.median,
                    }),
                    latency_s,
                }
            })
            .collect();
        let stats = self
            .stats
            .values()
            .map(|s| StatsRecord {
                epoch: s.epoch,
                timings_us: s.timings_us,
                memory_predicted: s.memory_predicted,
                memory_high_water: s.memory_high_water,
                memory_capacity: s.memory_capacity,
                firmware_crc_errors: s.link.crc_errors,
                firmware_retransmissions: s.link.retransmissions,
            })
            .collect();
        SessionReport {
            results,
            stats,
            errors: self.errors.clone(),
            link: self.link_stats(),
            elapsed_s: self.started.elapsed().as_secs_f64(),
        }
    }

    /// Epochs whose result says they were lost.
    pub fn lost_epochs(&self) -> Vec<u32> {
        self.results
            .values()
            .filter(|r| r.status == EpochStatus::Lost)
            .map(|r| r.epoch)
            .collect()
    }

    /// Sends one sequenced message (waiting for window room); returns its sequence number.
    pub fn send_message(&mut self, msg: &Message) -> Result<u16, SessionError> {
        loop {
            let limit = self.opts.window.min(
                self.capabilities
                    .map_or(usize::MAX, |c| c.rx_window.max(1) as usize),
            );
            let limit = limit.min(self.cwnd as usize).max(1);
            if self.window.len() < limit {
                break;
            }
            // Full: wait until a quarter of the window is free, so packets go in
            // bursts rather than one per acknowledgement.
            let resume = limit - limit / 4;
            while self.window.len() >= resume.max(1) {
                self.service(self.rto / 4)?;
            }
        }
        let seq = self.next_seq;
        let wire = self.encode(msg, seq)?;
        if self.window.is_empty() {
            self.last_progress = Instant::now();
        }
        self.next_seq = seq.wrapping_add(1);
        self.write(&wire)?;
        self.window.push_back((seq, wire));
        Ok(seq)
    }

    /// Writes raw bytes to the link (for tests of the firmware's defences).
    pub fn send_raw(&mut self, bytes: &[u8]) -> Result<(), SessionError> {
        self.write(bytes)?;
        self.flush()
    }

    /// Receives and handles what arrives for up to `wait`, then runs the timers.
    pub fn service(&mut self, wait: Duration) -> Result<(), SessionError> {
        self.flush()?;
        match self.t.recv(wait) {
            Ok(Some(bytes)) => {
                self.last_heard = Instant::now();
                self.absorb(&bytes)?;
            }
            Ok(None) => {}
            Err(error) => {
                return Err(SessionError::Io {
                    link: self.t.describe(),
                    error,
                })
            }
        }
        if !self.window.is_empty() && self.last_progress.elapsed() > self.backoff {
            self.link.retransmission_timeouts += 1;
            self.cwnd = (self.cwnd / 2.0).max(2.0);
            // Exponential back-off: a firmware busy with an epoch is not a lossy
            // link; progress resets it.
            self.backoff = (self.backoff * 2).min(self.rto * 16);
            // Our acknowledgement may be what was lost: a firmware whose window is
            // full of unacknowledged answers takes nothing new until it gets one.
            self.send_ack()?;
            let from = self.window.front().map(|w| w.0).unwrap_or(self.next_seq);
            self.retransmit_from(from)?;
            self.last_progress = Instant::now();
        }
        Ok(())
    }

    pub fn wait_for(
        &mut self,
        what: &str,
        done: impl Fn(&Self) -> bool,
    ) -> Result<(), SessionError> {
        let mut last_nudge = Instant::now();
        loop {
            if done(self) {
                return Ok(());
            }
            self.service(Duration::from_millis(20).min(self.rto))?;
            let silent = self.last_heard.elapsed();
            if silent > self.opts.timeout {
                return Err(SessionError::Timeout {
                    secs: silent.as_secs_f64(),
                    link: self.t.describe(),
                    what: what.to_string(),
                });
            }
            if silent > self.backoff && last_nudge.elapsed() > self.backoff {
                // Our window may be fine while an answer of the firmware was lost:
                // ask it to resend from what we expect.
                last_nudge = Instant::now();
                self.backoff = (self.backoff * 2).min(self.rto * 16);
                self.send_control(&Message::Nack(Nack {
                    expected: self.rx.expected(),
                    reason: nack_reason::TIMEOUT,
                }))?;
                self.link.nacks_sent += 1;
            }
        }
    }

    fn write(&mut self, bytes: &[u8]) -> Result<(), SessionError> {
        self.link.bytes_sent += bytes.len() as u64;
        self.link.packets_sent += 1;
        self.t.send(bytes).map_err(|error| SessionError::Io {
            link: self.t.describe(),
            error,
        })?;
        self.unflushed += bytes.len();
        if self.unflushed >= 64 * 1024 {
            self.flush()?;
        }
        Ok(())
    }

    /// Flushes the transport; also when nothing is buffered, so a transport whose
    /// writes are blocked reports it (see [`Transport::set_write_deadline`]).
    fn flush(&mut self) -> Result<(), SessionError> {
        self.unflushed = 0;
        self.t.flush().map_err(|error| SessionError::Io {
            link: self.t.describe(),
            error,
        })
    }

    /// The framed bytes of `msg` with sequence number `seq`.
    fn encode(&mut self, msg: &Message, seq: u16) -> Result<Vec<u8>, SessionError> {
        Ok(self
            .bufs
            .encode(
                Header {
                    message: msg.message_type(),
                    seq,
                },
                |p| msg.emit(p),
            )
            .map_err(|_| SessionError::Encode(msg.message_type()))?
            .to_vec())
    }

    /// Unsequenced control message (ack, nack).
    fn send_control(&mut self, msg: &Message) -> Result<(), SessionError> {
        let seq = self.next_seq;
        let wire = self.encode(msg, seq)?;
        self.write(&wire)?;
        self.flush()
    }

    fn retransmit_from(&mut self, from: u16) -> Result<(), SessionError> {
        let packets: Vec<Vec<u8>> = self
            .window
            .iter()
            .filter(|(s, _)| seq_diff(*s, from) >= 0)
            .map(|(_, w)| w.clone())
            .collect();
        for p in packets {
            self.link.retransmitted_packets += 1;
            self.write(&p)?;
        }
        self.flush()
    }

    fn release(&mut self, next_expected: u16) {
        let Some(&(base, _)) = self.window.front() else {
            return;
        };
        let d = seq_diff(next_expected, base);
        if d > 0 && d as usize <= self.window.len() {
            self.window.drain(..d as usize);
            self.last_progress = Instant::now();
            self.backoff = self.rto;
            self.cwnd = (self.cwnd + d as f64 / self.cwnd).min(self.opts.window as f64);
        }
    }

    fn absorb(&mut self, bytes: &[u8]) -> Result<(), SessionError> {
        let mut events = Vec::new();
        let mut input = bytes;
        while !input.is_empty() {
            let (n, ev) = self.decoder.feed(input);
            input = &input[n..];
            match ev {
                None => {}
                Some(Err(e)) => events.push(Event::Fault(e)),
                Some(Ok(p)) => {
                    let seq = p.seq();
                    match Message::parse(p.type_byte(), p.payload()) {
                        Ok(m) => events.push(Event::Packet(
                            seq,
                            m.message_type(),
                            Incoming::from_message(m),
                        )),
                        Err(_) => events.push(Event::Malformed(seq)),
                    }
                }
            }
        }
        for ev in events {
            self.handle(ev)?;
        }
        if self.delivered_unacked > 0 {
            self.send_ack()?;
        }
        Ok(())
    }

    fn send_ack(&mut self) -> Result<(), SessionError> {
        self.delivered_unacked = 0;
        let ack = Ack {
            next_expected: self.rx.expected(),
            window: 64,
        };
        self.send_control(&Message::Ack(ack))
    }

    fn handle(&mut self, ev: Event) -> Result<(), SessionError> {
        let (seq, t, msg) = match ev {
            Event::Fault(e) => {
                if let DecodeError::Packet(PacketError::Version(v)) = e {
                    self.errors.push(FirmwareError {
                        code: "Version".into(),
                        epoch: None,
                        text: format!("host received a packet of protocol version {v}; it speaks {PROTOCOL_VERSION}"),
                    });
                } else if self.rx.corrupted() {
                    self.link.nacks_sent += 1;
                    let nack = Nack {
                        expected: self.rx.expected(),
                        reason: nack_reason::CORRUPTED,
                    };
                    self.send_control(&Message::Nack(nack))?;
                }
                return Ok(());
            }
            Event::Malformed(seq) => {
                if self.rx.accept(seq) == Accept::Deliver {
                    self.delivered_unacked += 1;
                    self.errors.push(FirmwareError {
                        code: "Malformed".into(),
                        epoch: None,
                        text: format!("host could not parse the firmware's packet {seq}"),
                    });
                }
                return Ok(());
            }
            Event::Packet(seq, t, msg) => (seq, t, msg),
        };
        match msg {
            Incoming::Ack(a) => {
                self.release(a.next_expected);
                return Ok(());
            }
            Incoming::Nack(n) => {
                self.link.nacks_received += 1;
                self.cwnd = (self.cwnd / 2.0).max(2.0);
                self.release(n.expected);
                return self.retransmit_from(n.expected);
            }
            _ => {}
        }
        debug_assert!(t.is_sequenced());
        match self.rx.accept(seq) {
            Accept::Deliver => {
                self.delivered_unacked += 1;
                self.apply(msg);
            }
            Accept::Duplicate => {
                self.link.duplicates += 1;
                self.delivered_unacked += 1;
            }
            Accept::Gap { nack } => {
                self.link.gaps += 1;
                if nack {
                    self.link.nacks_sent += 1;
                    self.send_control(&Message::Nack(Nack {
                        expected: self.rx.expected(),
                        reason: nack_reason::GAP,
                    }))?;
                }
            }
        }
        Ok(())
    }

    fn apply(&mut self, msg: Incoming) {
        match msg {
            Incoming::Capabilities(c) => self.capabilities = Some(c),
            Incoming::Accepted(a) => self.accepted = Some(a),
            Incoming::Result(r) => {
                self.result_at.insert(r.epoch, Instant::now());
                self.results.insert(r.epoch, r);
            }
            Incoming::Stats(s) => {
                self.stats.insert(s.epoch, s);
            }
            Incoming::Points(p) => {
                use phototraverse_core::protocol::messages::points_flags;
                if p.flags & points_flags::ANSWER_END != 0 {
                    self.points_answered = true;
                    self.points_more = p.flags & points_flags::MORE != 0;
                }
                self.points.push(*p);
            }
            Incoming::Error(e, code) => {
                if matches!(code, ErrorCode::ConfigTooLarge | ErrorCode::ConfigInvalid) {
                    self.config_error = Some(e.clone());
                }
                eprintln!("phototraverse: firmware error {}: {}", e.code, e.text);
                self.errors.push(e);
            }
            Incoming::Ack(_) | Incoming::Nack(_) => {}
            Incoming::Other(t) => self.errors.push(FirmwareError {
                code: "Unexpected".into(),
                epoch: None,
                text: format!("host received an unexpected {t:?} message"),
            }),
        }
    }
}

/// Opens the link the options name and says hello: what `phototraverse run` calls.
pub fn connect(link: &LinkOptions) -> anyhow::Result<Session<Box<dyn Transport>>> {
    let t = link.open()?;
    Ok(Session::open(t, SessionOptions::from_link(link))?)
}

impl<T: Transport> Session<T> {
    /// Configures, streams every epoch and waits for all results: the whole
    /// session in one call.
    pub fn run<'a>(
        &mut self,
        config: &Configure,
        epochs: impl IntoIterator<Item = EpochFrames<'a>>,
    ) -> Result<SessionReport, SessionError> {
        self.configure(config)?;
        for f in epochs {
            self.send_epoch(&f)?;
        }
        self.finish()?;
        Ok(self.report())
    }
}

/// Bytes on the wire for one stereo epoch of `frame_bytes` per camera sent in
/// `chunk`-byte chunks, framing included (COBS worst case: no zero bytes in the data).
pub fn epoch_wire_bytes(frame_bytes: usize, chunk: usize) -> usize {
    let chunks = frame_bytes.div_ceil(chunk);
    let full = frame_bytes / chunk;
    let last = frame_bytes - full * chunk;
    let per_camera = full * wire_len(CHUNK_HEADER_LEN + chunk)
        + if last > 0 { wire_len(CHUNK_HEADER_LEN + last) } else { 0 }
        + wire_len(19) // FrameBegin
        + wire_len(13); // FrameEnd
    debug_assert!(chunks >= full);
    2 * per_camera
}
