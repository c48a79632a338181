#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""What SH visibility's accuracy costs in time: sh-local / sh-global against the path tracer.

For each scene (Kronander's corner case, the torso phantom under a directional light and under an
environment map and under a soft-tissue TF, one real abdominal CT in HU) the single-scattering
ground truth is traced once by the path tracer's reference mode (cached on disk in WORK/cache), then
sh-local and sh-global are rendered with one setting varied at a time from the defaults:
rays 16…256, coefficients 1/4/9/16, LOD data reduction 64/8/1, radius r_s 4…32 voxels and (global)
the global grid 16…128. Every SH run is a fresh process without cache, so its precompute seconds
(the sum of the visibility stages it ran: block pyramid, LOD selection, local and global visibility)
are what a transfer-function change costs.

Image error is measured as users see it: on the 8-bit display images (same display transform and
exposure for all), RMSE in display steps of 1/255 and the share of pixels whose largest channel
difference exceeds 2/255; and linear NRMSE of the radiance (RMS of the difference / mean reference
radiance over covered pixels). The reference's own noise (its estimated NRMS error) is printed as the
floor below which no figure can fall.

Writes WORK/results.csv and, with --docs DIR, DIR/table.md, DIR/accuracy-vs-time.png and
DIR/comparison.png (reference | sh-local | sh-global at defaults | sh-global at the most accurate
settings (BEST, with a 0.1-voxel render step) | its error map, full red at 32/255). Run from the repository root:

    tools/bench_sh_accuracy.py [--voxlight build/voxlight] [--work /tmp/sh-accuracy] [--docs docs/sh-accuracy]

