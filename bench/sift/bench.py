#!/usr/bin/env python3
"""Reduced SIFT (phototraverse) against OpenCV SIFT on pairs with known geometry.

Pairs: homography warps of real photographs (../shared/data/pairs and stereo; rotation up
to 45 deg, scale up to 2, perspective, brightness -40%, blur, noise), each 640x480, and the
Middlebury motorcycle rectified pair with ground-truth disparity.

For each pair and each extractor: features, repeatability (overlap error < 40 %, the
protocol of Mikolajczyk et al. / OpenCV's evaluation code), nearest-neighbour ratio-0.8
matches, correct matches (within 3 px of the known geometry), precision, extraction time
(minimum over repeats, decoding excluded, one thread) and working memory per pixel.
Ours runs with its keypoint cap set to OpenCV's keypoint count on the same image.

Usage: python3 bench/sift/bench.py [--data ../shared/data] [--bin target/release/phototraverse]
       [--repeat 5] [--json bench/sift/results.json]
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

import cv2
import numpy as np

STEREO_PAIR = "motorcycle/stereo"
# The configuration measured against issue 3's bars (README.md): the fine octave with the
# input taken as unblurred (input sigma 0: 0.8 and 1.6 px added to the fine octave and
# octave 0), strongest-first cap (no spreading grid), votes split between orientation
# bins, an 8x8 descriptor grid (1.6 samples per bin) and orientation windows sampled every
# other pixel from sigma 2, over a radius of 3 sigma (OpenCV: 4.5).
BAR_ARGS = ("--fine-octave --input-sigma 0 --grid 1x1 --soft-orientation "
            "--descriptor-grid 8 --orientation-stride-sigma 2 --orientation-radius 3")
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
W, H = 640, 480


def default_data():
    """../shared/data relative to the repository root (or to a parent, for git worktrees)."""
    d = ROOT
    for _ in range(3):
        cand = os.path.join(os.path.dirname(d), "shared", "data")
        if os.path.isdir(cand):
            return cand
        d = os.path.dirname(d)
    return os.path.join(ROOT, "..", "shared", "data")


# ---------------------------------------------------------------- pairs
def base_images(data):
    names = ["pairs/leuvenA.jpg", "pairs/aero1.jpg", "pairs/box_in_scene.png",
             "stereo/aloeL.jpg", "stereo/motorcycle_left.png"]
    out = []
    for n in names:
        p = os.path.join(data, n)
        img = cv2.imread(p, cv2.IMREAD_GRAYSCALE)
        if img is None:
            continue
        out.append((os.path.splitext(os.path.basename(n))[0], to_640x480(img)))
    return out


def to_640x480(img):
    h, w = img.shape
    s = max(W / w, H / h)
    img = cv2.resize(img, (int(round(w * s)), int(round(h * s))), interpolation=cv2.INTER_AREA)
    h, w = img.shape
    y0, x0 = (h - H) // 2, (w - W) // 2
    return np.ascontiguousarray(img[y0:y0 + H, x0:x0 + W])


def about_centre(m):
    c = np.array([[1, 0, W / 2], [0, 1, H / 2], [0, 0, 1]], float)
    ci = np.array([[1, 0, -W / 2], [0, 1, -H / 2], [0, 0, 1]], float)
    return c @ m @ ci


def rot_scale(deg, s):
    a = np.deg2rad(deg)
    return about_centre(np.array([[s * np.cos(a), -s * np.sin(a), 0], [s * np.sin(a), s * np.cos(a), 0], [0, 0, 1]]))


def warps():
    """(name, homography in pixel-centre coordinates, photometric change)."""
    persp = about_centre(np.array([[1.0, 0.08, 0], [0.05, 0.95, 0], [2.5e-4, 1.5e-4, 1]]))
    return [
        ("rot15", rot_scale(15, 1), None),
        ("rot45", rot_scale(45, 1), None),
        ("scale1.5", rot_scale(0, 1.5), None),
        ("scale2_rot10", rot_scale(10, 2.0), None),
        ("persp", persp, None),
        ("bright-40", np.eye(3), "bright"),
        ("blur", rot_scale(5, 1.1), "blur"),
        ("noise", rot_scale(-20, 0.8), "noise"),
    ]


def apply_warp(img, hm, photo, seed):
    out = cv2.warpPerspective(img, hm, (W, H), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    out = out.astype(np.float32)
    if photo == "bright":
        out *= 0.6
    elif photo == "blur":
        out = cv2.GaussianBlur(out, (0, 0), 1.5)
    elif photo == "noise":
        out += np.random.default_rng(seed).normal(0, 6.0, out.shape)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def read_pfm(path):
    with open(path, "rb") as f:
        kind = f.readline().decode().strip()
        w, h = map(int, f.readline().decode().split())
        scale = float(f.readline().decode().strip())
        data = np.frombuffer(f.read(), dtype="<f4" if scale < 0 else ">f4")
    ch = 3 if kind == "PF" else 1
    d = data.reshape(h, w, ch)[:, :, 0] if ch == 3 else data.reshape(h, w)
    return np.flipud(d).astype(np.float64)  # PFM rows are bottom-up


# ---------------------------------------------------------------- extractors
def run_opencv(img, repeat):
    cv2.setNumThreads(1)
    sift = cv2.SIFT_create()
    best = 1e9
    for _ in range(repeat):
        t = time.perf_counter()
        kps, desc = sift.detectAndCompute(img, None)
        best = min(best, time.perf_counter() - t)
    pts = np.array([k.pt for k in kps], float).reshape(-1, 2)  # OpenCV: pixel centres at integers
    # OpenCV's size is the diameter 2 sigma: the region radius used below is sigma.
    sig = np.array([k.size / 2 for k in kps], float)
    return dict(pts=pts, sigma=sig, desc=np.asarray(desc, np.float32).reshape(-1, 128), ms=best * 1e3)


def run_ours(binary, img, repeat, cap, tmp, extra=()):
    src = os.path.join(tmp, "img.png")
    out = os.path.join(tmp, "feat.txt")
    cv2.imwrite(src, img)
    res = subprocess.run([binary, "features", src, "--out", out, "--json", "--repeat", str(repeat),
                          "--max-keypoints", str(max(cap, 1))] + list(extra), check=True, capture_output=True, text=True)
    info = json.loads(res.stdout.strip().splitlines()[-1])
    with open(out) as f:
        n = int(f.readline().split()[0])
        rows = np.loadtxt(f, ndmin=2) if n else np.zeros((0, 132))
    pts = rows[:, 0:2] - 0.5  # COLMAP corner convention back to pixel centres
    return dict(pts=pts, sigma=rows[:, 2], desc=rows[:, 4:].astype(np.float32), ms=info["millis_min"],
                bpp=info["working_bytes_per_pixel"], info=info)


def opencv_bytes_per_pixel(img):
    """Peak RSS growth of OpenCV's SIFT on the image, per pixel, in a fresh process: the peak
    (VmHWM) is reset after the import (Linux: `5` into /proc/self/clear_refs), so the import's
    own peak does not hide the extractor's; the same on a 32x32 image is subtracted."""
    code = ("import cv2,sys,numpy as np;cv2.setNumThreads(1);"
            "img=np.load(sys.argv[1]);s=cv2.SIFT_create();"
            "kb=lambda k:int([l for l in open('/proc/self/status') if l.startswith(k)][0].split()[1]);"
            "rss=kb('VmRSS:');open('/proc/self/clear_refs','w').write('5');"
            "s.detectAndCompute(img,None);print(kb('VmHWM:')-rss)")

    def peak(a):
        with tempfile.TemporaryDirectory() as d:
            p = os.path.join(d, "i.npy")
            np.save(p, a)
            r = subprocess.run([sys.executable, "-c", code, p], capture_output=True, text=True)
        return float(r.stdout.strip()) * 1024

    try:
        return (peak(img) - peak(np.ascontiguousarray(img[:32, :32]))) / img.size
    except (ValueError, OSError):
        return float("nan")


