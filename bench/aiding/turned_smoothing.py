#!/usr/bin/env python3
"""An outage's misclosure spread by a rotation and a scale of its steps, re-solved from a
run's report.json with the model's sigmas as options: the model `run` smooths with since
the main after 5f50bf5 (`host/src/smoothing.rs`, a Kalman and Rauch-Tung-Striebel pass),
here as one sparse least-squares problem, to try other sigmas without running again. Until
then `run` smoothed per coordinate, each step's variance inside a stretch without fixes grown
by what the firmware's own variance of the centre grew by; this script chose the model
against that one.

It solves the fixes and steps (`step_m` of report.json) jointly over the three
coordinates, with, for the epochs inside the outage, a small rotation `t` (3 angles) and a
scale `l` of the steps as unknowns, each a random walk from the outage's first epoch:

    C_k - C_(k-1) = s_k + s_k x t_k + l_k s_k      (s_k the step; sd `--step-sd`, inside
                                                    at least `--outage-step` of |s_k|)
    t_k - t_(k-1) = 0 (sd `--turn-walk`, with `--turn-walk-per-rad` times the angle
                       the images turn by into epoch k added in quadrature),
    l_k - l_(k-1) = 0 (sd `--scale-walk`)
    t_first = 0 (sd `--turn-sd`),  l_first = 0 (sd `--scale-sd`)

so that a misclosure is spread the way an attitude error and a scale error of the images
grow along the path (a turn inside the outage included), not coordinate by coordinate.
Each fix observes its epoch's centre with its sigma (the antenna less its offset from the
centre, which report.json's residuals give). Sparse least squares (scipy).

Prints the largest position error inside the outage for the run's positions (`run`'s
smoothing) and for this model with the given sigmas, and, with an images-only run, whether
each meets the two bars of `outage.py` (at most 0.2 m, and no larger than the images alone
re-anchored to the truth at the outage's first epoch). The defaults are `run`'s sigmas.

usage: turned_smoothing.py AIDED_DIR START_S END_S [--images IMAGES_ONLY_DIR]
       [--step-sd M] [--outage-step R] [--turn-sd RAD] [--turn-walk RAD] [--scale-sd S]
       [--scale-walk S]
"""
import argparse
import os
import sys

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl

import outage

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "traverse"))
from photogrammetry import rotation  # noqa: E402  (the shared conventions)
from steps import rotation_vector  # noqa: E402


def cross_matrix(s):
    """[s]x: s x t = cross_matrix(s) @ t."""
    return np.array([[0, -s[2], s[1]], [s[2], 0, -s[0]], [-s[1], s[0], 0]])


class System:
    """Rows of a weighted linear least-squares problem, built one equation at a time."""

    def __init__(self):
        self.rows, self.cols, self.vals, self.rhs = [], [], [], []

    def add(self, terms, value, sd):
        r = len(self.rhs)
        for c, v in terms:
            self.rows.append(r)
            self.cols.append(c)
            self.vals.append(v / sd)
        self.rhs.append(value / sd)

    def solve(self, n):
        a = sp.csr_matrix((self.vals, (self.rows, self.cols)), shape=(len(self.rhs), n))
        return spl.spsolve((a.T @ a).tocsc(), a.T @ np.array(self.rhs))


