#!/usr/bin/env python3
"""How fast a run's attitude error walks: its change over LAG epochs, on straights and in turns.

    python3 bench/aiding/attitude_walk.py RUN_DIR [RUN_DIR ...] [--lags 10,20]

For every run (a `phototraverse run` output with `report.json`, whose dataset has
`gt_poses.txt`), at every fifth epoch k from the 20th: the attitude error (`attitude.py`'s,
in the world frame), its change from k to k + LAG as a rotation vector, split as
`attitude.py` splits it, along the true direction of travel at k, level across it and about
the vertical: roll, pitch and heading. A stretch is straight when the true heading turns by less than 0.5 mrad per epoch
over it. Prints the RMS change per part and per root epoch: a random walk's rate, which is
the same at every lag. An aided run's attitude at an outage's entry can be no better than
the fixes allow against this walk (`README.md`, "What the entry's attitude costs").
"""
import argparse
import math

import numpy as np
from scipy.spatial.transform import Rotation

import attitude  # the runs' poses against the truth, the error rotations, the travel axes


def changes(run_dir, lag):
    """(straight?, [roll, pitch, heading] change in rad) of every sampled stretch of a run."""
    truth, est = attitude.load(run_dir, None)
    err = [Rotation.from_rotvec(e / 1000) for e in attitude.errors(truth, est)]
    out = []
    for k in range(20, min(len(truth), len(est)) - lag, 5):
        change = (err[k + lag] * err[k].inv()).as_rotvec()
        turn = abs((attitude.heading_deg(truth, k + lag) - attitude.heading_deg(truth, k) + 180) % 360 - 180)
        out.append((math.radians(turn) < 5e-4 * lag, attitude.split(change, attitude.travel_axes(truth, k))))
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
