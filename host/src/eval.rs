//! Trajectory evaluation against ground truth, KITTI-style.
//!
//! Drift follows the KITTI odometry devkit (`evaluate_odometry.cpp`): segments
//! start every [`STEP_FRAMES`] frames; for each of 8 lengths `L` the segment
//! ends at the first frame whose ground-truth path distance from the start
//! exceeds `L`; the error pose is `inv(inv(E_a) E_b) inv(G_a) G_b`; its
//! translation norm / `L` and its rotation angle / `L` are averaged over all
//! segments of all lengths. The devkit uses `L = 100, 200, ..., 800 m`; a
//! shorter sequence has no such segments, so the lengths are
//! `L_i = i * min(100 m, P / 10)`, `i = 1..8`, with `P` the total ground-truth
//! path length: identical to the devkit from 1 km on, 10 % .. 80 % of the path
//! below that.
//!
//! ATE RMSE is the RMS of the position differences with no alignment: both
//! trajectories are expressed in the left camera frame of epoch 0, so they
//! share their origin by construction. As evo's `ape -a` / `-as` give them, the ATE is
//! also stated after the least-squares alignment of the estimated positions onto the
//! true ones (Umeyama 1991): rigid (SE(3)), and similarity (Sim(3), with its scale, for
//! comparisons with a monocular-style estimate). The relative pose error (RPE) is
//! evo's `rpe` over one frame: per consecutive pair, the error pose
//! `inv(inv(E_i) E_{i+1}) inv(G_i) G_{i+1}`, its translation norm and rotation angle,
//! RMS over the pairs. The final-position error is the distance between the last
//! positions as a percentage of the path length.
use crate::poses::KittiPose;
use nalgebra::{Matrix3, Matrix4, Vector3};
use serde::Serialize;

/// Frames between segment starts (devkit `step_size`).
pub const STEP_FRAMES: usize = 10;
/// Number of segment lengths (devkit: 100..800 m).
pub const NUM_LENGTHS: usize = 8;
/// Devkit base length, metres.
pub const DEVKIT_LENGTH_M: f64 = 100.0;

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum EvalError {
    #[error("ground truth has {gt} poses but the estimate has {est} (eval --common-prefix compares the poses both have)")]
    CountMismatch { gt: usize, est: usize },
    #[error("no poses to evaluate")]
    Empty,
}

/// Drift of the segments of one length.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct LengthDrift {
    pub length_m: f64,
    pub segments: usize,
    pub translation_pct: f64,
    pub rotation_deg_per_m: f64,
}

/// The evaluation summary (also the JSON written by `eval --json`).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Evaluation {
    pub frames: usize,
    pub path_length_m: f64,
    /// Segment lengths used (see the module documentation for the rule).
    pub segment_lengths_m: Vec<f64>,
    pub segments: usize,
    /// Mean translation drift over all segments, % (None when no segment fits).
    pub translation_drift_pct: Option<f64>,
    /// Mean rotation drift over all segments, deg/m.
    pub rotation_drift_deg_per_m: Option<f64>,
    pub per_length: Vec<LengthDrift>,
    /// RMS of position differences, metres, no alignment.
    pub ate_rmse_m: f64,
    /// The same after the rigid (SE(3)) least-squares alignment of the positions.
    pub ate_se3_rmse_m: f64,
    /// The same after the similarity (Sim(3)) alignment, and that alignment's scale.
    pub ate_sim3_rmse_m: f64,
    pub sim3_scale: f64,
    /// Relative pose error over one frame: RMS of the translation (m) and rotation (deg)
    /// of the error poses of consecutive frames (None for a single frame).
    pub rpe_translation_rmse_m: Option<f64>,
    pub rpe_rotation_rmse_deg: Option<f64>,
    pub final_position_error_m: f64,
    /// Final-position error as % of the path length (None for a zero-length path).
    pub final_position_error_pct: Option<f64>,
}

fn to_matrix(p: &KittiPose) -> Matrix4<f64> {
    Matrix4::from_fn(|i, j| {
        if i < 3 {
            p[i][j]
        } else if j == 3 {
            1.0
        } else {
            0.0
        }
    })
}