# ---------------------------------------------------------------- evaluation
def ratio_matches(da, db, ratio=0.8):
    if len(da) < 1 or len(db) < 2:
        return np.zeros((0, 2), int)
    bf = cv2.BFMatcher(cv2.NORM_L2)
    out = []
    for m in bf.knnMatch(da, db, k=2):
        if len(m) == 2 and m[0].distance < ratio * m[1].distance:
            out.append((m[0].queryIdx, m[0].trainIdx))
    return np.array(out, int).reshape(-1, 2)


class Homography:
    def __init__(self, hm):
        self.h = hm

    def map(self, p):
        q = np.c_[p, np.ones(len(p))] @ self.h.T
        return q[:, :2] / q[:, 2:3]

    def valid(self, p):
        return np.ones(len(p), bool)

    def jac(self, p):
        """Local affine (2x2) of the mapping at each point."""
        e = 1e-3
        j = np.zeros((len(p), 2, 2))
        for k in range(2):
            d = np.zeros(2)
            d[k] = e
            j[:, :, k] = (self.map(p + d) - self.map(p - d)) / (2 * e)
        return j


class Disparity:
    def __init__(self, disp):
        self.d = disp

    def _d(self, p):
        c = np.clip(np.rint(p[:, 0]).astype(int), 0, self.d.shape[1] - 1)
        r = np.clip(np.rint(p[:, 1]).astype(int), 0, self.d.shape[0] - 1)
        return self.d[r, c]

    def map(self, p):
        d = self._d(p)
        return np.c_[p[:, 0] - np.where(np.isfinite(d), d, np.nan), p[:, 1]]

    def valid(self, p):
        return np.isfinite(self._d(p))

    def jac(self, p):
        return np.repeat(np.eye(2)[None], len(p), 0)


