//! Protocol tests: message round trips, decoder resynchronisation, frame
//! assembly, and property tests feeding random and mutated streams to the decoder.
extern crate std;

use super::assembly::{AssemblyError, FrameAssembler};
use super::crc::crc32;
use super::messages::*;
use super::samples::{sample_messages, sample_result};
use super::*;
use crate::camera::{CalibrationPrecision, DistortionModel, Interior, Rig};

#[test]
fn points_fill_to_the_payload_limit_and_round_trip() {
    let mut m = Points::new(7, 0);
    let point = PointRecord {
        track: 9,
        xyz: [1.0, 2.0, 3.0],
        std: [0.1; 3],
    };
    let obs = PointObservation {
        track: 9,
        ..Default::default()
    };
    // A 256-byte limit (the firmware's answers): 6 points take 249 bytes.
    let mut n = 0;
    while m.push_point(point, 256) {
        n += 1;
    }
    assert_eq!(n, 6);
    assert!(!m.push_observation(obs, 256));
    assert_eq!(m.wire_len(), POINTS_HEADER_LEN + 6 * POINT_RECORD_LEN);
    let mut buf = [0u8; 256];
    assert_eq!(m.emit(&mut buf).unwrap(), m.wire_len());
    // 2 points + 6 observations = 9 + 80 + 156 = 245 bytes; a seventh would not fit.
    let mut m = Points::new(7, 1);
    assert!(m.push_point(point, 256) && m.push_point(point, 256));
    let mut k = 0;
    while m.push_observation(obs, 256) {
        k += 1;
    }
    assert_eq!(k, 6);
    let n = m.emit(&mut buf).unwrap();
    assert_eq!(n, 245);
    assert_eq!(Points::parse(&buf[..n]).unwrap(), m);
    // A count above the capacity is refused, not read past the arrays.
    buf[7] = POINTS_MAX as u8 + 1;
    assert_eq!(
        Points::parse(&buf[..n]),
        Err(ParseError::Invalid("points: record count above capacity"))
    );
}

fn encode(msg: &Message, seq: u16, out: &mut [u8]) -> usize {
    let mut raw = [0u8; MAX_PACKET];
    encode_packet(
        Header {
            message: msg.message_type(),
            seq,
        },
        &mut raw,
        out,
        |p| msg.emit(p),
    )
    .unwrap()
}

#[test]
fn every_message_round_trips_through_the_wire() {
    let chunk: [u8; 300] = core::array::from_fn(|i| (i % 7) as u8);
    let mut buf = [0u8; MAX_ENCODED];
    let mut wire = [0u8; MAX_ENCODED];
    for (k, msg) in sample_messages(&chunk).iter().enumerate() {
        let n = encode(msg, 1000 + k as u16, &mut wire);
        assert_eq!(wire[n - 1], 0);
        assert!(!wire[..n - 1].contains(&0));
        let mut dec = Decoder::new(&mut buf);
        let (used, ev) = dec.feed(&wire[..n]);
        assert_eq!(used, n);
        let p = ev.unwrap().unwrap();
        assert_eq!(p.seq(), 1000 + k as u16);
        assert_eq!(p.message_type(), Some(msg.message_type()));
        let back = Message::parse(p.type_byte(), p.payload()).unwrap();
        assert_eq!(&back, msg);
    }
}

#[test]
fn truncated_payloads_are_refused_not_panicking() {
    let chunk = [1u8; 4];
    let mut payload = [0u8; MAX_PAYLOAD];
    for msg in sample_messages(&chunk).iter() {
        let n = msg.emit(&mut payload).unwrap();
        for cut in 0..n {
            let r = Message::parse(msg.message_type() as u8, &payload[..cut]);
            // Chunk data and error text may legally be shorter; every fixed field must be there.
            if !matches!(msg, Message::FrameChunk(_) | Message::Error(_)) {
                assert_eq!(
                    r,
                    Err(ParseError::Truncated),
                    "{:?} cut at {cut}",
                    msg.message_type()
                );
            }
        }
    }
    assert_eq!(
        Message::parse(0x7F, &[]),
        Err(ParseError::UnknownType(0x7F))
    );
}