/// Inverse of a rigid transform (rotation transposed; robust to slightly non-orthonormal input
/// the same way the devkit's use of `inv` would be close to it).
fn rigid_inverse(m: &Matrix4<f64>) -> Matrix4<f64> {
    m.try_inverse().unwrap_or_else(|| {
        // A singular 3x3 block is not a pose; fall back to the transpose form.
        let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).transpose();
        let t = -(r * m.fixed_view::<3, 1>(0, 3));
        let mut out = Matrix4::identity();
        out.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
        out.fixed_view_mut::<3, 1>(0, 3).copy_from(&t);
        out
    })
}

fn position(p: &KittiPose) -> Vector3<f64> {
    Vector3::new(p[0][3], p[1][3], p[2][3])
}

/// Devkit `rotationError`: angle of the rotation part, radians.
fn rotation_angle(m: &Matrix4<f64>) -> f64 {
    let d = 0.5 * (m[(0, 0)] + m[(1, 1)] + m[(2, 2)] - 1.0);
    d.clamp(-1.0, 1.0).acos()
}

/// Cumulative ground-truth path distances (devkit `trajectoryDistances`).
pub fn trajectory_distances(poses: &[KittiPose]) -> Vec<f64> {
    let mut dist = Vec::with_capacity(poses.len());
    let mut acc = 0.0;
    for (i, p) in poses.iter().enumerate() {
        if i > 0 {
            acc += (position(p) - position(&poses[i - 1])).norm();
        }
        dist.push(acc);
    }
    dist
}

/// The segment lengths for a path of `path_length_m` (module documentation).
pub fn segment_lengths(path_length_m: f64) -> Vec<f64> {
    let unit = DEVKIT_LENGTH_M.min(path_length_m / 10.0);
    (1..=NUM_LENGTHS).map(|i| i as f64 * unit).collect()
}

/// Evaluates `est` against `gt`.
pub fn evaluate(gt: &[KittiPose], est: &[KittiPose]) -> Result<Evaluation, EvalError> {
    if gt.len() != est.len() {
        return Err(EvalError::CountMismatch {
            gt: gt.len(),
            est: est.len(),
        });
    }
    if gt.is_empty() {
        return Err(EvalError::Empty);
    }
    let n = gt.len();
    let dist = trajectory_distances(gt);
    let path_length_m = dist[n - 1];
    let lengths = segment_lengths(path_length_m);
    let gm: Vec<Matrix4<f64>> = gt.iter().map(to_matrix).collect();
    let em: Vec<Matrix4<f64>> = est.iter().map(to_matrix).collect();

    let mut per_length: Vec<LengthDrift> = Vec::with_capacity(NUM_LENGTHS);
    let (mut t_sum, mut r_sum, mut count) = (0.0, 0.0, 0usize);
    for &len in &lengths {
        let (mut lt, mut lr, mut lc) = (0.0, 0.0, 0usize);
        if len > 0.0 {
            for first in (0..n).step_by(STEP_FRAMES) {
                // Devkit lastFrameFromSegmentLength: first frame with dist > dist[first] + len.
                let Some(last) = (first..n).find(|&i| dist[i] > dist[first] + len) else {
                    continue;
                };
                let delta_gt = rigid_inverse(&gm[first]) * gm[last];
                let delta_est = rigid_inverse(&em[first]) * em[last];
                let err = rigid_inverse(&delta_est) * delta_gt;
                let t_err = err.fixed_view::<3, 1>(0, 3).norm();
                lt += t_err / len;
                lr += rotation_angle(&err) / len;
                lc += 1;
            }
        }
        t_sum += lt;
        r_sum += lr;
        count += lc;
        let mean = |s: f64| if lc > 0 { s / lc as f64 } else { 0.0 };
        per_length.push(LengthDrift {
            length_m: len,
            segments: lc,
            translation_pct: mean(lt) * 100.0,
            rotation_deg_per_m: mean(lr).to_degrees(),
        });
    }
    let sq: f64 = gt
        .iter()
        .zip(est)
        .map(|(g, e)| (position(g) - position(e)).norm_squared())
        .sum();
    let final_err = (position(&gt[n - 1]) - position(&est[n - 1])).norm();
    let (g, e): (Vec<Vector3<f64>>, Vec<Vector3<f64>>) = gt
        .iter()
        .zip(est)
        .map(|(g, e)| (position(g), position(e)))
        .unzip();
    let (ate_se3, _) = aligned_rmse(&g, &e, false);
    let (ate_sim3, sim3_scale) = aligned_rmse(&g, &e, true);
    let (rpe_t, rpe_r) = relative_pose_error(&gm, &em);
    Ok(Evaluation {
        frames: n,
        path_length_m,
        segment_lengths_m: lengths,
        segments: count,
        translation_drift_pct: (count > 0).then(|| t_sum / count as f64 * 100.0),
        rotation_drift_deg_per_m: (count > 0).then(|| (r_sum / count as f64).to_degrees()),
        per_length,
        ate_rmse_m: (sq / n as f64).sqrt(),
        ate_se3_rmse_m: ate_se3,
        ate_sim3_rmse_m: ate_sim3,
        sim3_scale,
        rpe_translation_rmse_m: rpe_t,
        rpe_rotation_rmse_deg: rpe_r,
        final_position_error_m: final_err,
        final_position_error_pct: (path_length_m > 0.0).then(|| final_err / path_length_m * 100.0),
    })
}

