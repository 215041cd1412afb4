//! The firmware's protocol loop: idle until configured, then assemble the
//! frames of each epoch into buffers carved from the arena, run the processor
//! on every complete epoch and answer results and statistics. A bad frame
//! costs its epoch (an Error and a LOST result), never the session.
use crate::link::{
    Flow, Link, LinkBuffers, Served, Tx, RX_HELD_PAYLOAD, RX_WINDOW, TX_MAX_PAYLOAD,
};
use crate::processor::{BuildError, Clock, EpochInput, EpochProcessor, ProcessorFactory};
use embedded_io::{Read, Write};
use phototraverse_core::budget::{slice_bytes, Arena, ComponentKind, MemoryBudget, Stage};
use phototraverse_core::protocol::assembly::{AssemblyError, FrameAssembler};
use phototraverse_core::protocol::messages::{
    points_flags, stage, Aux, Camera, Capabilities, ConfigAccepted, Configure, EpochResult,
    ErrorCode, Message, Points, ResultStatus, SettingError, StackUse, Stats,
};
use phototraverse_core::protocol::{MAX_PAYLOAD, PROTOCOL_VERSION};

/// Firmware version reported in the capabilities.
pub const FIRMWARE_VERSION: [u8; 3] = [0, 1, 0];

/// What the firmware accepts, whatever its memory.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    pub max_width: u16,
    pub max_height: u16,
    pub max_keypoints: u32,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_width: 4096,
            max_height: 4096,
            max_keypoints: 20_000,
        }
    }
}

/// Where a configured phase goes next.
// No allocator to box into: the configuration moves by value once per phase.
#[allow(clippy::large_enum_variant)]
enum Next {
    Configure(Configure),
    Idle,
    Eof,
}

/// Bytes of one frame buffer for a configuration.
pub fn frame_bytes(config: &Configure) -> Result<usize, BuildError> {
    usize::try_from(frame_bytes_u64(config)).map_err(|_| {
        BuildError::Invalid("max_width x max_height x pixel_bytes: more than this target addresses")
    })
}

/// [`frame_bytes`] before it meets the target's `usize`: the largest frame the
/// fields allow (65535 x 65535 x 2 bytes) overflows a 32-bit one.
pub fn frame_bytes_u64(config: &Configure) -> u64 {
    let p = &config.pipeline;
    p.max_width as u64 * p.max_height as u64 * p.pixel_bytes as u64
}

/// What a configuration needs from the firmware's working storage: the two frame
/// buffers and the processor's components. The firmware checks it before carving;
/// the host predicts with the same function (`phototraverse budget`, run reports).
pub fn configuration_budget<F: ProcessorFactory>(
    factory: &F,
    config: &Configure,
    budget: &mut MemoryBudget,
) -> Result<(), BuildError> {
    let frame = frame_bytes(config)?;
    budget.add(
        "firmware.frame_left",
        ComponentKind::Frame,
        slice_bytes::<u8>(frame),
    );
    budget.add(
        "firmware.frame_right",
        ComponentKind::Frame,
        slice_bytes::<u8>(frame),
    );
    factory.budget(config, budget)
}

/// The firmware: its working storage, processor factory, clock and limits.
pub struct Firmware<'w, F, C> {
    work: &'w mut [u8],
    /// Separate storage for the two frame buffers (a part whose RAM is in blocks);
    /// without it the frames are carved from `work` too.
    frames: Option<&'w mut [u8]>,
    /// Reads the stack's high-water mark, on a target that paints its stack.
    stack_gauge: Option<fn() -> StackUse>,
    factory: F,
    clock: C,
    limits: Limits,
}

impl<'w, F: ProcessorFactory, C: Clock> Firmware<'w, F, C> {
    pub fn new(work: &'w mut [u8], factory: F, clock: C, limits: Limits) -> Self {
        Firmware {
            work,
            frames: None,
            stack_gauge: None,
            factory,
            clock,
            limits,
        }
    }

