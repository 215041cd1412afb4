//! Sessions between the host and the firmware over every transport, with
//! faults, bad input and an unresponsive firmware.
use phototraverse_core::camera::{Interior, Rig};
use phototraverse_core::protocol::crc::crc32;
use phototraverse_core::protocol::messages::{
    Camera, Configure, ErrorCode, FrameBegin, FrameChunk, FrameEnd, Message, Pipeline, PixelFormat,
    ResultStatus, CONFIG_VERSION,
};
use phototraverse_core::protocol::{encode_packet, Header, MAX_PACKET};
use phototraverse_host::link::inproc::InProc;
use phototraverse_host::link::net::{Pty, SerialLink, TcpLink};
use phototraverse_host::link::{
    child, FaultConfig, FaultCounters, Faulty, FirmwareProcessor, LinkKind, LinkOptions, Transport,
};
use phototraverse_host::session::{EpochFrames, Session, SessionError, SessionOptions};
use std::io;
use std::time::Duration;

const W: u16 = 128;
const H: u16 = 96;

/// A test image of Gaussian blobs and a ramp; it moves with the epoch and is
/// shifted for the right camera (disparity).
fn image(epoch: u32, camera: u32, w: u16, h: u16) -> Vec<u8> {
    let mut seed = 12345u32;
    let mut next = || {
        seed = seed.wrapping_mul(1_103_515_245).wrapping_add(12345);
        (seed >> 8) as f64 / (1u32 << 24) as f64
    };
    let blobs: Vec<[f64; 4]> = (0..14)
        .map(|_| {
            [
                next() * w as f64,
                next() * h as f64,
                2.0 + 4.0 * next(),
                next(),
            ]
        })
        .collect();
    let shift = 1.5 * epoch as f64 + 4.0 * camera as f64;
    let mut v = Vec::with_capacity(w as usize * h as usize);
    for r in 0..h as usize {
        for c in 0..w as usize {
            let mut val = 40.0 + 0.3 * c as f64;
            for b in &blobs {
                let (dx, dy) = (c as f64 + shift - b[0], r as f64 - b[1]);
                let sign = if b[3] > 0.5 { 1.0 } else { -0.5 };
                val += sign * 150.0 * (-(dx * dx + dy * dy) / (2.0 * b[2] * b[2])).exp();
            }
            v.push(val.clamp(0.0, 255.0) as u8);
        }
    }
    v
}

/// Keypoints, extrema and refined locations the core's SIFT finds in an image under
/// `config`, extracted here.
fn local_sift(img: &[u8], w: u16, h: u16, config: &Configure) -> [u32; 3] {
    use phototraverse_core::budget::{Arena, MemoryBudget};
    use phototraverse_core::features::FeatureSet;
    use phototraverse_core::image::ImageView;
    use phototraverse_core::sift::Sift;
    let cfg = phototraverse_firmware_sim::processor::sift_config(config);
    let mut budget = MemoryBudget::new();
    cfg.working_budget(&mut budget).unwrap();
    FeatureSet::budget(cfg.max_keypoints, &mut budget, "kp", "desc");
    let mut storage = vec![0u8; budget.total()];
    let mut arena = Arena::new(&mut storage);
    let mut sift = Sift::new(cfg, &mut arena).unwrap();
    let mut set = FeatureSet::new(&mut arena, cfg.max_keypoints).unwrap();
    let stats = sift
        .extract(
            &ImageView::new(img, w as usize, h as usize).unwrap(),
            &mut set,
        )
        .unwrap();
    [set.len(), stats.extrema, stats.refined].map(|n| n as u32)
}

