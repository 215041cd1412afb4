#!/usr/bin/env python3
"""How well can a template from an earlier image be found in a later one, given the truth?

A check of temporal template matching itself, outside the traverse: for points of an
anchor image of a dataset rendered with `--depth` (KITTI layout), the true position in
each later image (the depth maps through `gt_poses.txt`) is compared with where
least-squares matching finds a 9 x 9 template of the anchor (`--half`). The least
squares is the core's model (`core/src/matching/lsm.rs`): gain, offset and a brightness ramp solved with
the shift, bilinear samples, central-difference gradients; it starts 0.3 px (uniform)
off the truth and iterates to 1e-5 px. Templates:

- `iso`: the anchor's samples magnified by the ratio of the depths (the core's default);
- `exact`: the anchor image sampled where each template sample's ray, through the later
  image's depth map, meets the surface: the exact warp, projective part included;
- `inverse`: the anchor's samples as they are, and the later image sampled on the anchor
  grid carried by the true local affine map (the comparison made at the anchor's
  resolution instead of the later image's);
- `self`: the later image's own samples at the truth (the solver's floor: zero).

Printed per template and lag (epochs after the anchor): the points, the mean error along
the image motion (radial from the principal point: positive outward, the sign that
lengthens the steps a window adjusts from it) with its standard error, and the median and
RMS error, split at 30 m of depth.

`render-plane OUT` writes a dataset of its own for a control independent of `synth`: one
textured plane (a photograph at 1.5 cm per texel) rendered with `--ss`^2 rays per pixel
(area sampling) as the camera moves 1 m forward per epoch: a side wall `--wall LAT`
metres to the left, or a plane facing the camera `--front Z` metres ahead.

    phototraverse synth --scene straight --photo-textures P1,...,P5 --seed 102 --frames 100 --depth --out D
    python3 bench/traverse/match_truth.py D --anchors 10,15,20,25,30,35,40,45,50,55,60,65,70,75,80
    python3 bench/traverse/match_truth.py render-plane /tmp/front --front 14 --texture ../shared/data/pairs/leuvenA.jpg
    python3 bench/traverse/match_truth.py /tmp/front --anchors 1,2,3,4
"""
import argparse
import os
import sys

import cv2
import numpy as np

from precision import rig, to_world
from steps import read_poses

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "sift"))
from bench import read_pfm  # noqa: E402 (the SIFT bench's PFM reader)

H = N = GRID = None  # the template's half-size, side and sample offsets (`set_half`)


def set_half(half):
    global H, N, GRID
    H, N = half, 2 * half + 1
    u, v = np.meshgrid(np.arange(N) - H, np.arange(N) - H)
    GRID = np.stack([u.ravel(), v.ravel()], 1).astype(float)


set_half(4)  # the core's (`RefineConfig::half_window`)
LAGS = [1, 2, 3, 5]


def write_pfm(path, a):
    h, w = a.shape
    with open(path, "wb") as fh:
        fh.write(b"Pf\n%d %d\n-1.0\n" % (w, h))
        fh.write(a[::-1].astype("<f4").tobytes())


def bilinear(img, x, y):
    x0 = np.floor(x).astype(int)
    y0 = np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    top = img[y0, x0] * (1 - fx) + img[y0, x0 + 1] * fx
    bot = img[y0 + 1, x0] * (1 - fx) + img[y0 + 1, x0 + 1] * fx
    return top * (1 - fy) + bot * fy


class Dataset:
    def __init__(self, root):
        self.root = root
        self.f, self.cx, self.cy, _ = rig(root)
        self.poses = read_poses(os.path.join(root, "gt_poses.txt"))
        self.images, self.depths = {}, {}

    def image(self, k):
        if k not in self.images:
            path = os.path.join(self.root, "image_0", "%06d.png" % k)
            self.images[k] = cv2.imread(path, 0).astype(np.float64)
        return self.images[k]

    def depth(self, k):
        if k not in self.depths:
            self.depths[k] = read_pfm(os.path.join(self.root, "depth_0", "%06d.pfm" % k))
        return self.depths[k]

    def point(self, k, c, r):
        """The object point seen at pixel (c, r) of image k (inverse depth interpolated:
        linear over a plane, as depth is not)."""
        z = 1.0 / bilinear(1.0 / self.depth(k), np.array([c]), np.array([r]))[0]
        return to_world(self.poses[k], c, r, z, self.f, self.cx, self.cy)

    def project(self, xw, k):
        """Pixel and depth of object point `xw` in image k."""
        xc = self.poses[k][:3, :3].T @ (xw - self.poses[k][:3, 3])
        return np.array([self.f * xc[0] / xc[2] + self.cx, self.f * xc[1] / xc[2] + self.cy]), xc[2]


