//! Motion-guided predictions for temporal matching: each stereo match of the previous
//! epoch is triangulated in the previous left camera's frame and projected into the
//! current left and right images with the predicted motion.
//!
//! Frame: the previous left camera is the identity pose (`M = I`, `C = 0`; x right,
//! y up, z backward, so forward travel is along -z). `motion` is the current left
//! camera's pose in that frame; [`relative_motion`] builds it from two object-frame poses.

use super::config::NONE;
use crate::camera::{Interior, Pose, Rig, MIN_DEPTH};
use crate::features::Keypoint;
use nalgebra::{Matrix3, Vector3};

/// Pose of `cur` in the camera frame of `prev`: `M = M_cur M_prev^T`, `C = M_prev (C_cur - C_prev)`.
pub fn relative_motion(prev: &Pose, cur: &Pose) -> Pose {
    let mp = prev.rotation();
    let m = cur.rotation() * mp.transpose();
    let c = mp * (cur.centre_vec() - prev.centre_vec());
    Pose::from_rotation(&m, [c[0], c[1], c[2]])
}

/// Midpoint triangulation of a stereo match in the left camera frame (metres);
/// `None` when the rays are parallel or the point is not in front of both cameras.
///
/// Not the window's linear intersection (`adjust::intersect`), on purpose: the two
/// estimators differ when the rays do not meet, which is what a miscalibrated rig
/// gives. With the window's, the motion check and the predictions made the
/// miscalibrated `curves` of `host/tests/accuracy.rs` drift 2.47 % instead of 0.57 %
/// (its steps erred 4 to 6 cm instead of about 1 cm after the first calibration
/// correction), for no gain on the calibrated scenes.
pub fn triangulate(rig: &Rig, left_px: [f64; 2], right_px: [f64; 2]) -> Option<Vector3<f64>> {
    triangulate_with(rig, &rig.relative_rotation(), left_px, right_px)
}

/// [`triangulate`] with the relative rotation computed once by the caller.
fn triangulate_with(
    rig: &Rig,
    mrel: &Matrix3<f64>,
    left_px: [f64; 2],
    right_px: [f64; 2],
) -> Option<Vector3<f64>> {
    let l = rig.left.pixel_to_corrected(left_px[0], left_px[1]);
    let r = rig.right.pixel_to_corrected(right_px[0], right_px[1]);
    triangulate_corrected(rig, mrel, l, r)
}

/// Midpoint triangulation from corrected photo-coordinates (mm) in the left camera
/// frame; `mrel` is the rig's relative rotation.
pub fn triangulate_corrected(
    rig: &Rig,
    mrel: &Matrix3<f64>,
    [xl, yl]: [f64; 2],
    [xr, yr]: [f64; 2],
) -> Option<Vector3<f64>> {
    let dl = Vector3::new(xl, yl, -rig.left.focal_mm);
    let dr = mrel.transpose() * Vector3::new(xr, yr, -rig.right.focal_mm);
    let b = Vector3::from(rig.base_m);
    // Closest points of 0 + s dl and b + u dr.
    let (a11, a12, a22) = (dl.dot(&dl), -dl.dot(&dr), dr.dot(&dr));
    let (r1, r2) = (dl.dot(&b), -dr.dot(&b));
    let det = a11 * a22 - a12 * a12;
    if det.is_nan() || det.abs() <= 1e-12 * a11 * a22 {
        return None;
    }
    let s = (r1 * a22 - a12 * r2) / det;
    let u = (a11 * r2 - a12 * r1) / det;
    if !(s > 0.0 && u > 0.0) {
        return None;
    }
    let p = (dl * s + b + dr * u) * 0.5;
    p.iter().all(|v| v.is_finite()).then_some(p)
}

/// Fills `out_left[i]` (per previous left keypoint) and `out_right[j]` (per previous
/// right keypoint) with the predicted current pixel positions of the stereo-matched
/// keypoints (`stereo[i]` = right index or [`NONE`]); everything else gets NaN, which
/// the temporal matcher treats as "no prediction". Returns the number of predictions.
pub fn predict_positions(
    rig: &Rig,
    motion: &Pose,
    prev_left: &[Keypoint],
    prev_right: &[Keypoint],
    stereo: &[u32],
    out_left: &mut [[f32; 2]],
    out_right: &mut [[f32; 2]],
) -> usize {
    out_left.fill([f32::NAN; 2]);
    out_right.fill([f32::NAN; 2]);
    // Rotations once per call: the per-point work is then a few multiply-adds.
    let mrel = rig.relative_rotation();
    let left_cam = Projector::new(motion, &rig.left);
    let right_cam = Projector::new(&rig.right_pose(motion), &rig.right);
    let mut count = 0;
    for (i, (&j, kl)) in stereo.iter().zip(prev_left).enumerate() {
        if j == NONE || i >= out_left.len() {
            continue;
        }
        let (Some(kr), true) = (prev_right.get(j as usize), (j as usize) < out_right.len()) else {
            continue;
        };
        let Some(p) = triangulate_with(
            rig,
            &mrel,
            [kl.x as f64, kl.y as f64],
            [kr.x as f64, kr.y as f64],
        ) else {
            continue;
        };
        let (Some(l), Some(r)) = (left_cam.pixel(&p), right_cam.pixel(&p)) else {
            continue;
        };
        out_left[i] = [l[0] as f32, l[1] as f32];
        out_right[j as usize] = [r[0] as f32, r[1] as f32];
        count += 1;
    }
    count
}

/// Collinearity with the rotation computed once (same result as `project_to_pixel`).
struct Projector<'c> {
    m: Matrix3<f64>,
    c: Vector3<f64>,
    cam: &'c Interior,
}

impl<'c> Projector<'c> {
    fn new(pose: &Pose, cam: &'c Interior) -> Self {
        Projector {
            m: pose.rotation(),
            c: pose.centre_vec(),
            cam,
        }
    }

    fn pixel(&self, p: &Vector3<f64>) -> Option<[f64; 2]> {
        let uvw = self.m * (p - self.c);
        if uvw[2].is_nan() || uvw[2] >= -MIN_DEPTH {
            return None;
        }
        let f = self.cam.focal_mm;
        self.cam
            .corrected_to_pixel(-f * uvw[0] / uvw[2], -f * uvw[1] / uvw[2])
            .ok()
    }
}
