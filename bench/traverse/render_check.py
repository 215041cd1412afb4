#!/usr/bin/env python3
"""Do a `synth` dataset's images agree with its true poses? A check of the data, not of a run.

Before an error of the traverse on a rendered street is called the traverse's, the rendering
must be shown to agree with `gt_poses.txt`. For each step k-1 -> k of the left camera, every
pixel of image k-1 with a depth (the `--depth` maps) is carried into image k with the true
poses, image k is resampled there, and the small rotation of camera k that best aligns the
two (Gauss-Newton on the image gradients, one step from zero) is solved for, in the sign of
`bench/aiding/attitude.py --rotations`: the error of the poses' step rotation, as a run's.
Poses with camera k turned by 1 mrad about x read +1 at step k and -1 at step k+1 (one
Gauss-Newton step reads 0.97). Pixels that the
step occludes (the depth map of epoch k disagrees by more than 1 %), near depth edges or
without texture are left out. A rendering that agrees with its poses gives rotations at the
level of the grey-level noise, with no trend: on the `drive` scene about 0.03 mrad per step,
summing to well under 1 mrad over 50 steps.

Printed per step: the rotation in mrad about the camera's x (right), y (down) and z (forward)
axes, the pixels used and the RMS grey-level difference after the warp; then the sum over the
steps, to compare with a run's summed rotation errors over the same stretch
(`bench/aiding/attitude.py RUN --rotations A..B`).

With `--scale`, the length of each step is solved beside its rotation: a last column, in %,
for how much longer the step the images show is than the poses' (the camera's motion along
its true direction); the steps of a run that fits the images would be that much longer.

    phototraverse synth --scene drive --seed 1 --frames 480 --depth --out D
    python3 bench/traverse/render_check.py D 405 455
    python3 bench/traverse/render_check.py D 1 30 --scale

usage: render_check.py DATASET FIRST LAST [--scale]   (numpy, opencv-python; KITTI layout)
"""
import argparse
import os
import sys

import cv2
import numpy as np

from precision import image_motion, rig, to_world
from steps import read_poses

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "sift"))
from bench import read_pfm  # noqa: E402 (the SIFT bench's PFM reader)

# A pixel the step occludes: its carried depth differs from the depth map's by more than this.
OCCLUSION = 0.01
# Pixels this close to an occlusion or the image border are left out (kernel side, pixels).
MARGIN = 5
# Grey-level gradient (per pixel) below which a pixel holds no texture to align on.
MIN_GRADIENT = 2.0


def frame(dataset, k):
    """Epoch k's left image and depth map."""
    path = os.path.join(dataset, "image_0", f"{k:06d}.png")
    image = cv2.imread(path, cv2.IMREAD_GRAYSCALE).astype(np.float32)
    return image, read_pfm(os.path.join(dataset, "depth_0", f"{k:06d}.pfm"))


def carry(pose_a, pose_b, z, f, cx, cy):
    """Pixels of camera a with depth z, in camera b (KITTI frames, camera to world poses):
    their image positions and depths."""
    h, w = z.shape
    c, r = np.meshgrid(np.arange(w), np.arange(h))
    with np.errstate(invalid="ignore"):
        world = to_world(pose_a, c, r, z, f, cx, cy)
        xb = (world - pose_b[:3, 3]) @ pose_b[:3, :3]
        u = f * xb[..., 0] / xb[..., 2] + cx
        v = f * xb[..., 1] / xb[..., 2] + cy
    return u, v, xb[..., 2]


