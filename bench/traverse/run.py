#!/usr/bin/env python3
"""Traverse benchmark: phototraverse (`run --link inproc`, release binary) against a plain
OpenCV frame-to-frame stereo odometry (peer_vo.py) on the same synthetic sequences, in the same
run: drift (KITTI-style segments, `phototraverse eval`) and time per epoch (median over the
sequence, per stage), with the ratios.

usage: run.py CACHE [--scenes straight,curves,curves-real] [--frames 100] [--bin PATH]
              [--results bench/traverse/RESULTS.md] [--cpu-split]

Scenes: see SCENES below; `all` is every one of them. A scene name with `@320` (e.g.
`handheld@320`, `all@320`) renders the scene at 320x240 (`synth --size 320x240`, the same
field of view) and runs ours with configs/embedded-320x240.toml.

CACHE keeps the synthesized scenes (CACHE/<scene>-<frames>/, made once and reused) and the runs
(CACHE/runs/<scene>-<frames>/{ours,peer}/ with the evaluation JSONs). Scenes are processed one at
a time (the machine is shared); ours and the peer run one after the other on the same data.
The binary defaults to target/release/phototraverse of this repository
(`cargo build --release -p phototraverse-host`).
"""
import argparse
import datetime
import json
import os
import platform
import resource
import shutil
import subprocess
import sys
import time

import steps

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
# Real photographs for the facades of the photo-* scenes: the development data beside the
# repository (../shared/data: Leuven facades, an aerial view, a cluttered desk, Middlebury's
# motorcycle, OpenCV's aloe plant; one of each pair).
DATA = os.path.join(os.path.dirname(REPO), "shared", "data")
PHOTOS = ",".join(os.path.join(DATA, f) for f in (
    "pairs/leuvenA.jpg", "pairs/aero1.jpg", "pairs/box_in_scene.png",
    "stereo/motorcycle_left.png", "stereo/aloeL.jpg"))
# The small variant of a scene (`NAME@320`): its size and our configuration.
SMALL = "@320"
SMALL_SIZE = "320x240"
SMALL_CONFIG = os.path.join(REPO, "configs", "embedded-320x240.toml")

# name -> synth arguments (scene and options); frames are appended.
SCENES = {
    "straight": ["--scene", "straight"],
    "curves": ["--scene", "curves"],
    # Issue 7's calibration-residual case: --realistic = blur 0.6, vignetting 0.25, flicker
    # 0.05, noise 1.5, JPEG 90 and calib base=0.003,focal=0.003,pp_px=1,rel_deg=0.05.
    "curves-real": ["--scene", "curves", "--realistic"],
    "hard": ["--scene", "hard"],
    # The same data as curves-real with the rig's relative orientation and the right
    # camera's interior estimated (`run --estimate-rig`), as issue 7's bar asks.
    "curves-real-rig": ["--scene", "curves", "--realistic"],
    # Seed 000's rig (576x384, distortion, converging cameras, 0.40 m base) on a straight
    # street, level (rig.toml; the peer rectifies it first).
    "seed2014": ["--scene", "seed2014"],
    # Seed 000's hand-held rig (0.40 m base, distortion, converging cameras, 2 deg tilt)
    # walking: +-1 deg on every angle, +-3 cm of bob and sway, 1 m per epoch (rig.toml;
    # the peer rectifies it first).
    "handheld": ["--scene", "handheld"],
    # 1.2 km at 2 m per epoch: turns of 25, 20, 60 and 40 m radius, grades of 2.5..4 %,
    # narrow stretches (facades 4..5 m away) and open country (buildings 30..110 m away).
    "drive": ["--scene", "drive"],
    # Moving vehicles covering up to ~45 % of the image: a van overtaking and braking
    # ahead of us (closest 4 m), oncoming cars, a van and a bus, crossing ones.
    "traffic": ["--scene", "traffic"],
    # Facades textured with real photographs (1..3 cm per texel), where a SIFT odometry is
    # at its best.
    "photo-straight": ["--scene", "straight", "--photo-textures", PHOTOS],
    "photo-curves": ["--scene", "curves", "--photo-textures", PHOTOS],
}
# Epochs per scene without --frames (default 100).
FRAMES_OF = {"drive": 600}
# Scenes that reuse another scene's dataset, and extra `run` options of our side.
DATASET_OF = {"curves-real-rig": "curves-real"}
OURS_ARGS = {"curves-real-rig": ["--estimate-rig"]}


