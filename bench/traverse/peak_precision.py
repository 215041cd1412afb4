#!/usr/bin/env python3
"""Does a correlation peak know its own precision? The stereo observations of a run
against rendered truth, grouped by the precision their NCC peak gives.

The traverse weights each right-image observation by the precision of the stereo
correlation that measured it, the left ones keeping `sigma_px` (`docs/traverse.md`,
"Observation weights from the correlation peak"): a parabola through the NCC peak `rho`
and its neighbours has the curvature `c` (per pixel squared), and
`sigma^2 = (1 - rho) / (n c)` over the template's `n` samples. This script recomputes
that figure for every stereo observation of a run's COLMAP model (a 9x9
template around the left position, bilinear, against the right image at the observed
right position and one pixel either side along the row) and sets it beside the
observation's disparity error against the depth map (as `precision.py` does: rectified
`synth --depth` datasets, depth edges left out).

Printed: per fifth of the observations by that sigma, the robust standard deviation and
the RMS (within 1.5 px) of the disparity errors and the share beyond 0.5 px; the same by
the peak's NCC. The disparity holds two observations' errors (left and right). Then the
same for the temporal errors in x and y (a left observation against the projection of
the point the depth map puts behind its previous-epoch observation), with the peak of
the previous epoch's template (the run's own template is its anchor, magnified, which
the model does not keep) against the current image, a pixel either side on each axis.

    phototraverse synth --scene straight --frames 40 --depth --out D
    phototraverse run D --link inproc --out D/run
    python3 bench/traverse/peak_precision.py D/run D

usage: peak_precision.py RUN_DIR DATASET_DIR     (numpy, opencv-python)
"""
import os
import sys

import cv2
import numpy as np

import precision
from steps import read_poses

# The traverse's template: half-size 4 (`RefineConfig::half_window`).
HALF = 4
N = (2 * HALF + 1) ** 2
# Floors of the precision's two figures, as `matching::refine::vertex`.
MIN_CURVATURE = 1e-4
MIN_MISMATCH = 1e-4


def image(dataset, camera, epoch):
    path = os.path.join(dataset, f"image_{camera}", f"{epoch:06d}.png")
    return cv2.imread(path, cv2.IMREAD_GRAYSCALE).astype(np.float32)


def patch(img, x, y):
    """The (2 HALF + 1)^2 bilinear samples around (x, y); None near the border."""
    offsets = np.arange(-HALF, HALF + 1)
    xs, ys = np.meshgrid(x + offsets, y + offsets)
    c, r = np.floor(xs).astype(int), np.floor(ys).astype(int)
    if c.min() < 0 or r.min() < 0 or c.max() >= img.shape[1] - 1 or r.max() >= img.shape[0] - 1:
        return None
    a, b = xs - c, ys - r
    return ((1 - a) * (1 - b) * img[r, c] + a * (1 - b) * img[r, c + 1]
            + (1 - a) * b * img[r + 1, c] + a * b * img[r + 1, c + 1])


def ncc(t, p):
    t, p = t - t.mean(), p - p.mean()
    d = np.sqrt((t * t).sum() * (p * p).sum())
    return (t * p).sum() / d if d > 0 else -1.0


def scores(template_img, at_template, img, centre, offsets):
    """NCC of the template around `at_template` in `template_img` with `img` at `centre`
    plus each of `offsets` (pixels); None near a border."""
    tpl = patch(template_img, *at_template)
    if tpl is None:
        return None
    out = []
    for dx, dy in offsets:
        p = patch(img, centre[0] + dx, centre[1] + dy)
        if p is None:
            return None
        out.append(ncc(tpl, p))
    return out


def vertex_sigma(a, b, c):
    """The sigma (pixels) of a parabola's vertex through the scores `a`, `b` (the peak),
    `c`: `matching::refine::vertex`."""
    curvature = max(2 * b - a - c, MIN_CURVATURE)
    return np.sqrt(max(1 - b, MIN_MISMATCH) / (N * curvature))


def peak(left_img, right_img, left, right):
    """NCC at the right position and a pixel either side along the left row: the
    peak's score and its sigma (pixels); None near the border."""
    s = scores(left_img, left, right_img, (right[0], left[1]), [(-1, 0), (0, 0), (1, 0)])
    return None if s is None else (s[1], vertex_sigma(*s))


