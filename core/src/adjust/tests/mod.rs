//! Adjustment tests: Jacobians against central differences, the seed's
//! normal-case intersection, P3P/RANSAC, chi-square quantiles, and synthetic
//! windows with known truth (clean, with blunders, degenerate). The shared scene and
//! helpers are here; the tests by subject in the modules below.
extern crate std;

use super::constraints::{base_length, distance, prior_residual, smoothness, wrap_angle};
use super::geometry::project_rig;
use super::quality::{chi2_quantile, ChiSquareTest};
use super::*;
use crate::budget::{Arena, MemoryBudget};
use crate::camera::{project, DistortionModel, Interior, Pose, Rig};
use crate::camera::{Camera, RelativeOrientation};
use nalgebra::Vector3;
use std::vec;
use std::vec::Vec;

/// Deterministic uniform and normal numbers (no std RNG in the core).
pub(crate) struct Rng(pub(crate) u64);
impl Rng {
    pub(crate) fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        lo + (hi - lo) * ((self.0 >> 11) as f64 / (1u64 << 53) as f64)
    }
    pub(crate) fn normal(&mut self) -> f64 {
        let u1 = self.uniform(1e-12, 1.0);
        let u2 = self.uniform(0.0, 1.0);
        libm::sqrt(-2.0 * libm::log(u1)) * libm::cos(2.0 * core::f64::consts::PI * u2)
    }
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
}

mod jacobians;
mod pnp;
mod rig;
mod windows;

// ---------- synthetic windows ----------

pub(crate) struct Scene {
    pub rig: Rig,
    pub poses: Vec<Pose>,
    pub points: Vec<[f64; 3]>,
    /// (epoch, camera, point, xy observed, true error added beyond noise)
    pub obs: Vec<(usize, u8, usize, [f64; 2], bool)>,
}

pub(crate) const PIXEL_MM: f64 = 0.005;
pub(crate) const SIGMA_MM: f64 = 0.3 * PIXEL_MM;

/// A random drive: `epochs` stereo pairs about 1 m apart with random attitude,
/// `n_points` street points each seen in at least two epochs, 0.3 px noise,
/// and a fraction `gross` of observations with a 10..50 px blunder.
pub(crate) fn scene(seed: u64, epochs: usize, n_points: usize, gross: f64) -> Scene {
    let mut rng = Rng(seed);
    let cam = Interior {
        width_px: 1280,
        height_px: 960,
        pixel_size_mm: [PIXEL_MM, PIXEL_MM],
        focal_mm: 8.0,
        principal_point_mm: [0.0, 0.0],
        radial: [0.0, 0.0, 0.0],
        decentering: [0.0, 0.0],
        distortion_model: DistortionModel::Correction,
    };
    let mut rig = Rig::rectified(cam, 0.5);
    rig.relative_angles = [0.002, -0.004, 0.001];
    rig.base_m = [0.5, 0.003, -0.002];
    let mut poses = Vec::new();
    let mut y = 0.0;
    let mut x = 0.0;
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
    let half = [3.2 - 0.01, 2.4 - 0.01];
    let mut points = Vec::new();
    let mut obs = Vec::new();
    while points.len() < n_points {
        let p = [
            rng.uniform(-8.0, 8.0),
            rng.uniform(4.0, y + 25.0),
            rng.uniform(-1.0, 6.0),
        ];
        let mut seen = Vec::new();
        for (e, pose) in poses.iter().enumerate() {
            for cam in [Camera::Left, Camera::Right] {
                let rp = RelativeOrientation::from_rig(&rig);
                if let Ok(pr) = project_rig(pose, &rp, cam, 8.0, &p) {
                    let depth_ok = (pose.to_camera(&p)[2]) < -3.0;
                    if pr.xy[0].abs() < half[0] && pr.xy[1].abs() < half[1] && depth_ok {
                        seen.push((e, cam as u8, pr.xy));
                    }
                }
            }
        }
        let epochs_seen = {
            let mut v: Vec<usize> = seen.iter().map(|s| s.0).collect();
            v.dedup();
            v.len()
        };
        if epochs_seen < 2 || seen.len() < 4 {
            continue;
        }
        let id = points.len();
        points.push(p);
        for (e, c, xy) in seen {
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
            obs.push((e, c, id, m, blunder));
        }
    }
    Scene {
        rig,
        poses,
        points,
        obs,
    }
}

/// Loads a scene into a window with perturbed initial values; returns the
/// window and the point indices.
pub(crate) fn load<'a>(
    s: &Scene,
    cfg: AdjustConfig,
    arena: &mut Arena<'a>,
    seed: u64,
) -> (Window<'a>, Vec<u32>) {
    let mut rng = Rng(seed);
    let mut w = Window::new(cfg, &s.rig, arena).unwrap();
    for (k, p) in s.poses.iter().enumerate() {
        let mut q = p.to_params();
        if k > 0 {
            for (i, qi) in q.iter_mut().enumerate() {
                *qi += if i < 3 {
                    rng.uniform(-0.01, 0.01)
                } else {
                    rng.uniform(-0.1, 0.1)
                };
            }
        }
        w.add_epoch(&Pose::from_params(&q), k as f64 * 0.2).unwrap();
    }
    let ids: Vec<u32> = s
        .points
        .iter()
        .map(|p| {
            w.add_point([
                p[0] + rng.uniform(-0.2, 0.2),
                p[1] + rng.uniform(-0.2, 0.2),
                p[2] + rng.uniform(-0.2, 0.2),
            ])
            .unwrap()
        })
        .collect();
    let wt = 1.0 / (SIGMA_MM * SIGMA_MM);
    for (e, c, p, xy, _) in &s.obs {
        let cam = if *c == 0 { Camera::Left } else { Camera::Right };
        w.add_observation(Observation::new(*e as u32, cam, ids[*p], *xy, [wt, wt]))
            .unwrap();
    }
    (w, ids)
}

/// Fraction of parameters (poses and points) within `k` sigma of the truth.
pub(crate) fn within(w: &Window, s: &Scene, ids: &[u32], k: f64) -> (usize, usize) {
    let (mut ok, mut n) = (0, 0);
    for (e, truth) in s.poses.iter().enumerate() {
        let est = w.epoch_pose(e).unwrap().to_params();
        let std = w.epoch_std(e).unwrap();
        let t = truth.to_params();
        for i in 0..6 {
            n += 1;
            // The datum epoch has sigma ~1e-6: compare at that scale.
            if (est[i] - t[i]).abs() <= k * std[i] + 1e-9 {
                ok += 1;
            }
        }
    }
    for (p, truth) in s.points.iter().enumerate() {
        let (Some(est), Some(std)) = (w.point(ids[p]), w.point_std(ids[p])) else {
            continue;
        };
        for a in 0..3 {
            n += 1;
            if (est[a] - truth[a]).abs() <= k * std[a] {
                ok += 1;
            }
        }
    }
    (ok, n)
}

fn arena_for(cfg: &AdjustConfig) -> Vec<u8> {
    let mut b = MemoryBudget::new();
    cfg.budget(&mut b);
    vec![0u8; b.total()]
}