def least_squares(img, tpl, start, offsets, iterations=30):
    """The core's least-squares model; the position where it settles, None where it leaves."""
    p = start.copy()
    gain, offset, rx, ry = 1.0, 0.0, 0.0, 0.0
    for _ in range(iterations):
        xs, ys = p[0] + offsets[:, 0], p[1] + offsets[:, 1]
        s = bilinear(img, xs, ys)
        gx = (bilinear(img, xs + 1, ys) - bilinear(img, xs - 1, ys)) / 2
        gy = (bilinear(img, xs, ys + 1) - bilinear(img, xs, ys - 1)) / 2
        r = tpl - (gain * s + offset + rx * GRID[:, 0] + ry * GRID[:, 1])
        j = np.stack([gain * gx, gain * gy, s, np.ones_like(s), GRID[:, 0], GRID[:, 1]], 1)
        d = np.linalg.lstsq(j, r, rcond=None)[0]
        p = p + d[:2]
        gain, offset, rx, ry = gain + d[2], offset + d[3], rx + d[4], ry + d[5]
        if np.abs(d[:2]).max() < 1e-5:
            return p
        if np.abs(p - start).max() > 1.5:
            return None
    return p


class Anchor:
    """What a point of anchor image `a` at pixel `at` gives every lag: its template
    samples and the object points one pixel either side (the true local map's base)."""

    def __init__(self, ds, a, at):
        self.a = a
        self.samples = bilinear(ds.image(a), at[0] + GRID[:, 0], at[1] + GRID[:, 1])
        self.sides = [ds.point(a, at[0] + dc, at[1] + dr) for dc, dr in ((1, 0), (-1, 0), (0, 1), (0, -1))]


def templates(ds, anchor, k, truth, depth_ratio):
    """The templates of `anchor` for image k, each with the offsets image k is sampled
    at around the match."""
    a, img_a = anchor.a, ds.image(anchor.a)
    out = {}
    # The magnified anchor template, read within its own samples as the core does.
    x, y = H + GRID[:, 0] / depth_ratio, H + GRID[:, 1] / depth_ratio
    padded = np.pad(anchor.samples.reshape(N, N), ((0, 1), (0, 1)), mode="edge")
    out["iso"] = bilinear(padded, x, y), GRID
    # The exact warp: each sample's ray through image k's depth onto the anchor image.
    xw = [ds.point(k, truth[0] + q[0], truth[1] + q[1]) for q in GRID]
    pa = np.array([ds.project(x, a)[0] for x in xw])
    if np.all(np.isfinite(pa)):
        out["exact"] = bilinear(img_a, pa[:, 0], pa[:, 1]), GRID
    # The true local affine map (anchor offsets to image k offsets), by central differences.
    d = [ds.project(x, k)[0] for x in anchor.sides]
    affine = np.stack([(d[0] - d[1]) / 2, (d[2] - d[3]) / 2], 1)
    out["inverse"] = anchor.samples, GRID @ affine.T
    out["self"] = bilinear(ds.image(k), truth[0] + GRID[:, 0], truth[1] + GRID[:, 1]), GRID
    return out


def measure(ds, anchors, rng):
    rows = {}
    for a in anchors:
        img_a, depth_a = ds.image(a), ds.depth(a)
        h, w = img_a.shape
        corners = cv2.goodFeaturesToTrack(img_a.astype(np.uint8), 600, 0.01, 8)
        for c, r in corners[:, 0, :]:
            c, r = float(c) + rng.uniform(-0.5, 0.5), float(r) + rng.uniform(-0.5, 0.5)
            ci, ri = int(round(c)), int(round(r))
            if not (20 < ci < w - 20 and 20 < ri < h - 20):
                continue
            patch = depth_a[ri - 3 : ri + 4, ci - 3 : ci + 4]
            # Away from depth edges: the template shows one surface.
            if not np.all(np.isfinite(patch)) or patch.max() / patch.min() > 1.03:
                continue
            xw = ds.point(a, c, r)
            z_a = ds.project(xw, a)[1]
            anchor = None  # taken at the first lag that keeps the point in view
            for lag in LAGS:
                k = a + lag
                if k >= len(ds.poses):
                    continue
                truth, z_k = ds.project(xw, k)
                if not (25 < truth[0] < w - 25 and 25 < truth[1] < h - 25) or z_k <= 0:
                    continue
                anchor = anchor or Anchor(ds, a, (c, r))
                tpls = templates(ds, anchor, k, truth, z_a / z_k)
                outward = truth - np.array([ds.cx, ds.cy])
                outward /= np.linalg.norm(outward)
                start = truth + rng.uniform(-0.3, 0.3, 2)
                for name, (tpl, offsets) in tpls.items():
                    p = least_squares(ds.image(k), tpl, start, offsets)
                    if p is not None:
                        e = p - truth
                        rows.setdefault((name, lag), []).append((e @ outward, np.hypot(*e), z_a))
    return rows


