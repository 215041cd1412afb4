#!/usr/bin/env python3
"""The image precision the matcher delivers, measured against rendered truth.

A run's COLMAP model (RUN_DIR/colmap) holds every tie point's image observations. On a
`synth` dataset rendered with `--depth` (a rectified rig, KITTI layout) the truth of each
observation is known:

- stereo: the observed disparity `x_left - x_right` of one epoch against the true one,
  `f B / Z`, with `Z` the depth map's value at the left observation;
- temporal: the left observation at epoch k against the projection, with the true poses,
  of the point the depth map puts behind the left observation at epoch k-1.

Each of these differences holds two observations' errors, so the precision of one
observation is the difference's spread over sqrt(2). Observations on a depth edge (the
depth varies by more than 1 % in the 4x4 pixels around them) are left out: the depth map
cannot say where such a point is. Reported: the robust standard deviation (1.4826 x the
median absolute deviation), which is what the bulk of the observations deliver, and the
RMS of the differences within 1.5 px, which also counts the tails the adjustment's robust
weighting has to handle.

    phototraverse synth --scene straight --frames 100 --depth --out D
    phototraverse run D --out D/run
    python3 bench/traverse/precision.py D/run D

usage: precision.py RUN_DIR DATASET_DIR        (numpy; opencv-python for peer_vo's reader)
"""
import os
import sys

import numpy as np

from peer_vo import read_calib
from steps import read_poses

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "sift"))
from bench import read_pfm  # noqa: E402 (the SIFT bench's PFM reader)

# Differences beyond this (px) are blunders, not precision: counted apart.
BLUNDER_PX = 1.5
# A depth edge: relative depth range in the 4x4 pixels around an observation.
EDGE_RANGE = 0.01


def rig(dataset):
    """Focal length (px), principal point and base (m) of a rectified KITTI pair."""
    p0, p1 = read_calib(os.path.join(dataset, "calib.txt"))
    f = p0[0, 0]
    return f, p0[0, 2], p0[1, 2], -p1[0, 3] / f


def to_world(pose, u, v, z, f, cx, cy):
    """The object point behind pixel (u, v) at depth z of a camera (KITTI frame, camera to
    world pose); u, v, z may be arrays of any one shape (the point on a last axis of 3)."""
    x = np.stack([(u - cx) / f * z, (v - cy) / f * z, z], -1)
    return x @ pose[:3, :3].T + pose[:3, 3]


def image_motion(x, y, z, f):
    """Pixel motion (du, dv) of a point at normalised (x, y) and depth z when its camera
    turns by a small rotation about x, y, z and moves along x, y, z (KITTI frame): two
    arrays with those six columns on a last axis."""
    zero = np.zeros_like(x * z)
    du = np.stack([f * x * y, -f * (1 + x * x), f * y, -f / z + zero, zero, f * x / z], -1)
    dv = np.stack([f * (1 + y * y), -f * x * y, -f * x, zero, -f / z + zero, f * y / z], -1)
    return du, dv


class Depths:
    """Left depth maps, read once each; the depth at a sub-pixel position."""

    def __init__(self, dataset):
        self.dir = os.path.join(dataset, "depth_0")
        self.maps = {}

    def at(self, epoch, u, v):
        if epoch not in self.maps:
            self.maps[epoch] = read_pfm(os.path.join(self.dir, f"{epoch:06d}.pfm"))
        d = self.maps[epoch]
        c, r = int(np.floor(u)), int(np.floor(v))
        if not (1 <= c < d.shape[1] - 2 and 1 <= r < d.shape[0] - 2):
            return None
        around = d[r - 1 : r + 3, c - 1 : c + 3]
        if not np.isfinite(around).all() or around.min() <= 0:
            return None
        if around.max() - around.min() > EDGE_RANGE * around.min():
            return None
        a, b = u - c, v - r
        return ((1 - a) * (1 - b) * d[r, c] + a * (1 - b) * d[r, c + 1]
                + (1 - a) * b * d[r + 1, c] + a * b * d[r + 1, c + 1])


def read_model(run):
    """Per image id, its points: (x, y) in the reports' pixels (centre of the top-left
    pixel = 0) by 3D point id."""
    images = {}
    with open(os.path.join(run, "colmap", "images.txt")) as f:
        lines = [l for l in f if not l.startswith("#")]
    for head, points in zip(lines[0::2], lines[1::2]):
        image_id = int(head.split()[0])
        v = points.split()
        images[image_id] = {
            int(v[j + 2]): (float(v[j]) - 0.5, float(v[j + 1]) - 0.5)
            for j in range(0, len(v), 3)
            if int(v[j + 2]) >= 0
        }
    return images


def summary(name, diffs):
    d = np.asarray(diffs)
    if len(d) == 0:
        return f"{name}: no observations"
    bulk = d[np.abs(d) < BLUNDER_PX]
    mad = 1.4826 * np.median(np.abs(d - np.median(d)))
    return (f"{name}: {len(d)} differences, per observation robust sd "
            f"{mad / np.sqrt(2):.3f} px, RMS {np.sqrt((bulk ** 2).mean()) / np.sqrt(2):.3f} px "
            f"(within {BLUNDER_PX} px), mean {bulk.mean():+.3f} px, beyond {BLUNDER_PX} px "
            f"{100 * (1 - len(bulk) / len(d)):.1f} %")


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    run, dataset = sys.argv[1], sys.argv[2]
    f, cx, cy, base = rig(dataset)
    poses = read_poses(os.path.join(dataset, "gt_poses.txt"))
    depths = Depths(dataset)
    images = read_model(run)
    epochs = len(poses)
    stereo, temporal_x, temporal_y = [], [], []
    for k in range(epochs):
        left, right = images.get(2 * k + 1, {}), images.get(2 * k + 2, {})
        for point, (u, v) in left.items():
            z = depths.at(k, u, v)
            if z is None:
                continue
            if point in right:
                stereo.append((u - right[point][0]) - f * base / z)
            before = images.get(2 * k - 1, {}).get(point) if k > 0 else None
            z0 = depths.at(k - 1, *before) if before else None
            if z0 is None:
                continue
            u0, v0 = before
            xyz = to_world(poses[k - 1], u0, v0, z0, f, cx, cy)
            cam = np.linalg.inv(poses[k]) @ np.append(xyz, 1.0)
            temporal_x.append(u - (f * cam[0] / cam[2] + cx))
            temporal_y.append(v - (f * cam[1] / cam[2] + cy))
    print(summary("stereo (disparity)", stereo))
    print(summary("temporal x", temporal_x))
    print(summary("temporal y", temporal_y))


if __name__ == "__main__":
    main()
