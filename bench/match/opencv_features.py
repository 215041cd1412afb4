#!/usr/bin/env python3
"""Writes OpenCV SIFT features of an image in COLMAP's text format (X, Y with the
top-left corner at 0,0; descriptor values as OpenCV gives them, 0..255).

Development aid and the peer of the comparisons: the matcher's bars are measured
with phototraverse's own extractor once it is available.
usage: opencv_features.py IMAGE OUT [--n N]
"""
import argparse
import cv2

ap = argparse.ArgumentParser()
ap.add_argument("image")
ap.add_argument("out")
ap.add_argument("--n", type=int, default=0)
a = ap.parse_args()
img = cv2.imread(a.image, cv2.IMREAD_GRAYSCALE)
sift = cv2.SIFT_create(nfeatures=a.n)
kps, desc = sift.detectAndCompute(img, None)
with open(a.out, "w") as f:
    f.write(f"{len(kps)} 128\n")
    for k, d in zip(kps, desc):
        # OpenCV keypoint coordinates have pixel centres at integers: +0.5 for COLMAP.
        f.write(f"{k.pt[0] + 0.5:.4f} {k.pt[1] + 0.5:.4f} {k.size / 2:.4f} {k.angle * 3.14159265 / 180:.5f} ")
        f.write(" ".join(str(int(round(v))) for v in d) + "\n")
