//! The traverse's adjustment on exact observations: a street drive whose image
//! measurements are the true projections, processed epoch by epoch as the traverse
//! does (add the epoch from a perturbed prediction, observe, solve, slide), with the
//! traverse's own adjustment settings. Any systematic error of the chain (conventions,
//! Jacobians, constraints, the prior carried at a slide, the fixed epochs' observations)
//! shows as a mean per-step error of the poses: on exact data it must vanish.
extern crate std;
use super::geometry::project_rig;
use super::tests::Rng;
use super::{Observation, Window};
use crate::budget::{Arena, MemoryBudget};
use crate::camera::{Camera, RelativeOrientation};
use crate::camera::{Interior, Pose, Rig};
use crate::traverse::TraverseConfig;
use nalgebra::Matrix3;
use std::vec;
use std::vec::Vec;

const EPOCHS: usize = 40;
/// Metres per epoch and seconds per epoch (constant velocity, as the smoothness
/// constraint expects).
const STEP_M: f64 = 1.0;
const DT_S: f64 = 0.1;

/// Street points along two facades, the ground and far buildings.
fn street_points(rng: &mut Rng, n: usize) -> Vec<[f64; 3]> {
    (0..n)
        .map(|i| {
            let y = rng.uniform(3.0, EPOCHS as f64 * STEP_M + 40.0);
            match i % 4 {
                0 => [-5.0 - rng.uniform(0.0, 0.3), y, rng.uniform(-1.5, 8.0)],
                1 => [6.0 + rng.uniform(0.0, 0.3), y, rng.uniform(-1.5, 8.0)],
                2 => [rng.uniform(-5.0, 6.0), y, -1.6],
                _ => [rng.uniform(-40.0, 40.0), y + 60.0, rng.uniform(0.0, 20.0)],
            }
        })
        .collect()
}

/// The true left poses: forward along +Y with a small, smooth wobble of the attitude.
fn true_poses() -> Vec<Pose> {
    (0..EPOCHS)
        .map(|k| {
            let t = k as f64;
            Pose::from_degrees(
                90.0 + 0.3 * libm::sin(0.4 * t),
                0.2 * libm::sin(0.3 * t + 1.0),
                0.25 * libm::sin(0.5 * t + 2.0),
                [0.0, t * STEP_M, 0.0],
            )
        })
        .collect()
}

/// Rotation of a pose (object to camera) as a matrix.
fn m(p: &Pose) -> Matrix3<f64> {
    p.rotation()
}

/// Mean per-step rotation error (about the camera's x, y, z; degrees) of `est`
/// against `truth`: the error of each epoch-to-epoch relative rotation.
fn mean_step_rotation_error(truth: &[Pose], est: &[Pose]) -> [f64; 3] {
    let mut sum = [0.0; 3];
    for k in 1..truth.len() {
        let rel_t = m(&truth[k]) * m(&truth[k - 1]).transpose();
        let rel_e = m(&est[k]) * m(&est[k - 1]).transpose();
        let e = rel_e * rel_t.transpose();
        // Small-angle rotation vector of the skew part.
        let w = [
            0.5 * (e[(2, 1)] - e[(1, 2)]),
            0.5 * (e[(0, 2)] - e[(2, 0)]),
            0.5 * (e[(1, 0)] - e[(0, 1)]),
        ];
        for a in 0..3 {
            sum[a] += w[a].to_degrees();
        }
    }
    sum.map(|s| s / (truth.len() - 1) as f64)
}

#[test]
fn exact_observations_leave_no_systematic_step_error() {
    let cam = Interior::pinhole_px(640, 480, 500.0);
    let rig = Rig::rectified(cam, 0.94);
    let truth = true_poses();
    let mut cfg = TraverseConfig::for_rig(rig, truth[0]);
    cfg.adjust.max_points = 4000;
    cfg.adjust.max_observations = 60_000;
    let adjust = cfg.adjust;
    let mut budget = MemoryBudget::new();
    adjust.budget(&mut budget);
    let mut mem = vec![0u8; budget.total()];
    let mut arena = Arena::new(&mut mem);
    let mut w = Window::new(adjust, &rig, &mut arena).unwrap();
    w.set_base_length(rig.base_length());

    let mut rng = Rng(5);
    let points = street_points(&mut rng, 1500);
    let rp = RelativeOrientation::from_rig(&rig);
    let half = [320.0, 240.0];
    let wt = 1.0 / libm::pow(cfg.sigma_px, 2.0);
    let mut ids: Vec<Option<u32>> = vec![None; points.len()];
    let mut est = Vec::new();
    for (k, pose) in truth.iter().enumerate() {
        if w.n_epochs() == adjust.window {
            est.push(w.slide().unwrap());
        }
        // The initial value is off as a motion prediction would be.
        let mut q = pose.to_params();
        if k > 0 {
            q[0] += 2e-3;
            q[2] -= 1e-3;
            q[4] += 0.05;
        }
        let id = w
            .add_epoch(&Pose::from_params(&q), k as f64 * DT_S)
            .unwrap();
        for (p, xyz) in points.iter().enumerate() {
            let seen = [Camera::Left, Camera::Right].map(|c| {
                project_rig(pose, &rp, c, cam.focal_mm, xyz)
                    .ok()
                    .filter(|pr| pr.xy[0].abs() < half[0] && pr.xy[1].abs() < half[1])
                    .filter(|_| pose.to_camera(xyz)[2] < -2.0)
                    .map(|pr| pr.xy)
            });
            let [Some(l), Some(r)] = seen else { continue };
            let point = match ids[p] {
                Some(i) if w.point(i).is_some() => i,
                // A new point starts off its truth, as an intersection would.
                _ => {
                    let i = w
                        .add_point([xyz[0] + 0.05, xyz[1] - 0.1, xyz[2] + 0.02])
                        .unwrap();
                    ids[p] = Some(i);
                    i
                }
            };
            for (c, xy) in [(Camera::Left, l), (Camera::Right, r)] {
                w.add_observation(Observation::new(id, c, point, xy, [wt, wt]))
                    .unwrap();
            }
        }
        if k > 0 {
            w.solve().unwrap();
        }
    }
    for slot in 0..w.n_epochs() {
        est.push(w.epoch_pose(slot).unwrap());
    }
    assert_eq!(est.len(), truth.len());
    let bias = mean_step_rotation_error(&truth, &est);
    for (a, b) in bias.iter().enumerate() {
        assert!(
            b.abs() < 1e-4,
            "mean step rotation error about axis {a}: {b:e} deg ({bias:?})"
        );
    }
    // And the trajectory itself is exact.
    let last = est.last().unwrap().centre;
    let t = truth.last().unwrap().centre;
    let d = (0..3).map(|a| (last[a] - t[a]).powi(2)).sum::<f64>().sqrt();
    assert!(d < 1e-3, "final position off by {d} m");
}