#[test]
fn configure_ignores_fields_of_later_versions() {
    let rig = Rig::rectified(Interior::pinhole_px(320, 240, 300.0), 0.3);
    let cfg = Configure {
        version: 3,
        rig,
        pipeline: Pipeline::default(),
        traverse: TraverseSettings {
            mode: AdjustMode::Seed2014,
            ..TraverseSettings::default()
        },
    };
    let mut payload = [0u8; 512];
    let n = cfg.emit(&mut payload).unwrap();
    payload[n..n + 8].copy_from_slice(&[9; 8]);
    assert_eq!(Configure::parse(&payload[..n + 8]).unwrap(), cfg);
}

#[test]
fn configure_v2_round_trips_and_v1_payloads_get_the_v1_behaviour() {
    let rig = Rig::rectified(Interior::pinhole_px(320, 240, 300.0), 0.3);
    let v2 = Configure {
        version: 2,
        rig,
        pipeline: Pipeline {
            fine_octave: true,
            ..Pipeline::default()
        },
        traverse: TraverseSettings {
            mode: AdjustMode::Seed2014,
            estimate_rig: true,
            sigma_px: 0.25,
            datum: [1.6, -0.02, 0.03, 100.0, -50.0, 1.5],
            ..TraverseSettings::default()
        },
    };
    let mut payload = [0u8; 512];
    let n = v2.emit(&mut payload).unwrap();
    assert_eq!(n, 301);
    assert_eq!(Configure::parse(&payload[..n]).unwrap(), v2);
    // Every mode code survives; an unknown one is refused by name.
    for mode in [AdjustMode::Window, AdjustMode::Seed2006] {
        let c = Configure {
            traverse: TraverseSettings {
                mode,
                ..v2.traverse
            },
            ..v2
        };
        let n = c.emit(&mut payload).unwrap();
        assert_eq!(Configure::parse(&payload[..n]).unwrap(), c);
    }
    let only_octave = Configure {
        traverse: TraverseSettings {
            estimate_rig: false,
            ..v2.traverse
        },
        ..v2
    };
    let n = only_octave.emit(&mut payload).unwrap();
    assert_eq!(Configure::parse(&payload[..n]).unwrap(), only_octave);
    payload[243] = 9;
    assert_eq!(
        Configure::parse(&payload[..n]),
        Err(ParseError::Invalid("adjustment mode"))
    );
    // A version-1 writer stops after the pipeline (243 bytes); the reader fills
    // the version-1 behaviour in: window mode, fixed rig, 0.5 px, omega 90 deg.
    let v1 = Configure { version: 1, ..v2 };
    let n1 = v1.emit(&mut payload).unwrap();
    assert_eq!(n1, 243);
    let back = Configure::parse(&payload[..n1]).unwrap();
    assert_eq!(back.rig, v2.rig);
    // The fine octave travels in the v2 flags: a v1 firmware extracts without it.
    assert!(!back.pipeline.fine_octave);
    assert_eq!(
        back.pipeline,
        Pipeline {
            fine_octave: false,
            ..v2.pipeline
        }
    );
    // v3 appends the fixed epochs; v2 and older leave the firmware's default.
    let v3 = Configure {
        version: 3,
        pipeline: Pipeline {
            fixed_epochs: Some(5),
            ..v2.pipeline
        },
        ..v2
    };
    let n3 = v3.emit(&mut payload).unwrap();
    assert_eq!(n3, 303);
    assert_eq!(Configure::parse(&payload[..n3]).unwrap(), v3);
    let firmware_default = Configure {
        pipeline: Pipeline {
            fixed_epochs: None,
            ..v3.pipeline
        },
        ..v3
    };
    let n3 = firmware_default.emit(&mut payload).unwrap();
    assert_eq!(Configure::parse(&payload[..n3]).unwrap(), firmware_default);
    // v4 appends the calibration's precision and sets the hold flag; v3 and older
    // get the check with the unstated precision.
    assert!(
        Configure::parse(&payload[..n3])
            .unwrap()
            .traverse
            .check_calibration
    );
    let v4 = Configure {
        version: 4,
        traverse: TraverseSettings {
            check_calibration: false,
            calibration_precision: CalibrationPrecision {
                principal_point_px: 0.5,
                focal: 0.002,
                angles_rad: 2e-4,
                base_m: 5e-4,
            },
            ..v3.traverse
        },
        ..v3
    };
    let n4 = v4.emit(&mut payload).unwrap();
    assert_eq!(n4, 335);
    assert_eq!(Configure::parse(&payload[..n4]).unwrap(), v4);
    payload[n4 - 8..n4].copy_from_slice(&0f64.to_le_bytes());
    assert_eq!(
        Configure::parse(&payload[..n4]),
        Err(ParseError::Invalid("calibration precision"))
    );
    // v5 appends each camera's distortion model and third radial term; v4 and
    // older read as correction-model lenses with k3 = 0.
    let mut v5 = Configure { version: 5, ..v4 };
    v5.rig.right.distortion_model = DistortionModel::Projection;
    v5.rig.right.radial[2] = -3e-9;
    let n5 = v5.emit(&mut payload).unwrap();
    assert_eq!(n5, 353);
    assert_eq!(Configure::parse(&payload[..n5]).unwrap(), v5);
    payload[n5 - 9] = 7;
    assert_eq!(
        Configure::parse(&payload[..n5]),
        Err(ParseError::Invalid("distortion model"))
    );
    payload[n5 - 9] = 1;
    assert_eq!(
        Configure::parse(&payload[..n5 - 1]),
        Err(ParseError::Truncated)
    );
    assert_eq!(back.traverse, TraverseSettings::default());
    assert_eq!(back.traverse.mode, AdjustMode::Window);
    assert!(!back.traverse.estimate_rig);
    assert!((back.traverse.datum[0] - core::f64::consts::FRAC_PI_2).abs() < 1e-15);
}

