#!/usr/bin/env python3
"""What an outage's error owes to the attitude the aided run enters it with: the outages of
a directory of runs re-smoothed (`turned_smoothing.py`'s model, `run`'s sigmas unless given) with the
steps inside turned by the true attitude error at the outage's first epoch, whole or in
part, against the images alone re-anchored there (`outage.py`'s second bar).

    python3 bench/aiding/entry_attitude.py ROOT [--part all|level|roll] [the model's sigmas]

ROOT holds aided runs `o<seed>-<start>..<end>` (an outage of START..END s) and, for each
seed, the images-only run `i<seed>`, as the runs of `bench/aiding/README.md` are named.
The attitude error is the truth's rotation against the run's `poses.txt` at the entry (the
aided window's attitude there, which the images' steps inside the outage carry;
`attitude.py`'s), put into the object frame. `--part roll` keeps only its component about
the true direction of travel at the entry (`attitude.py`'s axes), which the fixes on a
straight do not observe; `--part level` keeps the rest (heading and pitch), which they do;
`all` both.

Prints, per outage, the largest position error inside with `run`'s smoothing and with the
steps turned, the images alone's, and the entry's attitude error; then how many outages
meet both bars (at most 0.2 m, no larger than the images alone) each way and the sums.
"""
import argparse
import glob
import os
import re

import numpy as np
from scipy.spatial.transform import Rotation

import attitude
import outage
import turned_smoothing
from pose_graph import rigid_fit


def entry_error(run_dir, truth_object, first, part):
    """The rotation (object frame) that turns the run's attitude at `first` onto the truth,
    whole or the part `part` of it; `truth_object` the true centres in the object frame."""
    truth, est = attitude.load(run_dir, None)
    rv = attitude.errors(truth[first : first + 1], est[first : first + 1])[0] / 1000
    along = attitude.travel_axes(truth, first)[0]
    roll = along * (rv @ along)
    part_rv = {"all": rv, "roll": roll, "level": rv - roll}[part]
    # The object frame from the KITTI one: the truth is in both.
    to_kitti, _ = rigid_fit(truth_object, truth[:, :, 3])
    turn = to_kitti.T @ Rotation.from_rotvec(part_rv).as_matrix() @ to_kitti
    return turn, np.linalg.norm(rv)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("root", help="directory of o<seed>-<a>..<b> and i<seed> runs")
    p.add_argument("--part", choices=("all", "level", "roll"), default="all")
    for flag, default, text in turned_smoothing.OPTIONS:
        p.add_argument(flag, type=float, default=default, help=f"{text} (the model's, as turned_smoothing.py)")
    args = p.parse_args()
    rows = []
    for run_dir in sorted(glob.glob(f"{args.root}/o*")):
        m = re.fullmatch(r"o(\d+)-([\d.]+)\.\.([\d.]+)", os.path.basename(run_dir))
        if not m:
            continue
        seed, t0, t1 = m.group(1), float(m.group(2)), float(m.group(3))
        epochs, truth = outage.load(run_dir)
        inside = [i for i, e in enumerate(epochs) if t0 <= e["time"] <= t1]
        turn, size = entry_error(run_dir, truth, inside[0], args.part)
        turned = [dict(e) for e in epochs]
        for k in inside:
            if turned[k].get("step_m") is not None:
                turned[k]["step_m"] = list(turn @ np.array(turned[k]["step_m"]))
        largest = [
            np.linalg.norm(turned_smoothing.smooth(ep, inside, args) - truth, axis=1)[inside].max()
            for ep in (epochs, turned)
        ]
        bound = turned_smoothing.images_only_largest(f"{args.root}/i{seed}", inside)
        rows.append((*largest, bound))
        print(f"{seed:>3} {t0:g}..{t1:g}: run {largest[0]:.3f} m, entry turned {largest[1]:.3f} m, "
              f"images alone {bound:.3f} m; entry error {1e3 * size:.2f} mrad", flush=True)
    r = np.array(rows)
    met = [int(np.sum((r[:, c] <= 0.2) & (r[:, c] <= r[:, 2]))) for c in (0, 1)]
    print(f"{len(r)} outages, both bars: run {met[0]}, entry turned ({args.part}) {met[1]}; "
          f"sums of the largest errors: {r[:, 0].sum():.3f} m, {r[:, 1].sum():.3f} m (images alone {r[:, 2].sum():.3f} m)")


if __name__ == "__main__":
    main()
