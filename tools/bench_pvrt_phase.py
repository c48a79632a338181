#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""What PVRT's exitance coefficients buy under anisotropic scattering (issue #16, deliverable 4).

The smoke-like `cloud` phantom (64³) under a white scattering TF, seen against a directional light
(the light behind the cloud, slightly off the view axis), Henyey–Greenstein g = 0.6 (forward
scattering). The multiple-scattering ground truth is the path tracer's reference mode with the
same phase_g (cached in WORK/cache). pvrt is rendered at its defaults (SH-16 basis lights, 64³
grid, 30 photons per boundary cell, track-length estimator, CPCA 128 clusters) with phase_g 0.6 and
exitance_coefficients 1 (the isotropic transfer: the photons scatter by HG, the view does not),
4, 9 and 16; and once at phase_g 0 (today's pvrt, isotropic throughout). Each pvrt run is a fresh
process without cache, repeated --runs times for time ranges. Errors as in
tools/bench_pvrt_accuracy.py (linear NRMSE of the luminance over covered pixels; RMSE in 1/255
steps on the display image).

Writes WORK/results.csv and, with --docs DIR, DIR/phase-comparison.png (isotropic n=1 | HG n=16 |
path tracer, g = 0.6). Run from the repository root:

    tools/bench_pvrt_phase.py [--voxlight build/voxlight] [--work /tmp/pvrt-phase] [--docs docs/pvrt]
"""
import argparse
import csv
import os
import subprocess

from PIL import Image

from bench_sh_accuracy import errors, render
from voxlight_cli import mosaic, read_exr

SIZE = 128
G = 0.6
LIGHT = [{"type": "directional", "direction": [-0.25, -1.0, -0.2], "intensity": 8}]  # travels toward the camera
MULTIPLE = ["global_shadows", "multiple_scattering"]
CLOUD_TF = {"points": [{"value": 0.0, "color": [0.95, 0.95, 0.95], "extinction": 0},
                       {"value": 0.05, "color": [0.95, 0.95, 0.95], "extinction": 0},
                       {"value": 1.0, "color": [0.95, 0.95, 0.95], "extinction": 0.25}],
            "window": {"level": 0.5, "width": 1.0}}
ROWS = [("n=1 g=0 (isotropic pvrt)", {"exitance_coefficients": 1}),
        ("n=1", {"exitance_coefficients": 1, "phase_g": G}),
        ("n=4", {"exitance_coefficients": 4, "phase_g": G}),
        ("n=9", {"exitance_coefficients": 9, "phase_g": G}),
        ("n=16", {"exitance_coefficients": 16, "phase_g": G})]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--voxlight", default="build/voxlight")
    ap.add_argument("--work", default="/tmp/pvrt-phase")
    ap.add_argument("--docs", default=None)
    ap.add_argument("--runs", type=int, default=2)
    args = ap.parse_args()
    voxlight = os.path.abspath(args.voxlight)
    os.makedirs(args.work, exist_ok=True)
    cloud = os.path.join(args.work, "cloud64.nii.gz")
    if not os.path.exists(cloud):
        subprocess.run([voxlight, "phantom", "cloud", "--size", "64", "-q", "-o", cloud],
                       check=True)
    scene = {"volume": cloud, "lights": LIGHT, "image": {"width": SIZE, "height": SIZE},
             "transfer_function": CLOUD_TF, "camera": {"view": "anterior"}}
    ref_png, ref_exr, ref_st, _, ref_wall = render(
        voxlight, scene, "reference", args.work, "pathtrace", {"reference": True, "phase_g": G},
        MULTIPLE, os.path.join(args.work, "cache"))
    ref_lin = read_exr(ref_exr, args.work)
    floor = ref_st["pathtrace"].get("expected_nrmse", ref_st["pathtrace"]["relative_std_error"])
    print("reference: %d spp, estimated NRMS %.3f (%.0f s wall)" %
          (ref_st["pathtrace"]["spp"], floor, ref_wall), flush=True)
    rows, pngs = [], {}
    for label, params in ROWS:
        for run in range(args.runs):
            tag = "pvrt-%s-run%d" % (label.split()[0] + ("-g0" if "g=0" in label else ""), run)
            png, exr, st, pre, wall = render(voxlight, scene, tag, args.work, "pvrt", params,
                                             MULTIPLE)
            rmse, off, nrmse, _ = errors(ref_png, ref_lin, png, read_exr(exr, args.work))
            light = sum(s["seconds"] for s in st["stages"] if s["name"] == "pvrt_radiance")
            r = {"setting": label, "run": run, "nrmse_linear": round(nrmse, 4),
                 "rmse_255": round(rmse, 2), "precompute_s": round(pre, 2),
                 "light_change_ms": round(1e3 * light, 2),
                 "transfer_mb": round(st.get("pvrt_direct", {}).get("transfer_mb", 0), 1),
                 "cpca_mb": round(st.get("pvrt_cpca", {}).get("cpca_mb", 0), 1),
                 "radiance_mb": round(st.get("pvrt_radiance", {}).get("radiance_mb", 0), 1),
                 "reference_nrms": round(floor, 4)}
            rows.append(r)
            pngs[label] = png
            print("  %-26s run %d  NRMSE %.4f  RMSE %5.2f/255  precompute %6.2f s  light change "
                  "%6.2f ms  transfer %s MB  CPCA %s MB  radiance %s MB" %
                  (label, run, nrmse, rmse, pre, 1e3 * light, r["transfer_mb"], r["cpca_mb"],
                   r["radiance_mb"]), flush=True)
    with open(os.path.join(args.work, "results.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)
    if args.docs:
        os.makedirs(args.docs, exist_ok=True)
        tiles = [(Image.open(pngs["n=1"]), "pvrt n=1 (isotropic)"),
                 (Image.open(pngs["n=16"]), "pvrt HG n=16"),
                 (Image.open(ref_png), "path tracer")]
        mosaic([tiles], os.path.join(args.docs, "phase-comparison.png"))


if __name__ == "__main__":
    main()
