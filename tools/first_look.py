#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Contact sheet of `voxlight render VOLUME` — no scene, every default chosen from the data — on
each volume of ../shared/datasets (files and DICOM folders) and Debian's Colin27 T1.

Each tile is titled with the file, the transfer function and view voxlight chose, and the seconds
the whole command took. Look at every tile: the anatomy should be recognisable, framed tightly,
and in the right anatomical orientation (anterior view: the patient's left on the image's right).

    /usr/bin/python3 tools/first_look.py [--build build] [--out docs/first-look]
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATASETS = os.path.join(ROOT, "..", "shared", "datasets")
VOLUMES = [
    "ct/abdomen-totalseg/example_ct.nii.gz", "ct/abdomen-totalseg/dicom",
    "ct/abdomen-totalseg/dicom-jpeg2000", "ct/ct-pitch-oblique.nii.gz", "ct/lidc2-chest.mha",
    "ct/headsq/quarter.nhdr", "ct/bonsai.vti", "ct/engine.vti",
    "mr/t1-brain-dicom-120", "mr/forearm-dicom-3slices", "mr/mr-gd-contrast.nii.gz",
    "mr/seg3d-t1.nii.gz", "mr/stroke-t1-brain.nii.gz", "mr/HeadMRVolume.mhd",
    "/usr/share/mricron/templates/ch2.nii.gz",
]
SIZE = 256


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "first-look"))
    args = ap.parse_args()
    exe = os.path.join(args.build, "voxlight")
    os.makedirs(args.out, exist_ok=True)
    work = tempfile.mkdtemp(prefix="voxlight-first-look-")
    tiles = []
    for rel in VOLUMES:
        path = rel if os.path.isabs(rel) else os.path.join(DATASETS, rel)
        if not os.path.exists(path):
            print(f"note: {rel} absent, skipped", file=sys.stderr)
            continue
        png = os.path.join(work, f"{len(tiles)}.png")
        stats = os.path.join(work, f"{len(tiles)}.json")
        t = time.perf_counter()
        r = subprocess.run([exe, "render", path, "-o", png, "--stats", stats, "-q",
                            "--set", f"image.width={SIZE}", "--set", f"image.height={SIZE}"],
                           capture_output=True, text=True)
        seconds = time.perf_counter() - t
        if r.returncode != 0:
            print(f"{rel}: exit {r.returncode}: {r.stderr.strip()}", file=sys.stderr)
            continue
        s = json.load(open(stats))
        title = (f"{os.path.basename(rel.rstrip('/'))}\n{s['transfer_function']['name']}, "
                 f"{s.get('camera_view', '')}, {seconds:.1f} s")
        warnings = s.get("warnings", [])
        print(f"{rel:45s} {s['transfer_function']['name']:14s} {s.get('camera_view', ''):18s} "
              f"{seconds:5.2f} s{'  WARN: ' + '; '.join(warnings) if warnings else ''}")
        tiles.append((png, title))
    cols = 5
    rows = (len(tiles) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(2.6 * cols, 2.9 * rows))
    for ax in axes.flat:
        ax.axis("off")
    for ax, (png, title) in zip(axes.flat, tiles):
        ax.imshow(plt.imread(png))
        ax.set_title(title, fontsize=7)
    fig.tight_layout()
    out = os.path.join(args.out, "contact-sheet.png")
    fig.savefig(out, dpi=72)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
