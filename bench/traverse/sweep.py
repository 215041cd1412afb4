#!/usr/bin/env python3
"""A choice measured on many scenes at once: two builds of phototraverse (or one build under
two environments) on the datasets and peer runs that `run.py` left in its cache, paired
scene by scene.

    python3 bench/traverse/sweep.py CACHE --scenes all,all@320 --seeds 93,94,95 \\
        --bin NEW [--baseline-bin OLD] [--env K=V ...] [--baseline-env K=V ...] [--out DIR]

Why: one scene's drift moves by a quarter or more when anything upstream moves a match, so
a choice measured on one or two scenes is measured on noise. Paired over some eighty scene
runs, a geometric mean of the new build's drift over the old one's has a standard error of
about 3 %. The peer is not run again: its drift is read from `CACHE/runs/*/peer_eval.json`
(run `run.py` on the same scenes and seeds first), so a sweep costs only our two runs per
scene (about 3 s each for 100 epochs). Time is not measured here (`instructions.py`).

Prints, per scene, both builds' drift and rotation drift over the peer's (the issue's bars:
at 640x480 at most 0.5 in translation and 1 in rotation, at 320x240 at most 1) and the mean
scale error per step (`steps.py`); per scene kind and over all, the geometric means of the
new build's drift over the baseline's, over all with their standard errors; and the scenes
past a bar with either build.
`--env` sets environment variables of the new build's runs (for scratch switches of an
experiment), `--baseline-env` those of the baseline's; without `--baseline-bin` the
baseline is `--bin` itself.
"""
import argparse
import json
import math
import os
import sys
from collections import defaultdict

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import run as bench  # noqa: E402  (the scene table, the cache's layout, `run`'s options)
import steps  # noqa: E402


def parse_env(pairs, flag):
    env = {}
    for p in pairs:
        key, sep, value = p.partition("=")
        if not sep or not key:
            raise SystemExit(f"{flag} {p}: expected KEY=VALUE")
        env[key] = value
    return env


def run_ours(binary, env, scene, ds, out):
    """One run of a build on a cached dataset, as `run.py` runs ours; its drift and the
    mean scale error per step."""
    os.makedirs(os.path.dirname(out), exist_ok=True)
    bench.run_timed([binary, "run", ds, "--out", out, "--link", "inproc", "--quiet",
                     *bench.ours_args(scene)], out + ".log", env)
    poses = os.path.join(out, "poses.txt")
    ev = bench.evaluate(binary, ds, poses, out + "_eval.json", out + "_eval.log")
    scale = steps.summary(os.path.join(ds, "gt_poses.txt"), poses)["scale_pct"]["mean"]
    return ev["translation_drift_pct"], ev["rotation_drift_deg_per_m"], scale


def bars(scene):
    """The issue's bars on the ratios to the peer: (translation, rotation)."""
    return (1.0, 1.0) if bench.small(scene) else (0.5, 1.0)


def geomean(xs):
    return math.exp(sum(math.log(x) for x in xs) / len(xs)) if xs else float("nan")


def geomean_se(xs):
    """The geometric mean's standard error, from the spread of the logs (delta method):
    what a paired difference must exceed to be read as one."""
    if len(xs) < 2:
        return float("nan")
    g = geomean(xs)
    sd = math.sqrt(sum(math.log(x / g) ** 2 for x in xs) / (len(xs) - 1))
    return g * sd / math.sqrt(len(xs))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("cache", help="a run.py cache holding the scenes and their peer runs")
    ap.add_argument("--scenes", default="all", help="as run.py's (all, all@320, names)")
    ap.add_argument("--seeds", metavar="N,N,...", help="as run.py's (default: synth's own)")
    ap.add_argument("--frames", type=int, help="as run.py's (default: the scene's own)")
    ap.add_argument("--bin", required=True, help="the new build")
    ap.add_argument("--baseline-bin", help="the build to compare with (default: --bin)")
    ap.add_argument("--env", nargs="*", default=[], metavar="K=V",
                    help="environment of the new build's runs")
    ap.add_argument("--baseline-env", nargs="*", default=[], metavar="K=V",
                    help="environment of the baseline's runs")
    ap.add_argument("--out", default="/tmp/sweep", help="where the runs go (overwritten)")
    args = ap.parse_args()
    env, base_env = parse_env(args.env, "--env"), parse_env(args.baseline_env, "--baseline-env")
    baseline = args.baseline_bin or args.bin
    for b in (args.bin, baseline):
        if not os.access(b, os.X_OK):
            ap.error(f"{b}: not an executable")
    scenes = bench.scenes_arg(ap, args.scenes)
    seeds = bench.seeds_arg(ap, args.seeds)

    rows, skipped = [], []
    for scene in scenes:
        for seed in seeds:
            frames = bench.frames_of(scene, args.frames)
            suffix = f"{frames}{bench.seed_suffix(seed)}"
            ds = os.path.join(args.cache, f"{bench.dataset_of(scene)}-{suffix}")
            peer_json = os.path.join(args.cache, "runs", f"{scene}-{suffix}", "peer_eval.json")
            name = bench.label(scene, seed)
            if not (os.path.exists(os.path.join(ds, "synth.json")) and os.path.exists(peer_json)):
                skipped.append(name)
                continue
            with open(peer_json) as f:
                peer = json.load(f)
            pt, pr = peer["translation_drift_pct"], peer["rotation_drift_deg_per_m"]
            run_dir = os.path.join(args.out, f"{scene}-{suffix}")
            old = run_ours(baseline, base_env, scene, ds, os.path.join(run_dir, "baseline"))
            new = run_ours(args.bin, env, scene, ds, os.path.join(run_dir, "new"))
            rows.append((scene, name, (old[0] / pt, old[1] / pr, old[2]),
                         (new[0] / pt, new[1] / pr, new[2]), (new[0] / old[0], new[1] / old[1])))
            print(f"{name:28s} drift/peer {old[0] / pt:.3f} -> {new[0] / pt:.3f}  "
                  f"deg/m/peer {old[1] / pr:.3f} -> {new[1] / pr:.3f}  "
                  f"scale/step {old[2]:+.3f} -> {new[2]:+.3f} %", flush=True)
    if skipped:
        print(f"\nnot in the cache with a peer run (run.py first): {', '.join(skipped)}")
    if not rows:
        return 1
    kinds = defaultdict(list)
    for r in rows:
        kinds[r[0]].append(r)
    print("\nnew over baseline, geometric means (drift, rotation drift); mean scale per step:")
    for kind, rs in kinds.items():
        print(f"  {kind:24s} {geomean([r[4][0] for r in rs]):.3f} "
              f"{geomean([r[4][1] for r in rs]):.3f}   scale {sum(r[2][2] for r in rs) / len(rs):+.3f}"
              f" -> {sum(r[3][2] for r in rs) / len(rs):+.3f} %  ({len(rs)} runs)")
    drift, rot = [r[4][0] for r in rows], [r[4][1] for r in rows]
    print(f"  {'all':24s} {geomean(drift):.3f} {geomean(rot):.3f}   ({len(rows)} runs; "
          f"standard errors {geomean_se(drift):.3f}, {geomean_se(rot):.3f})")
    for which, k in (("baseline", 2), ("new", 3)):
        past = [f"{r[1]} ({r[k][0]:.2f} / {r[k][1]:.2f})" for r in rows
                if r[k][0] > bars(r[0])[0] or r[k][1] > bars(r[0])[1]]
        print(f"past a bar, {which}: {len(past)} of {len(rows)}" + (": " + ", ".join(past) if past else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