Takes ~30–60 min on the 2-core machine (most of it the references and the 512-ray runs); a
benchmark, not a test.
"""
import argparse
import csv
import json
import os
import subprocess
import sys
import time

import numpy as np
from PIL import Image

from voxlight_cli import read_exr

DATASETS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared",
                        "datasets")
SIZE = 128  # image side: small enough that a 1 % reference costs minutes, not hours
DEFAULTS = {"rays": 32, "coefficients": 4, "radius": 16, "data_reduction": 8,
            "global_resolution": 64}
SWEEPS = [  # (method, param, values) — one at a time from DEFAULTS
    ("sh-local", "rays", [16, 32, 64, 128, 256]),
    ("sh-local", "coefficients", [1, 4, 9, 16]),
    ("sh-local", "data_reduction", [64, 8, 1]),
    ("sh-local", "radius", [4, 8, 16, 32]),
    ("sh-global", "rays", [16, 32, 128]),
    ("sh-global", "coefficients", [1, 4, 9, 16]),
    ("sh-global", "data_reduction", [64, 8, 1]),
    ("sh-global", "radius", [4, 8, 16, 32]),
    ("sh-global", "global_resolution", [16, 32, 64, 128]),
    ("sh-global", "global_near", ["grid", "local"]),
    # The near shadow (traced first ½·(s − 1) voxels and the exit rule) against the plain product.
    ("sh-local", "near_shadow", [False, True]),
    ("sh-global", "near_shadow", [False, True]),
    # Voxels traced at every level on top (method param near_trace; default 0).
    ("sh-local", "near_trace", [0, 2, 4]),
    ("sh-global", "near_trace", [0, 2, 4]),
    ("ritschel", "subsample", [4, 2, 1]),
    ("ritschel", "coefficients", [4, 16]),
]
RITSCHEL_DEFAULTS = {"rays": 32, "coefficients": 4, "subsample": 2}
BEST = {"rays": 128, "coefficients": 16, "radius": 16, "data_reduction": 1,
        "global_resolution": 128, "step": 0.1}
# A sweep's error "falls as settings grow" unless a later value is worse than the best so far by
# more than this (display steps of RMSE): the reference's own noise moves figures by ~0.1.
MONOTONE_SLACK = 0.25
LIGHT = [{"type": "directional", "direction": [0.45, 0.55, -0.7], "intensity": 8}]
ENVIRONMENT = os.path.join(DATASETS, "env", "courtyard.hdr")


def scenes(work):
    out = []
    kron = os.path.join(work, "kronander.nii.gz")
    torso = os.path.join(work, "torso128.nii.gz")
    out.append(("kronander", kron, ["phantom", "kronander", "-q", "-o", kron],
                {"transfer_function": "generic", "camera": {"view": "oblique"}}))
    out.append(("torso", torso, ["phantom", "torso", "--size", "128", "-q", "-o", torso],
                {"transfer_function": "ct-bone", "camera": {"view": "anterior"}}))
    # Soft tissue: optically thin within a voxel, where grid visibility should be accurate.
    out.append(("torso-soft-tissue", torso, None,
                {"transfer_function": "ct-soft-tissue", "camera": {"view": "anterior"}}))
    if os.path.exists(ENVIRONMENT):  # SH's own regime: smooth light from everywhere
        out.append(("torso-environment", torso, None,
                    {"transfer_function": "ct-bone", "camera": {"view": "anterior"},
                     "lights": [{"type": "environment", "path": ENVIRONMENT, "intensity": 1}]}))
    # A real CT in Hounsfield units (lidc2-chest.mha is already windowed to uint8).
    ct = os.path.join(DATASETS, "ct", "abdomen-totalseg", "example_ct.nii.gz")
    if os.path.exists(ct):
        out.append(("abdomen-ct", ct, None,
                    {"transfer_function": "ct-bone", "camera": {"view": "oblique"}}))
    else:
        print("skipping the real CT: %s is absent" % ct, file=sys.stderr)
    return out


def render(voxlight, scene, name, work, method, params, effects, cache=None):
    doc = dict(scene)
    doc["method"] = {"name": method, "params": params}
    doc["effects"] = effects
    path = os.path.join(work, name + ".scene.json")
    with open(path, "w") as f:
        json.dump(doc, f)
    png, exr, stats = (os.path.join(work, name + e) for e in (".png", ".exr", ".json"))
    cmd = [voxlight, "render", path, "-q", "-o", png, "--exr", exr, "--stats", stats]
    if cache:
        cmd += ["--cache", cache]
    t = time.time()
    subprocess.run(cmd, check=True)
    with open(stats) as f:
        st = json.load(f)
    pre = sum(s["seconds"] for s in st["stages"] if s["ran"] and s["kind"] == "precompute")
    return png, exr, st, pre, time.time() - t


def errors(ref_png, ref_lin, png, lin):
    a = np.asarray(Image.open(ref_png).convert("RGB"), dtype=np.float64)
    b = np.asarray(Image.open(png).convert("RGB"), dtype=np.float64)
    d = np.abs(a - b)
    rmse = float(np.sqrt(np.mean(d ** 2)))
    off = float(np.mean(d.max(axis=2) > 2.0) * 100.0)
    lum = np.array([0.2126, 0.7152, 0.0722])
    covered = ref_lin[..., 3] > 0
    lr, ls = ref_lin[..., :3] @ lum, lin[..., :3] @ lum
    mean = float(lr[covered].mean()) if covered.any() else 1.0
    nrmse = float(np.sqrt(np.mean((lr - ls)[covered] ** 2)) / mean) if covered.any() else 0.0
    bias = float(ls[covered].mean() / mean - 1.0) if covered.any() else 0.0
    return rmse, off, nrmse, bias, d.max(axis=2)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--voxlight", default="build/voxlight")
    ap.add_argument("--work", default="/tmp/sh-accuracy")
    ap.add_argument("--docs", default=None)
    ap.add_argument("--scenes", default=None, help="comma-separated subset of scene names")
    ap.add_argument("--methods", default=None,
                    help="comma-separated subset of methods to sweep (rows of the others are kept)")
    ap.add_argument("--quick", action="store_true",
                    help="defaults and 16 coefficients per method only, no best-settings run "
                         "(minutes instead of an hour; for a check after a change)")
    ap.add_argument("--report-only", action="store_true",
                    help="rebuild the docs from WORK/results.csv and WORK/*-pictures.png")
    args = ap.parse_args()
    if args.quick:
        global SWEEPS
        SWEEPS = [(m, "coefficients", [4, 16]) for m in ("sh-local", "sh-global", "ritschel")]
        SWEEPS.append(("sh-global", "global_near", ["grid", "local"]))
        SWEEPS += [(m, "near_shadow", [False, True]) for m in ("sh-local", "sh-global")]
    if args.report_only:
        args.scenes = "-"  # run no scene; keep every earlier one
    voxlight = os.path.abspath(args.voxlight)
    os.makedirs(args.work, exist_ok=True)
    cache = os.path.join(args.work, "cache")
    rows, pictures = [], []
    for name, volume, make, extra in scenes(args.work):
        if args.scenes and name not in args.scenes.split(","):
            continue
        if make and not os.path.exists(volume):
            subprocess.run([voxlight] + make, check=True)
        if not os.path.exists(volume):
            print("skipping %s: %s is absent" % (name, volume), file=sys.stderr)
            continue
        scene = {"volume": os.path.abspath(volume), "lights": LIGHT,
                 "image": {"width": SIZE, "height": SIZE}}
        scene.update(extra)
        ref_png, ref_exr, ref_st, _, ref_wall = render(
            voxlight, scene, name + "-reference", args.work, "pathtrace", {"reference": True},
            ["global_shadows"], cache)
        ref_lin = read_exr(ref_exr, args.work)
        floor = ref_st["pathtrace"].get("expected_nrmse", ref_st["pathtrace"]["relative_std_error"])
        print("%s: reference %d spp, estimated NRMS %.2f %% (%.0f s wall, cached after)" %
              (name, ref_st["pathtrace"]["spp"], 100 * floor, ref_wall), flush=True)
        done = {}
        for method, param, values in SWEEPS:
            if args.methods and method not in args.methods.split(","):
                continue
            for v in values:
                params = dict(RITSCHEL_DEFAULTS) if method == "ritschel" else {
                    k: val for k, val in DEFAULTS.items()
                    if k != "global_resolution" or method == "sh-global"}
                params[param] = v
                key = (method, tuple(sorted(params.items())))
                if key not in done:
                    tag = "%s-%s-%s-%s" % (name, method, param, v)
                    effects = ["local_shadows"] if method == "sh-local" else ["global_shadows"]
                    png, exr, st, pre, wall = render(voxlight, scene, tag, args.work, method,
                                                     params, effects)
                    rmse, off, nrmse, bias, _ = errors(ref_png, ref_lin, png,
                                                       read_exr(exr, args.work))
                    done[key] = (rmse, off, nrmse, bias, pre)
                rmse, off, nrmse, bias, pre = done[key]
                rows.append({"scene": name, "method": method, "param": param, "value": v,
                             "rmse_255": round(rmse, 3), "pixels_off_pct": round(off, 2),
                             "nrmse_linear": round(nrmse, 4), "mean_bias": round(bias, 4),
                             "precompute_s": round(pre, 2),
                             "reference_nrms": round(floor, 4)})
                print("  %-9s %-17s %5s  RMSE %6.2f/255  off>2/255 %5.1f %%  NRMSE %.3f  "
                      "mean %+6.1f %%  precompute %6.2f s"
                      % (method, param, v, rmse, off, nrmse, 100 * bias, pre), flush=True)
        if args.methods or args.quick:  # partial: the picture and best row need the full sweep
            continue
        # The picture: reference | sh-local | sh-global (defaults) | sh-global (best) | error map.
        best = dict(BEST)
        png_l = os.path.join(args.work, "%s-sh-local-rays-32.png" % name)
        png_g = os.path.join(args.work, "%s-sh-global-rays-32.png" % name)
        png_b, exr_b, _, pre_b, _ = render(voxlight, scene, name + "-best", args.work, "sh-global",
                                           best, ["global_shadows"])
        rmse, off, nrmse, _, diff = errors(ref_png, ref_lin, png_b, read_exr(exr_b, args.work))
        rows.append({"scene": name, "method": "sh-global", "param": "best", "value": "all",
                     "rmse_255": round(rmse, 3), "pixels_off_pct": round(off, 2),
                     "nrmse_linear": round(nrmse, 4), "precompute_s": round(pre_b, 2),
                     "reference_nrms": round(floor, 4)})
        print("  sh-global best settings: RMSE %.2f/255, off %.1f %%, NRMSE %.3f, %.1f s" %
              (rmse, off, nrmse, pre_b), flush=True)
        heat = np.clip(diff / 32.0, 0, 1)  # 32/255 and more: full red
        err = np.stack([heat * 255, np.zeros_like(heat), (1 - heat) * 40], axis=2).astype(np.uint8)
        pictures.append([Image.open(p).convert("RGB") for p in (ref_png, png_l, png_g, png_b)] +
                        [Image.fromarray(err)])
        row = Image.new("RGB", (SIZE * 5, SIZE))
        for col, im in enumerate(pictures[-1]):
            row.paste(im.resize((SIZE, SIZE)), (col * SIZE, 0))
        row.save(os.path.join(args.work, name + "-pictures.png"))

    # Scenes not run this time keep their rows from an earlier run in the same work directory.
    csv_path = os.path.join(args.work, "results.csv")
    if (args.scenes or args.methods) and os.path.exists(csv_path):
        ran = {(r["scene"], r["method"]) for r in rows}
        with open(csv_path) as f:
            known = {name for name, _, _, _ in scenes(args.work)}
            old = [r for r in csv.DictReader(f)
                   if (r["scene"], r["method"]) not in ran and r["scene"] in known]
        for r in old:
            for k in ("rmse_255", "pixels_off_pct", "nrmse_linear", "precompute_s",
                      "reference_nrms", "mean_bias"):
                if r.get(k) not in (None, ""):
                    r[k] = float(r[k])
        rows = old + rows
    # The pictures in the order of the scene list, one saved row per scene.
    pictures = []
    for name, _, _, _ in scenes(args.work):
        sheet = os.path.join(args.work, name + "-pictures.png")
        if any(r["scene"] == name for r in rows) and os.path.exists(sheet):
            im = Image.open(sheet).convert("RGB")
            w = im.size[0] // 5
            pictures.append([im.crop((i * w, 0, (i + 1) * w, im.size[1])) for i in range(5)])
    with open(csv_path, "w", newline="") as f:
        fields = list(dict.fromkeys(k for r in rows for k in r))  # rows of older runs lack some
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)
    report(rows, pictures, args.docs)


def scenes_list():
    return scenes("/tmp")


def monotone(series):
    """Largest rise of RMSE over the best so far along a sweep (≤ slack: 'falls as it grows')."""
    best, worst_rise = float("inf"), 0.0
    for r in series:
        worst_rise = max(worst_rise, r["rmse_255"] - best)
        best = min(best, r["rmse_255"])
    return worst_rise


def report(rows, pictures, docs):
    lines = ["| scene | method | setting | RMSE (/255) | pixels off > 2/255 | NRMSE (linear) | "
             "precompute s |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append("| %s | %s | %s = %s | %.2f | %.1f %% | %.3f | %.2f |" % (
            r["scene"], r["method"], r["param"], r["value"], r["rmse_255"], r["pixels_off_pct"],
            r["nrmse_linear"], r["precompute_s"]))
    verdicts = []
    for scene in sorted({r["scene"] for r in rows}):
        for method, param, _ in SWEEPS:
            s = [r for r in rows if r["scene"] == scene and r["method"] == method and
                 r["param"] == param]
            if not s or param in ("global_near", "near_shadow"):  # alternatives, not a growing setting
                continue
            rise = monotone(s)
            verdicts.append("%s %s %s: %s" % (scene, method, param,
                                              "falls" if rise <= MONOTONE_SLACK else
                                              "does NOT fall (rise %.2f/255)" % rise))
    text = "\n".join(lines) + "\n\nAs settings grow:\n" + "\n".join("- " + v for v in verdicts)
    print(text)
    if not docs:
        return
    os.makedirs(docs, exist_ok=True)
    with open(os.path.join(docs, "table.md"), "w") as f:
        f.write(text + "\n")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    scenes_ = [n for n, _, _, _ in scenes_list() if any(r["scene"] == n for r in rows)]
    cols = 3
    nrows = (len(scenes_) + 1 + cols - 1) // cols  # one panel more for the legend
    fig, axes = plt.subplots(nrows, cols, figsize=(5.5 * cols, 4.2 * nrows), squeeze=False)
    flat = [a for row in axes for a in row]
    for ax, scene in zip(flat, scenes_):
        for method, param, _ in SWEEPS:
            s = [r for r in rows if r["scene"] == scene and r["method"] == method and
                 r["param"] == param]
            if not s:
                continue
            style = {"sh-global": "-o", "sh-local": "--s", "ritschel": ":^"}[method]
            ax.plot([r["precompute_s"] for r in s], [r["rmse_255"] for r in s], style, ms=3,
                    label="%s %s" % (method, param))
        ax.set_xscale("log")
        ax.set_xlabel("precompute seconds (TF change)")
        ax.set_ylabel("RMSE vs path tracer (1/255)")
        ax.set_title(scene)
        ax.grid(True, alpha=0.3)
    handles, labels = flat[0].get_legend_handles_labels()
    for ax in flat[len(scenes_):]:
        ax.axis("off")
    flat[len(scenes_)].legend(handles, labels, loc="center", fontsize=9)
    fig.tight_layout()
    fig.savefig(os.path.join(docs, "accuracy-vs-time.png"), dpi=110)
    if pictures:
        w, h = pictures[0][0].size
        sheet = Image.new("RGB", (w * 5, h * len(pictures)))
        for row, ims in enumerate(pictures):
            for col, im in enumerate(ims):
                sheet.paste(im.resize((w, h)), (col * w, row * h))
        sheet.save(os.path.join(docs, "comparison.png"))


if __name__ == "__main__":
    main()
