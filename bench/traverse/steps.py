#!/usr/bin/env python3
"""Per-step error analysis of a KITTI pose file against ground truth: splits the drift into a
systematic part (mean error of the epoch-to-epoch motion: a scale or heading bias accumulates
linearly with distance) and a random part (spread of the step errors: accumulates as a random
walk). This says where a trajectory's drift comes from, which `phototraverse eval`'s segment
averages do not.

For each step k-1 -> k: the true and estimated relative motions rel = inv(P_k-1) P_k (left camera
of k-1, KITTI axes: x right, y down, z forward), the error E = inv(rel_gt) rel_est; reported:
scale = |t_est| / |t_gt| - 1 (in %), E's translation per metre travelled (x, y, z in %) and E's
rotation vector (about x = pitch, y = yaw, z = roll) in millidegrees per step; mean and standard
deviation over the steps.

With `--unbiased OUT` (one EST), the trajectory EST would have without its bias: each
step's error less the mean error per step (its rotation, and its translation per metre of
step), written to OUT in the same format. What drift it has then is what its spread alone
gives: an odometry whose drift is mostly a bias, as the OpenCV peer's on the rendered
streets (a pitch of +1.6 to +3.7 mdeg per step), is measured at its best that way.

With `--yaw`, also each rotation error regressed on the step's true yaw (slope in % of
the yaw, with its standard error): a rotation whose axis is tilted against the true one
shows as a pitch or roll error in proportion to the turn, which the means above average
away over turns of both senses.

usage: steps.py GT EST [EST ...] [--yaw] [--unbiased OUT]
"""
import argparse
import sys

import numpy as np


def read_poses(path):
    rows = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            m = np.eye(4)
            m[:3] = np.array([float(v) for v in line.split()]).reshape(3, 4)
            rows.append(m)
    return rows


def rotation_vector(R):
    """Axis * angle (radians) of a rotation matrix."""
    c = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(c)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    s = np.linalg.norm(w)
    if s < 1e-15:
        return 0.5 * w  # small-angle limit
    return w / s * angle


def rotation_matrix(v):
    """The rotation of the rotation vector v (Rodrigues)."""
    angle = np.linalg.norm(v)
    if angle < 1e-15:
        return np.eye(3)
    k = v / angle
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1.0 - np.cos(angle)) * kx @ kx


def step_pairs(gt, est):
    """Per step k-1 -> k: the true relative motion rel_gt, the estimated one rel_est and the
    error E = inv(rel_gt) rel_est (4x4 each)."""
    if len(gt) != len(est):
        raise ValueError(f"{len(gt)} ground-truth poses, {len(est)} estimated")
    for k in range(1, len(gt)):
        rg = np.linalg.inv(gt[k - 1]) @ gt[k]
        re = np.linalg.inv(est[k - 1]) @ est[k]
        yield rg, re, np.linalg.inv(rg) @ re


def moving(d):
    """Whether a true step of length d (m) moves: standing still has no scale to speak of."""
    return d >= 1e-6


def unbiased(gt, est):
    """The poses of `est` with the mean step error taken out of every step (rotation vector
    per step, translation per metre of the true step), chained from est's first pose."""
    pairs = list(step_pairs(gt, est))
    rel_gt = [rg for rg, _, _ in pairs]
    errors = [e for _, _, e in pairs]
    lengths = np.array([max(np.linalg.norm(rg[:3, 3]), 1e-6) for rg in rel_gt])
    rot = np.array([rotation_vector(e[:3, :3]) for e in errors])
    per_m = np.array([e[:3, 3] for e in errors]) / lengths[:, None]
    mean_rot, mean_per_m = rot.mean(axis=0), per_m.mean(axis=0)
    poses = [est[0]]
    for rg, r, t, d in zip(rel_gt, rot, per_m, lengths):
        e = np.eye(4)
        e[:3, :3] = rotation_matrix(r - mean_rot)
        e[:3, 3] = (t - mean_per_m) * d
        poses.append(poses[-1] @ rg @ e)
    return poses