def inside(p, shape, margin=0):
    h, w = shape
    return (p[:, 0] >= margin) & (p[:, 0] <= w - 1 - margin) & (p[:, 1] >= margin) & (p[:, 1] <= h - 1 - margin)


def correct_mask(geom, pa, pb, tol=3.0):
    q = geom.map(pa)
    ok = geom.valid(pa) & np.all(np.isfinite(q), 1)
    d = np.linalg.norm(np.nan_to_num(q, nan=1e9) - pb, axis=1)
    return ok, ok & (d <= tol)


def overlap_error(ca, ea, cb, rb, grid=31):
    """1 - intersection/union of ellipse A (centre ca, matrix ea: x^T E x <= 1) and circle B,
    after scaling so that A's equivalent radius is 30 px (Mikolajczyk's normalisation),
    computed on a sampling grid over the union's bounding box."""
    ra = 1 / np.sqrt(np.sqrt(np.linalg.det(ea)))
    s = 30.0 / ra
    ea_s = ea / (s * s)
    cb_s = (cb - ca) * s
    rb_s = rb * s
    ext = max(1 / np.sqrt(np.linalg.eigvalsh(ea_s).min()), np.abs(cb_s).max() + rb_s)
    xs = np.linspace(-ext, ext, grid)
    gx, gy = np.meshgrid(xs, xs)
    pts = np.stack([gx.ravel(), gy.ravel()], 1)
    in_a = np.einsum("ni,ij,nj->n", pts, ea_s, pts) <= 1
    in_b = np.sum((pts - cb_s) ** 2, 1) <= rb_s * rb_s
    union = np.count_nonzero(in_a | in_b)
    return 1.0 if union == 0 else 1 - np.count_nonzero(in_a & in_b) / union


def repeatability(geom, fa, fb, shape_b, scale=3.0):
    """Regions are circles of radius `scale` sigma (OpenCV's size/2 scaled like its evaluation
    code magnifies regions). Counted among keypoints whose centre maps into both images."""
    pa, pb = fa["pts"], fb["pts"]
    if len(pa) == 0 or len(pb) == 0:
        return 0.0, 0
    q = geom.map(pa)
    ok_a = geom.valid(pa) & np.all(np.isfinite(q), 1)
    ok_a &= inside(np.nan_to_num(q, nan=-1e9), shape_b)
    # B keypoints visible in A: invert by nearest search is costly; use the forward-mapped A frame
    # bounds (the warp keeps most of the frame).
    na = int(np.count_nonzero(ok_a))
    nb = len(pb)
    jac = geom.jac(pa)
    ra = scale * fa["sigma"]
    rb = scale * fb["sigma"]
    used = np.zeros(nb, bool)
    corr = 0
    order = np.argsort(-ra)
    for i in order:
        if not ok_a[i]:
            continue
        # Ellipse of A's circle mapped by the local affine J: x^T (J^-T J^-1 / r^2) x <= 1.
        jinv = np.linalg.inv(jac[i])
        ea = jinv.T @ jinv / (ra[i] ** 2)
        # Overlap error < 0.4 needs radii within a factor 1/sqrt(0.6) and close centres.
        ra_eq = ra[i] * np.sqrt(abs(np.linalg.det(jac[i])))
        dist = np.linalg.norm(pb - q[i], axis=1)
        cand = np.where((dist < 0.6 * np.maximum(rb, ra_eq)) & (rb > 0.77 * ra_eq) & (rb < 1.3 * ra_eq) & ~used)[0]
        best, bj = 0.4, -1
        for j in cand:
            e = overlap_error(q[i], ea, pb[j], rb[j])
            if e < best:
                best, bj = e, j
        if bj >= 0:
            used[bj] = True
            corr += 1
    return corr / max(1, min(na, nb)), corr