/// Mean, mean absolute gradient and median computed here independently of the firmware.
fn expected_stats(img: &[u8], w: usize, h: usize) -> (f64, f64, u8) {
    let mean = img.iter().map(|&v| v as f64).sum::<f64>() / (w * h) as f64;
    let mut g = 0u64;
    for r in 0..h {
        for c in 0..w {
            let v = img[r * w + c] as i32;
            if c + 1 < w {
                g += (img[r * w + c + 1] as i32 - v).unsigned_abs() as u64;
            }
            if r + 1 < h {
                g += (img[(r + 1) * w + c] as i32 - v).unsigned_abs() as u64;
            }
        }
    }
    let mut sorted = img.to_vec();
    sorted.sort_unstable();
    // The lower median: the first value that half the pixels do not exceed.
    let median = sorted[(w * h - 1) / 2];
    (mean, g as f64 / (w * h) as f64, median)
}

fn config(w: u16, h: u16) -> Configure {
    let rig = Rig::rectified(Interior::pinhole_px(w as u32, h as u32, 100.0), 0.5);
    Configure {
        version: CONFIG_VERSION,
        traverse: Default::default(),
        rig,
        pipeline: Pipeline {
            max_width: w,
            max_height: h,
            ..Pipeline::default()
        },
    }
}

/// Epoch `epoch` of 8-bit `w` x `h` frames, 0.1 s apart.
fn gray_frames<'a>(
    epoch: u32,
    (left, right): (&'a [u8], &'a [u8]),
    w: u16,
    h: u16,
) -> EpochFrames<'a> {
    EpochFrames {
        epoch,
        timestamp_us: epoch as u64 * 100_000,
        width: w,
        height: h,
        format: PixelFormat::Gray8,
        left,
        right,
        aux: None,
    }
}

fn send_epochs<T: Transport>(s: &mut Session<T>, epochs: std::ops::Range<u32>, w: u16, h: u16) {
    for e in epochs {
        let (l, r) = (image(e, 0, w, h), image(e, 1, w, h));
        s.send_epoch(&gray_frames(e, (&l, &r), w, h)).unwrap();
    }
}

/// Checks every epoch's result against the images' statistics.
fn check_results<T: Transport>(s: &Session<T>, epochs: std::ops::Range<u32>, w: u16, h: u16) {
    for e in epochs {
        let r = s
            .result(e)
            .unwrap_or_else(|| panic!("no result for epoch {e}"));
        let (li, ri) = (image(e, 0, w, h), image(e, 1, w, h));
        if r.status == ResultStatus::FeaturesOnly {
            let cfg = config(w, h);
            let [l, rr] = [local_sift(&li, w, h, &cfg), local_sift(&ri, w, h, &cfg)];
            let want = [l[0], rr[0]];
            assert_eq!(r.counts.keypoints, want, "epoch {e}");
            assert!(
                want[0] > 10 && want[1] > 10,
                "the test images need features: {want:?}"
            );
            let sift = r.sift().expect("the feature processor's figures");
            assert_eq!(sift.extrema, [l[1], rr[1]], "epoch {e}");
            assert_eq!(sift.refined, [l[2], rr[2]], "epoch {e}");
        } else {
            assert_eq!(r.status, ResultStatus::StatsOnly, "epoch {e}");
            let got = r.image_stats().expect("the statistics processor's figures");
            for (k, img) in [&li, &ri].into_iter().enumerate() {
                let (mean, gradient, median) = expected_stats(img, w as usize, h as usize);
                let close = |a: f64, b: f64| (a - b).abs() < 1e-9;
                assert!(close(got.mean[k], mean), "epoch {e} camera {k}: {got:?}");
                assert!(
                    close(got.gradient_energy[k], gradient),
                    "epoch {e} camera {k}: {got:?}"
                );
                assert_eq!(got.median[k], median, "epoch {e} camera {k}");
            }
        }
        let st = s.stats(e).expect("stats follow each result");
        assert!(st.memory_high_water as usize >= 2 * w as usize * h as usize);
        assert!(st.memory_high_water <= st.memory_predicted);
    }
}