/// RMS of `est` aligned onto `gt` by least squares (Umeyama): rotation and translation,
/// and a scale when `with_scale`; with the scale used (1 without).
fn aligned_rmse(gt: &[Vector3<f64>], est: &[Vector3<f64>], with_scale: bool) -> (f64, f64) {
    let n = gt.len() as f64;
    let mean = |v: &[Vector3<f64>]| v.iter().sum::<Vector3<f64>>() / n;
    let (mg, me) = (mean(gt), mean(est));
    let cov: Matrix3<f64> = gt
        .iter()
        .zip(est)
        .map(|(g, e)| (g - mg) * (e - me).transpose())
        .sum::<Matrix3<f64>>()
        / n;
    let var_e = est.iter().map(|e| (e - me).norm_squared()).sum::<f64>() / n;
    let svd = cov.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return (f64::NAN, f64::NAN);
    };
    // A reflection is not a rotation: the smallest singular direction is flipped.
    let mut d = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = u * d * v_t;
    let scale = if with_scale && var_e > 0.0 {
        (Matrix3::from_diagonal(&svd.singular_values) * d).trace() / var_e
    } else {
        1.0
    };
    let t = mg - scale * r * me;
    let sq: f64 = gt
        .iter()
        .zip(est)
        .map(|(g, e)| (g - (scale * r * e + t)).norm_squared())
        .sum();
    ((sq / n).sqrt(), scale)
}

/// RMS translation (m) and rotation (deg) of the one-frame error poses.
fn relative_pose_error(gm: &[Matrix4<f64>], em: &[Matrix4<f64>]) -> (Option<f64>, Option<f64>) {
    let pairs = gm.len().saturating_sub(1);
    if pairs == 0 {
        return (None, None);
    }
    let (mut t, mut r) = (0.0, 0.0);
    for i in 0..pairs {
        let delta_gt = rigid_inverse(&gm[i]) * gm[i + 1];
        let delta_est = rigid_inverse(&em[i]) * em[i + 1];
        let err = rigid_inverse(&delta_est) * delta_gt;
        t += err.fixed_view::<3, 1>(0, 3).norm_squared();
        r += rotation_angle(&err).powi(2);
    }
    let rms = |s: f64| (s / pairs as f64).sqrt();
    (Some(rms(t)), Some(rms(r).to_degrees()))
}

