#!/usr/bin/env python3
"""An outage bridged by a pose graph over the images' relative poses, for comparison with
the smoothing `run` does (`host/src/smoothing.rs`).

The graph: the poses of every epoch (attitude and left perspective centre) are the
unknowns. Each step observes the relative pose of two consecutive epochs as an images-only
run (`run --images-only`) estimated it (`--chain aided`: as the aided run's firmware did):
the relative rotation, with `--sigma-rot` radians per axis, and the step in the earlier
camera's frame, with `--sigma-step` metres per axis. Each fix of the aided run observes its
epoch's left centre with its sigma (no lever arm: `synth` puts the antenna there); the
datum epoch is held. Gauss-Newton on the rotations' tangent space (numerical Jacobians per
step, a sparse solve). It knows the turn geometry and where the fixes see the attitude,
which the smoothing's per-coordinate chain does not; it does not know the images'
systematic errors, which the on-board window meets with the fixes.

Prints the bars as `outage.py` does: the largest position error inside the outage and the
RMS error outside, against the truth.

usage: pose_graph.py AIDED_DIR IMAGES_ONLY_DIR START_S END_S [--sigma-rot R] [--sigma-step S]
                     [--chain images|aided]
(numpy, scipy)
"""
import argparse
import json
import os

import numpy as np
import scipy.sparse as sparse
import scipy.sparse.linalg as sparse_linalg
from scipy.spatial.transform import Rotation

from attitude import kitti

ITERATIONS = 4
DATUM_SIGMA = 1e-6


def exp(w):
    return Rotation.from_rotvec(w).as_matrix()


def log(r):
    return Rotation.from_matrix(r).as_rotvec()


def rigid_fit(a, b):
    """R, t with b ~ R a + t (both (n, 3))."""
    ca, cb = a.mean(0), b.mean(0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])
    r = vt.T @ d @ u.T
    return r, cb - r @ ca


def aided_chain(aided_dir, epochs, to_kitti):
    """The aided run's own chain: the firmware's attitudes (poses.txt; the smoothing does not
    change them) and its steps (`step_m`, both centres from one window adjustment), the
    firmware's centres where a step is missing."""
    r, t = to_kitti
    poses = kitti(os.path.join(aided_dir, "poses.txt"))
    centre = lambda e: np.array(e.get("realtime_centre_m")
                                or [e["left"]["x"], e["left"]["y"], e["left"]["z"]])
    poses[0][:, 3] = r @ centre(epochs[0]) + t
    for k in range(1, len(epochs)):
        step = epochs[k].get("step_m")
        step = np.array(step) if step is not None else centre(epochs[k]) - centre(epochs[k - 1])
        poses[k][:, 3] = poses[k - 1][:, 3] + r @ step
    return poses


def inputs(aided_dir, images_dir, chain):
    """Truth and the chain's poses (KITTI frame), the fixes in that frame, epoch times."""
    report = json.load(open(os.path.join(aided_dir, "report.json")))
    truth = kitti(os.path.join(report["dataset"], "gt_poses.txt"))
    # The fixes are in the object frame; the truth is in both, which gives the frame change.
    r, t = rigid_fit(np.array(report["ground_truth"]), truth[:, :, 3])
    if chain == "aided":
        poses = aided_chain(aided_dir, report["epochs"], (r, t))
    else:
        poses = kitti(os.path.join(images_dir, "poses.txt"))
    fixes = [(r @ np.array(e["gnss"]["position"]) + t, e["gnss"]["sigma_m"])
             if e.get("gnss") else None for e in report["epochs"]]
    times = np.array([e["time"] for e in report["epochs"]])
    return truth, poses, fixes, times


class Rows:
    """A sparse least-squares system built row block by row block."""

    def __init__(self):
        self.rows, self.cols, self.vals, self.rhs = [], [], [], []

    def add(self, residual, jacobian, columns, sigma):
        base = len(self.rhs)
        for i, v in enumerate(residual):
            self.rhs.append(-v / sigma)
            for j, c in enumerate(columns):
                if jacobian[i, j] != 0.0:
                    self.rows.append(base + i)
                    self.cols.append(c)
                    self.vals.append(jacobian[i, j] / sigma)

    def solve(self, unknowns):
        a = sparse.csr_matrix((self.vals, (self.rows, self.cols)), shape=(len(self.rhs), unknowns))
        return sparse_linalg.spsolve((a.T @ a).tocsc(), a.T @ np.array(self.rhs))


def smooth(images, fixes, sigma_rot, sigma_step):
    n = len(images)
    rot = [p[:, :3].copy() for p in images]
    centre = [p[:, 3].copy() for p in images]
    rel_rot = [images[k - 1][:, :3].T @ images[k][:, :3] for k in range(1, n)]
    rel_step = [images[k - 1][:, :3].T @ (images[k][:, 3] - images[k - 1][:, 3]) for k in range(1, n)]
    for _ in range(ITERATIONS):
        rows = Rows()
        rows.add(np.zeros(6), np.eye(6), range(6), DATUM_SIGMA)
        for k in range(1, n):
            def residual(x, k=k):
                ra, ca = rot[k - 1] @ exp(x[:3]), centre[k - 1] + x[3:6]
                rb, cb = rot[k] @ exp(x[6:9]), centre[k] + x[9:12]
                return np.concatenate([log(rel_rot[k - 1].T @ ra.T @ rb) / sigma_rot,
                                       (ra.T @ (cb - ca) - rel_step[k - 1]) / sigma_step])
            r0, jac, eps = residual(np.zeros(12)), np.zeros((6, 12)), 1e-7
            for j in range(12):
                x = np.zeros(12)
                x[j] = eps
                jac[:, j] = (residual(x) - r0) / eps
            rows.add(r0, jac, range(6 * (k - 1), 6 * k + 6), 1.0)
        for k, fix in enumerate(fixes):
            if fix is not None:
                rows.add(centre[k] - fix[0], np.eye(3), range(6 * k + 3, 6 * k + 6), fix[1])
        x = rows.solve(6 * n)
        for k in range(n):
            rot[k] = rot[k] @ exp(x[6 * k:6 * k + 3])
            centre[k] = centre[k] + x[6 * k + 3:6 * k + 6]
        if np.abs(x).max() < 1e-7:
            break
    return np.array(centre)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("aided")
    ap.add_argument("images_only")
    ap.add_argument("start", type=float)
    ap.add_argument("end", type=float)
    ap.add_argument("--sigma-rot", type=float, default=1e-4)
    ap.add_argument("--sigma-step", type=float, default=1e-2)
    ap.add_argument("--chain", choices=["images", "aided"], default="images",
                    help="relative poses of the images-only run, or the aided run's own")
    args = ap.parse_args()
    truth, images, fixes, times = inputs(args.aided, args.images_only, args.chain)
    centres = smooth(images, fixes, args.sigma_rot, args.sigma_step)
    err = np.linalg.norm(centres - truth[:, :, 3], axis=1)
    inside = (times >= args.start) & (times <= args.end)
    print(f"outage {args.start}..{args.end} s, pose graph over the {args.chain} chain "
          f"(rotation {args.sigma_rot} rad, "
          f"step {args.sigma_step} m per step)")
    print(f"  largest position error inside: {err[inside].max():.3f} m")
    print(f"  outside: RMS position error {np.sqrt(np.mean(err[~inside] ** 2)):.4f} m")


if __name__ == "__main__":
    main()