#[test]
fn result_rig_block_is_optional_and_complete_when_present() {
    let mut r = EpochResult::empty(3, ResultStatus::Ok);
    let mut payload = [0u8; 512];
    let n = r.emit(&mut payload).unwrap();
    assert_eq!(n, 138);
    assert_eq!(EpochResult::parse(&payload[..n]).unwrap(), r);
    r.figures = sample_result().figures;
    let n = r.emit(&mut payload).unwrap();
    assert_eq!(n, 191);
    assert_eq!(EpochResult::parse(&payload[..n]).unwrap(), r);
    r.rig = Some(RigEstimate {
        params: [0.001, -0.002, 0.003, 0.4, 0.001, -0.002],
        std: [1e-4, 2e-4, 3e-4, 1e-3, 2e-3, 3e-3],
    });
    let n = r.emit(&mut payload).unwrap();
    assert_eq!(n, 239);
    assert_eq!(EpochResult::parse(&payload[..n]).unwrap(), r);
    for cut in 192..n {
        assert_eq!(
            EpochResult::parse(&payload[..cut]),
            Err(ParseError::Truncated),
            "cut at {cut}"
        );
    }
}

#[test]
fn every_result_block_round_trips_and_the_largest_fits_a_transmit_slot() {
    let rig = Some(RigEstimate {
        params: [0.001, -0.002, 0.003, 0.4, 0.001, -0.002],
        std: [1e-4, 2e-4, 3e-4, 1e-3, 2e-3, 3e-3],
    });
    let blocks = [
        (Figures::None, 138),
        (sample_result().figures, 191),
        (
            match sample_result().figures {
                Figures::Adjustment(a) => Figures::Adjustment(Adjustment { step_m: None, ..a }),
                other => other,
            },
            179,
        ),
        (
            Figures::Sift(SiftCounts {
                extrema: [5000, 4800],
                refined: [1200, 1100],
            }),
            154,
        ),
        (
            Figures::ImageStats(ImageStats {
                mean: [101.25, 99.5],
                gradient_energy: [12.125, 11.0625],
                median: [97, 255],
            }),
            172,
        ),
    ];
    let mut payload = [0u8; 512];
    let mut largest = 0;
    for (figures, len) in blocks {
        for rig in [None, rig] {
            let r = EpochResult {
                figures,
                rig,
                ..sample_result()
            };
            let n = r.emit(&mut payload).unwrap();
            assert_eq!(n, len + if rig.is_some() { 48 } else { 0 }, "{figures:?}");
            assert_eq!(EpochResult::parse(&payload[..n]).unwrap(), r);
            largest = largest.max(n);
        }
    }
    // The firmware's transmit slot holds 256 bytes of payload.
    assert_eq!(largest, 239);
    assert!(largest <= 256);
    // Blocks the wire does not define are refused by name: their length is unknown.
    let n = sample_result().emit(&mut payload).unwrap();
    payload[137] = 9;
    assert_eq!(
        EpochResult::parse(&payload[..n]),
        Err(ParseError::Invalid("result figures kind"))
    );
    // The step's presence byte follows the 40 bytes of the figures it ends.
    payload[137] = 1;
    payload[178] = 2;
    assert_eq!(
        EpochResult::parse(&payload[..n]),
        Err(ParseError::Invalid("result step presence"))
    );
}