fn full_session<T: Transport>(t: T, opts: SessionOptions, epochs: u32) -> Session<T> {
    let mut s = Session::open(t, opts).expect("hello");
    let acc = s.configure(&config(W, H)).expect("configuration accepted");
    assert_eq!(acc.frame_bytes, 2 * W as u32 * H as u32);
    send_epochs(&mut s, 0..epochs, W, H);
    s.finish().expect("all results");
    check_results(&s, 0..epochs, W, H);
    s
}

/// A session with the shipped firmware: SIFT features on every epoch.
fn sift_session<T: Transport>(t: T, epochs: u32) {
    let s = full_session(t, SessionOptions::default(), epochs);
    for e in 0..epochs {
        assert_eq!(s.result(e).unwrap().status, ResultStatus::FeaturesOnly);
    }
}

/// The shipped firmware (SIFT) in process.
fn inproc() -> InProc {
    InProc::spawn(4 << 20, Default::default(), FirmwareProcessor::Sift)
}

/// The bring-up firmware: image statistics check every byte of the frames.
fn inproc_stats() -> InProc {
    InProc::spawn(4 << 20, Default::default(), FirmwareProcessor::Stats)
}

#[test]
fn inproc_session_returns_a_result_per_epoch() {
    let s = full_session(inproc_stats(), SessionOptions::default(), 4);
    assert!(s.errors().is_empty(), "{:?}", s.errors());
    let s = full_session(inproc(), SessionOptions::default(), 6);
    assert_eq!(s.result(5).unwrap().status, ResultStatus::FeaturesOnly);
    let link = s.link_stats();
    assert_eq!(link.frame_bytes, 6 * 2 * W as u64 * H as u64);
    // A clean link loses nothing. A firmware starved of the CPU (a loaded
    // machine) may let the host's timer expire, and each time-out resends the
    // oldest packet with its probe, never the window.
    assert_eq!(link.resent_lost, 0, "a clean link loses nothing");
    assert!(
        link.resent_timeout <= link.retransmission_timeouts,
        "one packet per time-out: {link:?}"
    );
    assert!(s.errors().is_empty(), "{:?}", s.errors());
}

#[test]
fn noisy_link_gives_the_same_results_as_a_clean_one() {
    let faults = FaultConfig {
        ber: 1e-4,
        drop_packet: 0.01,
        seed: 42,
        ..Default::default()
    };
    let opts = SessionOptions {
        chunk: 256,
        rto: Duration::from_millis(50),
        ..Default::default()
    };
    let clean = full_session(inproc(), opts.clone(), 8);
    let noisy = full_session(Faulty::new(inproc(), faults), opts, 8);
    for e in 0..8 {
        assert_eq!(clean.result(e), noisy.result(e), "epoch {e}");
    }
    let link = noisy.link_stats();
    let f = link.faults.expect("fault counters");
    assert!(f[0].bits_flipped > 0 && f[0].packets_dropped > 0, "{f:?}");
    assert!(link.retransmitted_packets > 0, "{link:?}");
    assert!(noisy.lost_epochs().is_empty());
    println!("noisy link: {link:?}");
}

#[test]
fn every_packet_fault_kind_is_survived() {
    let faults = FaultConfig {
        ber: 2e-5,
        drop_packet: 0.01,
        drop_byte: 1e-5,
        truncate: 0.01,
        duplicate: 0.01,
        reorder: 0.01,
        seed: 9,
    };
    let opts = SessionOptions {
        chunk: 512,
        rto: Duration::from_millis(50),
        ..Default::default()
    };
    let s = full_session(Faulty::new(inproc_stats(), faults), opts, 5);
    let f: [FaultCounters; 2] = s.link_stats().faults.unwrap();
    let total: u64 = f
        .iter()
        .map(|c| c.packets_truncated + c.packets_duplicated + c.packets_reordered)
        .sum();
    assert!(total > 0, "{f:?}");
}

