#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""What PVRT's accuracy costs in time: pvrt against the path tracer with multiple scattering.

Zhang, Dong & Ma 2013 Tables 1–2 and Figs. 10–13 on our data. For each scene (the smoke-like
`cloud` phantom, the torso phantom under a soft-tissue TF, one real abdominal CT) the multiple-
scattering ground truth is traced once by the path tracer's reference mode (cached on disk in
WORK/cache), then pvrt is rendered with one setting varied at a time from the defaults: the basis
(SH order 2/4/6, DSF 42/162/642), photons per boundary cell 1/10/30/100, the transfer grid
(32/64/128 points per axis, capped at the volume's size) and CPCA clusters 0 (uncompressed)/32/
64/128/256. Each pvrt run is a fresh process without cache, so its precompute
seconds (the sum of the PVRT stages it ran) are what a TF change costs; its frame seconds are the
per-light-change radiance update (stage pvrt_radiance). sh-global (single scattering only) is
rendered at its defaults beside it, to show what multiple scattering adds.

Errors as in tools/bench_sh_accuracy.py: on the display images RMSE in 1/255 steps and the share of
pixels off by more than 2/255; linear NRMSE of the luminance over covered pixels. The reference's
own estimated NRMS error is the floor.

Writes WORK/results.csv and, with --docs DIR, DIR/table.md, DIR/accuracy-vs-time.png and
DIR/comparison.png (reference | pvrt defaults | pvrt single scattering | sh-global | pvrt error
map, full red at 32/255). Run from the repository root:

    tools/bench_pvrt_accuracy.py [--voxlight build/voxlight] [--work /tmp/pvrt-accuracy] [--docs docs/pvrt]

--set KEY=VALUE (repeatable; VALUE as JSON, else a string) changes the defaults every row starts
from, e.g. --set estimator=collision; --axes photons runs one sweep only, and --no-extras leaves
out the pictures, single-scattering and sh-global rows.

A benchmark, not a test: the references take most of its time.
"""
import argparse
import csv
import glob
import json
import os
import subprocess
import sys

import numpy as np
from PIL import Image

from bench_sh_accuracy import DATASETS, errors, render
from voxlight_cli import mosaic, read_exr

SIZE = 128
DEFAULTS = {"basis": "sh", "order": 4, "photons": 30, "clusters": 128}  # the estimator: pvrt's
SWEEPS = [  # (label, list of param overrides) — one axis at a time from DEFAULTS
    ("basis", [{"basis": "sh", "order": 2}, {"basis": "sh", "order": 4},
               {"basis": "sh", "order": 6}, {"basis": "dsf", "directions": 42},
               {"basis": "dsf", "directions": 162}, {"basis": "dsf", "directions": 642}]),
    ("photons", [{"photons": 1}, {"photons": 10}, {"photons": 30}, {"photons": 100}]),
    ("resolution", [{"resolution": 32}, {"resolution": 64}, {"resolution": 128}]),
    ("clusters", [{"clusters": 0}, {"clusters": 32}, {"clusters": 64}, {"clusters": 128},
                  {"clusters": 256}]),
]
LIGHT = [{"type": "directional", "direction": [0.45, 0.55, -0.7], "intensity": 8}]
MULTIPLE = ["global_shadows", "multiple_scattering"]
# Smoke: white, scattering, a few mean free paths across — where multiple scattering shows.
CLOUD_TF = {"points": [{"value": 0.0, "color": [0.95, 0.95, 0.95], "extinction": 0},
                       {"value": 0.05, "color": [0.95, 0.95, 0.95], "extinction": 0},
                       {"value": 1.0, "color": [0.95, 0.95, 0.95], "extinction": 0.25}],
            "window": {"level": 0.5, "width": 1.0}}


def scenes(work):
    out = []
    cloud = os.path.join(work, "cloud64.nii.gz")
    torso = os.path.join(work, "torso128.nii.gz")
    out.append(("cloud", cloud, ["phantom", "cloud", "--size", "64", "-q", "-o", cloud],
                {"transfer_function": CLOUD_TF, "camera": {"view": "anterior"}}))
    out.append(("torso-soft-tissue", torso, ["phantom", "torso", "--size", "128", "-q", "-o", torso],
                {"transfer_function": "ct-soft-tissue", "camera": {"view": "anterior"}}))
    ct = os.path.join(DATASETS, "ct", "abdomen-totalseg", "example_ct.nii.gz")
    if os.path.exists(ct):
        out.append(("abdomen-ct", ct, None,
                    {"transfer_function": "ct-soft-tissue", "camera": {"view": "anterior"}}))
    else:
        print("skipping the real CT: %s is absent" % ct, file=sys.stderr)
    return out


def stage_seconds(st, names, kind=None):
    return sum(s["seconds"] for s in st["stages"]
               if s["name"] in names and (s["ran"] or kind == "frame"))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--voxlight", default="build/voxlight")
    ap.add_argument("--work", default="/tmp/pvrt-accuracy")
    ap.add_argument("--docs", default=None)
    ap.add_argument("--scenes", default=None, help="comma-separated subset of scene names")
    ap.add_argument("--quick", action="store_true", help="defaults only (a check after a change)")
    ap.add_argument("--axes", default=None,
                    help="comma-separated subset of the sweeps (%s; defaults: the defaults alone)"
                    % ", ".join(label for label, _ in SWEEPS))
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="override a pvrt param of every row (VALUE as JSON, else a string)")
    ap.add_argument("--no-extras", action="store_true",
                    help="leave out the pictures, single-scattering and sh-global rows")
    ap.add_argument("--report-only", action="store_true",
                    help="rebuild the table, plot and pictures from WORK (results.csv and its images)")
    args = ap.parse_args()
    if args.report_only:
        with open(os.path.join(args.work, "results.csv")) as f:
            rows = list(csv.DictReader(f))
        for r in rows:
            for k in ("rmse_255", "pixels_off_pct", "nrmse_linear", "precompute_s",
                      "light_change_s", "reference_nrms"):
                r[k] = float(r[k])
        report(rows, sorted({r["scene"] for r in rows}, key=[r["scene"] for r in rows].index),
               args.docs, args.work)
        return
    sweeps = [("defaults", [{}])] if args.quick else SWEEPS
    if args.axes:
        wanted = args.axes.split(",")
        sweeps = [sw for sw in SWEEPS if sw[0] in wanted]
        if "defaults" in wanted:
            sweeps.append(("defaults", [{}]))
    defaults = dict(DEFAULTS)
    for kv in args.set:
        key, _, value = kv.partition("=")
        try:
            defaults[key] = json.loads(value)
        except ValueError:
            defaults[key] = value
    voxlight = os.path.abspath(args.voxlight)
    os.makedirs(args.work, exist_ok=True)
    cache = os.path.join(args.work, "cache")
    rows, pictures = [], []
    for name, volume, make, extra in scenes(args.work):
        if args.scenes and name not in args.scenes.split(","):
            continue
        if make and not os.path.exists(volume):
            subprocess.run([voxlight] + make, check=True)
        scene = {"volume": os.path.abspath(volume), "lights": LIGHT,
                 "image": {"width": SIZE, "height": SIZE}}
        scene.update(extra)
        ref_png, ref_exr, ref_st, _, ref_wall = render(
            voxlight, scene, name + "-reference", args.work, "pathtrace", {"reference": True},
            MULTIPLE, cache)
        ref_lin = read_exr(ref_exr, args.work)
        floor = ref_st["pathtrace"].get("expected_nrmse", ref_st["pathtrace"]["relative_std_error"])
        print("%s: reference %d spp, estimated NRMS %.2f %% (%.0f s wall, cached after)" %
              (name, ref_st["pathtrace"]["spp"], 100 * floor, ref_wall), flush=True)

        def row(label, params, effects=MULTIPLE, method="pvrt"):
            """Renders one setting and appends its row of the table."""
            tag = "%s-%s-%s-%s" % (name, method, label, "-".join("%s%s" % kv for kv in sorted(params.items())))
            png, exr, st, pre, _ = render(voxlight, scene, tag, args.work, method, params, effects)
            rmse, off, nrmse, _ = errors(ref_png, ref_lin, png, read_exr(exr, args.work))
            frame = stage_seconds(st, ["pvrt_radiance"], "frame")
            r = {"scene": name, "method": method, "axis": label,
                 "setting": " ".join("%s=%s" % kv for kv in sorted(params.items())) or "defaults",
                 "rmse_255": round(rmse, 3), "pixels_off_pct": round(off, 2),
                 "nrmse_linear": round(nrmse, 4), "precompute_s": round(pre, 2),
                 "light_change_s": round(frame, 4), "reference_nrms": round(floor, 4)}
            rows.append(r)
            print("  %-9s %-9s %-28s RMSE %6.2f/255  off %5.1f %%  NRMSE %.3f  precompute %6.2f s"
                  "  light change %.1f ms" % (method, label, r["setting"], rmse, off, nrmse, pre,
                                              1e3 * frame), flush=True)

        for label, variants in sweeps:
            for v in variants:
                params = dict(defaults)
                if "directions" in v:
                    params.pop("order")
                params.update(v)
                row(label, params)
        if not args.no_extras:
            row("pictures", dict(defaults))
            # The photon pass's settings are refused under single scattering (they change nothing).
            single = {k: v for k, v in defaults.items()
                      if k not in ("photons", "kernel_radius", "estimator")}
            row("single", dict(single, max_bounces=1), ["global_shadows"])
            row("sh-global", {}, ["global_shadows"], "sh-global")
            pictures.append(name)
    with open(os.path.join(args.work, "results.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)
    report(rows, pictures, args.docs, args.work)


def picture_row(scene, work):
    """reference | pvrt defaults | pvrt single scattering | sh-global | pvrt error map (full red
    at 32/255), from the images the runs left in WORK."""
    def one(pattern):
        found = sorted(glob.glob(os.path.join(work, pattern)))
        return found[0] if found else None
    names = [scene + "-reference.png", scene + "-pvrt-pictures-*.png",
             scene + "-pvrt-single-*.png", scene + "-sh-global-sh-global-*.png"]
    paths = [one(n) for n in names]
    if None in paths:
        return None
    a = np.asarray(Image.open(paths[0]).convert("RGB"), dtype=np.float64)
    b = np.asarray(Image.open(paths[1]).convert("RGB"), dtype=np.float64)
    heat = np.clip(np.abs(a - b).max(axis=2) / 32.0, 0, 1)
    err = np.stack([heat * 255, np.zeros_like(heat), (1 - heat) * 40], axis=2).astype(np.uint8)
    return [(Image.open(p), None) for p in paths] + [(Image.fromarray(err), None)]


def short_label(axis, setting):
    """The value an axis varies, from a row's setting string ("sh16", "dsf162", "100")."""
    kv = dict(item.split("=") for item in setting.split())
    if axis == "basis":
        return ("sh%d" % int(kv["order"]) ** 2 if kv["basis"] == "sh"
                else "dsf" + kv["directions"])
    return kv.get(axis, "")


def report(rows, pictures, docs, work):
    lines = ["| scene | method | axis | setting | RMSE (/255) | pixels off > 2/255 | NRMSE | "
             "precompute s | light change ms |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append("| %s | %s | %s | %s | %.2f | %.1f %% | %.3f | %.2f | %.1f |" % (
            r["scene"], r["method"], r["axis"], r["setting"], r["rmse_255"], r["pixels_off_pct"],
            r["nrmse_linear"], r["precompute_s"], 1e3 * r["light_change_s"]))
    text = "\n".join(lines)
    print(text)
    if not docs:
        return
    os.makedirs(docs, exist_ok=True)
    with open(os.path.join(docs, "table.md"), "w") as f:
        f.write(text + "\n")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names = sorted({r["scene"] for r in rows}, key=[r["scene"] for r in rows].index)
    fig, axes = plt.subplots(1, len(names), figsize=(5.5 * len(names), 4.2), squeeze=False)
    for ax, scene in zip(axes[0], names):
        for label, _ in SWEEPS:
            s = [r for r in rows if r["scene"] == scene and r["axis"] == label]
            if s:
                ax.plot([r["precompute_s"] for r in s], [r["rmse_255"] for r in s], "-o", ms=3,
                        label="pvrt " + label)
                for r in s:
                    ax.annotate(short_label(label, r["setting"]), (r["precompute_s"],
                                r["rmse_255"]), fontsize=7)
        for r in rows:
            if r["scene"] == scene and r["axis"] in ("single", "sh-global"):
                ax.plot([r["precompute_s"]], [r["rmse_255"]], "x", label=r["axis"])
        ax.set_xscale("log")
        ax.set_xlabel("precompute seconds (TF change)")
        ax.set_ylabel("RMSE vs path tracer, multiple scattering (1/255)")
        ax.set_title(scene)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(docs, "accuracy-vs-time.png"), dpi=110)
    rows_ = [r for r in (picture_row(scene, work) for scene in pictures) if r]
    if rows_:
        mosaic(rows_, os.path.join(docs, "comparison.png"),
               col_labels=["path tracer", "pvrt", "pvrt 1 bounce", "sh-global",
                           "pvrt error"],
               row_labels=[scene for scene in pictures if picture_row(scene, work)],
               row_label_w=110)

if __name__ == "__main__":
    main()