def base(scene):
    """The scene without its `@320`."""
    return scene[:-len(SMALL)] if scene.endswith(SMALL) else scene


def small(scene):
    return scene.endswith(SMALL)


def synth_args(scene):
    return SCENES[base(scene)] + (["--size", SMALL_SIZE] if small(scene) else [])


def ours_args(scene):
    return OURS_ARGS.get(base(scene), []) + (["--config", SMALL_CONFIG] if small(scene) else [])


# synth's own seed: datasets of other seeds are cached as `<scene>-<frames>-s<seed>`.
DEFAULT_SEED = 1


def seed_suffix(seed):
    return "" if seed in (None, DEFAULT_SEED) else f"-s{seed}"


def label(scene, seed):
    """A scene's name in the tables, with its seed when not synth's default."""
    return scene + (f" s{seed}" if seed_suffix(seed) else "")


def dataset_of(scene):
    return DATASET_OF.get(base(scene), base(scene)) + (SMALL if small(scene) else "")


def frames_of(scene, frames):
    """--frames if given, else the scene's own length."""
    return frames if frames is not None else FRAMES_OF.get(base(scene), 100)


def expand(names):
    """`all` and `all@320` to every scene (at 320x240)."""
    out = []
    for name in names:
        if base(name) == "all":
            out += [s + (SMALL if small(name) else "") for s in SCENES]
        else:
            out.append(name)
    return out


# Stage order of the table; stages missing on one side are shown as "-".
OUR_STAGES = ["sift_left", "sift_right", "stereo_match", "assemble", "initial_values", "adjust"]
PEER_STAGES = ["sift_left", "sift_right", "stereo_match", "triangulate", "temporal_match", "pnp"]


