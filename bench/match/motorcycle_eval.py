#!/usr/bin/env python3
"""Scores stereo tie points of the Middlebury Motorcycle pair against its ground-truth
disparity: the share of matches within 1 px of GT (|x_l - x_r - d(c, r)| and |y_l - y_r|),
ignoring matches where the GT is unknown. Also runs the OpenCV peer (SIFT + BFMatcher +
ratio 0.8, |dy| < 1 px) on the same images for the comparison.

usage: motorcycle_eval.py MATCHES [--data ../shared/data/stereo] [--peer]
MATCHES: `x_left y_left x_right y_right` per line, COLMAP convention (pixel centre + 0.5).
"""
import argparse
import os
import sys
import numpy as np

ap = argparse.ArgumentParser()
ap.add_argument("matches")
ap.add_argument("--data", default=os.path.join(os.path.dirname(__file__), "../../../shared/data/stereo"))
ap.add_argument("--peer", action="store_true")
a = ap.parse_args()

pfm = os.path.join(a.data, "motorcycle_disp.pfm")
if not os.path.exists(pfm):
    sys.exit(f"ground truth missing: {pfm} (the benchmark needs ../shared/data)")


def read_pfm(path):
    with open(path, "rb") as f:
        assert f.readline().strip() == b"Pf"
        w, h = map(int, f.readline().split())
        scale = float(f.readline())
        d = np.frombuffer(f.read(), dtype="<f4" if scale < 0 else ">f4").reshape(h, w)
    return d[::-1].astype(np.float64)  # PFM rows are bottom-up


gt = read_pfm(pfm)
h, w = gt.shape


def score(xl, yl, xr, yr, label):
    # Back to pixel centres; GT at the nearest pixel of the left point.
    c = np.clip(np.round(xl).astype(int), 0, w - 1)
    r = np.clip(np.round(yl).astype(int), 0, h - 1)
    d = gt[r, c]
    known = np.isfinite(d)
    err = np.hypot((xl - xr) - d, yl - yr)
    good = (err <= 1.0) & known
    n = int(known.sum())
    pct = 100.0 * good.sum() / max(n, 1)
    med = float(np.median(np.abs((xl - xr) - d)[known])) if n else float("nan")
    print(f"{label}: {len(xl)} matches, {n} with GT, {good.sum()} within 1 px = {pct:.1f}%, "
          f"median |disparity error| {med:.3f} px")
    return pct, n


m = np.loadtxt(a.matches, ndmin=2)
if m.size == 0:
    sys.exit("no matches")
xl, yl, xr, yr = (m[:, i] - 0.5 for i in range(4))
pct, n = score(xl, yl, xr, yr, "phototraverse")

if a.peer:
    import cv2
    L = cv2.imread(os.path.join(a.data, "motorcycle_left.png"), cv2.IMREAD_GRAYSCALE)
    R = cv2.imread(os.path.join(a.data, "motorcycle_right.png"), cv2.IMREAD_GRAYSCALE)
    sift = cv2.SIFT_create()
    kl, dl = sift.detectAndCompute(L, None)
    kr, dr = sift.detectAndCompute(R, None)
    pairs = cv2.BFMatcher().knnMatch(dl, dr, k=2)
    good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < 0.8 * p[1].distance]
    P = np.array([(*kl[g.queryIdx].pt, *kr[g.trainIdx].pt) for g in good])
    keep = np.abs(P[:, 1] - P[:, 3]) < 1.0
    score(P[keep, 0], P[keep, 1], P[keep, 2], P[keep, 3], "OpenCV SIFT + ratio + |dy|<1")
