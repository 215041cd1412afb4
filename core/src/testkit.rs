//! The test kit: the one test camera, the one synthetic drive with known truth, and
//! the deterministic random numbers they are drawn with. For the core's tests, its
//! benches (feature `testkit`) and the host's tests; never part of a firmware.
extern crate std;

use crate::adjust::geometry::project_rig;
use crate::camera::{Camera, DistortionModel, Interior, Pose, RelativeOrientation, Rig};
use std::vec::Vec;

/// Pixel size of the test camera, mm.
pub const PIXEL_MM: f64 = 0.005;
/// Focal length of the test camera, mm.
pub const FOCAL_MM: f64 = 8.0;
/// Noise of the drive's image observations: 0.3 px, in mm.
pub const SIGMA_MM: f64 = 0.3 * PIXEL_MM;

/// Deterministic uniform and normal numbers (Knuth's MMIX LCG; no std RNG in the
/// core).
pub struct Rng(pub u64);

impl Rng {
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        lo + (hi - lo) * ((self.0 >> 11) as f64 / (1u64 << 53) as f64)
    }

    /// Box-Muller.
    pub fn normal(&mut self) -> f64 {
        let u1 = self.uniform(1e-12, 1.0);
        let u2 = self.uniform(0.0, 1.0);
        libm::sqrt(-2.0 * libm::log(u1)) * libm::cos(2.0 * core::f64::consts::PI * u2)
    }

    /// `pose` moved by up to `angle_rad` on each angle and `metres` on each coordinate
    /// of the centre: a start value a few steps from the truth.
    pub fn perturbed(&mut self, pose: &Pose, angle_rad: f64, metres: f64) -> Pose {
        let mut q = pose.to_params();
        for (i, qi) in q.iter_mut().enumerate() {
            let off = if i < 3 { angle_rad } else { metres };
            *qi += self.uniform(-off, off);
        }
        Pose::from_params(&q)
    }

    /// Uniform integer in `0..n` (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.uniform(0.0, n as f64) as usize).min(n - 1)
    }
}

/// The test camera: 1280 x 960 pixels of 5 um, f = 8 mm, the principal point off
/// the centre and a mild lens (radial and decentering), so that every test
/// crosses the pixel-to-photo path with a real correction.
pub fn test_camera() -> Interior {
    Interior {
        width_px: 1280,
        height_px: 960,
        pixel_size_mm: [PIXEL_MM, PIXEL_MM],
        focal_mm: FOCAL_MM,
        principal_point_mm: [0.012, -0.008],
        radial: [-2.0e-3, 1.0e-5, 0.0],
        decentering: [1.0e-5, -2.0e-5],
        distortion_model: DistortionModel::Correction,
    }
}

/// The test rig: the test camera twice, 0.5 m apart, slightly converging and
/// offset, as a real calibration would leave them.
pub fn test_rig() -> Rig {
    let cam = test_camera();
    Rig {
        left: cam,
        right: cam,
        relative_angles: [0.002, -0.004, 0.001],
        base_m: [0.5, 0.003, -0.002],
    }
}

/// One image observation of a synthetic drive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveObservation {
    pub epoch: usize,
    pub camera: Camera,
    /// Index into [`Drive::points`].
    pub point: usize,
    /// Corrected reduced photo-coordinates, mm, with noise (and a blunder).
    pub xy: [f64; 2],
    /// A 10..50 px blunder was added.
    pub blunder: bool,
}

/// A synthetic drive with known truth: the rig's poses, the street points and
/// their noisy observations.
pub struct Drive {
    pub rig: Rig,
    pub poses: Vec<Pose>,
    pub points: Vec<[f64; 3]>,
    pub observations: Vec<DriveObservation>,
}

/// A random drive through the test rig: `epochs` stereo pairs about 1 m apart along
/// +Y with +-2 deg of attitude, `n_points` street points, each seen in at least
/// two epochs (`span` = 0) or in exactly `span` consecutive epochs by both cameras,
/// 0.3 px noise, and a fraction `gross` of observations with a 10..50 px blunder.
pub fn drive(seed: u64, epochs: usize, n_points: usize, gross: f64, span: usize) -> Drive {
    // Fewer epochs (or a longer span) could never see a point twice: no drive exists.
    assert!(
        epochs >= 2 && span <= epochs,
        "a drive needs 2 epochs or more and span <= epochs"
    );
    let mut rng = Rng(seed);
    let rig = test_rig();
    let relative = RelativeOrientation::from_rig(&rig);
    let mut poses = Vec::new();
    let (mut x, mut y) = (0.0, 0.0);
    for k in 0..epochs {
        if k > 0 {
            y += rng.uniform(0.8, 1.2);
            x += rng.uniform(-0.1, 0.1);
        }
        poses.push(Pose::from_degrees(
            90.0 + rng.uniform(-2.0, 2.0),
            rng.uniform(-2.0, 2.0),
            rng.uniform(-2.0, 2.0),
            [x, y, 1.5 + rng.uniform(-0.05, 0.05)],
        ));
    }
    // Inside the format in corrected coordinates, a hundredth of a millimetre in:
    // the drive observes corrected coordinates, so the lens does not enter.
    let half = [3.2 - 0.01, 2.4 - 0.01];
    let mut points = Vec::new();
    let mut observations = Vec::new();
    while points.len() < n_points {
        let p = [
            rng.uniform(-8.0, 8.0),
            rng.uniform(4.0, y + 25.0),
            rng.uniform(-1.0, 6.0),
        ];
        let first = if span > 0 {
            rng.below(epochs + 1 - span)
        } else {
            0
        };
        let last = if span > 0 { first + span } else { epochs };
        let mut seen = Vec::new();
        for (e, pose) in poses.iter().enumerate().take(last).skip(first) {
            for cam in [Camera::Left, Camera::Right] {
                if let Ok(pr) = project_rig(pose, &relative, cam, FOCAL_MM, &p) {
                    let in_front = pose.to_camera(&p)[2] < -3.0;
                    if pr.xy[0].abs() < half[0] && pr.xy[1].abs() < half[1] && in_front {
                        seen.push((e, cam, pr.xy));
                    }
                }
            }
        }
        let mut seen_epochs: Vec<usize> = seen.iter().map(|s| s.0).collect();
        seen_epochs.dedup();
        let complete = if span > 0 {
            seen.len() == 2 * span
        } else {
            seen_epochs.len() >= 2 && seen.len() >= 4
        };
        if !complete {
            continue;
        }
        let point = points.len();
        points.push(p);
        for (epoch, camera, xy) in seen {
            let mut m = [
                xy[0] + SIGMA_MM * rng.normal(),
                xy[1] + SIGMA_MM * rng.normal(),
            ];
            let blunder = rng.uniform(0.0, 1.0) < gross;
            if blunder {
                let mag = rng.uniform(10.0, 50.0) * PIXEL_MM;
                let ang = rng.uniform(0.0, 2.0 * core::f64::consts::PI);
                m[0] += mag * libm::cos(ang);
                m[1] += mag * libm::sin(ang);
            }
            observations.push(DriveObservation {
                epoch,
                camera,
                point,
                xy: m,
                blunder,
            });
        }
    }
    Drive {
        rig,
        poses,
        points,
        observations,
    }
}