    /// Carves the two frame buffers from `frames` instead of the working storage.
    pub fn with_frame_storage(mut self, frames: &'w mut [u8]) -> Self {
        self.frames = Some(frames);
        self
    }

    /// Reports the stack's high-water mark in every Stats, as `gauge` reads it.
    pub fn with_stack_gauge(mut self, gauge: fn() -> StackUse) -> Self {
        self.stack_gauge = Some(gauge);
        self
    }

    /// Bytes of working storage, frame storage included.
    fn storage_bytes(&self) -> usize {
        self.work.len() + self.frames.as_ref().map_or(0, |f| f.len())
    }

    pub fn capabilities(&self) -> Capabilities {
        Capabilities {
            firmware_version: FIRMWARE_VERSION,
            protocol_version: PROTOCOL_VERSION,
            max_payload: MAX_PAYLOAD as u16,
            rx_window: RX_WINDOW,
            max_width: self.limits.max_width,
            max_height: self.limits.max_height,
            pixel_formats: 0b11,
            processor: F::KIND,
            max_keypoints: self.limits.max_keypoints,
            work_bytes: self.storage_bytes().min(u32::MAX as usize) as u32,
            link_bytes: LinkBuffers::BYTES as u32,
            held_payload: RX_HELD_PAYLOAD as u16,
        }
    }

    /// Serves the port until it ends.
    pub fn run<P: Read + Write>(
        &mut self,
        port: &mut P,
        buffers: &mut LinkBuffers,
    ) -> Result<(), P::Error> {
        let mut link = Link::new(buffers);
        let mut pending = None;
        loop {
            let config = match pending.take() {
                Some(c) => c,
                None => match self.idle(port, &mut link)? {
                    Some(c) => c,
                    None => return Ok(()),
                },
            };
            match self.configured(port, &mut link, &config)? {
                Next::Configure(c) => pending = Some(c),
                Next::Idle => {}
                Next::Eof => return Ok(()),
            }
        }
    }

    /// Without a configuration: answer hello/reset, refuse frames.
    fn idle<P: Read + Write>(
        &mut self,
        port: &mut P,
        link: &mut Link,
    ) -> Result<Option<Configure>, P::Error> {
        let caps = self.capabilities();
        let mut refused = None;
        let served = link.serve(port, &self.clock, |tx, port, seq, msg| {
            match msg {
                Message::Hello(_) | Message::Reset(_) => {
                    tx.send(port, &Message::Capabilities(caps))?
                }
                Message::Configure(c) => return Ok(Flow::Exit(c)),
                Message::FrameBegin(b) if refused != Some(b.epoch) => {
                    refused = Some(b.epoch);
                    tx.error(
                        port,
                        ErrorCode::NotConfigured,
                        b.epoch,
                        seq,
                        format_args!("frame before a configuration"),
                    )?;
                }
                Message::FrameBegin(_)
                | Message::FrameChunk(_)
                | Message::FrameEnd(_)
                | Message::Aux(_) => {}
                other => unexpected(tx, port, seq, &other)?,
            }
            Ok(Flow::Continue)
        })?;
        Ok(match served {
            Served::Exit(c) => Some(c),
            Served::Eof => None,
        })
    }

