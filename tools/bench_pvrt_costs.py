#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""PVRT's costs on this machine (issue 16's benchmark): precompute seconds for the torso phantom at
128³ and 256³ with SH order 4 (16 basis lights) and DSF-162, the radiance update per light change
and the frame time at 512², beside sh-global on the same scene (the single-scattering method whose
precompute does the same job for shadows) — each the median and range over --runs fresh processes.

    tools/bench_pvrt_costs.py [--voxlight build/voxlight] [--runs 3] [--sizes 128,256]

Goals (issue 16): 128³ SH-16 precompute ≤ 60 s; light change ≤ 20 ms at 128³.
"""
import argparse
import json
import os
import statistics
import subprocess
import tempfile

PVRT_STAGES = ("pvrt_direct", "pvrt_transfer", "pvrt_cpca")
SH_STAGES = ("block_pyramid", "multires_grid", "local_visibility", "global_visibility")
CONFIGS = [("pvrt sh16", "pvrt", {"basis": "sh", "order": 4}),
           ("pvrt dsf162", "pvrt", {"basis": "dsf", "directions": 162}),
           ("sh-global", "sh-global", {})]


def run(voxlight, work, size, method, params, frames):
    doc = {"volume": {"phantom": "torso", "size": size}, "transfer_function": "ct-soft-tissue",
           "method": {"name": method, "params": params},
           "effects": ["global_shadows", "multiple_scattering"] if method == "pvrt"
           else ["global_shadows"],
           "lights": [{"type": "directional", "direction": [0.45, 0.55, -0.7], "intensity": 8}],
           "camera": {"view": "anterior"}, "image": {"width": 512, "height": 512}}
    scene = os.path.join(work, "scene.json")
    with open(scene, "w") as f:
        json.dump(doc, f)
    stats = os.path.join(work, "stats.json")
    subprocess.run([voxlight, "render", scene, "-q", "-o", os.path.join(work, "out.png"),
                    "--stats", stats, "--frames", str(frames)], check=True)
    with open(stats) as f:
        st = json.load(f)
    stages = {s["name"]: s for s in st["stages"]}
    names = PVRT_STAGES if method == "pvrt" else SH_STAGES
    pre = sum(stages[n]["seconds"] for n in names if n in stages and stages[n]["ran"])
    light = stages["pvrt_radiance"]["seconds"] if "pvrt_radiance" in stages else float("nan")
    return pre, light, stages["render"]["seconds"], {n: stages[n]["seconds"] for n in names
                                                      if n in stages and stages[n]["ran"]}


def fmt(xs, scale=1.0, digits=2):
    xs = [x * scale for x in xs]
    return "%.*f (%.*f–%.*f)" % (digits, statistics.median(xs), digits, min(xs), digits, max(xs))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--voxlight", default="build/voxlight")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--sizes", default="128,256")
    ap.add_argument("--frames", type=int, default=5, help="frames per run (render median)")
    args = ap.parse_args()
    voxlight = os.path.abspath(args.voxlight)
    print("| volume | method | precompute s | light change ms | frame 512² s | stages (last run) |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as work:
        for size in [int(s) for s in args.sizes.split(",")]:
            for label, method, params in CONFIGS:
                pres, lights, frames, last = [], [], [], {}
                for _ in range(args.runs):
                    pre, light, frame, last = run(voxlight, work, size, method, params,
                                                  args.frames)
                    pres.append(pre)
                    lights.append(light)
                    frames.append(frame)
                print("| torso %d³ | %s | %s | %s | %s | %s |" % (
                    size, label, fmt(pres), "—" if method != "pvrt" else fmt(lights, 1e3, 1),
                    fmt(frames, 1.0, 3), ", ".join("%s %.1f" % kv for kv in last.items())),
                    flush=True)


if __name__ == "__main__":
    main()