/// Builds the firmware binary (a no-op under `cargo test --workspace`, which
/// built it with the same profile; needed under `cargo test -p phototraverse-tests`).
fn ensure_firmware_binary() {
    static BUILT: std::sync::Once = std::sync::Once::new();
    BUILT.call_once(build_firmware_binary);
}

fn build_firmware_binary() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    // The binary is looked for beside this test's own: build it with the same profile
    // (`cargo test --release` runs from target/release).
    let exe = std::env::current_exe().expect("the test's own path");
    let release = exe.components().any(|c| c.as_os_str() == "release");
    let profile = if release { "release" } else { "test" };
    let ok = std::process::Command::new(cargo)
        .args([
            "build",
            "--profile",
            profile,
            "-p",
            "phototraverse-firmware-sim",
            "--bin",
            child::FIRMWARE_BIN,
        ])
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    assert!(ok, "building the firmware binary");
    child::firmware_binary().expect("firmware binary after building it");
}

#[test]
fn child_process_session() {
    ensure_firmware_binary();
    let opts = LinkOptions {
        link: LinkKind::Child,
        fw_memory: 4 << 20,
        fw_processor: FirmwareProcessor::Sift,
        ..Default::default()
    };
    let t = opts.open().unwrap();
    sift_session(t, 3);
}

#[test]
fn tcp_session_on_localhost() {
    ensure_firmware_binary();
    let t = TcpLink::spawn(4 << 20, FirmwareProcessor::Sift).unwrap();
    assert!(t.describe().contains("127.0.0.1"));
    sift_session(t, 3);
}

/// `std::fs::File` as an `embedded_io` port for the firmware on a pty master.
struct FilePort(std::fs::File);

