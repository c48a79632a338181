#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Method iso-lattice side by side (issue #14; Wyman et al. 2006 Figs. 8-11): the torso phantom's
bone and the abdominal CT's bone, ray-cast as an isosurface and shaded six ways — Blinn-Phong with
ambient, Lambert, Lambert + hard shadows, vicinity shading, the illumination lattice, and paths
traced from every hit point — under a key and a fill light (datasets/scenes/torso-iso-lit.json's),
1 bounce. Each image's seconds and its NRMS against a reference (paths from every hit point with
--ref-samples paths) over the pixels both hit are printed, written to OUT/iso-lattice.json and
captioned in the mosaic OUT/iso-lattice.png (vicinity shading is lit by a white sky, not the
scene's lights: no NRMS; phong's lights are divided by π, its convention's factor against the
Lambertian radiance albedo·E/π).

    /usr/bin/python3 tools/iso_gallery.py [--build build] [--out docs/iso] [--size 256]
        [--samples 100] [--ref-samples 1000] [--phantom-size 256] [--datasets ../shared/datasets]

The abdominal CT row is skipped with a note when the file is absent.
"""
import argparse
import json
import math
import os
import shutil
import sys
import tempfile

import numpy as np
from PIL import Image

from voxlight_cli import DATASETS, ROOT, mosaic, read_exr, render

SHADINGS = ["phong", "lambert", "shadows", "vicinity", "lattice", "paths"]
LIGHTS = [{"type": "directional", "direction": [0.35, 0.75, -0.55], "intensity": 3.0},
          {"type": "directional", "direction": [-0.6, -0.5, -0.3], "intensity": 0.8}]
# name → (volume under the datasets dir, or None for the phantom; camera; isovalue HU)
CASES = {"torso": (None, {"azimuth": 30, "elevation": 15}, 250),
         "abdomen-ct": ("ct/abdomen-totalseg/example_ct.nii.gz", {"view": "anterior"}, 250)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "iso"))
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--samples", type=int, default=100)
    ap.add_argument("--ref-samples", type=int, default=1000)
    ap.add_argument("--phantom-size", type=int, default=256)
    ap.add_argument("--datasets", default=DATASETS)
    a = ap.parse_args()
    exe = os.path.join(a.build, "voxlight")
    os.makedirs(a.out, exist_ok=True)
    work = tempfile.mkdtemp(prefix="voxlight-iso-gallery-")  # scenes, stats, EXRs
    rows, labels, results = [], [], {}
    for case, (volume, camera, iso) in CASES.items():
        if volume is None:
            vol = {"phantom": "torso", "size": a.phantom_size}
        else:
            vol = os.path.join(a.datasets, volume)
            if not os.path.exists(vol):
                print(f"note: {vol} is absent; the {case} row is skipped", file=sys.stderr)
                continue
            vol = os.path.abspath(vol)

        def scene(shading, samples):
            params = {"iso_value": iso, "shading": shading}
            if shading in ("lattice", "paths", "vicinity"):
                params["samples"] = samples
            lights = LIGHTS
            if shading == "phong":
                # Blinn-Phong's clinical convention: irradiance 1 shows the albedo, π times the
                # Lambertian radiance albedo·E/π of the other shadings; scaled so that they compare.
                lights = [dict(l, intensity=l["intensity"] / math.pi) for l in LIGHTS]
            return {"volume": vol, "transfer_function": "ct-bone",
                    "method": {"name": "iso-lattice", "params": params},
                    "lights": lights, "camera": camera,
                    "image": {"width": a.size, "height": a.size}}

        ref_exr = os.path.join(work, f"{case}-reference.exr")
        st = render(exe, scene("paths", a.ref_samples), os.path.join(work, f"{case}-reference.png"),
                    os.path.join(work, f"{case}-reference.stats.json"), ["--exr", ref_exr])
        ref = read_exr(ref_exr, work)
        print(f"{case}: reference ({a.ref_samples} paths per hit pixel) "
              f"{st['total_seconds']:.1f} s", flush=True)
        row, results[case] = [], {}
        for shading in SHADINGS:
            png = os.path.join(work, f"{case}-{shading}.png")
            exr = os.path.join(work, f"{case}-{shading}.exr")
            st = render(exe, scene(shading, a.samples), png,
                        os.path.join(work, f"{case}-{shading}.stats.json"), ["--exr", exr])
            img = read_exr(exr, work)
            both = (img[..., 3] > 0) & (ref[..., 3] > 0)
            d = img[..., :3][both] - ref[..., :3][both]
            nrms = float(np.sqrt(np.mean(d * d)) / np.sqrt(np.mean(ref[..., :3][both] ** 2)))
            frame = next(s["seconds"] for s in st["stages"] if s["name"] == "render")
            entry = {"render_seconds": frame, "total_seconds": st["total_seconds"],
                     "nrms": None if shading == "vicinity" else nrms}
            if "lattice" in st.get("iso_lattice", {}):
                entry["texels_computed"] = st["iso_lattice"]["lattice"]["texels_computed"]
            entry["hit_pixels"] = st["iso_lattice"]["hit_pixels"]
            results[case][shading] = entry
            cap = f"{shading} {frame:.1f} s" + ("" if shading == "vicinity" else f" NRMS {nrms:.3f}")
            print(f"  {cap}", flush=True)
            row.append((Image.open(png), cap))
        rows.append(row)
        labels.append(case)
    if not rows:
        sys.exit("nothing rendered")
    mosaic(rows, os.path.join(a.out, "iso-lattice.png"))
    with open(os.path.join(a.out, "iso-lattice.json"), "w") as f:
        json.dump({"size": a.size, "samples": a.samples, "ref_samples": a.ref_samples,
                   "results": results}, f, indent=1)
    shutil.rmtree(work)
    print("wrote", os.path.join(a.out, "iso-lattice.png"))


if __name__ == "__main__":
    main()
