#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Clip planes and shadows_from_removed, as Kronander et al. 2012 Fig. 14/15: one clip plane, one
point light on the removed side, rendered with sh-global in both shadow modes and with the path
tracer (the reference) in both modes, for the torso phantom and a real CT. Writes one mosaic per
volume (PNG, labelled tiles) and the seconds and clip-aware update cost of each render (JSON).

    /usr/bin/python3 tools/clip_planes_gallery.py [--build build] [--out docs/clip-planes]
        [--size 256] [--spp 64] [--datasets ../shared/datasets]

The light shines through the removed part onto the cut face: with shadows_from_removed true
(section view) the removed matter still shadows the face; with false the face is lit.
"""
import argparse
import json
import os
import sys
import tempfile

from PIL import Image

from voxlight_cli import DATASETS, ROOT, mosaic, render, resolve_volume

# name → (volume or None for the phantom, transfer function, clip plane normal, light position
# relative to the volume's centre (mm, LPS), view). The plane passes through the centre and keeps
# the posterior half (+y); the light is anterior, superior and to the patient's right.
CASES = {
    "torso": (None, "ct-soft-tissue", [0, 1, 0], [-120, -300, 160], "oblique"),
    "abdomen-ct": ("ct/abdomen-totalseg/example_ct.nii.gz", "ct-soft-tissue", [0, 1, 0],
                   [-120, -300, 160], "oblique"),
}
TILES = [("sh-global", True), ("sh-global", False), ("pathtrace", True), ("pathtrace", False)]


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "clip-planes"))
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--phantom-size", type=int, default=128)
    ap.add_argument("--datasets", default=DATASETS, help="the shared datasets directory")
    args = ap.parse_args()
    exe = os.path.join(args.build, "voxlight")
    os.makedirs(args.out, exist_ok=True)
    work = tempfile.mkdtemp(prefix="voxlight-clip-")
    report = {}
    for name, (volume, tf, normal, light, view) in CASES.items():
        vol, c = resolve_volume(exe, volume, args.datasets, args.phantom_size)
        if vol is None:
            continue
        plane = {"point": c, "normal": normal}
        light_at = [c[i] + light[i] for i in range(3)]
        tiles, rows = [], []
        for method, shadows in TILES:
            # The tracer's tile is the ground truth: its raw estimate, not the denoised display.
            params = {"spp": args.spp, "denoise": False} if method == "pathtrace" else {}
            scene = {"volume": vol, "transfer_function": tf,
                     "camera": {"view": view},
                     "lights": [{"type": "point", "position": light_at, "intensity": 2e6}],
                     "clip_planes": [dict(plane, shadows_from_removed=shadows)],
                     "method": {"name": method, "params": params},
                     "image": {"width": args.size, "height": args.size, "display": "filmic"}}
            if method == "pathtrace":
                scene["effects"] = ["local_shadows", "global_shadows"]  # single scattering
            tag = f"{name}-{method}-{'true' if shadows else 'false'}"
            path = os.path.join(work, tag + ".json")
            with open(path, "w") as f:
                json.dump(scene, f)
            png = os.path.join(work, tag + ".png")
            st = render(exe, path, png, os.path.join(work, tag + ".stats.json"))
            clip = st.get("clip_local_visibility")
            rows.append({"method": method, "shadows_from_removed": shadows,
                         "total_seconds": round(st["total_seconds"], 2),
                         "clip_local_visibility": clip})
            tiles.append((Image.open(png).convert("RGB"),
                          f"{method}, shadows_from_removed: {'true' if shadows else 'false'}"))
            print(tag, rows[-1], file=sys.stderr)
        report[name] = rows
        mosaic([tiles], os.path.join(args.out, f"{name}.png"))
    with open(os.path.join(args.out, "renders.json"), "w") as f:
        json.dump(report, f, indent=1)


if __name__ == "__main__":
    main()
