#!/usr/bin/env python3
"""The right image's rows against the left ones, over every stereo observation of a run.

    python3 bench/traverse/stereo_rows.py RUN_DIR [RUN_DIR ...]

Reads a `phototraverse run` output's `colmap/images.txt` (`precision.py`'s reader; images
in pairs: left, then the right image of the same epoch) and, for every point observed in both images of an epoch,
takes the right row less the left one. On a rectified rig the truth is zero, so their mean
is the stereo's vertical bias and their RMS its vertical noise. A rectified rig's stereo
search puts the right point on the left one's row, so only a build that settles the match
on both axes shows anything but zeros. Prints the count, mean, median and RMS, and the
mean and RMS per quarter of the image's rows (top first).
"""
import argparse

import numpy as np

from precision import read_model  # the runs' COLMAP images, by image id


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("runs", nargs="+", help="`phototraverse run` output directories")
    for run in p.parse_args().runs:
        images = read_model(run)
        rows, dy = [], []
        for k in range(len(images) // 2):
            left, right = images.get(2 * k + 1, {}), images.get(2 * k + 2, {})
            for point, (_, row) in left.items():
                if point in right:
                    rows.append(row)
                    dy.append(right[point][1] - row)
        rows, dy = np.array(rows), np.array(dy)
        if not len(dy):
            print(f"{run}: no point observed in both images of an epoch")
            continue
        print(f"{run}: {len(dy)} observations, right row less left: mean {dy.mean():+.4f} px, "
              f"median {np.median(dy):+.4f}, RMS {np.sqrt(np.mean(dy ** 2)):.4f}")
        edges = np.linspace(0, rows.max() + 1e-9, 5)
        for q in range(4):
            sel = (rows >= edges[q]) & (rows < edges[q + 1])
            if sel.any():
                print(f"  rows {edges[q]:5.0f} to {edges[q + 1]:5.0f}: {sel.sum():6d}, mean {dy[sel].mean():+.4f}, "
                      f"RMS {np.sqrt(np.mean(dy[sel] ** 2)):.4f}")


if __name__ == "__main__":
    main()
