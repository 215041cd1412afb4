#!/usr/bin/env python3
"""Do the stereo observations lean where their template holds a nearer surface? The
disparity errors of an oracle-bench log, split by what the depth map puts under each
observation's template.

A template centred on a far point beside a nearer surface (a post, a box, a building's
edge) holds some of that surface. In the right image the nearer surface lies farther
left than the far point by the difference of their disparities, so the correlation is
pulled towards the larger disparity: the far point comes out nearer than it is. This
script measures that lean on a rendered dataset.

Input: a log written by the oracle bench (`PT_LOG=FILE`, see
`oracle-observations.patch`: one line per observation, epoch, track, class, first, u, v,
error u, error v, disparity error, right sigma, depth, ...) and the dataset's depth maps
(`synth --depth`, KITTI layout). An observation "holds a nearer surface" where the
smallest depth in its 9x9 template, widened by `--reach` columns to the right (where a
nearer surface's right-image position can cover the point), is below `--ratio` times the
depth at its centre.

Printed: the mean, median and spread of the disparity errors (pixels; positive: the
disparity is too large, the point too near) of the observations with and without a
nearer surface in their template, per class of observation and per depth band.

    phototraverse synth --scene seed2014 --seed 65 --rig ideal.toml --layout kitti --depth --out D
    git apply bench/traverse/oracle-observations.patch
    PT_ORACLE=none PT_DROP=1 PT_LOG=D.obs cargo bench -p phototraverse-host --bench traverse_epoch -- D
    python3 bench/traverse/depth_edges.py D D.obs

usage: depth_edges.py DATASET_DIR LOG [--ratio R] [--reach PX]     (numpy)
"""
import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "sift"))
from bench import read_pfm  # noqa: E402 (the SIFT bench's PFM reader)

# The traverse's template: half-size 4 (`RefineConfig::half_window`).
HALF = 4
# Disparity errors beyond this (px) are blunders the oracle bench drops as well.
BLUNDER_PX = 2.0


def read_log(path):
    """Epochs, classes and the float columns u, v, err u, err v, disparity error,
    right sigma, depth of an oracle-bench log."""
    rows = [line.split() for line in open(path) if line.strip()]
    epochs = np.array([int(r[0]) for r in rows])
    classes = np.array([r[2] for r in rows])
    values = np.array([[float(x) for x in r[4:11]] for r in rows])
    return epochs, classes, values


def nearest_ratio(depth_dir, epochs, u, v, reach, usable):
    """Per observation: the smallest depth under its widened template over the depth
    at its centre (NaN where it cannot be read)."""
    files = sorted(f for f in os.listdir(depth_dir) if f.endswith(".pfm"))
    ratio = np.full(len(u), np.nan)
    current, depth = None, None
    for i in np.where(usable)[0]:
        if epochs[i] != current:
            current = epochs[i]
            depth = read_pfm(os.path.join(depth_dir, files[current]))
        x, y = int(round(u[i])), int(round(v[i]))
        if not (0 <= y < depth.shape[0] and 0 <= x < depth.shape[1]):
            continue
        centre = depth[y, x]
        window = depth[max(0, y - HALF) : y + HALF + 1, max(0, x - HALF) : x + HALF + 1 + reach]
        if np.isfinite(centre) and centre > 0:
            ratio[i] = np.nanmin(window) / centre
    return ratio


def describe(name, errors):
    if len(errors) == 0:
        print(f"{name:28s} n 0")
        return
    print(
        f"{name:28s} n {len(errors):6d}  mean {errors.mean():+.4f}  median {np.median(errors):+.4f}"
        f"  sd {errors.std():.3f}  beyond +0.5 {(errors > 0.5).sum():5d}  beyond -0.5 {(errors < -0.5).sum():5d}"
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset")
    ap.add_argument("log")
    ap.add_argument("--ratio", type=float, default=0.8, help="nearer: below this share of the centre's depth")
    ap.add_argument("--reach", type=int, default=4, help="columns the template is widened by, to the right")
    a = ap.parse_args()
    epochs, classes, values = read_log(a.log)
    u, v, _, _, disparity_error, _, depth = values.T
    usable = np.isfinite(disparity_error) & (np.abs(disparity_error) < BLUNDER_PX)
    ratio = nearest_ratio(os.path.join(a.dataset, "depth_0"), epochs, u, v, a.reach, usable)
    nearer = usable & (ratio < a.ratio)
    clear = usable & (ratio >= a.ratio)
    print(f"{usable.sum()} observations; disparity error in pixels (positive: too large)")
    describe("clear template", disparity_error[clear])
    describe("nearer surface in template", disparity_error[nearer])
    for c in np.unique(classes):
        describe(f"class {c}, clear", disparity_error[clear & (classes == c)])
        describe(f"class {c}, nearer surface", disparity_error[nearer & (classes == c)])
    for lo, hi in [(0, 20), (20, 40), (40, 80), (80, np.inf)]:
        band = (depth >= lo) & (depth < hi)
        describe(f"depth {lo}-{hi} m, clear", disparity_error[clear & band])
        describe(f"depth {lo}-{hi} m, nearer", disparity_error[nearer & band])


if __name__ == "__main__":
    main()