impl Evaluation {
    /// A human summary, several lines.
    pub fn summary(&self) -> String {
        let opt = |v: Option<f64>, unit: &str| match v {
            Some(v) => format!("{v:.4} {unit}"),
            None => "n/a (no segment fits)".to_string(),
        };
        let mut s = format!(
            "frames: {}, path length: {:.2} m, segments: {} (lengths {:.1}..{:.1} m)\n",
            self.frames,
            self.path_length_m,
            self.segments,
            self.segment_lengths_m.first().copied().unwrap_or(0.0),
            self.segment_lengths_m.last().copied().unwrap_or(0.0)
        );
        s += &format!(
            "translation drift: {}\n",
            opt(self.translation_drift_pct, "%")
        );
        s += &format!(
            "rotation drift:    {}\n",
            opt(self.rotation_drift_deg_per_m, "deg/m")
        );
        s += &format!(
            "ATE RMSE:          {:.4} m (no alignment; both start at the identity)\n",
            self.ate_rmse_m
        );
        s += &format!(
            "ATE aligned:       {:.4} m rigid (SE(3)), {:.4} m similarity (Sim(3), scale {:.5})\n",
            self.ate_se3_rmse_m, self.ate_sim3_rmse_m, self.sim3_scale
        );
        if let (Some(t), Some(r)) = (self.rpe_translation_rmse_m, self.rpe_rotation_rmse_deg) {
            s += &format!("RPE (1 frame):     {t:.4} m, {r:.4} deg RMS\n");
        }
        s += &format!(
            "final position:    {:.4} m = {} of the distance travelled\n",
            self.final_position_error_m,
            opt(self.final_position_error_pct, "%")
        );
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::poses::IDENTITY;

    /// A pose at `t` with yaw `psi` about the KITTI y axis (vertical).
    fn pose(psi: f64, t: [f64; 3]) -> KittiPose {
        let (s, c) = psi.sin_cos();
        [[c, 0.0, s, t[0]], [0.0, 1.0, 0.0, t[1]], [-s, 0.0, c, t[2]]]
    }

    /// A straight drive along KITTI z, `step` metres per frame.
    fn straight(n: usize, step: f64) -> Vec<KittiPose> {
        (0..n)
            .map(|i| pose(0.0, [0.0, 0.0, i as f64 * step]))
            .collect()
    }

    #[test]
    fn perfect_estimate_has_zero_error() {
        let gt: Vec<KittiPose> = (0..200)
            .map(|i| pose(i as f64 * 0.01, [i as f64 * 0.3, 0.1, i as f64]))
            .collect();
        let e = evaluate(&gt, &gt).unwrap();
        assert!(e.segments > 0);
        assert!(e.translation_drift_pct.unwrap() < 1e-12);
        assert!(e.rotation_drift_deg_per_m.unwrap() < 1e-6);
        assert_eq!(e.ate_rmse_m, 0.0);
        assert_eq!(e.final_position_error_pct, Some(0.0));
    }

    #[test]
    fn scale_error_gives_its_translation_drift() {
        let step = 0.05;
        let gt = straight(2001, step); // 100 m
        let est: Vec<KittiPose> = gt
            .iter()
            .map(|p| pose(0.0, [0.0, 0.0, p[2][3] * 1.01]))
            .collect();
        let e = evaluate(&gt, &est).unwrap();
        // Lengths 10..80 m; each segment runs one step past L, so the drift is
        // 1 % * (L + step) / L at most.
        assert_eq!(e.segment_lengths_m.len(), 8);
        assert!((e.segment_lengths_m[0] - 10.0).abs() < 1e-9);
        let t = e.translation_drift_pct.unwrap();
        assert!(
            t >= 1.0 - 1e-9 && t <= 1.0 * (1.0 + step / 10.0) + 1e-9,
            "{t}"
        );
        assert!(e.rotation_drift_deg_per_m.unwrap() < 1e-9);
        assert!((e.final_position_error_pct.unwrap() - 1.0).abs() < 1e-9);
        // ATE: RMS of 0.01 * z over z uniform in [0, 100].
        let expect: f64 =
            (gt.iter().map(|p| (0.01 * p[2][3]).powi(2)).sum::<f64>() / gt.len() as f64).sqrt();
        assert!((e.ate_rmse_m - expect).abs() < 1e-12);
    }

    #[test]
    fn heading_rate_error_gives_its_rotation_drift() {
        let step = 0.05;
        let n = 2001;
        let gt = straight(n, step);
        let rate = 0.002; // rad/m
                          // Dead reckoning with a biased gyro: heading grows with distance, position follows it.
        let mut est = vec![IDENTITY];
        let mut p = [0.0f64; 3];
        for i in 1..n {
            let psi = rate * (i - 1) as f64 * step;
            p[0] += step * psi.sin();
            p[2] += step * psi.cos();
            est.push(pose(rate * i as f64 * step, p));
        }
        let e = evaluate(&gt, &est).unwrap();
        let r = e.rotation_drift_deg_per_m.unwrap();
        let expect = rate.to_degrees();
        assert!(
            r >= expect - 1e-9 && r <= expect * (1.0 + step / 10.0) + 1e-9,
            "{r} vs {expect}"
        );
        // Translation drift of a constant-curvature error: chord deviation ~ rate L / 2.
        assert!(e.translation_drift_pct.unwrap() > 0.0);
    }

    #[test]
    fn devkit_lengths_for_long_paths() {
        assert_eq!(
            segment_lengths(5000.0),
            vec![100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0]
        );
        assert_eq!(segment_lengths(1000.0)[7], 800.0);
        assert_eq!(segment_lengths(50.0)[0], 5.0);
    }

    #[test]
    fn different_counts_are_an_error() {
        let gt = straight(10, 1.0);
        assert_eq!(
            evaluate(&gt, &gt[..9]).unwrap_err(),
            EvalError::CountMismatch { gt: 10, est: 9 }
        );
        assert_eq!(evaluate(&[], &[]).unwrap_err(), EvalError::Empty);
    }

    #[test]
    fn short_sequences() {
        let gt = straight(2, 1.0);
        let est = vec![IDENTITY, pose(0.0, [0.0, 0.0, 2.0])];
        let e = evaluate(&gt, &est).unwrap();
        // One start frame, all 8 lengths (0.1..0.8 m) end at frame 1: error 1 m each.
        assert_eq!(e.segments, 8);
        let expect = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8]
            .iter()
            .map(|l| 100.0 / l)
            .sum::<f64>()
            / 8.0;
        assert!((e.translation_drift_pct.unwrap() - expect).abs() < 1e-9);
        assert!((e.ate_rmse_m - (0.5f64).sqrt()).abs() < 1e-12);
        assert!((e.final_position_error_pct.unwrap() - 100.0).abs() < 1e-9);
        // A single pose: no path, no segment, no percentage.
        let e = evaluate(&gt[..1], &est[..1]).unwrap();
        assert_eq!(
            (
                e.segments,
                e.translation_drift_pct,
                e.final_position_error_pct
            ),
            (0, None, None)
        );
    }

