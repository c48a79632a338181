#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Plots and a Markdown report of `voxlight sweep` results: what accuracy costs in time.

    tools/sweep_report.py DIR [DIR ...] [--docs OUT] [--metric nrmse|flip|rmse_255|detected]

Each DIR is a `voxlight sweep --out DIR` folder (results.csv, reference.json, reference.png,
images/, maps/). For each it writes DIR/accuracy-vs-time.png (error against precompute seconds and
against frame seconds, one line per run, each point labelled with the value of the axis it varies;
the reference's own estimated error as a dotted floor), DIR/pareto.png (every variant by total
seconds = precompute + one frame; the Pareto front across methods joined), DIR/sheet.png
(reference | the most accurate variant of each run | its FLIP map) and DIR/report.md.

With --docs OUT the plots and sheets are copied to OUT/NAME-*.png and one OUT/report.md covers every
DIR, followed by the papers' own figures for the same trade-offs (../shared/papers/NOTES.md) so our
curves can be read beside them. Needs Debian's python3-matplotlib, python3-numpy, python3-pil.
"""
import argparse
import csv
import json
import math
import os
import shutil
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from PIL import Image  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from voxlight_cli import mosaic  # noqa: E402

METRICS = {
    "nrmse": "relative RMSE of the radiance (NRMSE)",
    "flip": "mean FLIP (display images)",
    "rmse_255": "RMSE of the display images (1/255 steps)",
    "detected": "fraction of pixels with FLIP > 0.05",
}

# What each method's paper reports for the same trade-off (from ../shared/papers/NOTES.md, their
# hardware and data): the numbers our curves are read beside.
PAPERS = {
    "sh-local": ("Kronander et al. 2012, Figs. 8–12",
                 "error (fraction of pixels HDR-VDP detects, >75 %) falls with rays up to a knee at "
                 "40–60 rays, time linear in rays; 1/4/9/16 SH coefficients (1 = ambient "
                 "occlusion); radius optimum 12–16 voxels; TF update 0.15–1.63 s on a GTX 295 "
                 "(engine 256³: 0.35 s local + 0.1 s global)."),
    "sh-global": ("Kronander et al. 2012, Figs. 8–12",
                  "global visibility adds 0.05–1.16 s to a TF update; error falls with the global "
                  "grid's resolution and with data reduction toward 1:1."),
    "ritschel": ("Ritschel 2007, Table 1",
                 "setup 70.4 s at 1:1, 12.3 s at 1:2, 4.0 s at 1:4, 2.3 s at 1:8 sub-sampling "
                 "(engine/foot 256³, N = 400, 8800 GTX); memory 256/64/16/4 MB; frame 36–76 ms."),
    "pathtrace": ("Kroes et al. 2012, Fig. 11",
                  "10 % NRMS against the converged image \"in a fraction of a second\" (GTX 470); "
                  "error ∝ 1/sqrt(spp)."),
    "pvrt": ("Zhang et al. 2013, Tables 1–2",
             "L2 error < 1 % against volumetric photon mapping with 10 photons per boundary voxel "
             "(DSF); CPCA 128 clusters 0.9 %, 32 clusters 2.2 %; precompute 73–395 s for "
             "256³–512³ (GTX 460M); light change ~1 ms."),
    "iso-lattice": ("Wyman et al. 2006, Figs. 11–12",
                    "against per-pixel path tracing (10,000 samples) the lattice converges with "
                    "samples per texel, ~100 samples/texel suffice (skull); hard shadows blur by "
                    "trilinear interpolation between texels on different isosurfaces; lattice "
                    "resolution 1/8, 1 and 8× the volume's (Fig. 12); precompute took hours on 30 "
                    "CPUs, render 10–50 fps (GeForce FX 5900)."),
}


def number(v):
    try:
        return float(v)
    except ValueError:
        return float("nan")


def load(d):
    with open(os.path.join(d, "results.csv"), newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        for k in ("precompute_s", "frame_s", "memory_mb", "nrmse", "rmse_255", "psnr_db", "ssim",
                  "flip", "detected", "reference_error"):
            r[k] = number(r[k])
        r["total_s"] = r["precompute_s"] + r["frame_s"]
    with open(os.path.join(d, "reference.json")) as f:
        ref = json.load(f)
    return rows, ref


def runs_of(rows):
    """{label: [rows]} in file order."""
    out = {}
    for r in rows:
        out.setdefault(r["label"], []).append(r)
    return out


def point_label(r):
    if r["axis"]:
        return "%s=%s" % (r["axis"], r["value"])
    return "base" if r["id"].endswith("-base") else ""


def ref_of(r):
    """Which reference a row was measured against: "0" (the sweep's) or a run's own N."""
    return (r.get("reference") or "0").strip()


def pareto(rows, metric):
    """Rows on the Pareto front of (total seconds, error): no other is both faster and better.
    Only rows measured against the sweep's own reference compete: an error against a run's own
    reference (another method's image) is not the same measure."""
    pts = sorted((r for r in rows if math.isfinite(r[metric]) and ref_of(r) == "0"),
                 key=lambda r: (r["total_s"], r[metric]))
    front, best = [], math.inf
    for r in pts:
        if r[metric] < best:
            front.append(r)
            best = r[metric]
    return front


def plot_accuracy(rows, ref, metric, out):
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8), sharey=True)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, (label, rs) in enumerate(runs_of(rows).items()):
        c = colours[i % len(colours)]
        for ax, x in zip(axes, ("precompute_s", "frame_s")):
            # One polyline per axis varied (through the base), so each curve is one parameter.
            groups = {}
            for r in rs:
                groups.setdefault(r["axis"], []).append(r)
            base = groups.pop("", [])
            first = True
            for axis, g in groups.items():
                g = sorted(base + g, key=lambda r: number(r["value"]) if r["value"] else 0)
                ax.plot([r[x] for r in g], [r[metric] for r in g], "-", color=c, alpha=0.35)
            own = ref_of(rs[0]) != "0"
            for r in rs:
                ax.plot(r[x], r[metric], "s" if own else "o", color=c, ms=5,
                        label=(label + (" (vs reference-%s)" % ref_of(rs[0]) if own else ""))
                        if first else None)
                first = False
                t = point_label(r)
                if t and x == "precompute_s":
                    ax.annotate(t, (r[x], r[metric]), fontsize=6, xytext=(3, 2),
                                textcoords="offset points", color=c)
    # Each reference's noise in nrmse's own terms (the rows' reference_error; absent from sweeps
    # run before 7 December, whose relative_std_error is normalised by the mean, not the RMS: no
    # floor drawn for them). A run with its own reference has its own floor: one line per
    # reference, named (reference 0's alone made a run's rows against another reference look as
    # if they had reached it).
    floors = {}
    for r in rows:
        if math.isfinite(r["reference_error"]) and r["reference_error"] > 0:
            floors[ref_of(r)] = r["reference_error"]
    for ax, x in zip(axes, ("precompute seconds (what a TF change costs)", "frame seconds")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(x)
        ax.grid(True, which="both", alpha=0.25)
        if metric == "nrmse":
            for k, floor in sorted(floors.items()):
                ax.axhline(floor, ls=":", color="grey" if k == "0" else "silver")
                ax.text(ax.get_xlim()[0], floor,
                        " reference's own error" if k == "0" else
                        " reference-%s's own error" % k, fontsize=7, va="bottom", color="grey")
    axes[0].set_ylabel(METRICS[metric])
    axes[0].legend(fontsize=8)
    what = ("the path-traced reference (%d spp)" % ref.get("spp", 0)
            if ref.get("method", "pathtrace") == "pathtrace" else "the %s reference (%s)" %
            (ref["method"], json.dumps(ref.get("params", {}))))
    if any(ref_of(r) != "0" for r in rows):
        what += "; squares: against their run's own reference"
    fig.suptitle("%s: %s against %s" % (ref.get("sweep", ""), METRICS[metric], what), fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def plot_pareto(rows, ref, metric, out):
    fig, ax = plt.subplots(figsize=(7, 4.8))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, (label, rs) in enumerate(runs_of(rows).items()):
        ax.plot([r["total_s"] for r in rs], [r[metric] for r in rs], "o",
                color=colours[i % len(colours)], ms=5, alpha=0.7, label=label)
    front = pareto(rows, metric)
    ax.plot([r["total_s"] for r in front], [r[metric] for r in front], "k-", lw=1,
            label="Pareto front")
    for r in front:
        ax.annotate(r["id"], (r["total_s"], r[metric]), fontsize=6, xytext=(3, 3),
                    textcoords="offset points")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("seconds: precompute + one frame")
    ax.set_ylabel(METRICS[metric])
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=8)
    title = "%s: which method is best for the time spent" % ref.get("sweep", "")
    if any(ref_of(r) != "0" for r in rows):
        title += "\n(front over the rows measured against the sweep's reference)"
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def best_of(rs, metric):
    finite = [r for r in rs if math.isfinite(r[metric])]
    return min(finite, key=lambda r: r[metric]) if finite else rs[0]


def sheet(d, rows, metric, out):
    ref = Image.open(os.path.join(d, "reference.png"))
    top, bottom = [(ref, "reference")], [(Image.new("RGB", ref.size), "FLIP maps 0..0.5")]
    for label, rs in runs_of(rows).items():
        b = best_of(rs, metric)
        img = os.path.join(d, "images", b["id"] + ".png")
        mp = os.path.join(d, "maps", b["id"] + ".png")
        if not (os.path.exists(img) and os.path.exists(mp)):
            continue
        top.append((Image.open(img), "%s %s" % (label, point_label(b))))
        bottom.append((Image.open(mp), "%s %.3f" % (metric, b[metric])))
    scale = max(1, round(256 / ref.size[0]))
    rows_ = [[(im.resize((im.size[0] * scale, im.size[1] * scale)), c) for im, c in row]
             for row in (top, bottom)]
    mosaic(rows_, out)


def table(rows, metric):
    lines = ["| run | varied | precompute s | frame s | memory MB | NRMSE | FLIP | SSIM | "
             "detected | RMSE /255 |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    front = {r["id"] for r in pareto(rows, metric)}
    for r in rows:
        mark = " ◆" if r["id"] in front else ""
        lines.append("| %s | %s%s | %.2f | %.3f | %.1f | %.3f | %.3f | %.3f | %.2f | %.1f |" % (
            r["label"], point_label(r) or "—", mark, r["precompute_s"], r["frame_s"],
            r["memory_mb"], r["nrmse"], r["flip"], r["ssim"], r["detected"], r["rmse_255"]))
    return "\n".join(lines)


def section(d, name, rows, ref, metric, prefix):
    scene = ref.get("scene", {})
    vol = scene.get("volume")
    img = scene.get("image", {})
    s = ["## %s" % name, ""]
    def describe_ref(r):
        if r.get("method", "pathtrace") == "pathtrace":
            return "path tracer %s, %d spp, estimated error %.1f %% (%s)" % (
                json.dumps(r.get("params", {})), r.get("spp", 0),
                100 * (r.get("relative_std_error") or 0),
                "cached" if r.get("cached") else "%.0f s" % r.get("seconds", 0))
        return "`%s` %s (%s)" % (r["method"], json.dumps(r.get("params", {})),
                                 "%.0f s" % r.get("seconds", 0))
    refs = "Reference: " + describe_ref(ref) + "".join(
        "; runs with their own: " + describe_ref(o) for o in ref.get("others", []))
    s.append("Scene: volume `%s`, TF `%s`, %s×%s pixels. %s. Each variant's time is charged in "
             "full for every precomputed field it reads (docs/sweeps.md); frame = median of %d." % (
                 json.dumps(vol) if isinstance(vol, dict) else os.path.basename(str(vol)),
                 scene.get("transfer_function", "?") if isinstance(
                     scene.get("transfer_function"), str) else "explicit points",
                 img.get("width", "?"), img.get("height", "?"), refs, ref.get("frames", 1)))
    s += ["", "![accuracy against time](%saccuracy-vs-time.png)" % prefix, "",
          "![Pareto front](%spareto.png)" % prefix, "",
          "![reference and the most accurate variant of each run](%ssheet.png)" % prefix, "",
          "◆ = on the Pareto front of (precompute + one frame, %s) among the rows measured against "
          "the sweep's reference; rows against a run's own reference are not ranked with them."
          % metric, "",
          table(rows, metric), ""]
    front = pareto(rows, metric)
    if front:
        s.append("Pareto front, fastest first: " + ", ".join(
            "`%s` (%.2f s, %.3f)" % (r["id"], r["total_s"], r[metric]) for r in front) + ".")
        s.append("")
    return s


# Axes along which a larger value is *less* accurate (coarser); every other axis: more accurate.
COARSER_WITH = {"data_reduction", "subsample"}
# A change smaller than this (relative) from the least to the most accurate setting reads "flat".
FLAT = 0.05


def trend(g, axis, metric):
    """'falls', 'flat' or 'rises': the error from the least to the most accurate numeric setting."""
    g = [r for r in g if math.isfinite(number(r["value"])) and math.isfinite(r[metric])]
    if len(g) < 2:
        return ""
    g = sorted(g, key=lambda r: number(r["value"]), reverse=axis in COARSER_WITH)
    a, b = g[0][metric], g[-1][metric]
    change = (b - a) / a if a > 0 else 0.0
    return "falls" if change < -FLAT else "**rises**" if change > FLAT else "**flat**"


def ours(rs, metric):
    """Our curve of one run in words: per axis, value → error (precompute s, frame s)."""
    base = [r for r in rs if r["id"].endswith("-base")]
    parts = []
    if base:
        b = base[0]
        parts.append("base %.3f (%.2f s + %.3f s)" % (b[metric], b["precompute_s"], b["frame_s"]))
    axes = {}
    for r in rs:
        if r["axis"]:
            axes.setdefault(r["axis"], []).append(r)
    for axis, g in axes.items():
        g = sorted(g, key=lambda r: number(r["value"]))
        t = trend(g, axis, metric)
        parts.append("%s%s: " % (axis, " (%s)" % t if t else "") + ", ".join(
            "%s → %.3f (%.2f s + %.3f s)" % (r["value"], r[metric], r["precompute_s"],
                                            r["frame_s"]) for r in g))
    if not parts:
        r = rs[0]
        parts.append("%.3f (%.2f s + %.3f s)" % (r[metric], r["precompute_s"], r["frame_s"]))
    return "; ".join(parts)


FINDINGS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "datasets", "sweeps",
                        "findings.md")


def papers_section(sweeps, metric):
    """`sweeps`: [(name, rows)]. Each paper's reported trade-off once, then our runs of its
    method: value → error (precompute s + frame s) along every axis."""
    s = ["## Beside the papers", "",
         "Their numbers come from their own GPUs, data and error measures; ours from 2 CPU cores, "
         "as %s (precompute s + frame s) per axis value. Read the shape of the curves (where "
         "error stops falling, how time grows with each parameter), not the absolute values." %
         metric, ""]
    for key, (where, text) in PAPERS.items():
        mine = [(name, label, rs) for name, rows in sweeps
                for label, rs in runs_of(rows).items()
                if rs[0]["method"] == key]
        if not mine:
            continue
        s.append("- **%s** — %s: %s" % (key, where, text))
        for name, label, rs in mine:
            s.append("  - ours, %s / `%s`: %s" % (name, label, ours(rs, metric)))
    s += ["", "(falls / flat / rises: the error from the least to the most accurate setting of "
          "an axis, flat within %d %%.)" % round(100 * FLAT), ""]
    if os.path.exists(FINDINGS):
        with open(FINDINGS) as f:
            s += [f.read()]
    return s


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("dirs", nargs="+")
    ap.add_argument("--docs", default=None, help="copy plots and write one report.md here")
    ap.add_argument("--metric", default="nrmse", choices=sorted(METRICS))
    args = ap.parse_args()
    combined, _ = ["# What accuracy costs in time", "",
                        "Generated by `tools/run_sweeps.sh` (`voxlight sweep` over "
                        "`datasets/sweeps/*.json`, then `tools/sweep_report.py`); "
                        "regenerate it when a method changes.", ""], []
    done = []
    for d in args.dirs:
        rows, ref = load(d)
        if not rows:
            print("%s: no rows" % d, file=sys.stderr)
            continue
        name = ref.get("sweep") or os.path.basename(os.path.normpath(d))
        plot_accuracy(rows, ref, args.metric, os.path.join(d, "accuracy-vs-time.png"))
        plot_pareto(rows, ref, args.metric, os.path.join(d, "pareto.png"))
        sheet(d, rows, args.metric, os.path.join(d, "sheet.png"))
        with open(os.path.join(d, "report.md"), "w") as f:
            f.write("\n".join(section(d, name, rows, ref, args.metric, "") +
                              papers_section([(name, rows)], args.metric)) + "\n")
        print("wrote %s" % os.path.join(d, "report.md"))
        if args.docs:
            os.makedirs(args.docs, exist_ok=True)
            for p in ("accuracy-vs-time.png", "pareto.png", "sheet.png"):
                shutil.copy(os.path.join(d, p), os.path.join(args.docs, "%s-%s" % (name, p)))
            shutil.copy(os.path.join(d, "results.csv"),
                        os.path.join(args.docs, "%s-results.csv" % name))
            combined += section(d, name, rows, ref, args.metric, name + "-")
            done.append((name, rows))
    if args.docs:
        with open(os.path.join(args.docs, "report.md"), "w") as f:
            f.write("\n".join(combined + papers_section(done, args.metric)) + "\n")
        print("wrote %s" % os.path.join(args.docs, "report.md"))


if __name__ == "__main__":
    main()
