#!/usr/bin/env python3
"""Instructions per epoch of two phototraverse builds on the same scenes (callgrind).

The time bar of the traverse ("within 1.2x of an earlier version") compares CPU times
measured by `run.py` in one run; on a shared machine a single run's CPU time moves by 10
to 25 %. Instruction counts do not: `valgrind --tool=callgrind` counts every instruction
the whole process executes (decoding, link and both threads included), the same on every
run. This script runs both builds on the first FRAMES epochs of each scene of a `run.py`
cache and prints the two counts and their ratio.

    python3 bench/traverse/instructions.py CACHE --bin NEW --baseline-bin OLD \\
        [--scenes straight,handheld] [--frames 100]

The scenes must be in CACHE already (`run.py` synthesises them; synth's default seed). The runs use `--link inproc` and the scene's own `run.py`
options (`curves-real-rig`: `--estimate-rig` on the `curves-real` dataset; `@320`: the
embedded profile). Needs valgrind (Debian package `valgrind`); about 40x slower than a
plain run.
"""
import argparse
import os
import shutil
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import run as bench  # noqa: E402  (the scene table and options of the benchmark)


def subset(src, frames, dst):
    """The first `frames` epochs of dataset `src` in `dst` (images linked, not copied)."""
    os.makedirs(dst)
    for name in os.listdir(src):
        path = os.path.join(src, name)
        if os.path.isdir(path):
            os.makedirs(os.path.join(dst, name))
            for f in sorted(os.listdir(path))[:frames]:
                os.symlink(os.path.join(path, f), os.path.join(dst, name, f))
        elif name in ("times.txt", "gt_poses.txt"):
            with open(path) as fi, open(os.path.join(dst, name), "w") as fo:
                fo.writelines(fi.readlines()[:frames])
        else:
            # gnss.txt and odometer.txt go whole: `run` matches them to the epochs'
            # times and ignores what lies beyond the sequence.
            shutil.copy(path, dst)


def instructions(binary, dataset, args, work):
    """Instructions of one `run` of `binary` on `dataset`."""
    out = os.path.join(work, "cg.out")
    cmd = ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", binary, "run",
           dataset, "--link", "inproc", "--out", os.path.join(work, "run")] + args
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    with open(out) as f:
        for line in f:
            if line.startswith("totals:"):
                return int(line.split()[1])
    raise RuntimeError(f"no totals in {out}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("cache", help="the run.py cache holding the scenes")
    ap.add_argument("--bin", required=True, help="the build measured")
    ap.add_argument("--baseline-bin", required=True, help="the build compared with")
    ap.add_argument("--scenes", default="all", help="as run.py's --scenes (default: all)")
    ap.add_argument("--frames", type=int, default=100,
                    help="epochs of each scene from its start (default: 100)")
    ap.add_argument("--cache-frames", type=int, default=None,
                    help="the length the scenes were synthesised with (default: run.py's)")
    a = ap.parse_args()
    if shutil.which("valgrind") is None:
        sys.exit("instructions.py: valgrind not found (Debian package `valgrind`)")
    scenes = bench.expand([s for s in a.scenes.split(",") if s])
    unknown = [s for s in scenes if bench.base(s) not in bench.SCENES]
    if unknown:
        ap.error(f"unknown scene(s) {', '.join(unknown)}")
    print("| scene | epochs | ours G instructions | baseline G instructions | ours / baseline |")
    print("| --- | --- | --- | --- | --- |")
    for scene in scenes:
        frames = a.cache_frames or bench.frames_of(scene, None)
        data = os.path.join(a.cache, f"{bench.dataset_of(scene)}-{frames}")
        if not os.path.isdir(data):
            print(f"{scene}: {data} missing (run run.py first)", file=sys.stderr)
            continue
        n = min(a.frames, frames)
        args = bench.ours_args(scene)
        with tempfile.TemporaryDirectory() as work:
            sub = os.path.join(work, "data")
            subset(data, n, sub)
            counts = []
            for binary in (a.bin, a.baseline_bin):
                run_dir = os.path.join(work, "w")
                os.makedirs(run_dir)
                counts.append(instructions(binary, sub, args, run_dir))
                shutil.rmtree(run_dir)
        ours, base = counts
        print(f"| {scene} | {n} | {ours / 1e9:.2f} | {base / 1e9:.2f} | {ours / base:.3f} |",
              flush=True)


if __name__ == "__main__":
    main()
