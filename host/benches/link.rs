//! Link benchmarks, a plain `harness = false` program:
//! `cargo bench -p phototraverse-host --bench link [-- --quick]`.
//!
//! 1. In-process throughput of frame data through the whole protocol (encode,
//!    COBS, CRC, window, decoder, assembly, whole-frame CRC), 640x480 stereo
//!    epochs, against a peer in the same run: the same frames moved as raw
//!    buffers over the same kind of channel to a thread that only CRCs them.
//! 2. Time of one 640x480 stereo epoch at 921600 baud: computed from the
//!    bytes on the wire (framing included) and measured through the bandwidth
//!    limiter.
use phototraverse_core::camera::{Interior, Rig};
use phototraverse_core::protocol::crc::crc32;
use phototraverse_core::protocol::messages::{Configure, Pipeline, PixelFormat, CONFIG_VERSION};
use phototraverse_host::link::inproc::InProc;
use phototraverse_host::link::throttle::Throttled;
use phototraverse_host::link::{FirmwareProcessor, Transport};
use phototraverse_host::session::{epoch_wire_bytes, EpochFrames, Session, SessionOptions};
use std::time::Instant;

const W: u16 = 640;
const H: u16 = 480;

fn frames(epoch: u32) -> (Vec<u8>, Vec<u8>) {
    let mk = |cam: u32| -> Vec<u8> {
        (0..W as u32 * H as u32)
            .map(|i| ((i * 31 + epoch * 7 + cam * 13) % 253) as u8)
            .collect()
    };
    (mk(0), mk(1))
}

fn config() -> Configure {
    let rig = Rig::rectified(Interior::pinhole_px(W as u32, H as u32, 700.0), 0.54);
    Configure {
        version: CONFIG_VERSION,
        traverse: Default::default(),
        rig,
        pipeline: Pipeline {
            max_width: W,
            max_height: H,
            ..Pipeline::default()
        },
    }
}

fn run_epochs<T: Transport>(
    t: T,
    opts: SessionOptions,
    epochs: u32,
    data: &[(Vec<u8>, Vec<u8>)],
) -> (f64, u64, u64) {
    let mut s = Session::open(t, opts).expect("hello");
    s.configure(&config()).expect("configure");
    let t0 = Instant::now();
    for e in 0..epochs {
        let (l, r) = &data[e as usize % data.len()];
        let f = EpochFrames {
            epoch: e,
            timestamp_us: 0,
            width: W,
            height: H,
            format: PixelFormat::Gray8,
            left: l,
            right: r,
            aux: None,
        };
        s.send_epoch(&f).expect("send");
    }
    s.finish().expect("results");
    let dt = t0.elapsed().as_secs_f64();
    let link = s.link_stats();
    (dt, link.frame_bytes, link.bytes_sent)
}

/// The peer: raw frames over a channel to a thread that CRCs them.
fn raw_channel(epochs: u32, data: &[(Vec<u8>, Vec<u8>)]) -> f64 {
    let (tx, rx) = std::sync::mpsc::channel::<Vec<u8>>();
    let t0 = Instant::now();
    let th = std::thread::spawn(move || {
        let mut acc = 0u32;
        while let Ok(v) = rx.recv() {
            acc ^= crc32(&v);
        }
        acc
    });
    for e in 0..epochs {
        let (l, r) = &data[e as usize % data.len()];
        tx.send(l.clone()).unwrap();
        tx.send(r.clone()).unwrap();
    }
    drop(tx);
    std::hint::black_box(th.join().unwrap());
    t0.elapsed().as_secs_f64()
}