#[test]
fn result_status_codes_are_stable_and_unknown_ones_are_kept() {
    let known = [
        (ResultStatus::Ok, 0),
        (ResultStatus::FeaturesOnly, 1),
        (ResultStatus::StatsOnly, 2),
        (ResultStatus::Lost, 3),
        (ResultStatus::Failed, 4),
        (ResultStatus::Flagged, 5),
        (ResultStatus::Predicted, 6),
    ];
    for (s, code) in known {
        assert_eq!(s.code(), code);
        assert_eq!(ResultStatus::from_code(code), s);
    }
    for code in 7..=u8::MAX {
        assert_eq!(ResultStatus::from_code(code), ResultStatus::Unknown(code));
    }
    // A newer firmware's status and flag bits reach the host as they were sent.
    let mut payload = [0u8; 512];
    let r = EpochResult {
        status: ResultStatus::Unknown(42),
        flags: ResultFlags(1 << 31) | ResultFlags::LOST,
        ..sample_result()
    };
    let n = r.emit(&mut payload).unwrap();
    assert_eq!(payload[4], 42);
    let back = EpochResult::parse(&payload[..n]).unwrap();
    assert_eq!(back.status, ResultStatus::Unknown(42));
    assert!(back.flags.contains(ResultFlags::LOST) && back.flags.bits() & (1 << 31) != 0);
}

#[test]
fn adjust_mode_codes_round_trip_and_unknown_ones_are_refused() {
    for (k, m) in AdjustMode::ALL.into_iter().enumerate() {
        assert_eq!(m.code() as usize, k);
        assert_eq!(AdjustMode::parse(m.code()), Ok(m));
    }
    assert_eq!(
        AdjustMode::parse(3),
        Err(ParseError::Invalid("adjustment mode"))
    );
}

