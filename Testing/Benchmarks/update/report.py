#!/usr/bin/env python3
"""Report of the whole-update benchmark: report.py OUT (the folder run.sh wrote).

Reads OUT/machine.txt and OUT/update_bench.csv; writes OUT/tre_vs_time.png (mean landmark TRE
against wall time, one point per setting, the Pareto front marked, the rigid registration alone
for reference) and OUT/summary.md.
"""
import csv
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))
from benchmark_common import (  # noqa: E402  (benchmark_common.py is in the folder above)
    machine_section, output_folder, plt, report_missing, save_atomically, table_row, write_atomically)

TRE_MEAN_TARGET = 1.0
TRE_P95_TARGET = 2.0
FIRST_SCAN_SECONDS = 10.0


def number(text):
    return float(text) if text not in ("", None) else None


def pareto(points):
    """The points no other point beats in both time and TRE (lower is better in both)."""
    front = []
    for p in sorted(points, key=lambda p: (p[0], p[1])):
        if not front or p[1] < front[-1][1]:
            front.append(p)
    return front


def main():
    out = output_folder()
    path = os.path.join(out, "update_bench.csv")
    if not os.path.exists(path):
        report_missing(path)
        sys.exit(1)
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    default = [r for r in rows if r["case"] == "default"]
    settings = [r for r in default if r["method"] == "brainshift"]
    rigid = [r for r in default if r["method"] == "rigid"]

    fig, axis = plt.subplots(figsize=(8, 5.2))
    points = [(number(r["total_seconds"]), number(r["tre_mean_mm"]), r) for r in settings]
    axis.scatter([t for t, _, _ in points], [e for _, e, _ in points], color="tab:blue", zorder=3,
                 label="brainshift, one point per setting")
    for r in rigid:
        axis.scatter(number(r["total_seconds"]), number(r["tre_mean_mm"]), color="black", marker="x", s=60,
                     label="rigid registration alone", zorder=3)
    # The front over every point, the rigid registration included (it is the fastest).
    everything = [(t, e, r) for t, e, r in points] + [(number(r["total_seconds"]), number(r["tre_mean_mm"]), r) for r in rigid]
    front = pareto([(t, e) for t, e, _ in everything])
    if front:
        axis.plot([t for t, _ in front], [e for _, e in front], color="tab:red", linewidth=1.2, marker="o",
                  markerfacecolor="none", markersize=11, label="Pareto front", zorder=2)
    for t, e, r in everything:
        if (t, e) in set(front) and r["method"] == "brainshift":
            axis.annotate(f"{number(r['mesh_resolution_mm']):g} mm, rtol {number(r['solver_rtol']):.0e}, "
                          f"{r['surface_iterations']} it", (t, e), fontsize=7, xytext=(4, -12), textcoords="offset points")
    axis.axhline(TRE_MEAN_TARGET, color="grey", linestyle="--", linewidth=0.8, label=f"target {TRE_MEAN_TARGET:g} mm")
    axis.axvline(FIRST_SCAN_SECONDS, color="grey", linestyle=":", linewidth=0.8, label=f"first scan {FIRST_SCAN_SECONDS:g} s")
    axis.set(xlabel="wall time of register (s)", ylabel="landmark TRE, mean (mm)",
             title="The whole update on the built-in case: accuracy against speed")
    axis.grid(True, alpha=0.3)
    axis.legend(fontsize=8)
    fig.tight_layout()
    save_atomically(fig, os.path.join(out, "tre_vs_time.png"))

    columns = ["case", "method", "mesh (mm)", "rtol", "surface it.", "equations", "total (s)", "rigid", "classify", "mesh",
               "surface", "simulate", "solve", "warp", "TRE mean", "p95", "max", "craniotomy", "near cavity", "brain",
               "folded voxels"]
    keys = ["case", "method", "mesh_resolution_mm", "solver_rtol", "surface_iterations", "equations", "total_seconds",
            "rigid_seconds", "classify_seconds", "mesh_seconds", "surface_seconds", "simulate_seconds",
            "simulate_solve_seconds", "warp_seconds", "tre_mean_mm", "tre_p95_mm", "tre_max_mm", "tre_craniotomy_mm",
            "tre_near_cavity_mm", "tre_brain_mm", "folded_voxels"]

    def cell(key, value):
        if value in ("", None):
            return ""
        if key.endswith("_seconds") or key.startswith("tre_"):
            return f"{float(value):.2f}"
        return value

    front_set = set(front)
    lines = ["# The whole update: speed against accuracy", "",
             "`brainshift register` on the built-in case (files and all), one row per setting; times in seconds, "
             "TRE in mm over the case's 46 landmarks (groups: craniotomy, near the cavity, deep brain). "
             f"Targets: TRE mean <= {TRE_MEAN_TARGET:g} mm and p95 <= {TRE_P95_TARGET:g} mm, the first scan "
             f"<= {FIRST_SCAN_SECONDS:g} s. Pareto-optimal settings of the default case are marked *.", "",
             table_row(columns), table_row(["---"] * len(columns))]
    for r in rows:
        cells = [cell(k, r[k]) for k in keys]
        if r["case"] == "default" and (number(r["total_seconds"]), number(r["tre_mean_mm"])) in front_set:
            cells[1] = r["method"] + " *"
        lines.append(table_row(cells))
    lines += ["", "![TRE against time](tre_vs_time.png)", ""]
    lines += machine_section(out)
    write_atomically(os.path.join(out, "summary.md"), "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
