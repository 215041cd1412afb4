#!/usr/bin/env python3
"""How fast a run's attitude error walks: its change over LAG epochs, on straights and in turns.

    python3 bench/aiding/attitude_walk.py RUN_DIR [RUN_DIR ...] [--lags 10,20]

For every run (a `phototraverse run` output with `report.json`, whose dataset has
`gt_poses.txt`), at every fifth epoch k from the 20th: the attitude error E_k = R_est R_true^T
(the world frame), its change from k to k + LAG as a rotation vector, split along the true
direction of travel at k (levelled), across it and about the vertical: roll, pitch and
heading. A stretch is straight when the true heading turns by less than 0.5 mrad per epoch
over it. Prints the RMS change per part and per root epoch: a random walk's rate, which is
the same at every lag. An aided run's attitude at an outage's entry can be no better than
the fixes allow against this walk (`README.md`, "What the entry's attitude costs").
"""
import argparse
import json
import math

import numpy as np
from scipy.spatial.transform import Rotation

import outage


def heading(pose):
    return math.atan2(pose[0, 2], pose[2, 2])


def changes(run_dir, lag):
    """(straight?, [roll, pitch, heading] change in rad) of every sampled stretch of a run."""
    dataset = json.load(open(f"{run_dir}/report.json"))["dataset"]
    truth = outage.kitti(f"{dataset}/gt_poses.txt")
    est = outage.kitti(f"{run_dir}/poses.txt")
    down = np.array([0.0, 1.0, 0.0])  # KITTI's y
    out = []
    for k in range(20, min(len(truth), len(est)) - lag, 5):
        e0 = est[k][:3, :3] @ truth[k][:3, :3].T
        e1 = est[k + lag][:3, :3] @ truth[k + lag][:3, :3].T
        change = Rotation.from_matrix(e1 @ e0.T).as_rotvec()
        across = np.cross(down, truth[k][:3, 2])
        across /= np.linalg.norm(across)
        along = np.cross(across, down)
        turn = abs((heading(truth[k + lag]) - heading(truth[k]) + math.pi) % (2 * math.pi) - math.pi)
        out.append((turn < 5e-4 * lag, [change @ along, change @ across, change @ down]))
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("runs", nargs="+")
    p.add_argument("--lags", default="10,20", help="comma-separated epochs")
    args = p.parse_args()
    for lag in (int(v) for v in args.lags.split(",")):
        rows = [row for run in args.runs for row in changes(run, lag)]
        for name, straight in (("straights", True), ("turns", False)):
            v = 1e3 * np.array([c for s, c in rows if s == straight])
            if not len(v):
                continue
            rms = np.sqrt(np.mean(v**2, axis=0))
            print(f"lag {lag:3d}, {name:9s} ({len(v):4d}): RMS change roll / pitch / heading "
                  f"{rms[0]:.3f} / {rms[1]:.3f} / {rms[2]:.3f} mrad, per root epoch "
                  f"{rms[0] / math.sqrt(lag):.3f} / {rms[1] / math.sqrt(lag):.3f} / {rms[2] / math.sqrt(lag):.3f}")


if __name__ == "__main__":
    main()
