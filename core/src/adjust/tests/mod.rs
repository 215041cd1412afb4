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
use crate::camera::{project, Interior, Pose, Rig};
use crate::camera::{Camera, RelativeOrientation};
use nalgebra::Vector3;
use std::vec;
use std::vec::Vec;

pub(crate) use crate::testkit::{DriveObservation, Rng, PIXEL_MM, SIGMA_MM};

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
}

mod jacobians;
mod pnp;
mod rig;
mod windows;

// ---------- synthetic windows ----------

pub(crate) type Scene = crate::testkit::Drive;

/// The test kit's drive, every point seen as long as it is visible.
pub(crate) fn scene(seed: u64, epochs: usize, n_points: usize, gross: f64) -> Scene {
    crate::testkit::drive(seed, epochs, n_points, gross, 0)
}

/// Loads a scene into a window with perturbed initial values; returns the
/// window and the point indices.
pub(crate) fn load<'a>(
    s: &Scene,
    cfg: AdjustConfig,
    arena: &mut Arena<'a>,
    seed: u64,
) -> (Window<'a>, Vec<u32>) {
    load_weighted(s, cfg, arena, seed, 1.0)
}

/// [`load`] with the observations' weights scaled by `weight_scale` (their a-priori
/// sigma by its inverse square root).
pub(crate) fn load_weighted<'a>(
    s: &Scene,
    cfg: AdjustConfig,
    arena: &mut Arena<'a>,
    seed: u64,
    weight_scale: f64,
) -> (Window<'a>, Vec<u32>) {
    let mut rng = Rng(seed);
    let mut w = Window::new(cfg, &s.rig, arena).unwrap();
    for (k, p) in s.poses.iter().enumerate() {
        let start = if k > 0 {
            rng.perturbed(p, 0.01, 0.1)
        } else {
            *p
        };
        w.add_epoch(&start, k as f64 * 0.2).unwrap();
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
    let wt = weight_scale / (SIGMA_MM * SIGMA_MM);
    for o in &s.observations {
        let (e, c, p, xy) = (&o.epoch, &o.camera, &o.point, &o.xy);
        let cam = *c;
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

pub(crate) fn arena_for(cfg: &AdjustConfig) -> Vec<u8> {
    let mut b = MemoryBudget::new();
    cfg.budget(&mut b);
    vec![0u8; b.total()]
}