def step_rotation(before, after, poses, k, f, cx, cy, scale=False):
    """The error (mrad, about x, y, z) of the poses' rotation from camera k-1 to k: minus the
    rotation of camera k that aligns image k onto image k-1 (`before` and `after`: their
    frames); with `scale`, a fourth value: how much longer (%) the step the images show
    is than the poses' step."""
    (ia, za), (ib, zb) = before, after
    u, v, zc = carry(poses[k - 1], poses[k], za, f, cx, cy)
    h, w = za.shape
    ok = np.isfinite(zc) & (zc > 0.5) & (u > 2) & (u < w - 3) & (v > 2) & (v < h - 3)
    um, vm = np.where(ok, u, 0).astype(np.float32), np.where(ok, v, 0).astype(np.float32)
    seen = cv2.remap(zb.astype(np.float32), um, vm, cv2.INTER_NEAREST)
    ok &= np.abs(seen - zc) < OCCLUSION * zc
    ok = cv2.erode(ok.astype(np.uint8), np.ones((MARGIN, MARGIN), np.uint8)).astype(bool)
    warped = cv2.remap(ib, um, vm, cv2.INTER_CUBIC).astype(np.float64)
    gx = cv2.Sobel(warped, cv2.CV_64F, 1, 0, ksize=3) / 8
    gy = cv2.Sobel(warped, cv2.CV_64F, 0, 1, ksize=3) / 8
    ok &= np.hypot(gx, gy) > MIN_GRADIENT
    du, dv = image_motion((u - cx) / f, (v - cy) / f, zc, f)
    # The rotation: the true depths carry the translation, which `scale` lengthens along
    # camera k's true motion (in its own frame).
    columns = [gx[..., None] * du[..., :3] + gy[..., None] * dv[..., :3]]
    if scale:
        move = poses[k][:3, :3].T @ (poses[k][:3, 3] - poses[k - 1][:3, 3])
        columns.append((gx * (du[..., 3:] @ move) + gy * (dv[..., 3:] @ move))[..., None])
    jac = np.concatenate(columns, -1)[ok]
    diff = (ia.astype(np.float64) - warped)[ok]
    solution = np.linalg.solve(jac.T @ jac, jac.T @ diff)
    found = np.concatenate([-solution[:3] * 1000, solution[3:] * 100])
    return found, int(ok.sum()), float(np.sqrt(np.mean(diff ** 2)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", help="a `synth` dataset rendered with --depth (KITTI layout)")
    ap.add_argument("first", type=int, help="first epoch k of the steps k-1 -> k")
    ap.add_argument("last", type=int, help="last epoch (exclusive)")
    ap.add_argument("--scale", action="store_true",
                    help="also solve each step's length: %% longer in the images than in the poses")
    args = ap.parse_args()
    if not os.path.isdir(os.path.join(args.dataset, "depth_0")):
        sys.exit(f"{args.dataset}: no depth_0/ (render it with `synth --depth`)")
    if not os.path.isfile(os.path.join(args.dataset, "calib.txt")):
        sys.exit(f"{args.dataset}: no calib.txt: the check reads the KITTI layout's pinhole "
                 "cameras (a rig.toml layout's lens model is not modelled here)")
    poses = read_poses(os.path.join(args.dataset, "gt_poses.txt"))
    f, cx, cy, _ = rig(args.dataset)
    total = np.zeros(4 if args.scale else 3)
    print("step      x mrad   y mrad   z mrad   pixels   grey RMS" + ("   scale %" if args.scale else ""))
    first = max(args.first, 1)
    after = frame(args.dataset, first - 1)
    for k in range(first, min(args.last, len(poses))):
        # Each frame is read once: this step's later frame is the next step's earlier one.
        before, after = after, frame(args.dataset, k)
        found, n, rms = step_rotation(before, after, poses, k, f, cx, cy, args.scale)
        total += found
        length = f"   {found[3]:+8.4f}" if args.scale else ""
        print(f"{k:5d}  {found[0]:8.3f} {found[1]:8.3f} {found[2]:8.3f}  {n:7d}   {rms:6.2f}{length}")
    print(f"sum    {total[0]:8.3f} {total[1]:8.3f} {total[2]:8.3f}")
    if args.scale:
        steps = min(args.last, len(poses)) - first
        print(f"mean scale {total[3] / max(steps, 1):+.4f} % per step")


if __name__ == "__main__":
    main()
