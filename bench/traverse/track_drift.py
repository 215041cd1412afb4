#!/usr/bin/env python3
"""Where a run's tracks drift off their surface points, against rendered truth.

`precision.py` compares each observation with the one before it; a track whose observations
slide slowly over the surface passes that test step by step. Here each left observation is
compared with the true projection of the point the track *started on*: the depth map behind
the track's first left observation, carried with the true poses into every later epoch. So
what a track's observations have drifted since it began shows, and so does the pose that the
observations of one epoch would give with the true points (a traverse keeps a transient bias:
the points it triangulates from a biased epoch carry it on).

For each epoch in FIRST..LAST, the pose offset that the epoch's left observations imply (a
linearised resection on the true points: rotation about x, y, z in mrad, in the sign of
`bench/aiding/attitude.py`, and translation along x, y, z in mm); then, pooled over the
stretch, the mean residual (observed minus true, px) by track age and by quarter of the
image width. Observations more than 2 px off are blunders, not drift, and left out; so are
tracks whose first observation sits on a depth edge.

    phototraverse synth --scene drive --seed 1 --frames 600 --depth --out D
    phototraverse run D --images-only --out D/run
    python3 bench/traverse/track_drift.py D/run D 405 456

usage: track_drift.py RUN_DIR DATASET_DIR FIRST LAST        (numpy; KITTI layout)
"""
import argparse
import os
import sys

import numpy as np

from peer_vo import DatasetError
from precision import Depths, image_motion, read_model, rig, to_world
from steps import read_poses

# Observations further than this from their track's true projection are blunders (px).
BLUNDER_PX = 2.0
# The fewest observations an epoch's implied pose is solved from.
MIN_OBSERVATIONS = 20
# Track ages (epochs since the first observation) pooled in the summary.
AGES = ((1, 1), (2, 3), (4, 6), (7, 10**6))


def starts(images, poses, depths, cam, first, last):
    """Per track observed in first..last: the epoch of its first left observation and the
    true point behind it (None where the depth map cannot say). Only the depth maps where
    those tracks start are read."""
    wanted = {p for k in range(first, last) for p in images.get(2 * k + 1, {})}
    out = {}
    for k in range(last):
        for point, (u, v) in images.get(2 * k + 1, {}).items():
            if point not in wanted or point in out:
                continue
            z = depths.at(k, u, v)
            out[point] = None if z is None else (k, to_world(poses[k], u, v, z, *cam))
    return out


def residuals(images, poses, start, cam, k):
    """Epoch k's left observations against their tracks' true projections: rows of
    (u, v, du, dv, x, y, depth, age), x and y the true normalised image coordinates."""
    f, cx, cy = cam
    world_to_camera = np.linalg.inv(poses[k])
    rows = []
    for point, (u, v) in images.get(2 * k + 1, {}).items():
        s = start.get(point)
        if s is None or s[0] == k:
            continue
        c = world_to_camera @ np.append(s[1], 1.0)
        x, y = c[0] / c[2], c[1] / c[2]
        du, dv = u - (f * x + cx), v - (f * y + cy)
        if abs(du) <= BLUNDER_PX and abs(dv) <= BLUNDER_PX:
            rows.append((u, v, du, dv, x, y, c[2], k - s[0]))
    return np.array(rows).reshape(-1, 8)


def implied_pose(rows, f):
    """The small pose offset (mrad about x, y, z; mm along x, y, z) that moves the true
    projections onto the observations."""
    ju, jv = image_motion(rows[:, 4], rows[:, 5], rows[:, 6], f)
    jac = np.vstack([ju, jv])
    diff = np.concatenate([rows[:, 2], rows[:, 3]])
    return np.linalg.lstsq(jac, diff, rcond=None)[0] * 1000


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", help="a `phototraverse run` output directory (its colmap/ model)")
    ap.add_argument("dataset", help="the `synth --depth` dataset it ran on (KITTI layout)")
    ap.add_argument("first", type=int)
    ap.add_argument("last", type=int, help="exclusive")
    args = ap.parse_args()
    if not os.path.isdir(os.path.join(args.dataset, "depth_0")):
        sys.exit(f"{args.dataset}: no depth_0/ (render it with `synth --depth`)")
    if not os.path.isfile(os.path.join(args.run, "colmap", "images.txt")):
        sys.exit(f"{args.run}: no colmap/images.txt (a `phototraverse run` output directory)")
    try:
        f, cx, cy, _ = rig(args.dataset)
    except DatasetError as e:
        sys.exit(str(e))
    cam = (f, cx, cy)
    poses = read_poses(os.path.join(args.dataset, "gt_poses.txt"))
    images = read_model(args.run)
    last = min(args.last, len(poses))
    start = starts(images, poses, Depths(args.dataset), cam, args.first, last)
    print("epoch   obs    x mrad  y mrad  z mrad    x mm    y mm    z mm")
    pooled, offsets = [], []
    for k in range(args.first, last):
        rows = residuals(images, poses, start, cam, k)
        pooled.append(rows)
        if len(rows) < MIN_OBSERVATIONS:
            print(f"{k:5d} {len(rows):5d}   (too few)")
            continue
        offsets.append(implied_pose(rows, f))
        print(f"{k:5d} {len(rows):5d}  " + " ".join(f"{v:7.2f}" for v in offsets[-1]))
    if offsets:
        print("mean       " + " ".join(f"{v:7.2f}" for v in np.mean(offsets, axis=0)))
    rows = np.vstack(pooled)
    print("mean residual (px), observed minus true:")
    for lo, hi in AGES:
        s = rows[(rows[:, 7] >= lo) & (rows[:, 7] <= hi)]
        if len(s):
            print(f"  age {lo}..{min(hi, 99)}: {len(s):6d} obs   u {s[:, 2].mean():+.3f}  "
                  f"v {s[:, 3].mean():+.3f}")
    width = 2 * (cx + 0.5)
    for q in range(4):
        s = rows[(rows[:, 0] >= q * width / 4) & (rows[:, 0] < (q + 1) * width / 4)]
        if len(s):
            print(f"  quarter {q + 1} of the width: {len(s):6d} obs   u {s[:, 2].mean():+.3f}  "
                  f"v {s[:, 3].mean():+.3f}   median depth {np.median(s[:, 6]):5.1f} m")


if __name__ == "__main__":
    main()
