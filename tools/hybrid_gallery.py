#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Hybrid scattering side by side (Kroes et al. 2012 Fig. 6): the path tracer with the phase
function only, hybrid (P_brdf from opacity and gradient, gradient_factor g_f) and the BRDF wherever
the gradient is non-zero, for the torso phantom (ct-bone; ct-angio: glossier contrast lumen and
metal stent) and the abdomen CT under ct-bone, lit by an
environment map and a directional light. Single scattering (the effects omit
multiple_scattering), raw estimates (no denoiser), the same spp everywhere. Writes one mosaic
(PNG, labelled tiles) and the seconds and surface-event fraction of each render (JSON).

    /usr/bin/python3 tools/hybrid_gallery.py [--build build] [--out docs/pathtrace]
        [--size 192] [--spp 64] [--phantom-size 128] [--datasets ../shared/datasets]
"""
import argparse
import json
import os
import sys
import tempfile

from PIL import Image

from voxlight_cli import DATASETS, ROOT, mosaic, render, resolve_volume

# name → (volume or None for the phantom, view, transfer function)
CASES = {
    "torso ct-bone": (None, "oblique", "ct-bone"),
    "torso ct-angio": (None, "anterior", "ct-angio"),
    "abdomen CT ct-bone": ("ct/abdomen-totalseg/example_ct.nii.gz", "anterior", "ct-bone"),
}
# label → method.params beyond spp
TILES = [("phase", {"scattering": "phase"}),
         ("hybrid g_f 0.5", {"scattering": "hybrid", "gradient_factor": 0.5}),
         ("hybrid g_f 1", {"scattering": "hybrid", "gradient_factor": 1.0}),
         ("brdf", {"scattering": "brdf"})]


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "pathtrace"))
    ap.add_argument("--size", type=int, default=192)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--phantom-size", type=int, default=128)
    ap.add_argument("--datasets", default=DATASETS, help="the shared datasets directory")
    args = ap.parse_args()
    exe = os.path.join(args.build, "voxlight")
    os.makedirs(args.out, exist_ok=True)
    work = tempfile.mkdtemp(prefix="voxlight-hybrid-")
    env = os.path.join(os.path.abspath(args.datasets), "env", "courtyard.hdr")
    report, rows, row_labels = {}, [], []
    for name, (volume, view, tf) in CASES.items():
        vol, _ = resolve_volume(exe, volume, args.datasets, args.phantom_size)
        if vol is None:
            continue
        tiles, runs = [], []
        for label, params in TILES:
            scene = {"volume": vol, "transfer_function": tf,
                     "camera": {"view": view},
                     "lights": [{"type": "environment", "path": env, "intensity": 0.6},
                                {"type": "directional", "direction": [0.4, 0.6, -0.7],
                                 "intensity": 2.5}],
                     "effects": ["local_shadows", "global_shadows"],
                     "method": {"name": "pathtrace",
                                "params": dict(params, spp=args.spp, denoise=False)},
                     "image": {"width": args.size, "height": args.size, "display": "filmic"}}
            tag = f"{name}-{label}".replace(" ", "-")
            path = os.path.join(work, tag + ".json")
            with open(path, "w") as f:
                json.dump(scene, f)
            png = os.path.join(work, tag + ".png")
            st = render(exe, path, png, os.path.join(work, tag + ".stats.json"))
            pt = st["details"]["pathtrace"] if "details" in st else st["pathtrace"]
            real = max(1, pt["real_collisions"])
            runs.append({"tile": label, "params": params,
                         "total_seconds": round(st["total_seconds"], 2),
                         "trace_seconds": round(pt["seconds"], 2),
                         "relative_std_error": round(pt["relative_std_error"], 4),
                         "surface_event_fraction": round(pt["surface_events"] / real, 3)})
            tiles.append((Image.open(png).convert("RGB"),
                          f"{label}: {runs[-1]['trace_seconds']} s"))
            print(tag, runs[-1], file=sys.stderr)
        report[name] = runs
        rows.append(tiles)
        row_labels.append(name)
    mosaic(rows, os.path.join(args.out, "hybrid.png"), row_labels=row_labels, row_label_w=140)
    with open(os.path.join(args.out, "hybrid.json"), "w") as f:
        json.dump({"size": args.size, "spp": args.spp, "renders": report}, f, indent=1)


if __name__ == "__main__":
    main()
