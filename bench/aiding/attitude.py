#!/usr/bin/env python3
"""Where a run's attitude goes wrong, against the truth of a `synth` dataset.

For each run (a `phototraverse run` output directory; its report.json names the dataset,
whose gt_poses.txt is the truth), four views, angles in mrad:

- `--every N` (default 20): the attitude error every N epochs, as the rotation that takes the
  estimated camera onto the true one (world frame: the datum camera's, as in poses.txt),
  split along the direction of travel at that epoch (`along`, the rotation a straight's
  fixes cannot see), the level axis across it (`across`, the slope) and the vertical
  (`up`, the heading). The vertical is the datum camera's -y (a level datum camera).
- `--turns`: the same error's change over each turn of the truth (a stretch where the
  heading changes by more than 0.5 deg per epoch, 5 epochs added on each side), split
  along the direction of travel at the turn's exit: what the turn added to the roll the
  next straight inherits.
- `--stretches A..B,...`: the mean error of the direction of each step in the camera's own
  frame (`x` right, `y` down; the step's unit vector against the true one), over each
  stretch: a bias of the images' direction of travel, which aided by fixes becomes an
  attitude error (the fixes hold the direction in the world, so the camera turns by it).
- `--rotations A..B,...`: the error of the steps' relative rotations (each in the earlier
  camera's frame: about `x` right, the slope; `y` down, the heading; `z` forward, the roll),
  summed over each stretch: what the images turned wrongly there.
- `--coverage`: whether the standard deviations of the angles in eop.csv cover their errors:
  the truth's omega, phi and kappa against eop.csv's, the share of epochs with all three
  within 3 sd (each angle's share too) and the median of error / sd per angle (0.67 for
  normal errors), over all the runs together; `--skip A..B,...` leaves epochs out (an
  outage with its entry and exit), `--only A..B,...` keeps those alone, epochs 0 to 19 are
  always left out (the datum's neighbours, whose sd is near 0).

usage: attitude.py RUN_DIR [RUN_DIR ...] [--every N] [--turns] [--stretches A..B,...]
                   [--rotations A..B,...] [--coverage [--skip A..B,...|--only A..B,...]]
                   [--truth GT_POSES]
(numpy, scipy)
"""
import argparse
import csv
import json
import os
import sys

import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "traverse"))
from photogrammetry import F, angles, rotation  # noqa: E402  (the shared conventions)

# A turn: the truth's heading changes by more than this per epoch (deg) ...
TURN_RATE_DEG = 0.5
# ... widened by this many epochs on each side, so that its onset and exit are in.
TURN_MARGIN = 5


def kitti(path):
    """Poses of a KITTI pose file as (n, 3, 4): camera to world."""
    return np.loadtxt(path).reshape(-1, 3, 4)


def load(run, truth_file):
    """The truth (the dataset's named by the run's report.json, or `truth_file`) and the run's
    poses."""
    if truth_file is None:
        report = json.load(open(os.path.join(run, "report.json")))
        truth_file = os.path.join(report["dataset"], "gt_poses.txt")
    return kitti(truth_file), kitti(os.path.join(run, "poses.txt"))


def errors(truth, est):
    """World-frame rotation vectors (mrad) taking each estimated attitude onto the true one."""
    return np.array([
        Rotation.from_matrix(t[:, :3] @ e[:, :3].T).as_rotvec() * 1000 for t, e in zip(truth, est)
    ])


UP = np.array([0.0, -1.0, 0.0])


def travel_axes(truth, k):
    """Unit vectors along the direction of travel at epoch k, level across it, and up."""
    a, b = max(k - 2, 0), min(k + 2, len(truth) - 1)
    t = truth[b][:, 3] - truth[a][:, 3]
    t /= np.linalg.norm(t)
    across = np.cross(t, UP)
    across /= np.linalg.norm(across)
    return t, across, UP


def heading_deg(truth, k):
    t, _, _ = travel_axes(truth, k)
    return np.degrees(np.arctan2(t[0], t[2]))


def turns(truth):
    """(first, last) epochs of each turn of the truth."""
    n = len(truth)
    rate = [abs((heading_deg(truth, k + 1) - heading_deg(truth, k) + 180) % 360 - 180)
            for k in range(n - 1)]
    out, k = [], 0
    while k < n - 1:
        if rate[k] > TURN_RATE_DEG:
            j = k
            while j < n - 1 and rate[j] > TURN_RATE_DEG:
                j += 1
            out.append((max(k - TURN_MARGIN, 0), min(j + TURN_MARGIN, n - 1)))
            k = j
        else:
            k += 1
    return out


def split(err, axes):
    return [float(err @ a) for a in axes]


def show_every(name, truth, err, every):
    print(f"{name}: attitude error (mrad) along / across / up the direction of travel")
    for k in range(0, len(err), every):
        along, across, up = split(err[k], travel_axes(truth, k))
        print(f"  {k:5d}  heading {heading_deg(truth, k):7.1f} deg   "
              f"{along:6.2f} {across:6.2f} {up:6.2f}")


def show_turns(name, truth, err):
    print(f"{name}: change of the attitude error over each turn (mrad), "
          "split at the turn's exit")
    for a, b in turns(truth):
        along, across, up = split(err[b] - err[a], travel_axes(truth, b))
        print(f"  {a:5d}..{b:<5d} heading {heading_deg(truth, a):7.1f} -> "
              f"{heading_deg(truth, b):7.1f} deg   along {along:6.2f}  across {across:6.2f}  "
              f"up {up:6.2f}")