impl embedded_io::ErrorType for FilePort {
    type Error = io::Error;
}
impl embedded_io::Read for FilePort {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        match io::Read::read(&mut self.0, buf) {
            // EIO on a pty master: the other side closed.
            Err(e) if e.raw_os_error() == Some(5) => Ok(0),
            other => other,
        }
    }
}
impl embedded_io::Write for FilePort {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        io::Write::write(&mut self.0, buf)
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

#[test]
fn serial_session_over_a_pseudo_terminal() {
    use phototraverse_firmware_sim::{Firmware, LinkBuffers, NoClock, SiftFactory};
    let pty = Pty::open().unwrap();
    let master = pty.master.try_clone().unwrap();
    std::thread::spawn(move || {
        let mut work = vec![0u8; 4 << 20];
        let mut buffers = Box::new(LinkBuffers::new());
        let mut fw = Firmware::new(&mut work, SiftFactory, NoClock, Default::default());
        let _ = fw.run(&mut FilePort(master), &mut buffers);
    });
    let t = SerialLink::open(pty.slave_path.to_str().unwrap(), 921_600).unwrap();
    sift_session(t, 2);
}

/// A firmware as on a part whose RAM is in blocks: the frames in their own storage,
/// checked on their own, and a stack gauge whose figures reach the host.
#[test]
fn frames_in_their_own_storage_and_the_stack_reach_the_host() {
    use phototraverse_core::protocol::messages::StackUse;
    use phototraverse_firmware_sim::{Firmware, LinkBuffers, NoClock, SiftFactory};
    let frame = W as usize * H as usize;
    // Frame storage for two frames of W x H: a configuration twice as wide is refused
    // naming the frame storage.
    let pty = Pty::open().unwrap();
    let master = pty.master.try_clone().unwrap();
    std::thread::spawn(move || {
        let mut work = vec![0u8; 1 << 20];
        let mut frames = vec![0u8; 2 * frame];
        let mut buffers = Box::new(LinkBuffers::new());
        let mut fw = Firmware::new(&mut work, SiftFactory, NoClock, Default::default())
            .with_frame_storage(&mut frames)
            .with_stack_gauge(|| StackUse {
                used: 4242,
                reserved: 65536,
            });
        let _ = fw.run(&mut FilePort(master), &mut buffers);
    });
    let t = SerialLink::open(pty.slave_path.to_str().unwrap(), 921_600).unwrap();
    let mut s = Session::open(t, SessionOptions::default()).expect("hello");
    let err = s.configure(&config(2 * W, H)).unwrap_err().to_string();
    assert!(
        err.contains("ConfigTooLarge")
            && err.contains(&format!(
                "the two frame buffers need {} bytes but the firmware's frame storage has {}",
                4 * frame,
                2 * frame
            )),
        "{err}"
    );
    let acc = s.configure(&config(W, H)).expect("configuration accepted");
    assert_eq!(acc.frame_bytes, 2 * frame as u32);
    send_epochs(&mut s, 0..2, W, H);
    s.finish().expect("all results");
    check_results(&s, 0..2, W, H);
    let stats = s.stats(1).expect("stats of epoch 1");
    assert_eq!(
        stats.stack,
        Some(StackUse {
            used: 4242,
            reserved: 65536
        })
    );
    // The feature processor reserves none of the traverse's capacities.
    assert!(stats.capacities.iter().all(|c| c.reserved == 0));
}

fn raw_packet(version: u8) -> Vec<u8> {
    let mut raw = [0u8; MAX_PACKET];
    let mut wire = vec![0u8; 64];
    let n = encode_packet(
        Header {
            message: phototraverse_core::protocol::MessageType::Reset,
            seq: 999,
        },
        &mut raw,
        &mut wire,
        |p| {
            p[0] = 0;
            Ok(1)
        },
    )
    .unwrap();
    // Re-encode with a different version byte and a CRC that matches it.
    raw[0] = version;
    let crc = crc32(&raw[..7]);
    raw[7..11].copy_from_slice(&crc.to_le_bytes());
    let m = phototraverse_core::protocol::cobs::encode(&raw[..11], &mut wire).unwrap();
    wire[m] = 0;
    assert!(n > 0);
    wire.truncate(m + 1);
    wire
}

fn wait_for_error<T: Transport>(s: &mut Session<T>, code: ErrorCode) -> String {
    let name = format!("{code:?}");
    for _ in 0..200 {
        if let Some(e) = s.errors().iter().find(|e| e.code == name) {
            return e.text.clone();
        }
        s.service(Duration::from_millis(10)).unwrap();
    }
    panic!("no {name} error; errors: {:?}", s.errors());
}

#[test]
fn bad_input_is_refused_clearly_and_the_session_goes_on() {
    let mut s = Session::open(inproc(), SessionOptions::default()).unwrap();

    // A configuration that does not fit the firmware's 4 MiB.
    let err = s.configure(&config(4000, 3000)).unwrap_err();
    let text = err.to_string();
    assert!(matches!(err, SessionError::ConfigRejected { .. }), "{text}");
    assert!(
        text.contains("ConfigTooLarge") && text.contains("24000000"),
        "{text}"
    );
    s.configure(&config(W, H)).unwrap();

    // Settings out of range are refused naming the setting, with the same limits
    // the host applies to a settings file (not clamped by the firmware).
    for (field, change) in [
        (
            "octaves",
            (|c: &mut Configure| c.pipeline.octaves = 0) as fn(&mut Configure),
        ),
        ("keypoints_per_image", |c| {
            c.pipeline.keypoints_per_image = 3
        }),
        ("window", |c| c.pipeline.window_len = 1),
        ("match_ratio", |c| c.pipeline.match_ratio = 1.5),
        ("sigma_px", |c| c.traverse.sigma_px = f64::NAN),
    ] {
        let mut bad = config(W, H);
        change(&mut bad);
        let err = s.configure(&bad).unwrap_err().to_string();
        assert!(
            err.contains("ConfigInvalid") && err.contains(field),
            "{field}: {err}"
        );
        assert_eq!(bad.validate().unwrap_err().field, field);
    }
    s.configure(&config(W, H)).unwrap();

    // A packet of another protocol version.
    s.send_raw(&raw_packet(9)).unwrap();
    let text = wait_for_error(&mut s, ErrorCode::Version);
    assert!(text.contains("version 9"), "{text}");

    // A frame larger than the configured capacity: that epoch is lost.
    let big = vec![7u8; 2 * W as usize * H as usize];
    s.send_epoch(&gray_frames(100, (&big, &big), 2 * W, H))
        .unwrap();
    let text = wait_for_error(&mut s, ErrorCode::FrameTooLarge);
    assert!(text.contains("256x96"), "{text}");

    // A chunk out of order: that epoch is lost.
    let img = image(0, 0, W, H);
    let begin = FrameBegin {
        epoch: 101,
        camera: Camera::Left,
        format: PixelFormat::Gray8,
        width: W,
        height: H,
        timestamp_us: 0,
    };
    s.send_message(&Message::FrameBegin(begin)).unwrap();
    s.send_message(&Message::FrameChunk(FrameChunk {
        epoch: 101,
        camera: Camera::Left,
        offset: 512,
        data: &img[512..1024],
    }))
    .unwrap();
    s.send_message(&Message::FrameEnd(FrameEnd {
        epoch: 101,
        camera: Camera::Left,
        total_bytes: img.len() as u32,
        crc32: crc32(&img),
    }))
    .unwrap();
    let text = wait_for_error(&mut s, ErrorCode::ChunkOutOfOrder);
    assert!(text.contains("offset 512, expected 0"), "{text}");

    // A frame whose whole-frame CRC does not match: that epoch is lost.
    let begin = FrameBegin {
        epoch: 102,
        ..begin
    };
    s.send_message(&Message::FrameBegin(begin)).unwrap();
    for (k, part) in img.chunks(1024).enumerate() {
        let offset = k as u32 * 1024;
        let chunk = FrameChunk {
            epoch: 102,
            camera: Camera::Left,
            offset,
            data: part,
        };
        s.send_message(&Message::FrameChunk(chunk)).unwrap();
    }
    let bad = FrameEnd {
        epoch: 102,
        camera: Camera::Left,
        total_bytes: img.len() as u32,
        crc32: !crc32(&img),
    };
    s.send_message(&Message::FrameEnd(bad)).unwrap();
    let text = wait_for_error(&mut s, ErrorCode::FrameCrc);
    assert!(text.contains("Crc"), "{text}");

    // The session goes on: good epochs still give results.
    send_epochs(&mut s, 0..3, W, H);
    s.finish().unwrap();
    check_results(&s, 0..3, W, H);
    assert_eq!(s.result(100).unwrap().status, ResultStatus::Lost);
    assert_eq!(s.result(101).unwrap().status, ResultStatus::Lost);
    assert_eq!(s.lost_epochs(), vec![100, 101, 102]);
}

/// A link whose firmware never answers.
#[test]
fn a_frame_of_another_size_than_the_cameras_is_refused_naming_the_field() {
    // The traverse expects the rig's W x H; a smaller frame fits the capacity, but
    // orienting it with the rig's interior orientation would be wrong.
    let t = InProc::spawn(32 << 20, Default::default(), FirmwareProcessor::Traverse);
    let mut s = Session::open(t, SessionOptions::default()).unwrap();
    s.configure(&config(W, H)).unwrap();
    let (w, h) = (W - 32, H - 16);
    let (l, r) = (image(0, 0, w, h), image(0, 1, w, h));
    s.send_epoch(&gray_frames(0, (&l, &r), w, h)).unwrap();
    let text = wait_for_error(&mut s, ErrorCode::FrameSize);
    assert!(
        text.contains("Left frame is 96x80") && text.contains("width_px x height_px is 128x96"),
        "{text}"
    );
    s.finish().unwrap();
    assert_eq!(s.result(0).unwrap().status, ResultStatus::Lost);
    // One error for the epoch, not one per camera or chunk.
    let n = s.errors().iter().filter(|e| e.code == "FrameSize").count();
    assert_eq!(n, 1, "{:?}", s.errors());
}

struct Silent;

impl Transport for Silent {
    fn send(&mut self, _: &[u8]) -> io::Result<()> {
        Ok(())
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
    fn recv(&mut self, timeout: Duration) -> io::Result<Option<Vec<u8>>> {
        std::thread::sleep(timeout);
        Ok(None)
    }
    fn describe(&self) -> String {
        "a silent link".into()
    }
}

#[test]
fn an_unresponsive_firmware_times_out_with_a_clear_message() {
    let opts = SessionOptions {
        timeout: Duration::from_millis(300),
        ..Default::default()
    };
    let err = Session::open(Silent, opts).err().expect("no answer");
    let text = err.to_string();
    assert!(matches!(err, SessionError::Timeout { .. }));
    assert!(
        text.contains("did not answer")
            && text.contains("a silent link")
            && text.contains("capabilities"),
        "{text}"
    );
}

#[test]
fn sixteen_bit_frames_are_scaled_on_arrival() {
    let mut s = Session::open(inproc_stats(), SessionOptions::default()).unwrap();
    let mut cfg = config(W, H);
    cfg.pipeline.pixel_bytes = 2;
    let acc = s.configure(&cfg).unwrap();
    assert_eq!(acc.frame_bytes, 4 * W as u32 * H as u32);
    // 12-bit pixels: the firmware keeps the top 8 bits.
    let to16 = |img: &[u8]| -> Vec<u8> {
        img.iter()
            .flat_map(|&v| ((v as u16) << 4 | 0xF).to_le_bytes())
            .collect()
    };
    let (l8, r8) = (image(3, 0, W, H), image(3, 1, W, H));
    let (l16, r16) = (to16(&l8), to16(&r8));
    let f = EpochFrames {
        epoch: 3,
        timestamp_us: 0,
        width: W,
        height: H,
        format: PixelFormat::Gray16 { bits: 12 },
        left: &l16,
        right: &r16,
        aux: None,
    };
    s.send_epoch(&f).unwrap();
    s.finish().unwrap();
    check_results(&s, 3..4, W, H);
}

#[test]
fn pacing_and_the_bandwidth_limit_hold() {
    use phototraverse_host::link::throttle::Throttled;
    use phototraverse_host::session::epoch_wire_bytes;
    let (w, h) = (64u16, 48u16);
    // Pacing: 4 epochs at 20 fps cannot take less than 3 frame intervals.
    let opts = SessionOptions {
        fps: Some(20.0),
        ..Default::default()
    };
    let mut s = Session::open(inproc_stats(), opts).unwrap();
    s.configure(&config(w, h)).unwrap();
    let t0 = std::time::Instant::now();
    send_epochs(&mut s, 0..4, w, h);
    s.finish().unwrap();
    assert!(
        t0.elapsed() >= Duration::from_millis(150),
        "{:?}",
        t0.elapsed()
    );

    // 230400 baud: an epoch takes what its bytes need on the wire, not much more.
    let baud = 230_400;
    let mut s = Session::open(
        Throttled::new(inproc_stats(), baud),
        SessionOptions::default(),
    )
    .unwrap();
    s.configure(&config(w, h)).unwrap();
    let t0 = std::time::Instant::now();
    send_epochs(&mut s, 0..1, w, h);
    s.finish().unwrap();
    let measured = t0.elapsed().as_secs_f64();
    let computed = epoch_wire_bytes(w as usize * h as usize, 1024) as f64 * 10.0 / baud as f64;
    assert!(
        measured > 0.9 * computed && measured < 1.5 * computed + 0.05,
        "measured {measured} s, computed {computed} s"
    );
}
