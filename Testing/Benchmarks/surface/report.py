#!/usr/bin/env python3
"""Report of the active surface benchmark: report.py OUT (the folder run.sh wrote).

Reads OUT/machine.txt, OUT/surface_sweep.csv and OUT/surface_speed.json; writes
OUT/error_vs_shift.png, OUT/error_vs_corruption.png and OUT/summary.md.
"""
import csv
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))
from benchmark_common import (  # noqa: E402  (benchmark_common.py is in the folder above)
    load_json, machine_section, output_folder, plt, report_missing, save_atomically, table_row,
    write_atomically)

# Targets of the surface stage (issue 7), on the built-in case.
MEAN_ERROR_TARGET = 0.5
P95_ERROR_TARGET = 1.5
RESIDUAL_TARGET = 0.5
SECONDS_TARGET = 2.0
METHODS = (("segmentation", "o", "segmentation alone"), ("guarded", "s", "image-guarded (default)"),
           ("image-refined", "^", "image-refined"))


def number(text):
    return float(text) if text not in ("", None) else None


def chart(rows, variable, target, xlabel, title, path, reference=None):
    fig, (mean_axis, p95_axis) = plt.subplots(1, 2, figsize=(11, 4.2))
    for method, marker, label in METHODS:
        for tgt, style in ((t, "-" if t == target[0] else "--") for t in target):
            points = sorted((number(r["value"]), r) for r in rows
                            if r["variable"] == variable and r["method"] == method and r["target"] == tgt)
            if not points:
                continue
            xs = [x for x, _ in points]
            name = f"{label}, {tgt}" if len(target) > 1 else label
            mean_axis.plot(xs, [number(r["mean_error_mm"]) for _, r in points], marker=marker, linestyle=style, label=name)
            p95_axis.plot(xs, [number(r["p95_error_mm"]) for _, r in points], marker=marker, linestyle=style, label=name)
    if reference:
        xs, means, p95s = reference
        mean_axis.plot(xs, means, color="grey", linestyle=":", label="no deformation (rigid only)")
        p95_axis.plot(xs, p95s, color="grey", linestyle=":", label="no deformation (rigid only)")
    mean_axis.axhline(MEAN_ERROR_TARGET, color="red", linewidth=0.8, label=f"target {MEAN_ERROR_TARGET:g} mm")
    p95_axis.axhline(P95_ERROR_TARGET, color="red", linewidth=0.8, label=f"target {P95_ERROR_TARGET:g} mm")
    mean_axis.set(xlabel=xlabel, ylabel="mean displacement error (mm)", title=title)
    p95_axis.set(xlabel=xlabel, ylabel="95th percentile error (mm)", title=title)
    for axis in (mean_axis, p95_axis):
        axis.grid(True, alpha=0.3)
        axis.legend(fontsize=7)
    fig.tight_layout()
    save_atomically(fig, path)


def main():
    out = output_folder()
    path = os.path.join(out, "surface_sweep.csv")
    if not os.path.exists(path):
        report_missing(path)
        sys.exit(1)
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    speed_path = os.path.join(out, "surface_speed.json")
    speed = load_json(speed_path) if os.path.exists(speed_path) else None

    # Doing nothing (the rigid alignment alone) errs by the true displacement itself.
    shift_rows = sorted({number(r["value"]): r for r in rows if r["variable"] == "shift" and r["target"] == "truth"}.items())
    reference = ([x for x, _ in shift_rows], [number(r["true_mean_mm"]) for _, r in shift_rows], None)
    reference = (reference[0], reference[1], [float("nan")] * len(reference[0]))
    chart(rows, "shift", ("truth", "classified"), "peak brain shift (mm)", "Error against shift size",
          os.path.join(out, "error_vs_shift.png"), reference)
    chart(rows, "corruption", ("corrupted",), "brain mask corruption (mm, s.d. of the boundary error)",
          "Error against a corrupted segmentation", os.path.join(out, "error_vs_corruption.png"))

    lines = ["# Active surface benchmark", "",
             "The built-in case (Colin27, intraoperative scan 256x256x60 at 0.94x0.94x2.5 mm) meshed at "
             f"{speed['mesh_resolution_mm'] if speed else '?'} mm; the brain surface's displacements compared with "
             "the truth (R(T^-1(x)) - x at each imposed node, in the model frame of the rigid result used). "
             "Error: |estimated - true displacement|; moving: nodes that truly move more than 2 mm; residual: "
             "how far a node ends from the true intraoperative boundary against how far it started from the "
             "preoperative one. Targets: "
             f"mean <= {MEAN_ERROR_TARGET:g} mm, p95 <= {P95_ERROR_TARGET:g} mm, residual <= {RESIDUAL_TARGET:g} mm, "
             f"stage <= {SECONDS_TARGET:g} s.", "",
             "Methods: *segmentation alone* (distance map of the intraoperative brain); *image-guarded* (the "
             "default: where the expected local contrast contradicts the segmentation, the image's edge decides); "
             "*image-refined* (the image's edge also refines the segmentation everywhere, weight 0.5).", "",
             table_row(["variable", "value", "target", "method", "mean (mm)", "p95 (mm)", "max (mm)",
                        "moving: error / true (mm)", "residual (mm)", "iterations", "time (s)"]),
             table_row(["---"] * 11)]
    for r in rows:
        lines.append(table_row([r["variable"], r["value"], r["target"], r["method"],
                                f"{number(r['mean_error_mm']):.2f}", f"{number(r['p95_error_mm']):.2f}",
                                f"{number(r['max_error_mm']):.2f}",
                                f"{number(r['moving_mean_error_mm']):.2f} / {number(r['moving_true_mm']):.2f}",
                                f"{number(r['residual_true_mm']):.2f}", r["iterations"], f"{number(r['seconds']):.2f}"]))
    lines += ["", "![error against shift](error_vs_shift.png)", "",
              "![error against corrupted masks](error_vs_corruption.png)", ""]
    if speed:
        lines += ["## Speed", "",
                  f"Stage on the default case (median of {speed['runs']} runs, {speed['surface_nodes']} surface nodes, "
                  f"{speed['iterations']} iterations): {speed['seconds_median']:.2f} s, of which the fit to the "
                  f"preoperative boundary (preparable before surgery) {speed['preop_boundary_seconds_median']:.2f} s, "
                  f"the intraoperative distance map {speed['target_seconds_median']:.2f} s and the iterations "
                  f"{speed['iteration_seconds_median']:.2f} s.", ""]
    lines += machine_section(out)
    write_atomically(os.path.join(out, "summary.md"), "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