def write_poses(path, poses):
    with open(path, "w") as f:
        for p in poses:
            f.write(" ".join(f"{v:.9e}" for v in p[:3].reshape(-1)) + "\n")


def yaw_slopes(gt, est):
    """Per rotation axis: slope (in % of the true yaw) and its standard error of the steps'
    rotation errors regressed on the steps' true yaw, with an intercept (the steps of
    step_errors: those that move)."""
    _, _, rot = step_errors(gt, est)
    yaw = np.array([np.degrees(rotation_vector(rg[:3, :3])[1]) * 1e3  # mdeg, as the errors
                    for rg, _, _ in step_pairs(gt, est) if moving(np.linalg.norm(rg[:3, 3]))])
    design = np.vstack([yaw, np.ones_like(yaw)]).T
    out = []
    for axis in range(3):
        coef, *_ = np.linalg.lstsq(design, rot[:, axis], rcond=None)
        resid = rot[:, axis] - design @ coef
        var = resid @ resid / (len(yaw) - 2) * np.linalg.inv(design.T @ design)
        out.append((coef[0] * 100.0, np.sqrt(var[0, 0]) * 100.0))
    return out


def step_errors(gt, est):
    """Arrays per step: scale % (n), translation error % of the step (n x 3), rotation mdeg (n x 3)."""
    scale, trans, rot = [], [], []
    for rg, re, e in step_pairs(gt, est):
        d = np.linalg.norm(rg[:3, 3])
        if not moving(d):
            continue
        scale.append((np.linalg.norm(re[:3, 3]) / d - 1.0) * 100.0)
        trans.append(e[:3, 3] / d * 100.0)
        rot.append(np.degrees(rotation_vector(e[:3, :3])) * 1e3)
    return np.array(scale), np.array(trans).reshape(-1, 3), np.array(rot).reshape(-1, 3)


def summary(gt_path, est_path):
    s, t, r = step_errors(read_poses(gt_path), read_poses(est_path))
    return {
        "steps": int(len(s)),
        "scale_pct": {"mean": float(s.mean()), "std": float(s.std())},
        "translation_pct_xyz": {"mean": t.mean(axis=0).tolist(), "std": t.std(axis=0).tolist()},
        "rotation_mdeg_xyz": {"mean": r.mean(axis=0).tolist(), "std": r.std(axis=0).tolist()},
    }


def describe(name, s):
    tm, ts = s["translation_pct_xyz"]["mean"], s["translation_pct_xyz"]["std"]
    rm, rs = s["rotation_mdeg_xyz"]["mean"], s["rotation_mdeg_xyz"]["std"]
    return (f"{name}: scale {s['scale_pct']['mean']:+.3f} +- {s['scale_pct']['std']:.3f} % per step; "
            f"translation error x/y/z {tm[0]:+.3f}/{tm[1]:+.3f}/{tm[2]:+.3f} "
            f"+- {ts[0]:.3f}/{ts[1]:.3f}/{ts[2]:.3f} % of the step; "
            f"rotation pitch/yaw/roll {rm[0]:+.2f}/{rm[1]:+.2f}/{rm[2]:+.2f} "
            f"+- {rs[0]:.2f}/{rs[1]:.2f}/{rs[2]:.2f} mdeg per step")


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("gt", help="ground-truth poses (KITTI)")
    p.add_argument("est", nargs="+", help="estimated poses (KITTI)")
    p.add_argument("--yaw", action="store_true", help="each rotation error's slope against the true yaw")
    p.add_argument("--unbiased", metavar="OUT", help="write EST without its mean step error (one EST)")
    args = p.parse_args()
    if args.unbiased:
        if len(args.est) != 1:
            p.error("--unbiased takes one EST")
        write_poses(args.unbiased, unbiased(read_poses(args.gt), read_poses(args.est[0])))
    for est in args.est:
        print(describe(est, summary(args.gt, est)))
        if args.yaw:
            slopes = yaw_slopes(read_poses(args.gt), read_poses(est))
            print("  against the true yaw: " + ", ".join(
                f"{name} {m:+.3f} % ({se:.3f})" for name, (m, se) in zip(("pitch", "yaw", "roll"), slopes)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