/// CPU cost of the protocol alone, one thread: encode every chunk of a frame,
/// decode it and assemble the frame (no channel, no threads).
fn codec_only(frames: u32, chunk: usize, data: &[(Vec<u8>, Vec<u8>)]) -> f64 {
    use phototraverse_core::protocol::assembly::FrameAssembler;
    use phototraverse_core::protocol::messages::{
        Camera, FrameBegin, FrameChunk, FrameEnd, Message,
    };
    use phototraverse_core::protocol::{Decoder, Header, PacketBuffers, MAX_ENCODED};
    let mut bufs = Box::<PacketBuffers>::default();
    let mut dec = Decoder::new(vec![0u8; MAX_ENCODED]);
    let mut frame = vec![0u8; W as usize * H as usize];
    let mut asm = FrameAssembler::new(&mut frame, W, H);
    let t0 = Instant::now();
    for k in 0..frames {
        let img = &data[k as usize % data.len()].0;
        let begin = FrameBegin {
            epoch: k,
            camera: Camera::Left,
            format: PixelFormat::Gray8,
            width: W,
            height: H,
            timestamp_us: 0,
        };
        asm.begin(begin).unwrap();
        for (i, part) in img.chunks(chunk).enumerate() {
            let m = Message::FrameChunk(FrameChunk {
                epoch: k,
                camera: Camera::Left,
                offset: (i * chunk) as u32,
                data: part,
            });
            let wire = bufs
                .encode(
                    Header {
                        message: m.message_type(),
                        seq: i as u16,
                    },
                    |p| m.emit(p),
                )
                .unwrap();
            let (_, ev) = dec.feed(wire);
            let p = ev.unwrap().unwrap();
            if let Message::FrameChunk(c) = Message::parse(p.type_byte(), p.payload()).unwrap() {
                asm.chunk(&c).unwrap();
            }
        }
        asm.end(&FrameEnd {
            epoch: k,
            camera: Camera::Left,
            total_bytes: img.len() as u32,
            crc32: crc32(img),
        })
        .unwrap();
    }
    frames as f64 * W as f64 * H as f64 / 1e6 / t0.elapsed().as_secs_f64()
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let data: Vec<_> = (0..4).map(frames).collect();
    let epoch_bytes = 2.0 * W as f64 * H as f64;
    for chunk in [1024usize, 4087] {
        println!(
            "codec only (one thread, encode + decode + assemble), chunk {chunk}: {:.1} MB/s",
            codec_only(if quick { 40 } else { 400 }, chunk, &data)
        );
    }

    let epochs = if quick { 20 } else { 200 };
    let mb = epochs as f64 * epoch_bytes / 1e6;
    // The session keeps chunks within what the firmware holds after a gap (256
    // bytes), so larger options do not reach the wire.
    for chunk in [128usize, 256] {
        let opts = SessionOptions {
            chunk,
            window: 64,
            ..Default::default()
        };
        // The statistics processor reads every pixel but leaves the link the bottleneck.
        let fw = InProc::spawn(8 << 20, Default::default(), FirmwareProcessor::Stats);
        let (dt, frame_bytes, wire) = run_epochs(fw, opts, epochs, &data);
        assert_eq!(frame_bytes as f64, epochs as f64 * epoch_bytes);
        let peer = raw_channel(epochs, &data);
        println!(
            "inproc chunk {chunk:>4}: {epochs} stereo 640x480 epochs, {:.1} MB frame data in {:.3} s = {:.1} MB/s \
             (wire {:.1} MB, overhead {:.2}%); peer raw channel + CRC {:.1} MB/s; ratio protocol/peer {:.2}",
            mb,
            dt,
            mb / dt,
            wire as f64 / 1e6,
            100.0 * (wire as f64 / frame_bytes as f64 - 1.0),
            mb / peer,
            peer / dt
        );
    }

    // The shipped firmware (SIFT on both images) for reference: where the time goes then.
    let sift_epochs = if quick { 3 } else { 10 };
    let fw = InProc::spawn(16 << 20, Default::default(), FirmwareProcessor::Sift);
    let (dt, _, _) = run_epochs(fw, SessionOptions::default(), sift_epochs, &data);
    println!(
        "inproc with SIFT on both images: {sift_epochs} epochs in {dt:.3} s = {:.1} epochs/s ({:.1} MB/s of frames)",
        sift_epochs as f64 / dt,
        sift_epochs as f64 * epoch_bytes / 1e6 / dt
    );

    let baud = 921_600u32;
    for chunk in [256usize, 1024, 4087] {
        let wire = epoch_wire_bytes(W as usize * H as usize, chunk);
        println!(
            "640x480 stereo epoch at {baud} baud, chunk {chunk:>4}: {wire} bytes on the wire (worst-case COBS) \
             = {:.3} s computed (8N1)",
            wire as f64 * 10.0 / baud as f64
        );
    }
    let measured_epochs = if quick { 1 } else { 2 };
    let opts = SessionOptions {
        timeout: std::time::Duration::from_secs(30),
        ..Default::default()
    };
    let t = Throttled::new(
        InProc::spawn(8 << 20, Default::default(), FirmwareProcessor::Sift),
        baud,
    );
    let (dt, _, wire) = run_epochs(t, opts, measured_epochs, &data);
    println!(
        "640x480 stereo epoch at {baud} baud, chunk {}, measured through the limiter: {:.3} s per epoch \
         ({} wire bytes per epoch)",
        SessionOptions::default().chunk,
        dt / measured_epochs as f64,
        wire / measured_epochs as u64
    );
}