def median(values):
    v = sorted(x for x in values if x is not None)
    if not v:
        return float("nan")
    n = len(v)
    return v[n // 2] if n % 2 else 0.5 * (v[n // 2 - 1] + v[n // 2])


def uptime():
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    except OSError:
        with open("/proc/loadavg") as f:
            return "load average " + " ".join(f.read().split()[:3])


def cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def run_timed(cmd, log, env=None):
    """Run cmd (with `env` added to the environment); returns (wall s, children's CPU s).
    Fails loudly with the log's tail."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    with open(log, "w") as f:
        rc = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT,
                            env={**os.environ, **(env or {})}).returncode
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if rc != 0:
        with open(log) as f:
            tail = f.read()[-2000:]
        raise RuntimeError(f"{' '.join(cmd)} failed ({rc}):\n{tail}")
    return wall, cpu


def synthesize(binary, cache, scene, frames, seed=None):
    """The scene's dataset, synthesized once: a finished dataset has synth.json."""
    ds = os.path.join(cache, f"{scene}-{frames}{seed_suffix(seed)}")
    if os.path.exists(os.path.join(ds, "synth.json")):
        return ds, None
    tmp = ds + ".partial"
    shutil.rmtree(tmp, ignore_errors=True)
    os.makedirs(cache, exist_ok=True)
    seeded = ["--seed", str(seed)] if seed is not None else []
    cmd = [binary, "synth", *synth_args(scene), *seeded, "--frames", str(frames), "--out", tmp]
    print(f"[{label(scene, seed)}] synthesizing {frames} frames ...", flush=True)
    wall, _ = run_timed(cmd, tmp + ".log")
    shutil.rmtree(ds, ignore_errors=True)
    os.rename(tmp, ds)
    os.replace(tmp + ".log", os.path.join(ds, "synth.log"))
    return ds, wall


def evaluate(binary, ds, poses, out_json, log):
    run_timed([binary, "eval", os.path.join(ds, "gt_poses.txt"), poses, "--json", out_json], log)
    with open(out_json) as f:
        return json.load(f)


def cpu_split(binary, ds, runs, frames, traverse_cpu, config=()):
    """Our CPU per epoch split by running the same dataset with lighter firmware processors:
    `stats` (decoding, link, framing: the host's share), `sift` (+ SIFT on both images); the
    traverse's remainder is matching, initial values and adjustment. CPU time does not depend
    on the machine's load, unlike the wall times of report.json."""
    cpu = {}
    for proc in ("stats", "sift"):
        out = os.path.join(runs, f"ours_{proc}")
        shutil.rmtree(out, ignore_errors=True)
        _, c = run_timed([binary, "run", ds, "--out", out, "--link", "inproc", "--quiet",
                          "--fw-processor", proc, *config],
                         os.path.join(runs, f"ours_{proc}.log"))
        cpu[proc] = c * 1e3 / frames
    return {"host_decode_link": cpu["stats"], "sift_both": cpu["sift"] - cpu["stats"],
            "match_adjust_rest": traverse_cpu - cpu["sift"]}


def common_fields(ev, epochs, cpu_s, wall_s):
    """The figures both sides report alike: drift from `phototraverse eval`, process time,
    flagged (ours) or lost (peer) epochs, keypoints and stereo matches per epoch."""
    return {
        "translation_pct": ev["translation_drift_pct"],
        "rotation_deg_per_m": ev["rotation_drift_deg_per_m"],
        "ate_m": ev["ate_rmse_m"],
        "final_pct": ev["final_position_error_pct"],
        "process_cpu_ms_per_epoch": cpu_s * 1e3 / len(epochs),
        "process_wall_s": wall_s,
        "flagged": sum(e["status"] != "ok" for e in epochs),
        "keypoints": median(sum(e["keypoints"]) / 2 for e in epochs),
        "stereo_matches": median(e["stereo_matches"] for e in epochs),
    }


def run_baseline(baseline, ds, runs, scene, frames, name):
    """Another build of phototraverse (an earlier commit) on the same dataset with the same
    options, right after ours: its CPU per epoch and drift, for the time bar "within 1.2x
    of an earlier version" measured in one run whatever the machine's speed."""
    out = os.path.join(runs, "baseline")
    shutil.rmtree(out, ignore_errors=True)
    print(f"[{name}] baseline: {baseline} run ...", flush=True)
    wall, cpu = run_timed([baseline, "run", ds, "--out", out, "--link", "inproc", "--quiet",
                           *ours_args(scene)], os.path.join(runs, "baseline.log"))
    ev = evaluate(baseline, ds, os.path.join(out, "poses.txt"),
                  os.path.join(runs, "baseline_eval.json"), os.path.join(runs, "baseline_eval.log"))
    return {"process_cpu_ms_per_epoch": cpu * 1e3 / frames, "process_wall_s": wall,
            "translation_pct": ev["translation_drift_pct"],
            "rotation_deg_per_m": ev["rotation_drift_deg_per_m"]}


def run_scene(binary, cache, scene, frames, split=False, baseline=None, seed=None):
    ds, synth_wall = synthesize(binary, cache, dataset_of(scene), frames, seed)
    name = label(scene, seed)
    runs = os.path.join(cache, "runs", f"{scene}-{frames}{seed_suffix(seed)}")
    ours_dir, peer_dir = os.path.join(runs, "ours"), os.path.join(runs, "peer")
    for d in (ours_dir, peer_dir):
        shutil.rmtree(d, ignore_errors=True)
    os.makedirs(runs, exist_ok=True)

    print(f"[{name}] ours: phototraverse run --link inproc {' '.join(ours_args(scene))}...",
          flush=True)
    ours_wall, ours_cpu = run_timed(
        [binary, "run", ds, "--out", ours_dir, "--link", "inproc", "--quiet",
         *ours_args(scene)],
        os.path.join(runs, "ours.log"))
    print(f"[{name}] peer: peer_vo.py ...", flush=True)
    peer_wall, peer_cpu = run_timed(
        [sys.executable, os.path.join(HERE, "peer_vo.py"), ds, "--out", peer_dir],
        os.path.join(runs, "peer.log"))

    ours_eval = evaluate(binary, ds, os.path.join(ours_dir, "poses.txt"),
                         os.path.join(runs, "ours_eval.json"), os.path.join(runs, "ours_eval.log"))
    peer_eval = evaluate(binary, ds, os.path.join(peer_dir, "poses.txt"),
                         os.path.join(runs, "peer_eval.json"), os.path.join(runs, "peer_eval.log"))
    gt = os.path.join(ds, "gt_poses.txt")
    unbiased = os.path.join(peer_dir, "poses_unbiased.txt")
    steps.write_poses(unbiased, steps.unbiased(steps.read_poses(gt),
                                               steps.read_poses(os.path.join(peer_dir, "poses.txt"))))
    peer_unbiased = evaluate(binary, ds, unbiased, os.path.join(runs, "peer_unbiased_eval.json"),
                             os.path.join(runs, "peer_unbiased_eval.log"))
    ours_steps = steps.summary(gt, os.path.join(ours_dir, "poses.txt"))
    peer_steps = steps.summary(gt, os.path.join(peer_dir, "poses.txt"))
    with open(os.path.join(ours_dir, "report.json")) as f:
        report = json.load(f)
    with open(os.path.join(peer_dir, "peer.json")) as f:
        peer = json.load(f)

    oe, pe = report["epochs"], peer["epochs"]
    # Timing medians skip epoch 0 (bootstrap: no temporal matching or adjustment on either side).
    o_t, p_t = oe[1:] or oe, pe[1:] or pe
    result = {
        "scene": label(scene, seed),
        "base_scene": scene,
        "seed": seed if seed is not None else DEFAULT_SEED,
        "frames": len(oe),
        "synth": synth_args(scene) + (["--seed", str(seed)] if seed_suffix(seed) else []),
        "dataset": ds,
        "path_length_m": ours_eval.get("path_length_m"),
        "ours": {
            **common_fields(ours_eval, oe, ours_cpu, ours_wall),
            "ms": median(e["stage_ms"].get("total") for e in o_t),
            "stage_ms": {s: median(e["stage_ms"].get(s) for e in o_t) for s in OUR_STAGES},
            "tie_points": median(e["tie_points"] for e in oe[1:]),
            "observations": median(e["observations"] for e in oe[1:]),
            "steps": ours_steps,
        },
        "peer": {
            **common_fields(peer_eval, pe, peer_cpu, peer_wall),
            "ms": median(e["stage_ms"]["total"] for e in p_t),
            "cpu_ms": median(e["stage_cpu_ms"]["total"] for e in p_t),
            "stage_ms": {s: median(e["stage_ms"].get(s) for e in p_t) for s in PEER_STAGES},
            "stage_cpu_ms": {s: median(e["stage_cpu_ms"].get(s) for e in p_t) for s in PEER_STAGES},
            "temporal_matches": median(e.get("temporal_matches") for e in pe[1:]),
            "pnp_inliers": median(e.get("pnp_inliers") for e in pe[1:]),
            "pnp_inlier_quads": median(e.get("pnp_inlier_quads") for e in pe[1:]),
            "steps": peer_steps,
            "unbiased": {"translation_pct": peer_unbiased["translation_drift_pct"],
                         "rotation_deg_per_m": peer_unbiased["rotation_drift_deg_per_m"]},
        },
        "synth_wall_s": synth_wall,
    }
    if baseline:
        try:
            result["baseline"] = run_baseline(baseline, ds, runs, scene, len(oe), name)
        except RuntimeError as e:
            # An older build may refuse a newer configuration (the embedded profile).
            why = [line for line in str(e).splitlines() if line.strip()]
            print(f"[{name}] baseline left out: {why[-1] if why else e}", flush=True)
    if split:
        print(f"[{name}] ours: CPU split (--fw-processor stats, sift) ...", flush=True)
        result["ours"]["cpu_split_ms"] = cpu_split(
            binary, ds, runs, len(oe), result["ours"]["process_cpu_ms_per_epoch"],
            ["--config", SMALL_CONFIG] if small(scene) else [])
    with open(os.path.join(runs, "result.json"), "w") as f:
        json.dump(result, f, indent=1)
    return result


def ratio(a, b):
    return a / b if b else float("inf")


def fmt_stages(stages):
    return ", ".join(f"{k} {v:.1f}" for k, v in stages.items())


def table(results):
    """Markdown table: drift, time, ratios ours/peer (below 1: ours is better/faster)."""
    lines = [
        "| scene | frames | ours drift % | ours deg/m | ours ms/epoch wall (CPU) | peer drift % "
        "| peer deg/m | peer ms/epoch wall (CPU) | drift ours/peer | deg/m ours/peer "
        "| wall ours/peer | CPU ours/peer |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in results:
        o, p = r["ours"], r["peer"]
        oc, pc = o["process_cpu_ms_per_epoch"], p["process_cpu_ms_per_epoch"]
        lines.append(
            f"| {r['scene']} | {r['frames']} | {o['translation_pct']:.3f} | "
            f"{o['rotation_deg_per_m']:.4f} | {o['ms']:.1f} ({oc:.1f}) | "
            f"{p['translation_pct']:.3f} | {p['rotation_deg_per_m']:.4f} | "
            f"{p['ms']:.1f} ({pc:.1f}) | "
            f"{ratio(o['translation_pct'], p['translation_pct']):.2f} | "
            f"{ratio(o['rotation_deg_per_m'], p['rotation_deg_per_m']):.2f} | "
            f"{ratio(o['ms'], p['ms']):.2f} | {ratio(oc, pc):.2f} |")
    if any("unbiased" in r["peer"] for r in results):
        lines += ["", unbiased_table(results)]
    if any("baseline" in r for r in results):
        lines += ["", baseline_table(results)]
    if len({r["seed"] for r in results}) > 1:
        lines += ["", seeds_table(results)]
    return "\n".join(lines)


# The accuracy issue's drift bars, ours / peer: (translation, rotation) at 640x480 and at
# 320x240 with the embedded profile.
BARS = {False: (0.5, 1.0), True: (1.0, 1.0)}


def seeds_table(results):
    """Per scene over its seeds (`--seeds`): the drift ratios ours / peer, median and worst,
    and on how many seeds both drift bars hold. One sequence's drift is one draw: decisions
    at thresholds make it scatter by 20..30 % between numerically equivalent builds."""
    lines = [
        "| scene | seeds | drift ours/peer median (worst) | deg/m ours/peer median (worst) "
        "| bars met |",
        "| --- | --- | --- | --- | --- |",
    ]
    by_scene = {}
    for r in results:
        by_scene.setdefault(r["base_scene"], []).append(r)
    for scene, rs in by_scene.items():
        t = [ratio(r["ours"]["translation_pct"], r["peer"]["translation_pct"]) for r in rs]
        a = [ratio(r["ours"]["rotation_deg_per_m"], r["peer"]["rotation_deg_per_m"]) for r in rs]
        bt, ba = BARS[small(scene)]
        met = sum(x <= bt and y <= ba for x, y in zip(t, a))
        lines.append(f"| {scene} | {', '.join(str(r['seed']) for r in rs)} "
                     f"| {median(t):.2f} ({max(t):.2f}) | {median(a):.2f} ({max(a):.2f}) "
                     f"| {met} of {len(rs)} |")
    return "\n".join(lines)


def unbiased_table(results):
    """Ours against the peer without its bias (`steps.py --unbiased`: its mean error per
    step taken out of every step), the peer at its best: where its drift is mostly a bias
    of these renders, another street may not give it one."""
    lines = [
        "| scene | peer drift % | peer without its step bias: drift %, deg/m "
        "| drift ours/that | deg/m ours/that |",
        "| --- | --- | --- | --- | --- |",
    ]
    for r in results:
        o, p = r["ours"], r["peer"]
        if "unbiased" not in p:
            continue
        u = p["unbiased"]
        lines.append(
            f"| {r['scene']} | {p['translation_pct']:.3f} | {u['translation_pct']:.3f}, "
            f"{u['rotation_deg_per_m']:.4f} | {ratio(o['translation_pct'], u['translation_pct']):.2f} "
            f"| {ratio(o['rotation_deg_per_m'], u['rotation_deg_per_m']):.2f} |")
    return "\n".join(lines)


def baseline_table(results):
    """Our CPU per epoch against the baseline build's (`--baseline-bin`), both also
    against the peer's, and the baseline's drift."""
    lines = [
        "| scene | ours CPU ms/epoch | baseline CPU ms/epoch | CPU ours/baseline "
        "| CPU ours/peer | CPU baseline/peer | baseline drift % | baseline deg/m |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in results:
        if "baseline" not in r:
            continue
        b = r["baseline"]
        oc, bc = r["ours"]["process_cpu_ms_per_epoch"], b["process_cpu_ms_per_epoch"]
        pc = r["peer"]["process_cpu_ms_per_epoch"]
        lines.append(
            f"| {r['scene']} | {oc:.1f} | {bc:.1f} | {ratio(oc, bc):.2f} | {ratio(oc, pc):.2f} "
            f"| {ratio(bc, pc):.2f} | {b['translation_pct']:.3f} | {b['rotation_deg_per_m']:.4f} |")
    return "\n".join(lines)


def shown(args):
    """Arguments as a reader of RESULTS.md would type them: paths relative to the repository."""
    top = os.path.dirname(REPO) + os.sep
    return " ".join(",".join(os.path.relpath(p, REPO) if p.startswith(top) else p
                             for p in a.split(",")) for a in args)


def ours_options(scene):
    """`, ours with ...` when our side runs with extra options."""
    extra = ours_args(scene)
    return f"; ours with `run {shown(extra)}`" if extra else ""


def details(results):
    lines = []
    for r in results:
        o, p = r["ours"], r["peer"]
        lines += [
            f"- **{r['scene']}** (`phototraverse synth {shown(r['synth'])} --frames {r['frames']}`, "
            f"{r['path_length_m']:.1f} m{ours_options(r['base_scene'])}):",
            f"  - ours: median stage ms (wall, in the firmware): {fmt_stages(o['stage_ms'])}; "
            f"process CPU {o['process_cpu_ms_per_epoch']:.1f} ms/epoch incl. decoding and link; "
            f"ATE {o['ate_m']:.3f} m, final {o['final_pct']:.3f} %; flagged epochs {o['flagged']}; "
            f"median keypoints/image {o['keypoints']:.0f}, stereo matches {o['stereo_matches']:.0f}, "
            f"tie points {o['tie_points']:.0f}, observations {o['observations']:.0f}",
            f"  - peer: median stage ms wall: {fmt_stages(p['stage_ms'])}; thread CPU: "
            f"{fmt_stages(p['stage_cpu_ms'])}, total {p['cpu_ms']:.1f} (excl. decoding); "
            f"process CPU {p['process_cpu_ms_per_epoch']:.1f} ms/epoch incl. decoding; ATE {p['ate_m']:.3f} m, final {p['final_pct']:.3f} %; "
            f"lost epochs {p['flagged']}; median keypoints/image {p['keypoints']:.0f}, "
            f"stereo matches {p['stereo_matches']:.0f}, temporal matches "
            f"{p['temporal_matches']:.0f}, PnP inliers {p['pnp_inliers']:.0f} "
            f"(of which quads, i.e. with a stereo match at the current epoch too: "
            f"{p['pnp_inlier_quads']:.0f})",
            *([f"  - ours, CPU ms per epoch split (runs with --fw-processor stats and sift): "
               f"{fmt_stages(o['cpu_split_ms'])}"] if "cpu_split_ms" in o else []),
            f"  - step errors (steps.py; mean = bias, +- = spread): "
            f"{steps.describe('ours', o['steps'])}; {steps.describe('peer', p['steps'])}",
        ]
    return "\n".join(lines)


def git_commit():
    try:
        return subprocess.run(["git", "-C", REPO, "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True).stdout.strip()
    except OSError:
        return "unknown"


def write_results(path, results, before, after, binary, argv):
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    text = f"""# Traverse benchmark: phototraverse against an OpenCV stereo odometry

Written by `python3 bench/traverse/run.py {' '.join(argv)}` on {now}, commit {git_commit()},
binary `{binary}`.
Machine: {cpu_model()}, {os.cpu_count()} cores (shared).
Load before: `{before}`
Load after: `{after}`

Drift: KITTI-style segments (`phototraverse eval`). Time "wall": median over epochs 1.. of the
wall time per epoch excluding image decoding (ours: `stage_ms.total` of report.json, measured in
the firmware; peer: `time.perf_counter` around its stages). Wall times grow with the machine's
load (2 cores shared by several jobs), so the table also gives "CPU": the CPU time of the whole
process (getrusage of the child: decoding, link and start-up included, on both sides alike)
divided by the number of epochs, which load barely changes. Both sides run one after the other
in the same invocation on the same data, one thread each (ours: the in-process firmware; peer:
cv2.setNumThreads(1)). Ratios are ours / peer: below 1, ours is better or faster. The second
table compares with the peer without its bias (its mean error per step taken out of every
step, `steps.py --unbiased`): the peer at its best, as a street that does not bias it would
show it.

{table(results)}

{details(results)}
"""
    with open(path, "w") as f:
        f.write(text)


def scenes_arg(ap, text):
    """The scenes of a `--scenes` list (`all`, `all@320` expanded); an error names unknown ones."""
    scenes = expand([s for s in text.split(",") if s])
    unknown = [s for s in scenes if base(s) not in SCENES]
    if unknown:
        ap.error(f"unknown scene(s) {', '.join(unknown)}; known: {', '.join(SCENES)}")
    return scenes


def seeds_arg(ap, text):
    """The seeds of a `--seeds` list; `[None]` (synth's own) without one."""
    try:
        return [int(x) for x in text.split(",") if x] if text else [None]
    except ValueError:
        ap.error(f"--seeds {text}: expected whole numbers separated by commas")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("cache", help="directory of synthesized scenes and runs (reused)")
    ap.add_argument("--scenes", default="straight,curves,curves-real",
                    help=f"comma-separated, from {', '.join(SCENES)}; all = every one; "
                         f"NAME{SMALL} at 320x240 with configs/embedded-320x240.toml")
    ap.add_argument("--frames", type=int,
                    help="epochs of every scene (default: 100; drive 600, its 1.2 km)")
    ap.add_argument("--cpu-split", action="store_true",
                    help="also split our CPU per epoch into host, SIFT and the rest (2 more runs)")
    ap.add_argument("--bin", default=os.path.join(REPO, "target", "release", "phototraverse"))
    ap.add_argument("--baseline-bin", metavar="PATH",
                    help="another phototraverse build (say, of an earlier commit) run on the "
                         "same scenes after ours: its CPU per epoch and drift beside ours")
    ap.add_argument("--seeds", metavar="N,N,...",
                    help="synthesize and run every scene with each of these seeds (synth's "
                         f"--seed; default: {DEFAULT_SEED} only) and add a table of the drift "
                         "ratios per scene over the seeds")
    ap.add_argument("--results", default=os.path.join(HERE, "RESULTS.md"),
                    help="markdown file written with the table ('-' to skip)")
    args = ap.parse_args()
    scenes = scenes_arg(ap, args.scenes)
    photos = [s for s in scenes if "--photo-textures" in SCENES[base(s)]]
    missing = [f for f in PHOTOS.split(",") if not os.path.exists(f)]
    if photos and missing:
        ap.error(f"{', '.join(photos)} need the photographs {', '.join(missing)}")
    if not os.access(args.bin, os.X_OK):
        ap.error(f"{args.bin}: no binary (cargo build --release -p phototraverse-host)")
    if args.baseline_bin and not os.access(args.baseline_bin, os.X_OK):
        ap.error(f"{args.baseline_bin}: not an executable")
    seeds = seeds_arg(ap, args.seeds)
    before = uptime()
    results = []
    for scene, seed in ((sc, sd) for sc in scenes for sd in seeds):
        frames = frames_of(scene, args.frames)
        r = run_scene(args.bin, args.cache, scene, frames, args.cpu_split, args.baseline_bin,
                      seed)
        results.append(r)
        o, p = r["ours"], r["peer"]
        print(f"[{r['scene']}] ours {o['translation_pct']:.3f} % {o['rotation_deg_per_m']:.4f} deg/m "
              f"{o['ms']:.1f} ms | peer {p['translation_pct']:.3f} % "
              f"{p['rotation_deg_per_m']:.4f} deg/m {p['ms']:.1f} ms", flush=True)
    after = uptime()
    print()
    print(table(results))
    print()
    print(details(results))
    print(f"\nload before: {before}\nload after:  {after}")
    if args.results != "-":
        write_results(args.results, results, before, after, args.bin, sys.argv[1:])
        print(f"written to {args.results}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
