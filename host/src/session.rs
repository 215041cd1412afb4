//! The host side of a firmware session: hello, configuration, epochs streamed
//! as frame begin/chunk/end per camera, results and statistics collected. The
//! core's reliable [`Endpoint`] does sequencing, acknowledgements, selective
//! repeat and time-outs; the session moves bytes between it and the transport,
//! sizes frame chunks for the line, and keeps the deadlines.
use crate::link::{FaultCounters, LinkOptions, Transport};
use phototraverse_core::protocol::crc::crc32;
use phototraverse_core::protocol::messages::{
    stage, Aux, Camera, Capabilities, ConfigAccepted, Configure, EpochResult, ErrorCode,
    FrameBegin, FrameChunk, FrameEnd, Hello, Message, MessageType, PixelFormat, Points,
    PointsRequest, Reset, ResultStatus, Stats, CHUNK_HEADER_LEN,
};
use phototraverse_core::protocol::{
    wire_len, Endpoint, EndpointBuffers, EndpointConfig, Event, SendError, MAX_ENCODED, MAX_PACKET,
    MAX_PAYLOAD, PROTOCOL_VERSION,
};
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// Frame bytes per chunk packet by default (`run --chunk`, [`SessionOptions::chunk`]).
pub const DEFAULT_CHUNK: usize = 256;

/// Session tuning.
#[derive(Debug, Clone)]
pub struct SessionOptions {
    /// Frame bytes per chunk packet.
    pub chunk: usize,
    /// Most packets in flight unacknowledged (also bounded by the firmware's window).
    pub window: usize,
    /// No answer for this long: the firmware is declared unresponsive.
    pub timeout: Duration,
    /// Lower bound of the retransmission time-out (raised for slow links; the
    /// endpoint adapts it to the measured round trip above this).
    pub rto: Duration,
    /// Epochs paced at this rate; `None`: as fast as the link goes.
    pub fps: Option<f64>,
    /// Epochs outstanding and none completed for this long: the run stops.
    pub progress_timeout: Duration,
}

impl Default for SessionOptions {
    fn default() -> Self {
        SessionOptions {
            chunk: DEFAULT_CHUNK,
            window: 64,
            timeout: Duration::from_secs(5),
            rto: Duration::from_millis(20),
            fps: None,
            progress_timeout: Duration::from_secs(30),
        }
    }
}

impl SessionOptions {
    pub fn from_link(o: &LinkOptions) -> Self {
        SessionOptions {
            chunk: o.chunk,
            timeout: Duration::from_secs_f64(o.link_timeout.max(0.01)),
            progress_timeout: Duration::from_secs_f64(o.progress_timeout.max(0.01)),
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
    /// Packets written: data, retransmissions and acknowledgements.
    pub packets_sent: u64,
    /// Frame pixel bytes handed to the link.
    pub frame_bytes: u64,
    /// Data packets sent again (lost, or with a time-out's probe).
    pub retransmitted_packets: u64,
    /// Sent again because later packets, or a probe sent after them, arrived
    /// and these did not.
    pub resent_lost: u64,
    /// Sent again with a time-out's probe: the oldest in flight, one per time-out.
    pub resent_timeout: u64,
    pub retransmission_timeouts: u64,
    pub acks_sent: u64,
    pub nacks_sent: u64,
    pub packets_received: u64,
    pub crc_errors: u64,
    pub framing_errors: u64,
    pub oversized: u64,
    pub version_errors: u64,
    /// Decoding resumed at a delimiter after a damaged run (CRC, framing, oversized).
    pub resyncs: u64,
    /// Firmware packets held after a gap until it was filled.
    pub held: u64,
    pub duplicates: u64,
    /// Frame bytes per chunk at the end (the session shrinks chunks on a noisy line).
    pub chunk_bytes: usize,
    /// Fraction of our packets the firmware received damaged (recent, decayed).
    pub damage_rate: f32,
    pub faults: Option<[FaultCounters; 2]>,
}

impl LinkStats {
    /// One line for people: what the link did, to say why a run stopped.
    pub fn summary(&self) -> String {
        format!(
            "{} packets sent ({} retransmitted: {} lost, {} with a time-out's probe; {} \
             retransmission time-outs; chunks of {} bytes, {:.1} % of them damaged), {} \
             received ({} CRC errors, {} framing errors, {} oversized, {} \
             resynchronisations, {} held after a gap)",
            self.packets_sent,
            self.retransmitted_packets,
            self.resent_lost,
            self.resent_timeout,
            self.retransmission_timeouts,
            self.chunk_bytes,
            100.0 * self.damage_rate,
            self.packets_received,
            self.crc_errors,
            self.framing_errors,
            self.oversized,
            self.resyncs,
            self.held,
        )
    }
}

/// MORE answers without a point before [`Session::pull_points`] gives up.
const MAX_EMPTY_POINTS_ROUNDS: u32 = 8;

/// Why a session call failed.
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
    #[error(
        "no progress for {secs:.1} s over {link} while waiting for {what} ({pending} epochs \
         outstanding): the line damages or drops too much; link: {summary}"
    )]
    NoProgress {
        secs: f64,
        link: String,
        what: String,
        pending: usize,
        summary: String,
    },
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
    /// Standard deviations of the left and right camera's pose (zero: not available).
    pub sigma: [f64; 6],
    pub right_sigma: [f64; 6],
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
    pub relative_sd_m: [f32; 3],
    pub step_m: Option<[f32; 3]>,
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
            other => Incoming::Other(other.message_type()),
        }
    }
}