def smooth(epochs, inside, args):
    """The centres of every epoch under the model above."""
    n, first, m = len(epochs), inside[0], len(inside)
    turn, scale = 3 * n, 3 * n + 3 * m  # first columns of the outage's t and l
    eq = System()
    for k, e in enumerate(epochs):
        g = e.get("gnss")
        if g:
            offset = np.array(g["position"]) + np.array(g["residual_m"]) - outage.centre(e)
            for c in range(3):
                eq.add([(3 * k + c, 1.0)], g["position"][c] - offset[c], g["sigma_m"])
        if k == 0:
            continue
        s = e.get("step_m")
        sd = args.step_sd
        if s is None:  # no step from a window adjustment: the output positions' difference
            s = np.array(e["realtime_centre_m"]) - np.array(epochs[k - 1]["realtime_centre_m"])
            sd *= 10.0
        s = np.array(s)
        j = k - first if first <= k <= inside[-1] else None
        if j is not None:  # the images' own step error, which no fix holds inside
            sd = max(sd, args.outage_step * np.linalg.norm(s))
        x = cross_matrix(s)
        for c in range(3):
            terms = [(3 * k + c, 1.0), (3 * (k - 1) + c, -1.0)]
            if j is not None:
                terms += [(turn + 3 * j + a, -x[c, a]) for a in range(3)]
                terms.append((scale + j, -s[c]))
            eq.add(terms, s[c], sd)
    for a in range(3):
        eq.add([(turn + a, 1.0)], 0.0, args.turn_sd)
    eq.add([(scale, 1.0)], 0.0, args.scale_sd)
    turned = step_turns(epochs)
    for j in range(1, m):
        walk = np.hypot(args.turn_walk, args.turn_walk_per_rad * turned[first + j])
        for a in range(3):
            eq.add([(turn + 3 * j + a, 1.0), (turn + 3 * (j - 1) + a, -1.0)], 0.0, walk)
        eq.add([(scale + j, 1.0), (scale + j - 1, -1.0)], 0.0, args.scale_walk)
    return eq.solve(3 * n + 4 * m)[: 3 * n].reshape(n, 3)


def step_turns(epochs):
    """The angle (rad) the images turn by into each epoch (0 for the first)."""
    r = [rotation(*np.radians([e["left"][k] for k in ("omega_deg", "phi_deg", "kappa_deg")]))
         for e in epochs]
    return np.array([0.0] + [np.linalg.norm(rotation_vector(b @ a.T)) for a, b in zip(r, r[1:])])


# The model's sigmas as `run` has them (host/src/smoothing.rs), with the option of each.
OPTIONS = [
    ("--step-sd", 3.7e-3, "m (run's estimate between fixes: 3.7 to 3.9 mm)"),
    ("--outage-step", 5e-3, "the least sd of a step inside the outage, of its length"),
    ("--turn-sd", 1.5e-3, "rad, at the outage's entry"),
    ("--turn-walk", 4e-4, "rad per step"),
    ("--turn-walk-per-rad", 0.0, "rad per step and per rad the images turn by in it (not run's)"),
    ("--scale-sd", 1e-3, "at the outage's entry"),
    ("--scale-walk", 1e-4, "per step"),
]


def images_only_largest(images_dir, inside):
    """The images-only run's largest error inside, re-anchored at the outage's first epoch."""
    offsets = outage.reanchored_offsets(images_dir, inside[0])
    return max(np.linalg.norm(offsets[i]) for i in inside)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("aided")
    p.add_argument("start_s", type=float)
    p.add_argument("end_s", type=float)
    p.add_argument("--images", help="images-only run of the same dataset, for the bars")
    for flag, default, text in OPTIONS:
        p.add_argument(flag, type=float, default=default, help=text)
    args = p.parse_args()
    epochs, truth = outage.load(args.aided)
    inside = [i for i, e in enumerate(epochs) if args.start_s <= e["time"] <= args.end_s]
    run = np.array([outage.centre(e) for e in epochs])
    model = smooth(epochs, inside, args)
    largest = {name: np.linalg.norm(c - truth, axis=1)[inside].max() for name, c in (("run", run), ("turned", model))}
    bound = images_only_largest(args.images, inside) if args.images else None
    for name, err in largest.items():
        bars = ""
        if bound is not None:
            met = err <= 0.2 and err <= bound
            bars = f"  (images alone re-anchored {bound:.3f} m: bars {'met' if met else 'missed'})"
        print(f"{name:>7}: largest position error inside {err:.3f} m{bars}")


if __name__ == "__main__":
    main()