def evaluate(geom, fa, fb, shape_b):
    m = ratio_matches(fa["desc"], fb["desc"])
    if len(m):
        ok, good = correct_mask(geom, fa["pts"][m[:, 0]], fb["pts"][m[:, 1]])
        n_match, n_good = int(np.count_nonzero(ok)), int(np.count_nonzero(good))
    else:
        n_match = n_good = 0
    rep, _ = repeatability(geom, fa, fb, shape_b)
    return dict(features=[len(fa["pts"]), len(fb["pts"])], matches=n_match, correct=n_good,
                precision=(n_good / n_match if n_match else 0.0), repeatability=rep)


# ---------------------------------------------------------------- main
def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=default_data())
    ap.add_argument("--bin", default=os.path.join(ROOT, "target", "release", "phototraverse"))
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", default=os.path.join(ROOT, "bench", "sift", "results.json"))
    ap.add_argument("--quick", action="store_true", help="one base image, four warps, no stereo")
    ap.add_argument("--bases", default="", help="comma-separated base image names (default: all)")
    ap.add_argument("--ours-args", default=BAR_ARGS,
                    help=f"arguments for `phototraverse features` (default: the issue-3 configuration, {BAR_ARGS!r}; "
                         "'' for the extractor's defaults)")
    args = ap.parse_args()
    if not os.path.isdir(args.data):
        print(f"data directory {args.data} is missing: nothing to benchmark", file=sys.stderr)
        return 2
    if not os.path.exists(args.bin):
        print(f"{args.bin} missing: run `cargo build --release -p phototraverse-host` first", file=sys.stderr)
        return 2
    cv2.setNumThreads(1)
    pairs = []
    bases = base_images(args.data)
    ws = warps()
    if args.bases:
        keep = args.bases.split(",")
        bases = [b for b in bases if b[0] in keep]
    if args.quick:
        bases = bases[:1]
        ws = [ws[i] for i in (1, 3, 4, 7)]
    for bname, img in bases:
        for i, (wname, hm, photo) in enumerate(ws):
            pairs.append((f"{bname}/{wname}", img, apply_warp(img, hm, photo, i), Homography(hm)))
    sd = os.path.join(args.data, "stereo")
    left = cv2.imread(os.path.join(sd, "motorcycle_left.png"), cv2.IMREAD_GRAYSCALE)
    right = cv2.imread(os.path.join(sd, "motorcycle_right.png"), cv2.IMREAD_GRAYSCALE)
    if not args.quick and left is not None and right is not None and os.path.exists(os.path.join(sd, "motorcycle_disp.pfm")):
        pairs.append((STEREO_PAIR, left, right, Disparity(read_pfm(os.path.join(sd, "motorcycle_disp.pfm")))))

    rows = []
    cache = {}
    with tempfile.TemporaryDirectory() as tmp:
        def feats(img):
            key = img.tobytes().__hash__()
            if key not in cache:
                cv = run_opencv(img, args.repeat)
                ours = run_ours(args.bin, img, args.repeat, len(cv["pts"]), tmp, args.ours_args.split())
                cache[key] = (cv, ours)
            return cache[key]

        for name, a, b, geom in pairs:
            cva, oa = feats(a)
            cvb, ob = feats(b)
            row = dict(pair=name, size=[a.shape[1], a.shape[0]])
            row["opencv"] = evaluate(geom, cva, cvb, b.shape)
            row["ours"] = evaluate(geom, oa, ob, b.shape)
            row["opencv"]["ms"] = (cva["ms"] + cvb["ms"]) / 2
            row["ours"]["ms"] = (oa["ms"] + ob["ms"]) / 2
            row["ours"]["bytes_per_px"] = oa["bpp"]
            rows.append(row)
            print_row(row)
    mem_cv = opencv_bytes_per_pixel(bases[0][1]) if bases else float("nan")
    summary = summarise(rows, mem_cv)
    print_summary(summary)
    with open(args.json, "w") as f:
        json.dump(dict(rows=rows, summary=summary), f, indent=1)
    print(f"saved {args.json}")
    return 0