def temporal_peak(before_img, img, before, at):
    """The sigma (pixels; x, y) of the peak of the template at `before` in
    `before_img` against `img` at `at` and a pixel either side on each axis."""
    s = scores(before_img, before, img, at, [(-1, 0), (0, 0), (1, 0), (0, -1), (0, 1)])
    return None if s is None else [vertex_sigma(*s[:3]), vertex_sigma(s[3], s[1], s[4])]


def temporal(dataset, images, depths, poses, f, cx, cy):
    """Temporal errors (x, y) and the peaks' sigmas (x, y) of every left observation
    whose previous-epoch observation has a depth."""
    rows = []
    for k in range(1, len(poses)):
        left, before = images.get(2 * k + 1, {}), images.get(2 * k - 1, {})
        if not left:
            continue
        prev_img, cur_img = image(dataset, 0, k - 1), image(dataset, 0, k)
        for point, (u, v) in left.items():
            if point not in before:
                continue
            u0, v0 = before[point]
            z0 = depths.at(k - 1, u0, v0)
            sigma = temporal_peak(prev_img, cur_img, (u0, v0), (u, v)) if z0 else None
            if sigma is None:
                continue
            xyz = poses[k - 1] @ np.array([(u0 - cx) / f * z0, (v0 - cy) / f * z0, z0, 1.0])
            cam = np.linalg.inv(poses[k]) @ xyz
            rows.append((u - (f * cam[0] / cam[2] + cx), v - (f * cam[1] / cam[2] + cy), *sigma))
    return np.asarray(rows)


def table(name, key, errors, edges):
    print(f"{name}: observations, error robust sd / RMS within 1.5 px (px), beyond 0.5 px")
    last = len(edges) - 2
    for i, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
        # Each value in one bin: the upper edge belongs to the next, except the last's.
        inside = (key >= lo) & ((key <= hi) if i == last else (key < hi))
        e = errors[inside]
        if len(e) == 0:
            continue
        mad = 1.4826 * np.median(np.abs(e - np.median(e)))
        bulk = e[np.abs(e) < precision.BLUNDER_PX]
        print(f"  {lo:.4f} .. {hi:.4f}: {len(e):5d}, {mad:.3f} / {np.sqrt((bulk ** 2).mean()):.3f}, "
              f"{100 * (np.abs(e) > 0.5).mean():.1f} %")


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    run, dataset = sys.argv[1], sys.argv[2]
    f, cx, cy, base = precision.rig(dataset)
    poses = read_poses(os.path.join(dataset, "gt_poses.txt"))
    epochs = len(poses)
    depths = precision.Depths(dataset)
    images = precision.read_model(run)
    errors, sigmas, scores = [], [], []
    for k in range(epochs):
        left, right = images.get(2 * k + 1, {}), images.get(2 * k + 2, {})
        if not left:
            continue
        li, ri = image(dataset, 0, k), image(dataset, 1, k)
        for point, (u, v) in left.items():
            z = depths.at(k, u, v) if point in right else None
            if z is None:
                continue
            found = peak(li, ri, (u, v), right[point])
            if found is None:
                continue
            errors.append((u - right[point][0]) - f * base / z)
            scores.append(found[0])
            sigmas.append(found[1])
    errors, sigmas, scores = map(np.asarray, (errors, sigmas, scores))
    if len(errors) == 0:
        sys.exit("no stereo observation with a depth")
    table("by the peak's sigma (fifths)", sigmas, errors, np.quantile(sigmas, np.linspace(0, 1, 6)))
    table("by the peak's NCC", scores, errors, np.array([-1.0, 0.9, 0.95, 0.98, np.inf]))
    rows = temporal(dataset, images, depths, poses, f, cx, cy)
    if len(rows) == 0:
        return
    for axis, name in enumerate("xy"):
        key = rows[:, 2 + axis]
        table(f"temporal {name}, by the peak's sigma (fifths)", key, rows[:, axis],
              np.quantile(key, np.linspace(0, 1, 6)))


if __name__ == "__main__":
    main()
