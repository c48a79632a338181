# SPDX-License-Identifier: MIT
"""Helpers the gallery and benchmark scripts share to drive the voxlight CLI: where the shared
datasets are, a volume's world centre, one render of a scene (dict) with its stats, the seconds of
its precompute stages, reading a linear EXR, and a labelled mosaic of tiles (PIL).

    import voxlight_cli   # from a script in tools/ (its directory is on sys.path)
"""
import json
import os
import subprocess
import sys

import numpy as np
from PIL import Image, ImageDraw

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# The shared datasets beside the repository (../shared/datasets relative to it).
DATASETS = os.path.join(ROOT, "..", "shared", "datasets")


def centre(exe, volume):
    """World centre of a volume file (mm) from `voxlight info --json`."""
    r = subprocess.run([exe, "info", "--json", volume], capture_output=True, text=True, check=True)
    info = json.loads(r.stdout)
    half = [e / 2 for e in info["extent_mm"]]
    cols = info["direction_columns"]
    return [info["origin_mm"][row] + sum(cols[c][row] * half[c] for c in range(3))
            for row in range(3)]


def resolve_volume(exe, volume, datasets, phantom_size):
    """The scene's volume entry and its world centre: the torso phantom (centred on the origin)
    when `volume` is None, else the file under `datasets`; (None, None) with a note when absent."""
    if volume is None:
        return {"phantom": "torso", "size": phantom_size}, [0.0, 0.0, 0.0]
    path = os.path.join(datasets, volume)
    if not os.path.exists(path):
        print(f"note: {path} is absent; skipped", file=sys.stderr)
        return None, None
    return path, centre(exe, path)


def render(exe, scene, out_png, stats, extra=()):
    """Renders `scene` (a path, or a dict written beside `stats` as .scene.json) to `out_png`;
    returns the stats. Exits with the CLI's message when it fails."""
    if isinstance(scene, dict):
        path = os.path.splitext(stats)[0] + ".scene.json"
        with open(path, "w") as f:
            json.dump(scene, f)
        scene = path
    r = subprocess.run([exe, "render", scene, "-o", out_png, "--stats", stats, "-q", *extra],
                       capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{scene}: exit {r.returncode}: {r.stderr.strip()}")
    with open(stats) as f:
        return json.load(f)


def stage_seconds(stats, kind="precompute"):
    """{stage name: seconds} of the stages of `kind` that ran (were computed, not cached)."""
    return {s["name"]: s["seconds"] for s in stats["stages"] if s["ran"] and s["kind"] == kind}


def read_exr(path, work):
    """Linear RGBA as float32: one float TIFF per channel via oiiotool (PIL reads mode F; Debian 12
    has no Python OpenImageIO). `work` is a directory for the temporary TIFFs."""
    tifs = [os.path.join(work, "tmp-%s.tif" % c) for c in "RGBA"]
    cmd = ["oiiotool", path]
    for c, t in zip("RGB", tifs):
        cmd += ["--dup", "--ch", c, "-d", "float", "-o", t, "--pop"]
    cmd += ["--ch", "A", "-d", "float", "-o", tifs[3]]
    subprocess.run(cmd, check=True, capture_output=True)
    a = np.stack([np.asarray(Image.open(t), dtype=np.float32) for t in tifs], axis=2)
    for t in tifs:
        os.remove(t)
    return a


def mosaic(rows, out_png, col_labels=None, row_labels=None, label_h=18, row_label_w=0):
    """Writes a grid of tiles: `rows` is a list of rows, each a list of (PIL image, caption or
    None); optional column labels above and row labels at the left (row_label_w pixels wide)."""
    w, h = rows[0][0][0].size
    top = label_h if col_labels else 0
    cap = label_h if any(c for row in rows for _, c in row) else 0
    cols = max(len(r) for r in rows)
    sheet = Image.new("RGB", (row_label_w + w * cols, top + (h + cap) * len(rows)), "black")
    draw = ImageDraw.Draw(sheet)
    for j, text in enumerate(col_labels or []):
        draw.text((row_label_w + j * w + 4, 3), text, fill="white")
    for i, row in enumerate(rows):
        y = top + i * (h + cap)
        if row_labels:
            for k, line in enumerate(row_labels[i].split("\n")):
                draw.text((4, y + cap + 4 + 13 * k), line, fill="white")
        for j, (im, text) in enumerate(row):
            sheet.paste(im.convert("RGB"), (row_label_w + j * w, y + cap))
            if text:
                draw.text((row_label_w + j * w + 4, y + 3), text, fill="white")
    sheet.save(out_png, optimize=True)
