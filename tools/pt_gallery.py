#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Path tracer gallery (issue #13; Kroes et al. 2012 Figs. 1, 7–9): the torso phantom (ct-bone) and
the abdominal CT under the courtyard environment map, then with an area light added, then with
depth of field (thin lens, autofocus on the first visible surface at the image centre) and finally
all of it with multiple scattering. Each tile's scene is written to OUT/gallery/<case>-<tile>.json
(paths relative to that file, so the committed scenes render as they are) and rendered from there;
the mosaic goes to OUT/gallery.png and the seconds, spp and estimated errors to
OUT/gallery/renders.json.

    /usr/bin/python3 tools/pt_gallery.py [--build build] [--out docs/pathtrace] [--size 256]
        [--spp 128] [--phantom-size 128] [--datasets ../shared/datasets]

The abdominal CT row is skipped with a note when the file is absent.
"""
import argparse
import json
import os
import sys

from PIL import Image

from voxlight_cli import DATASETS, ROOT, centre, mosaic, render

# name → (volume under the datasets dir, or None for the phantom; view; TF)
CASES = {"torso": (None, "oblique", "ct-bone"),
         "abdomen-ct": ("ct/abdomen-totalseg/example_ct.nii.gz", "anterior", "ct-bone")}
ENVIRONMENT = "env/courtyard.hdr"
ENV_INTENSITY = 0.4
APERTURE_MM = 60.0  # thin-lens diameter: what lies behind the focused surface blurs visibly
# Area light: a disk above the patient's right shoulder and in front (LPS: −x, −y, +z), facing the
# volume's centre.
AREA_OFFSET_MM = [-250.0, -300.0, 350.0]
AREA_RADIUS_MM = 80.0
AREA_RADIANCE = 100.0
# tile label → (area light, aperture, multiple scattering)
TILES = [("environment", False, False, False),
         ("+ area light", True, False, False),
         ("+ depth of field", True, True, False),
         ("+ multiple scattering", True, True, True)]


def case_scene(volume_entry, world_centre, view, tf, env_path, size, spp, area, lens, multiple):
    lights = [{"type": "environment", "path": env_path, "intensity": ENV_INTENSITY}]
    if area:
        pos = [c + o for c, o in zip(world_centre, AREA_OFFSET_MM)]
        n = [-o for o in AREA_OFFSET_MM]
        norm = sum(v * v for v in n) ** 0.5
        lights.append({"type": "area", "shape": "disk", "position": pos,
                       "normal": [v / norm for v in n], "radius": AREA_RADIUS_MM,
                       "intensity": AREA_RADIANCE})
    camera = {"view": view}
    if lens:
        camera.update({"aperture": APERTURE_MM, "focus_distance": "auto"})
    effects = ["local_shadows", "global_shadows"] + (["multiple_scattering"] if multiple else [])
    return {"volume": volume_entry, "transfer_function": tf, "camera": camera, "lights": lights,
            "effects": effects,
            "method": {"name": "pathtrace", "params": {"spp": spp}},
            "image": {"width": size, "height": size, "display": "filmic"}}


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "pathtrace"))
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--spp", type=int, default=128)
    ap.add_argument("--phantom-size", type=int, default=128)
    ap.add_argument("--datasets", default=DATASETS, help="the shared datasets directory")
    args = ap.parse_args()
    exe = os.path.join(args.build, "voxlight")
    scenes_dir = os.path.join(args.out, "gallery")
    os.makedirs(scenes_dir, exist_ok=True)
    datasets = os.path.abspath(args.datasets)
    # Paths in the committed scenes are relative to the scene files.
    rel = lambda p: os.path.relpath(p, os.path.abspath(scenes_dir))
    env = os.path.join(datasets, ENVIRONMENT)
    if not os.path.exists(env):
        sys.exit(f"{env} is absent: the gallery needs the environment map")
    rows, row_labels, report = [], [], {}
    for name, (volume, view, tf) in CASES.items():
        if volume is None:
            entry, world_centre = {"phantom": "torso", "size": args.phantom_size}, [0.0] * 3
        else:
            path = os.path.join(datasets, volume)
            if not os.path.exists(path):
                print(f"note: {path} is absent; the {name} row is skipped", file=sys.stderr)
                continue
            entry, world_centre = rel(path), centre(exe, path)
        tiles, runs = [], []
        for label, area, lens, multiple in TILES:
            tag = name + "-" + label.strip("+ ").replace(" ", "-")
            scene = case_scene(entry, world_centre, view, tf, rel(env), args.size, args.spp, area,
                               lens, multiple)
            scene_path = os.path.join(scenes_dir, tag + ".json")
            with open(scene_path, "w") as f:
                json.dump(scene, f, indent=1)
            png = os.path.join(scenes_dir, tag + ".png")
            st = render(exe, scene_path, png, os.path.join(scenes_dir, tag + ".stats.json"))
            details = st.get("details", st)
            pt = details["pathtrace"]
            runs.append({"tile": label, "scene": os.path.basename(scene_path),
                         "spp": pt["spp"], "trace_seconds": round(pt["seconds"], 2),
                         "relative_std_error": round(pt["relative_std_error"], 4),
                         "denoised": details.get("denoise", {}).get("applied", False)})
            tiles.append((Image.open(png).convert("RGB"),
                          f"{label}: {runs[-1]['trace_seconds']} s"))
            os.remove(png)
            os.remove(os.path.join(scenes_dir, tag + ".stats.json"))
            print(tag, runs[-1], file=sys.stderr, flush=True)
        rows.append(tiles)
        row_labels.append(name)
        report[name] = runs
    mosaic(rows, os.path.join(args.out, "gallery.png"), row_labels=row_labels, row_label_w=90)
    with open(os.path.join(scenes_dir, "renders.json"), "w") as f:
        json.dump({"size": args.size, "spp": args.spp, "renders": report}, f, indent=1)


if __name__ == "__main__":
    main()