/// Smallest frame chunk the session shrinks to on a noisy line.
const MIN_CHUNK: usize = 32;
/// Unacknowledged packets the host keeps at most.
const HOST_WINDOW_SLOTS: usize = 64;
/// Bytes written before the transport is flushed.
const FLUSH_BYTES: usize = 64 * 1024;

/// The host side of one session over a transport.
pub struct Session<T: Transport> {
    t: T,
    opts: SessionOptions,
    ep: Endpoint<Vec<u8>>,
    /// Origin of the endpoint's clock.
    epoch0: Instant,
    unflushed: usize,
    /// The last intact packet from the firmware (garbage does not count: a line
    /// that garbles everything is a firmware that does not answer).
    last_heard: Instant,
    /// The last sequenced message delivered from the firmware.
    last_delivery: Instant,
    last_nudge: Instant,
    /// The last epoch result, or the first epoch sent after it.
    last_result: Instant,
    started: Instant,
    /// Frame bytes in the last chunk sent.
    chunk_now: usize,
    /// The progress deadline: the option, or more when an epoch takes longer
    /// than that to cross a baud-limited link.
    progress_timeout: Duration,
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
        let window = opts.window.clamp(1, HOST_WINDOW_SLOTS);
        let mut rto = opts.rto;
        if let Some(rate) = t.bytes_per_sec() {
            // A full window must fit through the wire before anything times out.
            let window_bytes = (window * wire_len(chunk + CHUNK_HEADER_LEN)) as f64;
            rto = rto.max(Duration::from_secs_f64(2.0 * window_bytes / rate));
        }
        let cfg = EndpointConfig {
            // The host answers nothing itself: it never needs transmit room to take a message.
            tx_reserve: 0,
            min_rto_us: rto.as_micros() as u64,
            max_rto_us: 16 * rto.as_micros() as u64,
            ..EndpointConfig::default()
        };
        let buffers = EndpointBuffers {
            decode: vec![0u8; MAX_ENCODED],
            reorder: vec![0u8; HOST_WINDOW_SLOTS * MAX_PACKET],
            reorder_slot: MAX_PACKET,
            window: vec![0u8; window * MAX_ENCODED],
            window_slot: MAX_ENCODED,
            raw: vec![0u8; MAX_PACKET],
        };
        let mut s = Session {
            t,
            opts: SessionOptions {
                chunk,
                window,
                rto,
                ..opts
            },
            ep: Endpoint::new(buffers, cfg),
            epoch0: now,
            unflushed: 0,
            last_heard: now,
            last_delivery: now,
            last_nudge: now,
            last_result: now,
            started: now,
            chunk_now: chunk,
            progress_timeout: opts.progress_timeout,
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
        if let Some(rate) = self.t.bytes_per_sec() {
            let bytes = epoch_wire_bytes(f.left.len(), self.opts.chunk) as f64;
            let transfer = Duration::from_secs_f64(3.0 * bytes / rate);
            self.progress_timeout = self.opts.progress_timeout.max(transfer);
        }
        if self.results.len() >= self.sent_epochs.len() {
            // Nothing outstanding: the progress deadline starts with this epoch.
            self.last_result = Instant::now();
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
            let mut offset = 0;
            while offset < data.len() {
                let n = self.chunk_size().min(data.len() - offset);
                self.send_message(&Message::FrameChunk(FrameChunk {
                    epoch: f.epoch,
                    camera,
                    offset: offset as u32,
                    data: &data[offset..offset + n],
                }))?;
                offset += n;
                self.link.frame_bytes += n as u64;
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

    /// Frame bytes for the next chunk: at most the option's size, and small enough
    /// for the firmware to hold the chunk when it arrives after a gap (so a loss
    /// costs one packet); on a line that damages packets, the size with the best
    /// goodput for the damage rate the firmware reports.
    fn chunk_size(&mut self) -> usize {
        let held = self
            .capabilities
            .map_or(usize::MAX, |c| c.held_payload as usize);
        let max = self
            .opts
            .chunk
            .min(held.saturating_sub(CHUNK_HEADER_LEN))
            .max(MIN_CHUNK);
        self.chunk_now = self.ep.tx.advised_payload(MIN_CHUNK, max);
        self.chunk_now
    }

    /// Waits until every epoch sent has its result (processed or lost) and
    /// every processed epoch its statistics.
    pub fn finish(&mut self) -> Result<(), SessionError> {
        self.flush()?;
        let pending: Vec<u32> = self.sent_epochs.iter().map(|e| e.0).collect();
        self.wait_for("the results of the epochs sent", |s| {
            pending.iter().all(|e| match s.results.get(e) {
                Some(r) => r.status == ResultStatus::Lost || s.stats.contains_key(e),
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

    /// The firmware's statistics of every epoch, in epoch order.
    pub fn all_stats(&self) -> impl Iterator<Item = &Stats> {
        self.stats.values()
    }

    pub fn errors(&self) -> &[FirmwareError] {
        &self.errors
    }

    pub fn link_stats(&self) -> LinkStats {
        let d = self.ep.rx.decoder_counters();
        let sent = self.ep.tx.sent;
        LinkStats {
            bytes_sent: sent.bytes,
            packets_sent: sent.packets,
            retransmitted_packets: sent.resent_lost + sent.resent_timeout,
            resent_lost: sent.resent_lost,
            resent_timeout: sent.resent_timeout,
            retransmission_timeouts: sent.timeouts,
            acks_sent: sent.acks,
            nacks_sent: sent.nacks,
            packets_received: d.packets as u64,
            crc_errors: d.crc_errors as u64,
            framing_errors: (d.framing_errors + d.truncated) as u64,
            oversized: d.oversized as u64,
            version_errors: d.version_errors as u64,
            resyncs: (d.crc_errors + d.framing_errors + d.truncated + d.oversized) as u64,
            held: self.ep.tx.counters.gaps as u64,
            duplicates: self.ep.tx.counters.duplicates as u64,
            bytes_received: d.bytes,
            chunk_bytes: self.chunk_now,
            damage_rate: self.ep.tx.damage_rate(),
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
                    sigma: r.sigma.map(f64::from),
                    right_sigma: r.right_sigma.map(f64::from),
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
                        relative_sd_m: a.relative_sd_m,
                        step_m: a.step_m,
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
            .filter(|r| r.status == ResultStatus::Lost)
            .map(|r| r.epoch)
            .collect()
    }

    /// Sends one sequenced message (waiting for window room); returns its sequence number.
    pub fn send_message(&mut self, msg: &Message) -> Result<u16, SessionError> {
        let limit = self.ep.tx.send_limit();
        if self.ep.tx.in_flight() >= limit || self.ep.tx.room() == 0 {
            // Full: wait until an eighth of the window is free, so packets go in
            // bursts rather than one per acknowledgement.
            let resume = (limit - limit / 8).max(1);
            let waiting = Instant::now();
            while self.ep.tx.in_flight() >= resume || self.ep.tx.room() == 0 {
                self.service(Duration::from_millis(20))?;
                // A stopped firmware acknowledges nothing, and the probes that
                // ask it to are too small to fill the pipe and block a write.
                let silent = self.last_heard.elapsed().min(waiting.elapsed());
                self.check_silence(silent, "acknowledgements to free the link's window")?;
            }
        }
        let seq = match self.ep.tx.send(msg) {
            Ok(seq) => seq,
            Err(SendError::TooLarge) | Err(SendError::Full) => {
                return Err(SessionError::Encode(msg.message_type()))
            }
        };
        self.transmit()?;
        Ok(seq)
    }

    /// Writes raw bytes to the link (for tests of the firmware's defences).
    pub fn send_raw(&mut self, bytes: &[u8]) -> Result<(), SessionError> {
        self.t.send(bytes).map_err(|error| SessionError::Io {
            link: self.t.describe(),
            error,
        })?;
        self.flush()
    }

    /// Microseconds on the endpoint's clock.
    fn now_us(&self) -> u64 {
        self.epoch0.elapsed().as_micros() as u64
    }

    /// Writes whatever the endpoint has due: acknowledgements, resends, new packets.
    fn transmit(&mut self) -> Result<(), SessionError> {
        let now = self.now_us();
        while let Some(bytes) = self.ep.poll_transmit(now) {
            self.unflushed += bytes.len();
            if let Err(error) = self.t.send(bytes) {
                return Err(SessionError::Io {
                    link: self.t.describe(),
                    error,
                });
            }
        }
        if self.unflushed >= FLUSH_BYTES {
            self.flush()?;
        }
        Ok(())
    }

    /// Receives and handles what arrives for up to `wait` (less when a
    /// retransmission comes due sooner), then sends what is due.
    pub fn service(&mut self, wait: Duration) -> Result<(), SessionError> {
        self.transmit()?;
        self.flush()?;
        let now = self.now_us();
        let wait = match self.ep.poll_at(now) {
            Some(at) => wait.min(Duration::from_micros(at.saturating_sub(now))),
            None => wait,
        };
        match self.t.recv(wait) {
            Ok(Some(bytes)) => {
                let before = self.ep.rx.decoder_counters().packets;
                self.absorb(&bytes);
                if self.ep.rx.decoder_counters().packets != before {
                    self.last_heard = Instant::now();
                }
                self.ep.acknowledge();
            }
            Ok(None) => {}
            Err(error) => {
                return Err(SessionError::Io {
                    link: self.t.describe(),
                    error,
                })
            }
        }
        self.transmit()?;
        self.check_progress()
    }

    /// Epochs outstanding and none completed within the progress deadline: the
    /// line is too poor to go on (the firmware may still be answering, garbled).
    fn check_progress(&self) -> Result<(), SessionError> {
        let pending = self.sent_epochs.len().saturating_sub(self.results.len());
        let quiet = self.last_result.elapsed();
        if pending > 0 && quiet > self.progress_timeout {
            return Err(self.no_progress(quiet, "the results of the epochs sent"));
        }
        Ok(())
    }

    fn no_progress(&self, quiet: Duration, what: &str) -> SessionError {
        SessionError::NoProgress {
            secs: quiet.as_secs_f64(),
            link: self.t.describe(),
            what: what.to_string(),
            pending: self.sent_epochs.len().saturating_sub(self.results.len()),
            summary: self.link_stats().summary(),
        }
    }

    pub fn wait_for(
        &mut self,
        what: &str,
        done: impl Fn(&Self) -> bool,
    ) -> Result<(), SessionError> {
        let started = Instant::now();
        loop {
            if done(self) {
                return Ok(());
            }
            self.service(Duration::from_millis(20))?;
            // Acknowledgements get through but no answer does (a line that lets
            // short packets pass and damages every long one).
            let quiet = self.last_delivery.elapsed().min(started.elapsed());
            if quiet > self.progress_timeout {
                return Err(self.no_progress(quiet, what));
            }
            let silent = self.last_heard.elapsed();
            self.check_silence(silent, what)?;
            let patience = self.answer_patience();
            if silent > patience && self.last_nudge.elapsed() > patience {
                // An answer of the firmware may be lost and the firmware has no
                // reason to look at its timers: ask it to resend now.
                self.last_nudge = Instant::now();
                self.ep.nudge();
            }
        }
    }

    /// How long the firmware may be silent before the host asks it to resend: a
    /// retransmission time-out, or twice the firmware's work on its last epoch,
    /// whichever is longer, but at most half the link time-out, so that a lost
    /// answer is asked for before the session gives up. The firmware cannot answer
    /// while it computes an epoch (one thread, on a microcontroller), so a shorter
    /// wait makes it resend answers that were never lost.
    fn answer_patience(&self) -> Duration {
        let rto = Duration::from_micros(self.ep.tx.rto_us());
        let last = self.stats.values().next_back().map(|s| &s.timings_us);
        answer_patience(rto, last, self.opts.timeout / 2)
    }

    /// Nothing intact heard for `silent`: past the link time-out, the firmware
    /// does not answer.
    fn check_silence(&self, silent: Duration, what: &str) -> Result<(), SessionError> {
        if silent > self.opts.timeout {
            return Err(SessionError::Timeout {
                secs: silent.as_secs_f64(),
                link: self.t.describe(),
                what: what.to_string(),
            });
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

    /// Feeds received bytes to the endpoint and takes the messages it delivers.
    fn absorb(&mut self, bytes: &[u8]) {
        let mut input = bytes;
        loop {
            let now = self.now_us();
            let (n, event) = self.ep.receive(now, input);
            input = &input[n..];
            match event {
                Some(Event::Message { .. }) => {
                    self.last_delivery = Instant::now();
                    let taken = self
                        .ep
                        .rx
                        .message()
                        .map(|(seq, m)| (seq, m.map(Incoming::from_message)));
                    match taken {
                        Some((_, Ok(msg))) => self.apply(msg),
                        Some((seq, Err(_))) => self.errors.push(FirmwareError {
                            code: "Malformed".into(),
                            epoch: None,
                            text: format!("host could not parse the firmware's packet {seq}"),
                        }),
                        None => {}
                    }
                }
                Some(Event::Version(v)) => self.errors.push(FirmwareError {
                    code: "Version".into(),
                    epoch: None,
                    text: format!(
                        "host received a packet of protocol version {v}; it speaks {PROTOCOL_VERSION}"
                    ),
                }),
                None if input.is_empty() => return,
                None => {}
            }
        }
    }

    fn apply(&mut self, msg: Incoming) {
        match msg {
            Incoming::Capabilities(c) => self.capabilities = Some(c),
            Incoming::Accepted(a) => self.accepted = Some(a),
            Incoming::Result(r) => {
                self.last_result = Instant::now();
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
            Incoming::Other(t) => self.errors.push(FirmwareError {
                code: "Unexpected".into(),
                epoch: None,
                text: format!("host received an unexpected {t:?} message"),
            }),
        }
    }
}

/// Opens the link the options name and says hello (`run_dataset` does the same with
/// the image a QEMU link needs).
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

/// [`Session::answer_patience`] from the retransmission time-out and the stage
/// timings of the firmware's last epoch (assembly is the frames' transfer, not work).
fn answer_patience(
    rto: Duration,
    last: Option<&[u32; stage::COUNT]>,
    at_most: Duration,
) -> Duration {
    let work_us = last.map_or(0, |t| t[stage::TOTAL].saturating_sub(t[stage::ASSEMBLE]));
    rto.max(Duration::from_micros(2 * u64::from(work_us)).min(at_most))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_host_waits_out_the_firmware_s_work_before_it_asks_for_a_resend() {
        let rto = Duration::from_millis(20);
        let cap = Duration::from_millis(2500);
        assert_eq!(answer_patience(rto, None, cap), rto, "no epoch yet");
        let mut t = [0u32; stage::COUNT];
        t[stage::ASSEMBLE] = 900_000; // the frames' transfer: not work
        t[stage::TOTAL] = 950_000;
        assert_eq!(
            answer_patience(rto, Some(&t), cap),
            Duration::from_millis(100)
        );
        t[stage::TOTAL] = 905_000;
        assert_eq!(answer_patience(rto, Some(&t), cap), rto, "quick work");
        // An epoch of 2 s on an emulated core: asked again before the link gives up.
        t[stage::TOTAL] = 2_900_000;
        assert_eq!(answer_patience(rto, Some(&t), cap), cap);
    }
}
