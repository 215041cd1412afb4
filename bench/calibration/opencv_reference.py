#!/usr/bin/env python3
"""Calibrates OpenCV's chessboard stereo pairs with cv2.stereoCalibrate and writes the
fixtures of the calibration import test (tests/fixtures/calibration/):

- opencv_stereo.yml, opencv_stereo.xml: the calibration as OpenCV's FileStorage
  writes it (M1, D1, M2, D2, R, T, image_width, image_height), T in millimetres
  (the chessboard's 25 mm squares);
- opencv_projections.csv: points in the left camera's OpenCV frame (x right, y down,
  z forward, millimetres) and where cv2.projectPoints puts them in the left and right
  images (pixels, OpenCV's convention: the centre of the top-left pixel at 0, 0),
  for points that both images see within their format.

Usage: python3 bench/calibration/opencv_reference.py CHESSBOARD_DIR OUT_DIR
(CHESSBOARD_DIR holds left01.jpg..., right01.jpg..., 9x6 inner corners.)
"""
import glob
import os
import sys

import cv2
import numpy as np

SQUARE_MM = 25.0
PATTERN = (9, 6)


def corners(path):
    img = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    ok, c = cv2.findChessboardCorners(img, PATTERN)
    if not ok:
        return img.shape, None
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3)
    return img.shape, cv2.cornerSubPix(img, c, (11, 11), (-1, -1), crit)


def calibrate(src):
    board = np.zeros((PATTERN[0] * PATTERN[1], 3), np.float32)
    board[:, :2] = np.mgrid[0 : PATTERN[0], 0 : PATTERN[1]].T.reshape(-1, 2) * SQUARE_MM
    objects, lefts, rights = [], [], []
    for left in sorted(glob.glob(os.path.join(src, "left*.jpg"))):
        shape, cl = corners(left)
        _, cr = corners(left.replace("left", "right"))
        if cl is not None and cr is not None:
            objects.append(board)
            lefts.append(cl)
            rights.append(cr)
    size = (shape[1], shape[0])
    _, k1, d1, _, _ = cv2.calibrateCamera(objects, lefts, size, None, None)
    _, k2, d2, _, _ = cv2.calibrateCamera(objects, rights, size, None, None)
    rms, k1, d1, k2, d2, r, t, _, _ = cv2.stereoCalibrate(
        objects, lefts, rights, k1, d1, k2, d2, size
    )
    print(f"{len(objects)} pairs, stereo RMS {rms:.3f} px, image {size[0]}x{size[1]}")
    return size, k1, d1, k2, d2, r, t


def write_storage(path, size, k1, d1, k2, d2, r, t):
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
    for name, value in (("M1", k1), ("D1", d1), ("M2", k2), ("D2", d2), ("R", r), ("T", t)):
        fs.write(name, value)
    fs.write("image_width", size[0])
    fs.write("image_height", size[1])
    fs.release()


def reference_points(size, k1, d1, k2, d2, r, t):
    """A grid of directions at several depths, kept where both images see it."""
    w, h = size
    rows = []
    for depth in (1500.0, 4000.0, 12000.0):
        for u in np.linspace(-0.75, 0.75, 9):
            for v in np.linspace(-0.55, 0.55, 7):
                rows.append((u * depth, v * depth, depth))
    pts = np.array(rows)
    left = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), k1, d1)[0].reshape(-1, 2)
    rvec, _ = cv2.Rodrigues(r)
    right = cv2.projectPoints(pts, rvec, t, k2, d2)[0].reshape(-1, 2)
    inside = lambda p: (p[:, 0] >= 0) & (p[:, 0] <= w - 1) & (p[:, 1] >= 0) & (p[:, 1] <= h - 1)
    keep = inside(left) & inside(right)
    return pts[keep], left[keep], right[keep]


def main():
    src, out = sys.argv[1], sys.argv[2]
    os.makedirs(out, exist_ok=True)
    cal = calibrate(src)
    write_storage(os.path.join(out, "opencv_stereo.yml"), *cal)
    write_storage(os.path.join(out, "opencv_stereo.xml"), *cal)
    pts, left, right = reference_points(*cal)
    with open(os.path.join(out, "opencv_projections.csv"), "w") as f:
        f.write("x_mm,y_mm,z_mm,left_col,left_row,right_col,right_row\n")
        for p, l, q in zip(pts, left, right):
            f.write(",".join(f"{v:.17g}" for v in (*p, *l, *q)) + "\n")
    print(f"{len(pts)} reference points written to {out}")


if __name__ == "__main__":
    main()
