#!/usr/bin/env python3
"""The velocity of a run (eop.csv's speed_m_s and sd_speed_m_s on the left camera's rows)
against the true speed: central differences of the ground-truth centres in report.json
over the epoch times, as the run computes its own.

usage: velocity.py RUN_DIR
"""
import csv
import json
import sys

import numpy as np

d = sys.argv[1]
rows = [r for r in csv.DictReader(open(f"{d}/eop.csv")) if r["camera"] == "left"]
speed = np.array([float(r["speed_m_s"]) for r in rows])
sd = np.array([float(r["sd_speed_m_s"] or "nan") for r in rows])
report = json.load(open(f"{d}/report.json"))
gt = np.array(report["ground_truth"])
t = np.array([e["time"] for e in report["epochs"]])
n = len(gt)
true = np.array(
    [np.linalg.norm(gt[min(k + 1, n - 1)] - gt[max(k - 1, 0)]) / (t[min(k + 1, n - 1)] - t[max(k - 1, 0)]) for k in range(n)]
)
print(f"mean speed {speed.mean() * 3.6:.3f} km/h, truth {true.mean() * 3.6:.3f} km/h: "
      f"{(speed.mean() / true.mean() - 1) * 100:+.3f} %")
print(f"per epoch: mean |error| {np.mean(np.abs(speed / true - 1)) * 100:.3f} %, "
      f"RMS {np.sqrt(np.mean((speed - true) ** 2)) * 3.6:.3f} km/h; "
      f"stated sd: median {np.nanmedian(sd) * 3.6:.3f} km/h; "
      f"within 2 sd: {100 * np.mean(np.abs(speed - true) <= 2 * sd):.1f} %")
