#!/usr/bin/env python3
"""Reads the COLMAP model a run wrote (RUN_DIR/colmap) with pycolmap, and compares its
reprojection errors with the run's own figures: the model's RMS as the run computed it
(report.json `colmap_rms_reprojection_px`) and the image residuals of the run's last
adjustments (report.json `residuals_px`).

usage: check.py RUN_DIR        (pip install pycolmap numpy)
"""
import json
import sys

import numpy as np
import pycolmap


def main():
    run = sys.argv[1]
    rec = pycolmap.Reconstruction(f"{run}/colmap")
    errors = []
    for point_id, point in rec.points3D.items():
        for el in point.track.elements:
            image = rec.images[el.image_id]
            camera = rec.cameras[image.camera_id]
            xy = image.points2D[el.point2D_idx].xy
            cam_point = image.cam_from_world() * point.xyz
            uv = camera.img_from_cam(cam_point)
            errors.append(np.linalg.norm(np.asarray(uv).ravel()[:2] - xy))
    errors = np.array(errors)
    report = json.load(open(f"{run}/report.json"))
    residuals = np.array(report.get("residuals_px", []), dtype=float)
    print(f"pycolmap {pycolmap.__version__}: {len(rec.cameras)} cameras, {len(rec.images)} images, "
          f"{len(rec.points3D)} points, {len(errors)} observations")
    print(f"reprojection error (pycolmap): RMS {np.sqrt(np.mean(errors ** 2)):.4f} px, "
          f"median {np.median(errors):.4f} px")
    print(f"the run's figure for the model: RMS {report.get('colmap_rms_reprojection_px', float('nan')):.4f} px")
    if residuals.size:
        print(f"the run's adjustment residuals: RMS {np.sqrt(np.mean(residuals ** 2)):.4f} px, "
              f"median {np.median(residuals):.4f} px ({residuals.size} residuals)")


if __name__ == "__main__":
    main()