    /// Checks limits and memory, carves buffers, then serves epochs.
    fn configured<P: Read + Write>(
        &mut self,
        port: &mut P,
        link: &mut Link,
        config: &Configure,
    ) -> Result<Next, P::Error> {
        let p = &config.pipeline;
        if let Err(text) = self.check_limits(config) {
            link.tx(&self.clock).error(
                port,
                ErrorCode::ConfigInvalid,
                u32::MAX,
                u16::MAX,
                format_args!("{text}"),
            )?;
            return Ok(Next::Idle);
        }
        let mut budget = MemoryBudget::new();
        let planned = configuration_budget(&self.factory, config, &mut budget)
            .and_then(|()| frame_bytes(config));
        let frame = match planned {
            Ok(frame) => frame,
            Err(e) => {
                link.tx(&self.clock).error(
                    port,
                    ErrorCode::ConfigInvalid,
                    u32::MAX,
                    u16::MAX,
                    format_args!("processor: {e:?}"),
                )?;
                return Ok(Next::Idle);
            }
        };
        let capacity = self.storage_bytes();
        if let Some(text) = self.shortfall(&budget) {
            link.tx(&self.clock).error(
                port,
                ErrorCode::ConfigTooLarge,
                u32::MAX,
                u16::MAX,
                format_args!("{text}"),
            )?;
            return Ok(Next::Idle);
        }
        let caps = self.capabilities();
        let Firmware {
            work,
            frames,
            stack_gauge,
            factory,
            clock,
            ..
        } = self;
        let mut arena = Arena::new(work);
        let mut frame_arena = frames.as_deref_mut().map(Arena::new);
        let built = (|| {
            let frame_from = frame_arena.as_mut().unwrap_or(&mut arena);
            let left = frame_from.alloc_slice::<u8>(frame)?;
            let right = frame_from.alloc_slice::<u8>(frame)?;
            let processor = factory.build(config, &mut arena)?;
            Ok::<_, BuildError>((left, right, processor))
        })();
        let (left, right, processor) = match built {
            Ok(b) => b,
            Err(e) => {
                let code = match e {
                    BuildError::OutOfMemory(_) => ErrorCode::ConfigTooLarge,
                    BuildError::Invalid(_) => ErrorCode::ConfigInvalid,
                };
                link.tx(&*clock).error(
                    port,
                    code,
                    u32::MAX,
                    u16::MAX,
                    format_args!("processor: {e:?}"),
                )?;
                return Ok(Next::Idle);
            }
        };
        let used = arena.used() + frame_arena.as_ref().map_or(0, Arena::used);
        let frames_carved = frame_arena
            .as_ref()
            .map_or([0; Stage::ALL.len()], Arena::carved);
        let carved = arena.carved();
        let accepted = ConfigAccepted {
            predicted_bytes: budget.total() as u32,
            frame_bytes: 2 * frame as u32,
            capacity_bytes: capacity as u32,
            carved_bytes: core::array::from_fn(|k| (carved[k] + frames_carved[k]) as u32),
        };
        link.tx(&*clock)
            .send(port, &Message::ConfigAccepted(accepted))?;
        let mut epochs = Epochs {
            frames: [
                FrameAssembler::new(left, p.max_width, p.max_height),
                FrameAssembler::new(right, p.max_width, p.max_height),
            ],
            processor,
            caps,
            clock: &*clock,
            aux: None,
            lost: [u32::MAX; 4],
            lost_at: 0,
            started_us: 0,
            ok: 0,
            lost_count: 0,
            predicted: budget.total() as u32,
            high_water: used as u32,
            capacity: capacity as u32,
            stack_gauge: *stack_gauge,
            last_epoch: u32::MAX,
            points_index: 0,
        };
        let served = link.serve(port, &*clock, |tx, port, seq, msg| {
            epochs.handle(tx, port, seq, msg)
        })?;
        Ok(match served {
            Served::Exit(n) => n,
            Served::Eof => Next::Eof,
        })
    }

    /// Why the storage cannot hold what `budget` predicts, if it cannot.
    fn shortfall(&self, budget: &MemoryBudget) -> Option<Shortfall> {
        let frames = budget.total_of(ComponentKind::Frame);
        let total = budget.total();
        match &self.frames {
            None if total > self.work.len() => Some(Shortfall::Total {
                needed: total,
                frames,
                capacity: self.work.len(),
            }),
            Some(store) if frames > store.len() => Some(Shortfall::Frames {
                needed: frames,
                capacity: store.len(),
            }),
            Some(_) if total - frames > self.work.len() => Some(Shortfall::Arena {
                needed: total - frames,
                capacity: self.work.len(),
            }),
            _ => None,
        }
    }