def report(rows):
    print("template  lag  points  outward mean px (se)  median  RMS   | < 30 m: outward, median | >= 30 m: outward, median")
    for name in ("iso", "exact", "inverse", "self"):
        for lag in LAGS:
            if (name, lag) not in rows:
                continue
            a = np.array(rows[(name, lag)])
            parts = []
            for sel in (a[:, 2] < 30, a[:, 2] >= 30):
                b = a[sel]
                parts.append("%+.4f, %.3f" % (b[:, 0].mean(), np.median(b[:, 1])) if len(b) else "-")
            print(
                "%-8s  %3d  %6d  %+.4f (%.4f)      %.3f   %.3f | %s | %s"
                % (name, lag, len(a), a[:, 0].mean(), a[:, 0].std() / len(a) ** 0.5,
                   np.median(a[:, 1]), np.sqrt((a[:, 1] ** 2).mean()), parts[0], parts[1])
            )


def mirrored(x, n):
    """Texel coordinate `x` of a texture `n` texels wide tiled by mirroring."""
    x = np.mod(x, 2 * n)
    return np.where(x >= n - 0.5, 2 * n - 1 - x, x)


def render_plane(args):
    """A textured plane, `ss` x `ss` rays per pixel, the camera 1 m forward per epoch."""
    tex = cv2.imread(args.texture, 0)
    if tex is None:
        sys.exit("render-plane: cannot read the texture %s" % args.texture)
    tex = tex.astype(np.float32)
    texel, f, w, h = 0.015, 500.0, 640, 480
    cx, cy = (w - 1) / 2, (h - 1) / 2
    cols, rows = np.meshgrid(np.arange(w), np.arange(h))
    os.makedirs(os.path.join(args.out, "image_0"), exist_ok=True)
    os.makedirs(os.path.join(args.out, "depth_0"), exist_ok=True)

    def hit(x, y, k):
        """Ray distance along the optical axis to the plane and the texture coordinates."""
        dx, dy = (x - cx) / f, (y - cy) / f
        if args.front:
            t = np.full_like(dx, args.front - k)
            return t, (dx * t + 8) / texel, (dy * t + 6) / texel, np.ones_like(dx, bool)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -args.wall / dx
        ok = (dx < 0) & (t > 0.5) & (t < 200)
        return t, np.where(ok, (k + t) / texel, 0), np.where(ok, (dy * t + 3) / texel, 0), ok

    for k in range(args.frames):
        acc = np.zeros((h, w))
        for i in range(args.ss):
            for j in range(args.ss):
                t, u, v, ok = hit(cols + (i + 0.5) / args.ss - 0.5, rows + (j + 0.5) / args.ss - 0.5, k)
                # The photograph tiles by mirroring: no edges on the plane.
                u, v = mirrored(u, tex.shape[1]), mirrored(v, tex.shape[0])
                val = cv2.remap(tex, u.astype(np.float32), v.astype(np.float32), cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_REFLECT)
                acc += np.where(ok, val, 128.0)
        cv2.imwrite(os.path.join(args.out, "image_0", "%06d.png" % k),
                    np.clip(np.round(acc / args.ss ** 2), 0, 255).astype(np.uint8))
        t, _, _, ok = hit(cols.astype(float), rows.astype(float), k)
        write_pfm(os.path.join(args.out, "depth_0", "%06d.pfm" % k), np.where(ok, t, np.inf))
    np.savetxt(os.path.join(args.out, "gt_poses.txt"),
               [[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, float(k)] for k in range(args.frames)])
    # A right camera only for the calibration's form (a base of 0.5 m): no right images.
    with open(os.path.join(args.out, "calib.txt"), "w") as fh:
        fh.write("P0: %g 0 %g 0 0 %g %g 0 0 0 1 0\n" % (f, cx, f, cy))
        fh.write("P1: %g 0 %g %g 0 %g %g 0 0 0 1 0\n" % (f, cx, -0.5 * f, f, cy))


def main():
    np.seterr(divide="ignore", invalid="ignore")  # sky and off-plane pixels: infinite depth
    if len(sys.argv) > 1 and sys.argv[1] == "render-plane":
        ap = argparse.ArgumentParser(prog="match_truth.py render-plane", description=render_plane.__doc__)
        ap.add_argument("out")
        ap.add_argument("--texture", required=True, help="a photograph (grey levels are read)")
        ap.add_argument("--wall", type=float, default=8.0, help="a side wall this far left (m)")
        ap.add_argument("--front", type=float, default=0.0, help="instead, a plane facing the camera this far ahead (m)")
        ap.add_argument("--ss", type=int, default=6, help="rays per pixel side")
        ap.add_argument("--frames", type=int, default=10)
        render_plane(ap.parse_args(sys.argv[2:]))
        return
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dataset", help="rendered with --depth (KITTI layout)")
    ap.add_argument("--anchors", required=True, help="anchor epochs, comma-separated")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--half", type=int, default=4, help="template half-size (default: the core's, 4)")
    args = ap.parse_args()
    set_half(args.half)
    ds = Dataset(args.dataset)
    anchors = [int(a) for a in args.anchors.split(",")]
    report(measure(ds, anchors, np.random.default_rng(args.seed)))


if __name__ == "__main__":
    main()