#[test]
fn decoder_resynchronises_after_garbage_and_counts() {
    let mut wire = [0u8; 3 * MAX_ENCODED];
    let ack = Message::Ack(Ack {
        next_expected: 5,
        window: 8,
        ..Ack::default()
    });
    let mut at = 0;
    at += encode(&ack, 1, &mut wire[at..]);
    // Garbage, a corrupted packet, an oversized run, then a good packet.
    wire[at..at + 5].copy_from_slice(&[1, 2, 3, 4, 0]);
    at += 5;
    let n = encode(&ack, 2, &mut wire[at..]);
    wire[at + 3] ^= 0x10;
    at += n;
    let mut small = [0u8; 40];
    let big = [0x55u8; 100];
    let mut stream = heapless::Vec::<u8, 4096>::new();
    stream.extend_from_slice(&wire[..at]).unwrap();
    stream.extend_from_slice(&big).unwrap();
    stream.push(0).unwrap();
    let n = encode(&ack, 3, &mut wire);
    stream.extend_from_slice(&wire[..n]).unwrap();

    let mut dec = Decoder::new(&mut small);
    let mut input = &stream[..];
    let mut good = heapless::Vec::<u16, 8>::new();
    let mut bad = 0;
    // Feed byte by byte: the decoder must not depend on how reads are split.
    while !input.is_empty() {
        let (n, ev) = dec.feed(&input[..1]);
        assert_eq!(n, 1);
        input = &input[1..];
        match ev {
            Some(Ok(p)) => good.push(p.seq()).unwrap(),
            Some(Err(_)) => bad += 1,
            None => {}
        }
    }
    assert_eq!(&good[..], &[1, 3]);
    assert_eq!(bad, 3);
    let c = dec.counters();
    assert_eq!((c.packets, c.oversized), (2, 1));
    assert_eq!(c.crc_errors + c.framing_errors + c.truncated, 2);
}

#[test]
fn wrong_version_is_reported_as_such() {
    let mut raw = [0u8; 64];
    let mut wire = [0u8; 80];
    let n = encode_packet(
        Header {
            message: MessageType::Reset,
            seq: 0,
        },
        &mut raw,
        &mut wire,
        |p| Reset { reason: 0 }.emit(p),
    )
    .unwrap();
    // Rewrite the version and fix the CRC so only the version is wrong.
    let len = HEADER_LEN + 1;
    raw[0] = 9;
    let crc = crc32(&raw[..len]);
    raw[len..len + 4].copy_from_slice(&crc.to_le_bytes());
    let m = cobs::encode(&raw[..len + 4], &mut wire).unwrap();
    wire[m] = 0;
    assert!(n > 0);
    let mut buf = [0u8; 80];
    let mut dec = Decoder::new(&mut buf);
    let (_, ev) = dec.feed(&wire[..=m]);
    assert_eq!(
        ev.unwrap().unwrap_err(),
        DecodeError::Packet(PacketError::Version(9))
    );
}

fn begin(epoch: u32, w: u16, h: u16, format: PixelFormat) -> FrameBegin {
    FrameBegin {
        epoch,
        camera: Camera::Left,
        format,
        width: w,
        height: h,
        timestamp_us: 0,
    }
}