    /// The settings' own limits (the same the host checks), then this firmware's.
    fn check_limits(&self, config: &Configure) -> Result<(), Refusal> {
        config.validate().map_err(Refusal::Setting)?;
        let p = &config.pipeline;
        let l = &self.limits;
        if p.max_width > l.max_width || p.max_height > l.max_height {
            return Err(Refusal::FrameSize(
                [p.max_width, p.max_height],
                [l.max_width, l.max_height],
            ));
        }
        if p.keypoints_per_image > l.max_keypoints {
            return Err(Refusal::Keypoints(p.keypoints_per_image, l.max_keypoints));
        }
        if config.rig.validate().is_err() {
            return Err(Refusal::Rig);
        }
        Ok(())
    }
}

/// Which storage a configuration overflows, and by how much.
enum Shortfall {
    Total {
        needed: usize,
        frames: usize,
        capacity: usize,
    },
    Frames {
        needed: usize,
        capacity: usize,
    },
    Arena {
        needed: usize,
        capacity: usize,
    },
}

impl core::fmt::Display for Shortfall {
    fn fmt(&self, f: &mut core::fmt::Formatter) -> core::fmt::Result {
        match *self {
            Shortfall::Total {
                needed,
                frames,
                capacity,
            } => write!(
                f,
                "configuration needs {needed} bytes ({frames} for frames) but the firmware has {capacity}"
            ),
            Shortfall::Frames { needed, capacity } => write!(
                f,
                "the two frame buffers need {needed} bytes but the firmware's frame storage has {capacity}"
            ),
            Shortfall::Arena { needed, capacity } => write!(
                f,
                "configuration needs {needed} bytes besides the frames but the firmware's arena has {capacity}"
            ),
        }
    }
}

/// Why a configuration is refused before anything is carved.
enum Refusal {
    Setting(SettingError),
    FrameSize([u16; 2], [u16; 2]),
    Keypoints(u32, u32),
    Rig,
}

impl core::fmt::Display for Refusal {
    fn fmt(&self, f: &mut core::fmt::Formatter) -> core::fmt::Result {
        match self {
            Refusal::Setting(e) => write!(f, "{e}"),
            Refusal::FrameSize([w, h], [mw, mh]) => write!(
                f,
                "max_width, max_height {w}x{h} exceed this firmware's largest frame {mw}x{mh}"
            ),
            Refusal::Keypoints(n, max) => write!(
                f,
                "keypoints_per_image {n} exceeds this firmware's limit of {max}"
            ),
            Refusal::Rig => write!(
                f,
                "rig: the interior orientation or the base does not validate"
            ),
        }
    }
}

fn unexpected<P: Write>(
    tx: &mut Tx,
    port: &mut P,
    seq: u16,
    msg: &Message,
) -> Result<(), P::Error> {
    tx.error(
        port,
        ErrorCode::Unexpected,
        u32::MAX,
        seq,
        format_args!("unexpected {:?} message", msg.message_type()),
    )
}

