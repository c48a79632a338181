#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""SH visibility gallery, as Kronander et al. 2012 Fig. 14/15: gradient shading, sh-local and
sh-global side by side under (a) one point light, (b) an environment map, (c) a clip plane with
shadows_from_removed true (section view) and (d) the same plane with false, for the torso phantom
and a real abdominal CT (skipped with a message when the shared datasets lack it). Writes one
mosaic per volume (rows a–d, columns gradient | sh-local | sh-global; each SH tile captioned with
the seconds of the precompute stages that render ran) and renders.json with every render's stage
seconds, the bytes of local and global visibility and the tile's mean display grey (0–255) over
the pixels where its row's gradient tile shows matter (the same pixels in every column).

    /usr/bin/python3 tools/sh_gallery.py [--build build] [--out docs/sh-gallery] [--size 256]
        [--phantom-size 128] [--datasets ../shared/datasets]

Every render is a fresh process without cache, so an SH tile's precompute seconds are what that
scene costs from scratch (block pyramid, LOD, local visibility, its clip-aware update, global
visibility), measured on whatever else the machine is doing.
"""
import argparse
import json
import math
import os
import sys
import tempfile

import numpy as np
from PIL import Image

from voxlight_cli import DATASETS, ROOT, mosaic, render, resolve_volume, stage_seconds

# name → (volume file under the datasets directory, or None for the torso phantom; TF; view)
VOLUMES = {
    "torso": (None, "ct-soft-tissue", "oblique"),
    "abdomen-ct": ("ct/abdomen-totalseg/example_ct.nii.gz", "ct-bone", "oblique"),
}
METHODS = ["gradient", "sh-local", "sh-global"]
# Gradient shading lights a surface of colour a under irradiance E with a·E·cosθ; the volumetric
# methods scatter a·E/(4π) (isotropic phase; render/shading.h kVolumetricHeadlightIrradiance). Its
# tiles are shown 4π darker (−3.65 stops) so that a fully lit sample reads alike in every column.
GRADIENT_EXPOSURE = -math.log2(4 * math.pi)
# One point light anterior, superior and to the patient's right of the volume's centre (mm, LPS):
# the light of docs/clip-planes, so that the clip rows light the cut face through the removed half.
POINT_OFFSET = [-120, -300, 160]
POINT_INTENSITY = 2e6
ENVIRONMENT = "env/courtyard.hdr"
# The clip plane passes through the centre and keeps the posterior half (+y, LPS).
CLIP_NORMAL = [0, 1, 0]
ROWS = [  # (tag, row label, environment light?, clip plane shadows_from_removed or None)
    ("point", "(a) point light", False, None),
    ("environment", "(b) environment map\ncourtyard.hdr", True, None),
    ("clip-true", "(c) clip plane,\npoint light,\nshadows_from_removed:\ntrue", False, True),
    ("clip-false", "(d) clip plane,\npoint light,\nshadows_from_removed:\nfalse", False, False),
]
# A pixel of the gradient tile brighter than this (0–255) shows matter; the mean grey of every tile
# of its row is taken over those pixels.
COVERED_GREY = 8
VISIBILITY_STAGES = ("block_pyramid", "multires_grid", "local_visibility",
                     "clip_local_visibility", "global_visibility")


def scene_for(vol, tf, view, size, light_at, env, shadows, plane_point, method):
    lights = ([{"type": "environment", "path": env, "intensity": 1}] if env else
              [{"type": "point", "position": light_at, "intensity": POINT_INTENSITY}])
    s = {"volume": vol, "transfer_function": tf, "camera": {"view": view}, "lights": lights,
         "method": {"name": method, "params": {}},
         "image": {"width": size, "height": size, "display": "filmic",
                   "exposure": GRADIENT_EXPOSURE if method == "gradient" else 0.0}}
    if shadows is not None:
        s["clip_planes"] = [{"point": plane_point, "normal": CLIP_NORMAL,
                             "shadows_from_removed": shadows}]
    return s


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "sh-gallery"))
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--phantom-size", type=int, default=128)
    ap.add_argument("--datasets", default=DATASETS, help="the shared datasets directory")
    args = ap.parse_args()
    exe = os.path.join(args.build, "voxlight")
    env = os.path.join(args.datasets, ENVIRONMENT)
    if not os.path.exists(env):
        sys.exit(f"{env} is absent: the environment-map row needs it (--datasets DIR)")
    os.makedirs(args.out, exist_ok=True)
    work = tempfile.mkdtemp(prefix="voxlight-sh-gallery-")
    report = {}
    for name, (volume, tf, view) in VOLUMES.items():
        vol, c = resolve_volume(exe, volume, args.datasets, args.phantom_size)
        if vol is None:
            continue
        light_at = [c[i] + POINT_OFFSET[i] for i in range(3)]
        rows, entries = [], []
        for tag, _, use_env, shadows in ROWS:
            row = []
            for method in METHODS:
                scene = scene_for(vol, tf, view, args.size, light_at, env if use_env else None,
                                  shadows, c, method)
                base = os.path.join(work, f"{name}-{tag}-{method}")
                st = render(exe, scene, base + ".png", base + ".stats.json")
                pre = {k: round(v, 2) for k, v in stage_seconds(st).items()
                       if k in VISIBILITY_STAGES}
                entry = {"row": tag, "method": method, "precompute_seconds": pre,
                         "total_seconds": round(st["total_seconds"], 2)}
                for k in ("local_visibility", "global_visibility"):
                    if k in st and "bytes" in st[k]:
                        entry[k + "_bytes"] = st[k]["bytes"]
                if "clip_local_visibility" in st:
                    entry["clip_local_visibility"] = st["clip_local_visibility"]
                entries.append(entry)
                print(name, entry, file=sys.stderr)
                im = Image.open(base + ".png").convert("RGB")
                grey = np.asarray(im.convert("L"), dtype=np.float64)
                if method == METHODS[0]:
                    covered = grey > COVERED_GREY
                entry["mean_grey"] = round(float(grey[covered].mean()), 1)
                caption = f"precompute {sum(pre.values()):.1f} s" if pre else None
                row.append((im, caption))
            rows.append(row)
        report[name] = {"volume": volume or f"torso phantom {args.phantom_size}^3",
                        "transfer_function": tf, "renders": entries}
        labels = [f"gradient (exposure {GRADIENT_EXPOSURE:.2f} stops)"] + METHODS[1:]
        mosaic(rows, os.path.join(args.out, f"{name}.png"), col_labels=labels,
               row_labels=[label for _, label, _, _ in ROWS], row_label_w=150)
    with open(os.path.join(args.out, "renders.json"), "w") as f:
        json.dump(report, f, indent=1)


if __name__ == "__main__":
    main()
