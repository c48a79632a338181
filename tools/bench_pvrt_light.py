#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""PVRT's light change and frame at n = 1 and 16 exitance coefficients (issue #16).

The cloud of tools/bench_pvrt_phase.py (64³, 128², phase_g 0.6 for n = 16) and the torso of
tools/bench_pvrt_costs.py (128³, ct-soft-tissue, 512²), pvrt defaults otherwise. Per case one
process fills WORK/cache with the precompute, then --runs fresh processes read it and report the
`pvrt_radiance` stage (the light change; for n > 1 toward the eye also a camera move's) and the
median `render` of 5 frames. --evaluation sets exitance_evaluation for n > 1; the display and EXR
images are kept in WORK for comparisons (`voxlight compare`).

    tools/bench_pvrt_light.py [--voxlight build/voxlight] [--work /tmp/pvrt-light] [--runs 3]
                              [--evaluation grid|sample] [--cases cloud1,cloud16,torso1,torso16]
"""
import argparse
import json
import os
import subprocess

CLOUD_TF = {"points": [{"value": 0.0, "color": [0.95] * 3, "extinction": 0},
                       {"value": 0.05, "color": [0.95] * 3, "extinction": 0},
                       {"value": 1.0, "color": [0.95] * 3, "extinction": 0.25}],
            "window": {"level": 0.5, "width": 1.0}}
MULTIPLE = ["global_shadows", "multiple_scattering"]


def scene(which, n, cloud, evaluation):
    p = {"exitance_coefficients": n}
    if n > 1:
        p["phase_g"] = 0.6
        if evaluation:
            p["exitance_evaluation"] = evaluation
    if which == "cloud":
        return {"volume": cloud, "transfer_function": CLOUD_TF, "effects": MULTIPLE,
                "lights": [{"type": "directional", "direction": [-0.25, -1.0, -0.2], "intensity": 8}],
                "image": {"width": 128, "height": 128}, "camera": {"view": "anterior"},
                "method": {"name": "pvrt", "params": p}}
    return {"volume": {"phantom": "torso", "size": 128}, "transfer_function": "ct-soft-tissue",
            "effects": MULTIPLE, "method": {"name": "pvrt", "params": p},
            "lights": [{"type": "directional", "direction": [0.45, 0.55, -0.7], "intensity": 8}],
            "camera": {"view": "anterior"}, "image": {"width": 512, "height": 512}}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--voxlight", default="build/voxlight")
    ap.add_argument("--work", default="/tmp/pvrt-light")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--evaluation", default=None, choices=["grid", "sample"])
    ap.add_argument("--cases", default="cloud1,cloud16,torso1,torso16")
    args = ap.parse_args()
    vox = os.path.abspath(args.voxlight)
    os.makedirs(args.work, exist_ok=True)
    cloud = os.path.join(args.work, "cloud64.nii.gz")
    if not os.path.exists(cloud):
        subprocess.run([vox, "phantom", "cloud", "--size", "64", "-q", "-o", cloud], check=True)
    for case in args.cases.split(","):
        which, n = case.rstrip("0123456789"), int(case.lstrip("cloudtrso"))
        doc = os.path.join(args.work, case + ".json")
        with open(doc, "w") as f:
            json.dump(scene(which, n, cloud, args.evaluation), f)
        lights, frames = [], []
        for run in range(args.runs + 1):
            stats = os.path.join(args.work, "stats.json")
            subprocess.run([vox, "render", doc, "-q", "-o", os.path.join(args.work, case + ".png"),
                            "--exr", os.path.join(args.work, case + ".exr"), "--stats", stats,
                            "--frames", "5", "--cache", os.path.join(args.work, "cache")],
                           check=True)
            with open(stats) as f:
                st = {s["name"]: s for s in json.load(f)["stages"]}
            if run == 0:
                continue  # filled the cache
            lights.append(1e3 * st["pvrt_radiance"]["seconds"])
            frames.append(1e3 * st["render"]["seconds"])
        print("%-6s n=%2d  light change ms %s  frame ms %s  load %.1f" %
              (which, n, " ".join("%.1f" % x for x in lights),
               " ".join("%.0f" % x for x in frames), os.getloadavg()[0]), flush=True)


if __name__ == "__main__":
    main()