def print_row(r):
    o, c = r["ours"], r["opencv"]
    if not hasattr(print_row, "hdr"):
        print_row.hdr = True
        print(f"{'pair':28} | {'feat cv/ours':>11} | {'rep cv/ours':>11} | {'match cv/ours':>13} | "
              f"{'correct cv/ours':>15} | {'prec cv/ours':>12} | {'ms cv/ours':>13}")
    print(f"{r['pair']:28} | {c['features'][0]:5d}/{o['features'][0]:5d} | {c['repeatability']:.3f}/{o['repeatability']:.3f} | "
          f"{c['matches']:6d}/{o['matches']:6d} | {c['correct']:7d}/{o['correct']:7d} | "
          f"{c['precision']:.3f}/{o['precision']:.3f} | {c['ms']:6.1f}/{o['ms']:6.1f}", flush=True)


def summarise(rows, mem_cv):
    # The stereo pair, not the warps of the motorcycle_left base image.
    moto = [r for r in rows if r["pair"] == STEREO_PAIR]
    warp = [r for r in rows if r["pair"] != STEREO_PAIR]

    def agg(rs, who):
        m = sum(r[who]["matches"] for r in rs)
        g = sum(r[who]["correct"] for r in rs)
        return dict(matches=m, correct=g, precision=(g / m if m else 0.0),
                    repeatability=float(np.mean([r[who]["repeatability"] for r in rs])) if rs else 0.0,
                    ms=float(np.mean([r[who]["ms"] for r in rs])) if rs else 0.0)

    s = {}
    for label, rs in (("warps", warp), ("motorcycle", moto)):
        if not rs:
            continue
        cv, ours = agg(rs, "opencv"), agg(rs, "ours")
        s[label] = dict(opencv=cv, ours=ours,
                        precision_ok=ours["precision"] >= cv["precision"],
                        correct_ratio=(ours["correct"] / cv["correct"] if cv["correct"] else 0.0))
    ms640 = [r for r in warp if r["size"] == [640, 480]]
    if ms640:
        cvt = float(np.mean([r["opencv"]["ms"] for r in ms640]))
        ot = float(np.mean([r["ours"]["ms"] for r in ms640]))
        s["speed_640x480"] = dict(opencv_ms=cvt, ours_ms=ot, speedup=cvt / ot if ot else 0.0)
    s["memory"] = dict(ours_bytes_per_px=rows[0]["ours"]["bytes_per_px"] if rows else 0.0,
                       opencv_bytes_per_px_rss=mem_cv)
    return s


def print_summary(s):
    print()
    for label in ("warps", "motorcycle"):
        if label in s:
            v = s[label]
            print(f"{label:10}: precision cv {v['opencv']['precision']:.3f} ours {v['ours']['precision']:.3f} "
                  f"({'PASS' if v['precision_ok'] else 'FAIL'}); correct cv {v['opencv']['correct']} ours {v['ours']['correct']} "
                  f"= {v['correct_ratio']:.2f} ({'PASS' if v['correct_ratio'] >= 0.6 else 'FAIL'}); "
                  f"repeatability cv {v['opencv']['repeatability']:.3f} ours {v['ours']['repeatability']:.3f}")
    if "speed_640x480" in s:
        v = s["speed_640x480"]
        print(f"speed 640x480: opencv {v['opencv_ms']:.1f} ms, ours {v['ours_ms']:.1f} ms, "
              f"speedup {v['speedup']:.2f}x ({'PASS' if v['speedup'] >= 4 else 'FAIL'})")
    m = s["memory"]
    print(f"memory: ours {m['ours_bytes_per_px']:.2f} B/px ({'PASS' if m['ours_bytes_per_px'] <= 6 else 'FAIL'}), "
          f"opencv peak RSS growth {m['opencv_bytes_per_px_rss']:.0f} B/px")


if __name__ == "__main__":
    sys.exit(main())