/// State of a configured session.
struct Epochs<'a, 'c, Pr> {
    frames: [FrameAssembler<'a>; 2],
    processor: Pr,
    caps: Capabilities,
    clock: &'c dyn Clock,
    aux: Option<Aux>,
    /// Recently lost epochs (each reported once).
    lost: [u32; 4],
    lost_at: usize,
    started_us: u64,
    ok: u32,
    lost_count: u32,
    predicted: u32,
    high_water: u32,
    capacity: u32,
    stack_gauge: Option<fn() -> StackUse>,
    /// Epoch of the last result (named in tie point reports).
    last_epoch: u32,
    /// Index of the next Points message of the current report.
    points_index: u16,
}

/// Most Points messages sent in answer to one request: the link keeps this many
/// transmit slots free before it takes a message in.
const POINTS_PER_REQUEST: usize = 4;

impl<Pr: EpochProcessor> Epochs<'_, '_, Pr> {
    fn handle<P: Write>(
        &mut self,
        tx: &mut Tx,
        port: &mut P,
        seq: u16,
        msg: Message,
    ) -> Result<Flow<Next>, P::Error> {
        match msg {
            Message::Configure(c) => return Ok(Flow::Exit(Next::Configure(c))),
            Message::Hello(_) | Message::Reset(_) => {
                // The configuration is dropped; the host configures again after the capabilities.
                tx.send(port, &Message::Capabilities(self.caps))?;
                return Ok(Flow::Exit(Next::Idle));
            }
            Message::Aux(a) => self.aux = Some(a),
            Message::PointsRequest(r) => self.points(tx, port, r.flush != 0)?,
            Message::FrameBegin(b) => {
                if b.camera == Camera::Left {
                    self.started_us = self.clock.now_us();
                }
                let expected = self.processor.frame_size(b.camera.index());
                if let Some((w, h)) = expected.filter(|&s| s != (b.width, b.height)) {
                    // Refused before its chunks arrive: the rest of the epoch is ignored.
                    self.frames[b.camera.index()].refuse(b.epoch);
                    return self
                        .lose(
                            tx,
                            port,
                            b.epoch,
                            ErrorCode::FrameSize,
                            seq,
                            format_args!(
                                "{:?} frame is {}x{}, the configured camera's width_px x height_px is {w}x{h}",
                                b.camera, b.width, b.height
                            ),
                        )
                        .map(|_| Flow::Continue);
                }
                match self.frames[b.camera.index()].begin(b) {
                    Ok(Some(abandoned)) => self.lose(
                        tx,
                        port,
                        abandoned,
                        ErrorCode::EpochIncomplete,
                        seq,
                        format_args!("epoch {abandoned} abandoned: epoch {} began first", b.epoch),
                    )?,
                    Ok(None) => {}
                    Err(AssemblyError::TooLarge { bytes, capacity }) => self.lose(
                        tx,
                        port,
                        b.epoch,
                        ErrorCode::FrameTooLarge,
                        seq,
                        format_args!(
                            "frame {}x{} ({bytes} bytes) exceeds the configured capacity ({capacity} bytes)",
                            b.width, b.height
                        ),
                    )?,
                    Err(e) => self.lose(tx, port, b.epoch, ErrorCode::Other, seq, format_args!("{e:?}"))?,
                }
            }
            Message::FrameChunk(c) => match self.frames[c.camera.index()].chunk(&c) {
                Ok(()) | Err(AssemblyError::AlreadyFailed) => {}
                Err(AssemblyError::OutOfOrder { expected, got }) => self.lose(
                    tx,
                    port,
                    c.epoch,
                    ErrorCode::ChunkOutOfOrder,
                    seq,
                    format_args!(
                        "chunk of {:?} frame at offset {got}, expected {expected}",
                        c.camera
                    ),
                )?,
                Err(e) => self.lose(
                    tx,
                    port,
                    c.epoch,
                    ErrorCode::Unexpected,
                    seq,
                    format_args!("chunk: {e:?}"),
                )?,
            },
            Message::FrameEnd(e) => match self.frames[e.camera.index()].end(&e) {
                Ok(()) => self.try_process(tx, port, e.epoch)?,
                Err(AssemblyError::AlreadyFailed) => {}
                Err(err) => self.lose(
                    tx,
                    port,
                    e.epoch,
                    ErrorCode::FrameCrc,
                    seq,
                    format_args!("frame end: {err:?}"),
                )?,
            },
            other => unexpected(tx, port, seq, &other)?,
        }
        Ok(Flow::Continue)
    }

    /// Answers a PointsRequest: up to [`POINTS_PER_REQUEST`] Points messages,
    /// the last without [`points_flags::MORE`] once the report is complete.
    fn points<P: Write>(&mut self, tx: &mut Tx, port: &mut P, flush: bool) -> Result<(), P::Error> {
        for k in 0..POINTS_PER_REQUEST {
            let mut msg = Points::new(self.last_epoch, self.points_index);
            let more = self
                .processor
                .points(flush && k == 0, TX_MAX_PAYLOAD, &mut msg);
            if more {
                msg.flags |= points_flags::MORE;
            }
            if flush {
                msg.flags |= points_flags::FLUSH;
            }
            if !more || k + 1 == POINTS_PER_REQUEST {
                msg.flags |= points_flags::ANSWER_END;
            }
            self.points_index = if more {
                self.points_index.wrapping_add(1)
            } else {
                0
            };
            tx.send(port, &Message::Points(msg))?;
            if !more {
                break;
            }
        }
        Ok(())
    }