#[test]
fn assembler_builds_checks_and_scales_frames() {
    let mut buf = [0u8; 2 * 8 * 4];
    let mut a = FrameAssembler::new(&mut buf, 8, 4);
    let img: [u8; 32] = core::array::from_fn(|i| i as u8 * 3);
    assert_eq!(a.begin(begin(1, 8, 4, PixelFormat::Gray8)), Ok(None));
    for (k, part) in img.chunks(10).enumerate() {
        a.chunk(&FrameChunk {
            epoch: 1,
            camera: Camera::Left,
            offset: k as u32 * 10,
            data: part,
        })
        .unwrap();
    }
    a.end(&FrameEnd {
        epoch: 1,
        camera: Camera::Left,
        total_bytes: 32,
        crc32: crc32(&img),
    })
    .unwrap();
    let (view, _) = a.image(1).unwrap();
    assert_eq!(view.get(7, 3), Some(31 * 3));

    // u16 with 12 significant bits scaled to 8.
    let px: [u16; 32] = core::array::from_fn(|i| (i as u16) << 7);
    let mut bytes = [0u8; 64];
    for (i, v) in px.iter().enumerate() {
        bytes[2 * i..2 * i + 2].copy_from_slice(&v.to_le_bytes());
    }
    a.begin(begin(2, 8, 4, PixelFormat::Gray16 { bits: 12 }))
        .unwrap();
    a.chunk(&FrameChunk {
        epoch: 2,
        camera: Camera::Left,
        offset: 0,
        data: &bytes,
    })
    .unwrap();
    a.end(&FrameEnd {
        epoch: 2,
        camera: Camera::Left,
        total_bytes: 64,
        crc32: crc32(&bytes),
    })
    .unwrap();
    let (view, _) = a.image(2).unwrap();
    assert_eq!(view.get(5, 2), Some(((21u16 << 7) >> 4) as u8));

    // Out of order, then the rest of that frame is ignored, not re-reported.
    a.begin(begin(3, 8, 4, PixelFormat::Gray8)).unwrap();
    let c = FrameChunk {
        epoch: 3,
        camera: Camera::Left,
        offset: 10,
        data: &img[10..20],
    };
    assert_eq!(
        a.chunk(&c),
        Err(AssemblyError::OutOfOrder {
            expected: 0,
            got: 10
        })
    );
    assert_eq!(a.chunk(&c), Err(AssemblyError::AlreadyFailed));
    assert!(a.image(3).is_none());

    // Too large for the buffer; CRC mismatch; abandoned epoch.
    assert!(matches!(
        a.begin(begin(4, 9, 4, PixelFormat::Gray8)),
        Err(AssemblyError::TooLarge { .. })
    ));
    a.begin(begin(5, 8, 4, PixelFormat::Gray8)).unwrap();
    a.chunk(&FrameChunk {
        epoch: 5,
        camera: Camera::Left,
        offset: 0,
        data: &img,
    })
    .unwrap();
    assert!(matches!(
        a.end(&FrameEnd {
            epoch: 5,
            camera: Camera::Left,
            total_bytes: 32,
            crc32: 1
        }),
        Err(AssemblyError::Crc { .. })
    ));
    a.begin(begin(6, 8, 4, PixelFormat::Gray8)).unwrap();
    assert_eq!(a.begin(begin(7, 8, 4, PixelFormat::Gray8)), Ok(Some(6)));
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    /// Feeds `stream` in pieces of `split` bytes; every outcome must be handled
    /// without panic and every packet returned must be internally consistent.
    pub(crate) fn feed_all(buf: &mut [u8], stream: &[u8], split: usize) -> (u32, u32) {
        let cap = buf.len();
        let mut dec = Decoder::new(buf);
        let mut input = stream;
        let (mut ok, mut bad) = (0, 0);
        while !input.is_empty() {
            let take = split.clamp(1, input.len());
            let mut piece = &input[..take];
            input = &input[take..];
            while !piece.is_empty() {
                let (n, ev) = dec.feed(piece);
                assert!(n >= 1 && n <= piece.len());
                piece = &piece[n..];
                match ev {
                    Some(Ok(p)) => {
                        ok += 1;
                        assert!(p.payload().len() <= MAX_PAYLOAD && p.payload().len() < cap);
                        // Whatever parses must re-emit to the same payload length or less.
                        if let Ok(m) = Message::parse(p.type_byte(), p.payload()) {
                            let mut out = [0u8; MAX_PAYLOAD];
                            let _ = m.emit(&mut out);
                        }
                    }
                    Some(Err(_)) => bad += 1,
                    None => {}
                }
            }
        }
        (ok, bad)
    }

    fn valid_stream(seed: u64, count: usize, out: &mut heapless::Vec<u8, 8192>) {
        let chunk: [u8; 64] = core::array::from_fn(|i| (seed as usize + i) as u8);
        let msgs = sample_messages(&chunk);
        let mut wire = [0u8; MAX_ENCODED];
        for k in 0..count {
            let m = &msgs[(seed as usize + k) % msgs.len()];
            let n = encode(m, k as u16, &mut wire);
            if out.extend_from_slice(&wire[..n]).is_err() {
                break;
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 3000, ..ProptestConfig::default() })]

        #[test]
        fn random_bytes_never_panic(stream in proptest::collection::vec(any::<u8>(), 0..600), split in 1usize..64, cap in 1usize..300) {
            let mut buf = [0u8; 300];
            feed_all(&mut buf[..cap], &stream, split);
        }

        #[test]
        fn mutated_valid_streams_keep_good_packets(seed in any::<u64>(), flips in proptest::collection::vec((any::<u16>(), any::<u8>()), 0..6), split in 1usize..200) {
            let mut s = heapless::Vec::<u8, 8192>::new();
            valid_stream(seed, 6, &mut s);
            let clean = s.clone();
            let mut touched = 0;
            for (pos, mask) in flips {
                let i = pos as usize % s.len();
                if mask != 0 { s[i] ^= mask; touched += 1; }
            }
            let mut buf = [0u8; MAX_ENCODED];
            let (ok, bad) = feed_all(&mut buf, &s, split);
            // Each corruption costs at most the two packets around it.
            prop_assert!(ok + 2 * touched >= 6, "ok {} touched {}", ok, touched);
            let _ = bad;
            let (ok_clean, bad_clean) = feed_all(&mut buf, &clean, split);
            prop_assert_eq!((ok_clean, bad_clean), (6, 0));
        }
    }
}

