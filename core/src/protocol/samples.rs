//! Sample messages for tests and fuzzing, one place for the core's tests and the
//! fuzz harness (the `samples` feature).
use super::messages::*;
use super::{MAX_PAYLOAD, PROTOCOL_VERSION};
use crate::camera::{Interior, Rig};

/// One message of every type, every field set (the chunk's data borrowed from `chunk`).
pub fn sample_messages(chunk: &[u8]) -> [Message<'_>; 16] {
    let rig = Rig::rectified(Interior::pinhole_px(640, 480, 700.0), 0.54);
    [
        Message::Hello(Hello {
            session: 0xDEAD_BEEF,
            host_version: [0, 1, 2],
        }),
        Message::Capabilities(Capabilities {
            firmware_version: [0, 1, 0],
            protocol_version: PROTOCOL_VERSION,
            max_payload: MAX_PAYLOAD as u16,
            rx_window: 32,
            max_width: 1280,
            max_height: 1024,
            pixel_formats: 3,
            processor: processor_kind::SIFT,
            max_keypoints: 4000,
            work_bytes: 16 << 20,
            link_bytes: 40_000,
            held_payload: 265,
        }),
        Message::Configure(Configure {
            version: CONFIG_VERSION,
            rig,
            pipeline: Pipeline::default(),
            traverse: TraverseSettings {
                mode: AdjustMode::Seed2006,
                estimate_rig: true,
                sigma_px: 0.7,
                datum: [1.5, 0.01, -0.02, 10.0, 20.0, 2.2],
                ..TraverseSettings::default()
            },
        }),
        Message::ConfigAccepted(ConfigAccepted {
            predicted_bytes: 1,
            frame_bytes: 2,
            capacity_bytes: 3,
            carved_bytes: [4, 5, 6, 7, 8, 9],
        }),
        Message::FrameBegin(FrameBegin {
            epoch: 7,
            camera: Camera::Right,
            format: PixelFormat::Gray16 { bits: 12 },
            width: 640,
            height: 480,
            timestamp_us: 123_456_789_012,
        }),
        Message::FrameChunk(FrameChunk {
            epoch: 7,
            camera: Camera::Left,
            offset: 4096,
            data: chunk,
        }),
        Message::FrameEnd(FrameEnd {
            epoch: 7,
            camera: Camera::Left,
            total_bytes: 307_200,
            crc32: 0x1234_5678,
        }),
        Message::Aux(Aux {
            epoch: 7,
            flags: AUX_ODOMETER | AUX_GNSS,
            odometer_m: 1.25,
            odometer_sigma_m: 0.01,
            gnss_m: [1.0, 2.0, 3.0],
            gnss_sigma_m: [0.1, 0.2, 0.3],
            gnss_lever_arm_m: [0.0, 1.2, 0.5],
        }),
        Message::Result(sample_result()),
        Message::Stats(Stats {
            epoch: 7,
            timings_us: [1, 2, 3, 4, 5, 6, 7, 28],
            memory_predicted: 100,
            memory_high_water: 90,
            memory_capacity: 1000,
            epochs_ok: 7,
            epochs_lost: 1,
            link: LinkCounters {
                packets_ok: 9,
                crc_errors: 1,
                retransmissions: 2,
                ..Default::default()
            },
            capacities: [CapacityUse {
                peak: 90,
                reserved: 120,
            }; capacity::COUNT],
            stack: Some(StackUse {
                used: 21_000,
                reserved: 4_177_000,
            }),
        }),
        Message::Error(ErrorMsg {
            code: ErrorCode::ChunkOutOfOrder,
            epoch: 7,
            seq: 99,
            text: "chunk at 10, expected 0",
        }),
        Message::Ack(Ack {
            next_expected: 65535,
            window: 32,
            sack: 0x8000_0000_0000_0005,
            received: 65000,
            damaged: 17,
            probe: 255,
            answers: 3,
        }),
        Message::Nack(Nack {
            expected: 3,
            reason: nack_reason::TIMEOUT,
        }),
        Message::Reset(Reset { reason: 1 }),
        Message::Points(sample_points()),
        Message::PointsRequest(PointsRequest { flush: 1 }),
    ]
}

/// A Result with every field set but the rig block (a cut at its start parses).
pub fn sample_result() -> EpochResult {
    EpochResult {
        epoch: 7,
        status: ResultStatus::Flagged,
        pose: [1.5, 0.1, -0.2, 3.0, 40.0, 1.6],
        sigma: [1e-4, 2e-4, 3e-4, 0.01, 0.02, 0.03],
        right_sigma: [1e-4, 2e-4, 3e-4, 0.011, 0.021, 0.032],
        flags: ResultFlags::FEW_TIE_POINTS | ResultFlags::CHI2 | ResultFlags::ROTATION_FROM_MATCHES,
        counts: Counts {
            keypoints: [900, 880],
            stereo_matches: 400,
            tie_points: 300,
            window_points: 250,
            observations: 1000,
            new_points: 40,
            dropped: 3,
        },
        figures: Figures::Adjustment(Adjustment {
            sigma0: 0.9,
            rms_px: 0.35,
            chi2: 0.81 * 1234.0,
            redundancy: 1234,
            relative_sd_m: [0.002, 0.004, 0.003],
            step_m: Some([0.01, 2.0, -0.02]),
        }),
        rig: None,
    }
}

/// A Points message with two points and three observations.
pub fn sample_points() -> Points {
    let mut m = Points::new(41, 3);
    m.flags = points_flags::MORE;
    for k in 0..2u32 {
        assert!(m.push_point(
            PointRecord {
                track: 100 + k,
                xyz: [1.5 + k as f64, 20.25, -1.125],
                std: [0.01, 0.25, 0.02],
            },
            MAX_PAYLOAD
        ));
    }
    for k in 0..3u32 {
        assert!(m.push_observation(
            PointObservation {
                track: 100 + k % 2,
                epoch: 40 + k,
                camera: (k % 2) as u8,
                flags: PointObservation::FLAGGED * (k == 2) as u8,
                col: 310.5 + k as f32,
                row: 12.25,
                residual_px: [0.125, -0.5],
            },
            MAX_PAYLOAD
        ));
    }
    m
}