    /// A curve climbing gently: positions not on one line, so an alignment is determined.
    fn curve(n: usize) -> Vec<KittiPose> {
        (0..n)
            .map(|i| {
                let a = i as f64 * 0.05;
                pose(a, [20.0 * a.sin(), -0.1 * i as f64, 20.0 * (1.0 - a.cos())])
            })
            .collect()
    }

    /// `p` moved by the similarity `x -> s R x + t` (R a rotation about KITTI x).
    fn moved(p: &[KittiPose], s: f64, angle: f64, t: [f64; 3]) -> Vec<KittiPose> {
        let r = nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), angle);
        p.iter()
            .map(|q| {
                let c = s * (r * position(q)) + Vector3::from(t);
                let rot = r * Matrix3::from_fn(|i, j| q[i][j]);
                let mut out = *q;
                for i in 0..3 {
                    for j in 0..3 {
                        out[i][j] = rot[(i, j)];
                    }
                    out[i][3] = c[i];
                }
                out
            })
            .collect()
    }

    #[test]
    fn alignment_takes_out_a_rigid_motion_and_a_scale() {
        let gt = curve(60);
        let rigid = moved(&gt, 1.0, 0.2, [3.0, -1.0, 2.0]);
        let e = evaluate(&gt, &rigid).unwrap();
        assert!(e.ate_rmse_m > 1.0, "{}", e.ate_rmse_m);
        assert!(e.ate_se3_rmse_m < 1e-9 && e.ate_sim3_rmse_m < 1e-9, "{e:?}");
        assert!((e.sim3_scale - 1.0).abs() < 1e-9);
        // A relative error does not see where the trajectory is.
        assert!(e.rpe_translation_rmse_m.unwrap() < 1e-9);
        let scaled = moved(&gt, 1.1, -0.3, [1.0, 2.0, 0.0]);
        let e = evaluate(&gt, &scaled).unwrap();
        assert!(e.ate_se3_rmse_m > 0.1, "{e:?}");
        assert!(e.ate_sim3_rmse_m < 1e-9, "{e:?}");
        assert!((e.sim3_scale - 1.0 / 1.1).abs() < 1e-9, "{}", e.sim3_scale);
    }

    #[test]
    fn the_relative_pose_error_is_the_error_of_each_step() {
        // Every step 2 cm too long along the motion: RPE 0.02 m, no rotation error.
        let gt = straight(30, 1.0);
        let est = straight(30, 1.02);
        let e = evaluate(&gt, &est).unwrap();
        assert!(
            (e.rpe_translation_rmse_m.unwrap() - 0.02).abs() < 1e-12,
            "{e:?}"
        );
        assert!(e.rpe_rotation_rmse_deg.unwrap() < 1e-12);
        assert_eq!(
            evaluate(&gt[..1], &est[..1])
                .unwrap()
                .rpe_translation_rmse_m,
            None
        );
    }
}
