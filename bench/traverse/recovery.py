#!/usr/bin/env python3
"""Recovery after losses, per scene of a run.py cache: the accuracy issue's second bar.

For every `CACHE/runs/<scene>/ours/` (report.json, poses.txt) against the scene's
`gt_poses.txt`: how many epochs were `predicted`, which were losses (predicted, or flagged
"continuity lost"), and the steps whose error exceeds 5x the scene's median step error,
in translation (m) or rotation (deg), counting neither the loss epochs nor the 3 epochs that
follow each. "after a loss" are those of them that come after the first loss: the bar asks
for none.

    python3 bench/traverse/recovery.py /tmp/ptcache
"""
import argparse
import json
import math
import os

import numpy as np

from steps import read_poses, rotation_vector

# Epochs after a loss that may still be poor (the bar's "first 3 epochs following a loss").
GRACE = 3
# A step is an outlier beyond this multiple of the scene's median step error.
FACTOR = 5.0


def step_errors(gt, est):
    """Translation (m) and rotation (deg) error of every epoch-to-epoch motion."""
    rot, tr = [], []
    for k in range(1, len(gt)):
        true = np.linalg.inv(gt[k - 1]) @ gt[k]
        ours = np.linalg.inv(est[k - 1]) @ est[k]
        err = np.linalg.inv(ours) @ true
        rot.append(math.degrees(np.linalg.norm(rotation_vector(err[:3, :3]))))
        tr.append(float(np.linalg.norm(err[:3, 3])))
    return np.array(tr), np.array(rot)


def scene(cache, run):
    d = os.path.join(cache, "runs", run, "ours")
    # run.py records the dataset each run used (`curves-real-rig` runs on `curves-real`'s).
    with open(os.path.join(cache, "runs", run, "result.json")) as f:
        ds = json.load(f)["dataset"]
    gt = read_poses(os.path.join(ds, "gt_poses.txt"))
    est = read_poses(os.path.join(d, "poses.txt"))
    if len(est) != len(gt):
        return None
    epochs = json.load(open(os.path.join(d, "report.json")))["epochs"]
    predicted = sum(e["status"] == "predicted" for e in epochs)
    losses = [
        e["epoch"]
        for e in epochs
        if e["status"] == "predicted" or "continuity lost" in (e["note"] or "")
    ]
    tr, rot = step_errors(gt, est)
    excluded = {k for loss in losses for k in range(loss, loss + GRACE + 1)}
    outliers = [
        k
        for k in range(1, len(gt))
        if k not in excluded
        and (tr[k - 1] > FACTOR * np.median(tr) or rot[k - 1] > FACTOR * np.median(rot))
    ]
    after = [k for k in outliers if losses and k > losses[0]]
    return predicted, losses, outliers, after


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("cache", help="run.py's cache directory (with runs/)")
    args = ap.parse_args()
    runs = os.path.join(args.cache, "runs")
    if not os.path.isdir(runs):
        ap.error(f"{runs}: no runs (run bench/traverse/run.py with this cache first)")
    print(f"{'scene':24s} predicted losses  steps > {FACTOR:g}x median: outside losses / after a loss")
    for run in sorted(os.listdir(runs)):
        if not os.path.exists(os.path.join(runs, run, "result.json")):
            continue
        r = scene(args.cache, run)
        if r is None:
            print(f"{run:24s} poses and ground truth differ in length")
            continue
        predicted, losses, outliers, after = r
        print(
            f"{run:24s} {predicted:9d} {len(losses):6d}  {len(outliers):3d} / {len(after):3d}"
            f"  {after[:10]}{' ...' if len(after) > 10 else ''}"
        )


if __name__ == "__main__":
    main()
