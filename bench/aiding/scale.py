#!/usr/bin/env python3
"""Scale drift of a run against the ground truth in its report.json: the estimated path
length (the polyline through the left perspective centres) over the true one, minus one,
and the same for the start-to-end distance, in %.

usage: scale.py RUN_DIR [RUN_DIR ...]
"""
import json
import sys

import numpy as np


def length(p):
    return np.linalg.norm(np.diff(p, axis=0), axis=1).sum()


for d in sys.argv[1:]:
    r = json.load(open(f"{d}/report.json"))
    gt = np.array(r["ground_truth"])
    est = np.array([[e["left"][k] for k in "xyz"] for e in r["epochs"]])
    path = (length(est) / length(gt) - 1) * 100
    chord = (np.linalg.norm(est[-1] - est[0]) / np.linalg.norm(gt[-1] - gt[0]) - 1) * 100
    print(f"{d}: path length {path:+.4f} %, start to end {chord:+.4f} %")
