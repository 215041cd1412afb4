#!/usr/bin/env python3
"""Bars of a GNSS outage run (`phototraverse run DATASET --gnss-outage A..B`) against the
ground truth in its report.json, and against an images-only run of the same dataset
(`--images-only`) re-anchored to the truth at the outage's first epoch.

Prints, for the epochs whose time lies in the outage: the largest position error; the same
for the images-only run after re-anchoring (its pose at the outage's first epoch replaced by
the truth, the rest of its trajectory moved rigidly with it); the same again with the
re-anchored run also closed on the truth at the first epoch after the outage, its misclosure
there spread in proportion to the epochs (what an aided run that entered the outage without
error could give); and the share of epochs whose error is within 3 standard deviations on
each coordinate (the sd of eop.csv / report.json);
for the other epochs: the RMS position error (3D) and per coordinate; and the same two figures
for the positions as the firmware output them (`realtime_centre_m`), before `run` smoothed them
over all the fixes. Distances in metres.

usage: outage.py AIDED_DIR IMAGES_ONLY_DIR START_S END_S
"""
import json
import math
import sys

import numpy as np


def load(d):
    r = json.load(open(f"{d}/report.json"))
    return r["epochs"], np.array(r["ground_truth"])


def kitti(path):
    """4x4 poses of a KITTI pose file."""
    rows = []
    for line in open(path):
        if line.strip() and not line.startswith("#"):
            m = np.eye(4)
            m[:3] = np.array([float(v) for v in line.split()]).reshape(3, 4)
            rows.append(m)
    return rows


def centre(e):
    return np.array([e["left"]["x"], e["left"]["y"], e["left"]["z"]])


def reanchored_offsets(images_dir, first):
    """The images-only run's position errors (m, per epoch, KITTI frame of poses.txt) once
    its pose at epoch `first` is put onto the true one (gt_poses.txt) and the rest of its
    trajectory moved rigidly with it."""
    dataset = json.load(open(f"{images_dir}/report.json"))["dataset"]
    truth = kitti(f"{dataset}/gt_poses.txt")
    est = kitti(f"{images_dir}/poses.txt")
    anchor = truth[first] @ np.linalg.inv(est[first])
    return [(anchor @ e)[:3, 3] - t[:3, 3] for e, t in zip(est, truth)]


def main():
    aided_dir, images_dir, t0, t1 = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
    ep, gt = load(aided_dir)
    ep_img, _ = load(images_dir)
    inside = [i for i, e in enumerate(ep) if t0 <= e["time"] <= t1]
    outside = [i for i, e in enumerate(ep) if not t0 <= e["time"] <= t1]
    err = np.array([centre(e) - gt[i] for i, e in enumerate(ep)])
    first = inside[0]
    reanchored = reanchored_offsets(images_dir, first)
    img_err = [np.linalg.norm(reanchored[i]) for i in inside]
    # Closed at both ends: a perfect entry and the fixes' return, the misclosure spread.
    after = min(inside[-1] + 1, len(reanchored) - 1)
    offsets = reanchored[first : after + 1]
    span = max(after - first, 1)
    closed = [np.linalg.norm(o - offsets[-1] * k / span) for k, o in enumerate(offsets[: len(inside)])]
    norms = np.linalg.norm(err, axis=1)
    covered = 0
    for i in inside:
        sd = ep[i]["left"]["sigma"]
        if sd and all(abs(err[i][a]) <= 3 * sd[3 + a] for a in range(3)):
            covered += 1
    dist = sum(np.linalg.norm(gt[i] - gt[i - 1]) for i in inside[1:])
    print(f"outage {t0}..{t1} s: epochs {inside[0]}..{inside[-1]} ({len(inside)}), {dist:.1f} m")
    print(f"  largest position error inside: {norms[inside].max():.3f} m (epoch {inside[int(np.argmax(norms[inside]))]})")
    print(f"  images only, re-anchored at epoch {first}: largest error {max(img_err):.3f} m")
    print(f"  images only, re-anchored and closed on the truth at epoch {after}: largest error {max(closed):.3f} m")
    print(f"  within 3 sd on every coordinate: {covered}/{len(inside)} = {100 * covered / len(inside):.1f} %")
    rms = math.sqrt(float(np.mean(norms[outside] ** 2)))
    per = np.sqrt(np.mean(err[outside] ** 2, axis=0))
    print(f"  outside ({len(outside)} epochs): RMS position error {rms:.4f} m (X/Y/Z {per[0]:.4f}/{per[1]:.4f}/{per[2]:.4f})")
    if all(e.get("realtime_centre_m") for e in ep):
        # The positions as the firmware output them, before the smoothing over the fixes.
        rt = np.array([np.array(e["realtime_centre_m"]) - gt[i] for i, e in enumerate(ep)])
        rt_norms = np.linalg.norm(rt, axis=1)
        rt_rms = math.sqrt(float(np.mean(rt_norms[outside] ** 2)))
        print(f"  the firmware's positions (before smoothing): largest inside {rt_norms[inside].max():.3f} m, RMS outside {rt_rms:.4f} m")


if __name__ == "__main__":
    main()
