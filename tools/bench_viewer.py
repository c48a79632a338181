#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""The viewer's responsiveness, repeated: issue #15's "logged UI frame <= 50 ms during a TF change
and during a clip-plane drag", as ranges over several sessions.

Each session is one `voxlight view --log` process under Xvfb + Mesa llvmpipe running a script of
scripted drags, one motion per UI frame through the functions the mouse drags call (coarse
renders meanwhile, full when released):
  - a window/level drag (the TF change: every motion a new TF, the TF stages rerun);
  - an orbit drag;
  - a clip plane facing the view, dragged by its gizmo handle; then a coronal one, dragged too.
The viewer logs each drag's own UI frames ("view: clip-plane drag: N frames, ui frame work mean
A ms, max B ms, K over 50 ms"), the start-up measurement of the GLSL path (uploads, the shader
compile, the probe) and its coarse/full render times; this script prints, per scene and drag
kind, the range over sessions of the mean and the worst UI frame and the frames over 50 ms, with
the machine's load average beside them.

    xvfb-run is used when DISPLAY is unset.
    /usr/bin/python3 tools/bench_viewer.py [--runs 4] [--frames 120] [--renderer auto|cpu|gpu]
                                          [--scene datasets/scenes/demo-torso.json ...]
                                          [--logs DIR]