    fn is_lost(&self, epoch: u32) -> bool {
        self.lost.contains(&epoch)
    }

    /// Reports an epoch lost once: an Error with the cause and a LOST result.
    fn lose<P: Write>(
        &mut self,
        tx: &mut Tx,
        port: &mut P,
        epoch: u32,
        code: ErrorCode,
        seq: u16,
        text: core::fmt::Arguments,
    ) -> Result<(), P::Error> {
        if self.is_lost(epoch) {
            return Ok(());
        }
        self.lost[self.lost_at] = epoch;
        self.lost_at = (self.lost_at + 1) % self.lost.len();
        self.lost_count += 1;
        tx.error(port, code, epoch, seq, text)?;
        tx.send(
            port,
            &Message::Result(EpochResult::empty(epoch, ResultStatus::Lost)),
        )
    }

    fn try_process<P: Write>(
        &mut self,
        tx: &mut Tx,
        port: &mut P,
        epoch: u32,
    ) -> Result<(), P::Error> {
        if self.is_lost(epoch)
            || !self.frames[0].is_complete(epoch)
            || !self.frames[1].is_complete(epoch)
        {
            return Ok(());
        }
        let assembled = self.clock.now_us();
        let (Some((left, lb)), Some((right, rb))) =
            (self.frames[0].image(epoch), self.frames[1].image(epoch))
        else {
            return Ok(());
        };
        let aux = self.aux.filter(|a| a.epoch == epoch);
        let input = EpochInput {
            epoch,
            left,
            right,
            timestamps_us: [lb.timestamp_us, rb.timestamp_us],
            aux,
        };
        let mut out = self.processor.process(&input, self.clock);
        let done = self.clock.now_us();
        out.timings_us[stage::ASSEMBLE] = assembled.saturating_sub(self.started_us) as u32;
        out.timings_us[stage::TOTAL] = done.saturating_sub(self.started_us) as u32;
        self.ok += 1;
        self.last_epoch = epoch;
        self.points_index = 0;
        tx.send(port, &Message::Result(out.result))?;
        let stats = Stats {
            epoch,
            timings_us: out.timings_us,
            memory_predicted: self.predicted,
            memory_high_water: self.high_water,
            memory_capacity: self.capacity,
            epochs_ok: self.ok,
            epochs_lost: self.lost_count,
            link: tx.counters(),
            capacities: self.processor.capacities(),
            stack: self.stack_gauge.map(|gauge| gauge()),
        };
        tx.send(port, &Message::Stats(stats))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use phototraverse_core::camera::{Interior, Rig};
    use phototraverse_core::protocol::messages::{Pipeline, TraverseSettings, CONFIG_VERSION};

    #[test]
    fn the_largest_frame_the_fields_allow_is_refused_not_wrapped() {
        let mut config = Configure {
            version: CONFIG_VERSION,
            rig: Rig::rectified(Interior::pinhole_px(640, 480, 700.0), 0.5),
            pipeline: Pipeline::default(),
            traverse: TraverseSettings::default(),
        };
        config.pipeline.max_width = u16::MAX;
        config.pipeline.max_height = u16::MAX;
        config.pipeline.pixel_bytes = 2;
        assert_eq!(frame_bytes_u64(&config), 8_589_672_450);
        // What a 32-bit target's `usize` makes of it: refused, not wrapped to 4.3 GB less.
        assert!(u32::try_from(frame_bytes_u64(&config)).is_err());
        let mut budget = MemoryBudget::new();
        budget.add("a", ComponentKind::Frame, usize::MAX);
        budget.add("b", ComponentKind::Frame, 2);
        assert_eq!(budget.total(), usize::MAX, "the total saturates");
    }
}
