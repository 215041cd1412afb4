#!/usr/bin/env python3
"""Peer of the matching-cost benchmark: OpenCV's brute-force matcher (k=2 for the ratio
test, L2, one thread) on the same three descriptor pairs of one epoch (stereo at k,
temporal left and right), as written by `MATCH_BENCH_DUMP=DIR cargo bench -p
phototraverse-core --bench match_epoch`.
usage: peer_bfmatcher.py DIR
"""
import sys
import time
import numpy as np
import cv2

cv2.setNumThreads(1)
d = sys.argv[1]
load = lambda n: np.fromfile(f"{d}/{n}.u8", dtype=np.uint8).reshape(-1, 128).astype(np.float32)
L0, R0, L1, R1 = (load(n) for n in ("left0", "right0", "left1", "right1"))
bf = cv2.BFMatcher(cv2.NORM_L2)
times = []
for _ in range(20):
    t0 = time.thread_time()
    for a, b in ((L1, R1), (L0, L1), (R0, R1)):
        pairs = bf.knnMatch(a, b, k=2)
        good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < 0.8 * p[1].distance]
    times.append((time.thread_time() - t0) * 1e3)
times.sort()
print(f"OpenCV BFMatcher knn(2)+ratio, 3 pairs of {len(L1)}x{len(R1)}, 1 thread, CPU time: median {times[len(times)//2]:.3f} ms per epoch")