"""
import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = ["datasets/scenes/demo-torso.json", "datasets/scenes/abdomen-ct-soft-tissue.json"]
DRAG = re.compile(r"view: (.+?) drag: (\d+) frames, ui frame work mean ([\d.]+) ms, "
                  r"max ([\d.]+) ms, (\d+) over")
WARMUP = re.compile(r"view: measuring: GLSL warm-up .*? ([\d.]+) s(?:, after uploads of "
                    r"([\d.]+) s in (\d+) UI frame)?")
SLOW = re.compile(r"view: slow frame ([\d.]+) ms")
RENDER = re.compile(r"view: render (coarse|full) \d+x\d+ in ([\d.]+) s")
SUMMARY = re.compile(r"coarse renders (\d+) \(([\d.]+)-([\d.]+) s\); full renders (\d+) "
                     r"\(([\d.]+)-([\d.]+) s\)")


def steps(frames):
    return [
        {"drag": {"kind": "window", "by": [60, -40], "frames": frames}},
        {"drag": {"kind": "orbit", "by": [80, 10], "frames": frames}},
        {"clip_add": {"normal": "camera", "offset": -20}},
        {"clip_drag": {"index": 0, "by": [0, -60], "frames": frames}},
        {"clip_add": {"normal": [0, 1, 0], "offset": 0}},
        {"clip_drag": {"index": 1, "by": [-40, 40], "frames": frames}},
    ]


def load():
    return os.getloadavg()[0]


def session(binary, scene, script, renderer, tmp):
    cmd = [binary, "view", "-q", "--log", "--renderer", renderer, scene, "--script", script,
           "--screenshot", os.path.join(tmp, "shot.png")]
    if not os.environ.get("DISPLAY"):
        cmd = ["xvfb-run", "-a", "-s", "-screen 0 1400x900x24"] + cmd
    before = load()
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"bench_viewer: {' '.join(cmd)} failed ({p.returncode}):\n{p.stderr[-2000:]}")
    return p.stderr, (before + load()) / 2


def rng(values, fmt="{:.1f}"):
    if not values:
        return "-"
    lo, hi = min(values), max(values)
    return fmt.format(lo) if lo == hi else fmt.format(lo) + "–" + fmt.format(hi)


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--runs", type=int, default=4)
    ap.add_argument("--frames", type=int, default=120, help="UI frames per drag")
    ap.add_argument("--renderer", default="auto", choices=["auto", "cpu", "gpu"])
    ap.add_argument("--logs", help="keep each session's --log output in this directory")
    ap.add_argument("--scene", action="append", help="scene files (default: the torso and the "
                    "abdominal CT)")
    args = ap.parse_args()
    binary = os.path.join(args.build, "voxlight")
    if not os.path.exists(binary):
        sys.exit(f"bench_viewer: {binary} is missing: build first")
    if not os.environ.get("DISPLAY") and not shutil.which("xvfb-run"):
        sys.exit("bench_viewer: no DISPLAY and no xvfb-run (tools/setup.sh installs it)")
    scenes = args.scene or SCENES
    with tempfile.TemporaryDirectory() as tmp:
        script = os.path.join(tmp, "steps.json")
        with open(script, "w") as f:
            json.dump(steps(args.frames), f)
        for scene in scenes:
            drags, warm, loads, slow, coarse, full = {}, [], [], [], [], []
            medians = {"coarse": [], "full": []}
            for run in range(args.runs):
                err, ld = session(binary, scene, script, args.renderer, tmp)
                if args.logs:
                    os.makedirs(args.logs, exist_ok=True)
                    name = os.path.splitext(os.path.basename(scene))[0]
                    with open(os.path.join(args.logs, f"{name}-{run + 1}.log"), "w") as f:
                        f.write(err)
                loads.append(ld)
                for m in DRAG.finditer(err):
                    d = drags.setdefault(m.group(1), {"mean": [], "max": [], "over": [], "n": 0})
                    d["mean"].append(float(m.group(3)))
                    d["max"].append(float(m.group(4)))
                    d["over"].append(int(m.group(5)))
                    d["n"] += 1
                for m in WARMUP.finditer(err):
                    warm.append((float(m.group(1)), float(m.group(2) or 0), int(m.group(3) or 0)))
                slow += [float(v) for v in SLOW.findall(err)]
                for kind in medians:
                    times = sorted(float(t) for k, t in RENDER.findall(err) if k == kind)
                    if times:
                        medians[kind].append(times[len(times) // 2])
                for m in SUMMARY.finditer(err):
                    if int(m.group(1)):
                        coarse.append((float(m.group(2)), float(m.group(3))))
                    if int(m.group(4)):
                        full.append((float(m.group(5)), float(m.group(6))))
                print(f"  {scene}: session {run + 1}/{args.runs} done, load {ld:.1f}",
                      file=sys.stderr)
            print(f"\n## {scene} — {args.runs} sessions, renderer {args.renderer}, "
                  f"load average {rng(loads)}")
            print("| drag | drags | UI frame work, mean per drag (ms) | worst frame per drag (ms) "
                  "| drags with a frame over 50 ms |")
            print("|---|---|---|---|---|")
            for name, d in drags.items():
                over = sum(1 for v in d["over"] if v > 0)
                print(f"| {name} | {d['n']} | {rng(d['mean'])} | {rng(d['max'])} | {over} of "
                      f"{d['n']} (frames over: {sum(d['over'])}) |")
            if warm:
                print(f"GLSL warm-up (shader compile) {rng([w[0] for w in warm], '{:.3f}')} s; "
                      f"uploads before it {rng([w[1] for w in warm], '{:.3f}')} s in "
                      f"{rng([w[2] for w in warm], '{:.0f}')} UI frames")
            for kind, m in medians.items():
                if m:
                    print(f"{kind} renders (the worker's), median per session: "
                          f"{rng(m, '{:.3f}')} s")
            if coarse:
                print(f"coarse renders {rng([c[0] for c in coarse], '{:.3f}')} (fastest per "
                      f"session) to {rng([c[1] for c in coarse], '{:.3f}')} s (slowest)")
            if full:
                print(f"full renders {rng([c[0] for c in full], '{:.3f}')} (fastest per session) "
                      f"to {rng([c[1] for c in full], '{:.3f}')} s (slowest)")
            print(f"frames over 50 ms anywhere in the sessions (start-up included): {len(slow)}"
                  + (f", {rng(slow)} ms" if slow else ""))


if __name__ == "__main__":
    main()
