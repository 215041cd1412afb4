//! Constant-velocity motion prediction from the last two epochs.
use super::Stamped;
use crate::camera::Pose;
use nalgebra::Rotation3;

/// The pose at `time` continuing the motion between the last two epochs at
/// constant velocity (in the vehicle's frame), or the last pose when only one is
/// known; `None` before the first epoch.
pub(super) fn predict(history: &[Option<Stamped>; 2], time: f64) -> Option<Pose> {
    let last = history[1]?;
    let Some(before) = history[0] else {
        return Some(last.pose);
    };
    Some(constant_velocity(
        (&before.pose, before.time),
        (&last.pose, last.time),
        time,
    ))
}

/// The pose at `time` continuing the motion from `a` to `b` (poses with their times)
/// at constant velocity in the vehicle's frame; one step per epoch without usable times.
pub fn constant_velocity(a: (&Pose, f64), b: (&Pose, f64), time: f64) -> Pose {
    let (before, last) = (
        Stamped {
            pose: *a.0,
            time: a.1,
        },
        Stamped {
            pose: *b.0,
            time: b.1,
        },
    );
    let dt = last.time - before.time;
    // Without usable times, one epoch is one step.
    let s = if dt > 0.0 && (time - last.time).is_finite() && time > last.time {
        (time - last.time) / dt
    } else {
        1.0
    };
    let ma = before.pose.rotation();
    let mb = last.pose.rotation();
    // Rotation and displacement of the last step, in the camera frame of `before`.
    let step = Rotation3::from_matrix_unchecked(mb * ma.transpose());
    let step_rot = step.powf(s);
    let disp = ma * (last.pose.centre_vec() - before.pose.centre_vec()) * s;
    let m = step_rot.matrix() * mb;
    let c = last.pose.centre_vec() + mb.transpose() * disp;
    Pose::from_rotation(&m, [c[0], c[1], c[2]])
}
