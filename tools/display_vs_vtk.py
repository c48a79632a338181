#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""voxlight's PNG display transforms next to VTK's image of the same view.

Same volume, transfer function (voxlight's, exported through --stats), camera and shading
coefficients as tools/bench_render_vs_vtk.py. For each case prints the 5th/50th/95th percentile of
the brightness (Rec. 709 luma, 0..255) over the pixels that show the object in either image, for
VTK and for voxlight's "clinical", "srgb" and "filmic" display transforms, and writes a side-by-side
picture (VTK | clinical | srgb | filmic) per case into --out.

    xvfb-run -a /usr/bin/python3 tools/display_vs_vtk.py [--build build] [--out docs/display]
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_render_vs_vtk import vtk_setup  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MODES = ["clinical", "srgb", "filmic"]
SIZE = 384


def luma(png):
    img = plt.imread(png)[..., :3].astype(np.float64)
    if img.max() <= 1.0:
        img = img * 255.0
    return img, 0.2126 * img[..., 0] + 0.7152 * img[..., 1] + 0.0722 * img[..., 2]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "display"))
    args = ap.parse_args()
    exe = os.path.join(args.build, "voxlight")
    os.makedirs(args.out, exist_ok=True)
    work = tempfile.mkdtemp(prefix="voxlight-display-")
    torso = os.path.join(work, "torso256.vti")
    subprocess.run([exe, "phantom", "torso", "-o", torso, "-q"], check=True)
    cases = [("torso phantom, ct-bone", torso, "ct-bone")]
    for name, rel, preset in (("bonsai CT, generic", "ct/bonsai.vti", "generic"),
                              ("engine CT, generic", "ct/engine.vti", "generic")):
        path = os.path.join(ROOT, "..", "shared", "datasets", rel)
        if os.path.exists(path):
            cases.append((name, os.path.abspath(path), preset))
        else:
            print(f"note: ../shared/datasets/{rel} absent, case skipped", file=sys.stderr)
    print(f"{'case':28s} {'image':9s} {'p5':>5s} {'p50':>5s} {'p95':>5s}   (luma 0..255 over the object)")
    fig, axes = plt.subplots(len(cases), 1 + len(MODES), figsize=(3.2 * (1 + len(MODES)), 3.4 * len(cases)))
    axes = np.atleast_2d(axes)
    for row, (name, path, preset) in enumerate(cases):
        scene = os.path.join(work, "scene.json")
        json.dump({"volume": path, "transfer_function": preset, "method": "gradient",
                   "camera": {"azimuth": 30, "elevation": 20},
                   "image": {"width": SIZE, "height": SIZE}}, open(scene, "w"))
        images = {}
        for mode in MODES:
            png = os.path.join(work, f"voxlight-{mode}.png")
            st = os.path.join(work, "stats.json")
            subprocess.run([exe, "render", scene, "-o", png, "--stats", st, "-q",
                            "--set", f"image.display={mode}"], check=True)
            images[mode] = png
        stats = json.load(open(st))
        _, _, save = vtk_setup(path, stats, SIZE)
        vtk_png = os.path.join(work, "vtk.png")
        save(vtk_png)
        _, vtk_luma = luma(vtk_png)
        lumas = {m: luma(images[m])[1] for m in MODES}
        mask = vtk_luma > 2.0
        for m in MODES:
            mask |= lumas[m] > 2.0
        for label, (img, l) in [("VTK", luma(vtk_png))] + [(m, luma(images[m])) for m in MODES]:
            p5, p50, p95 = np.percentile(l[mask], [5, 50, 95])
            print(f"{name:28s} {label:9s} {p5:5.0f} {p50:5.0f} {p95:5.0f}")
            col = 0 if label == "VTK" else 1 + MODES.index(label)
            ax = axes[row, col]
            ax.imshow(img.astype(np.uint8))
            ax.set_title(f"{label}: {name}\nluma p5/50/95 {p5:.0f}/{p50:.0f}/{p95:.0f}", fontsize=8)
            ax.axis("off")
    fig.tight_layout()
    out = os.path.join(args.out, "display-vs-vtk.png")
    fig.savefig(out, dpi=64)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