def show_stretches(name, truth, est, stretches):
    print(f"{name}: mean error of each step's direction in the camera frame (mrad), x / y")
    for a, b in stretches:
        d = []
        for k in range(max(a, 1), min(b, len(est))):
            steps = []
            for p in (est, truth):
                s = p[k - 1][:, :3].T @ (p[k][:, 3] - p[k - 1][:, 3])
                steps.append(s / np.linalg.norm(s))
            d.append((steps[0] - steps[1])[:2] * 1000)
        m = np.mean(d, axis=0)
        print(f"  {a:5d}..{b:<5d} {m[0]:6.2f} {m[1]:6.2f}")


def show_rotations(name, truth, est, stretches):
    print(f"{name}: summed error of the steps' rotations in the camera frame (mrad), x / y / z")
    for a, b in stretches:
        total = np.zeros(3)
        for k in range(max(a, 1), min(b, len(est))):
            turned = est[k - 1][:, :3].T @ est[k][:, :3]
            true = truth[k - 1][:, :3].T @ truth[k][:, :3]
            total += Rotation.from_matrix(turned @ true.T).as_rotvec() * 1000
        print(f"  {a:5d}..{b:<5d} {total[0]:6.2f} {total[1]:6.2f} {total[2]:6.2f}")


# Epochs after the datum left out of the coverage: their sd is near 0.
COVERAGE_FROM = 20


def angles_deg(pose, m0):
    """Omega, phi, kappa (deg) of a KITTI pose relative to the datum epoch whose rotation
    is `m0`: `M = F R^T F M0`, as the product's `pose_from_kitti`."""
    return np.degrees(angles(F @ pose[:, :3].T @ F @ m0))


def angle_errors(run, truth):
    """Per left epoch with standard deviations: |error| and sd of omega, phi, kappa (deg);
    the datum is the run's first epoch."""
    rows = [r for r in csv.DictReader(open(os.path.join(run, "eop.csv")))
            if r["camera"] == "left"]
    m0 = rotation(*np.radians([float(rows[0][a + "_deg"]) for a in ("omega", "phi", "kappa")]))
    out = {}
    for k, r in enumerate(rows):
        if not r["sd_omega_deg"]:
            continue
        est = np.array([float(r[a + "_deg"]) for a in ("omega", "phi", "kappa")])
        sd = np.array([float(r["sd_" + a + "_deg"]) for a in ("omega", "phi", "kappa")])
        err = (est - angles_deg(truth[k], m0) + 180) % 360 - 180
        out[k] = (np.abs(err), sd)
    return out


def show_coverage(runs, truth_file, skip, only):
    inside = lambda k, spans: any(a <= k <= b for a, b in spans)
    err, sd = [], []
    for run in runs:
        truth, _ = load(run, truth_file)
        for k, (e, s) in angle_errors(run, truth).items():
            if k < COVERAGE_FROM or inside(k, skip) or (only and not inside(k, only)):
                continue
            err.append(e)
            sd.append(s)
    err, sd = np.array(err), np.array(sd)
    within = err <= 3 * sd
    share = within.mean(axis=0) * 100
    median = np.median(err / sd, axis=0)
    print(f"{len(err)} epochs of {len(runs)} runs: all three angles within 3 sd "
          f"{within.all(axis=1).mean() * 100:.1f} %; omega / phi / kappa "
          f"{share[0]:.1f} / {share[1]:.1f} / {share[2]:.1f} %; median error / sd "
          f"{median[0]:.2f} / {median[1]:.2f} / {median[2]:.2f}")


def parse_stretches(text):
    return [tuple(int(v) for v in s.split("..")) for s in text.split(",") if s]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", help="`phototraverse run` output directories")
    view = ap.add_mutually_exclusive_group()
    view.add_argument("--every", type=int, default=20, help="the error every N epochs (default)")
    view.add_argument("--turns", action="store_true", help="the error's change over each turn")
    view.add_argument("--stretches", default="", metavar="A..B,...",
                      help="the mean error of the steps' direction in the camera frame")
    view.add_argument("--rotations", default="", metavar="A..B,...",
                      help="the summed error of the steps' rotations in the camera frame")
    view.add_argument("--coverage", action="store_true",
                      help="whether eop.csv's standard deviations of the angles cover their errors")
    ap.add_argument("--skip", default="", metavar="A..B,...",
                    help="with --coverage: epochs left out (an outage, its entry and exit)")
    ap.add_argument("--only", default="", metavar="A..B,...",
                    help="with --coverage: only these epochs")
    ap.add_argument("--truth", help="gt_poses.txt, for a run without a report.json (the peer's)")
    args = ap.parse_args()
    stretches = parse_stretches(args.stretches)
    rotations = parse_stretches(args.rotations)
    if args.coverage:
        show_coverage(args.runs, args.truth, parse_stretches(args.skip),
                      parse_stretches(args.only))
        return
    for run in args.runs:
        truth, est = load(run, args.truth)
        if stretches:
            show_stretches(run, truth, est, stretches)
        elif rotations:
            show_rotations(run, truth, est, rotations)
        elif args.turns:
            show_turns(run, truth, errors(truth, est))
        else:
            show_every(run, truth, errors(truth, est), args.every)


if __name__ == "__main__":
    main()