/// The million-stream fuzz run (release mode, about a minute):
/// `cargo test -p phototraverse-core --release decoder_million -- --ignored --nocapture`.
#[test]
#[ignore]
fn decoder_million_random_and_mutated_streams() {
    use rand_free::XorShift;
    let mut rng = XorShift(0x9E37_79B9_7F4A_7C15);
    let chunk: [u8; 200] = core::array::from_fn(|i| i as u8);
    let msgs = sample_messages(&chunk);
    let mut encoded = [[0u8; 600]; 14];
    let mut lens = [0usize; 14];
    for (k, m) in msgs.iter().enumerate() {
        lens[k] = encode(m, k as u16, &mut encoded[k]);
    }
    let mut buf = [0u8; MAX_ENCODED];
    let mut stream = [0u8; 2048];
    let (mut total_ok, mut total_bad) = (0u64, 0u64);
    const STREAMS: u32 = 1_000_000;
    for s in 0..STREAMS {
        let len = (rng.next() % 2048) as usize;
        if s % 2 == 0 {
            for b in stream[..len].iter_mut() {
                *b = rng.next() as u8;
            }
        } else {
            // Valid packets concatenated, then mutated: flips, deletions, truncation.
            let mut at = 0;
            while at < len {
                let k = (rng.next() % 14) as usize;
                let n = lens[k].min(len - at);
                stream[at..at + n].copy_from_slice(&encoded[k][..n]);
                at += n;
            }
            for _ in 0..rng.next() % 6 {
                let i = (rng.next() as usize) % len.max(1);
                if len > 0 {
                    stream[i] ^= 1 << (rng.next() % 8);
                }
            }
            if len > 0 && rng.next() % 3 == 1 {
                let i = (rng.next() as usize) % len;
                stream.copy_within(i + 1..len, i);
            }
        }
        let split = 1 + (rng.next() % 300) as usize;
        let cap = if s % 7 == 0 {
            1 + (rng.next() % 512) as usize
        } else {
            MAX_ENCODED
        };
        let (ok, bad) = properties::feed_all(&mut buf[..cap], &stream[..len], split);
        total_ok += ok as u64;
        total_bad += bad as u64;
    }
    std::println!(
        "decoder fuzz: {STREAMS} streams, {total_ok} packets accepted, {total_bad} dropped"
    );
    assert!(total_ok > 0 && total_bad > 0);
}

mod rand_free {
    /// xorshift64: a dependency-free generator for the long fuzz run.
    pub struct XorShift(pub u64);
    impl XorShift {
        pub fn next(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }
    }
}

#[test]
fn the_largest_frame_the_fields_allow_is_counted_exactly_and_refused() {
    // 65535 x 65535 x 2 bytes: more than a 32-bit usize holds.
    let b = begin(1, u16::MAX, u16::MAX, PixelFormat::Gray16 { bits: 16 });
    assert_eq!(b.frame_bytes(), 8_589_672_450);
    let mut buf = [0u8; 64];
    let mut a = FrameAssembler::new(&mut buf, 8, 4);
    assert_eq!(
        a.begin(b),
        Err(AssemblyError::TooLarge {
            bytes: 8_589_672_450,
            capacity: 64,
        })
    );
}
