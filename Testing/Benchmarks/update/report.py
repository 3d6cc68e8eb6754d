#!/usr/bin/env python3
"""Report of the whole-update benchmark: report.py OUT (the folder run.sh wrote).

Reads OUT/machine.txt and OUT/update_bench.csv (with elastix.py's rows "elastix rigid" and
"elastix rigid+bspline" when run.sh ran it, and their OUT/runs/<case>/elastix/elastix_result.json
when present); writes OUT/tre_vs_time.png (mean landmark TRE against wall time, one point per
setting, the Pareto front marked, the rigid registration alone and elastix for reference) and
OUT/summary.md (the table, and "Against elastix": BrainShift's default setting beside elastix, per
case). Rows may be missing: what is there is reported.
"""
import csv
import json
import os
import sys

from matplotlib import ticker

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))
from benchmark_common import (  # noqa: E402  (benchmark_common.py is in the folder above)
    machine_section, output_folder, plt, report_missing, save_atomically, table_row, write_atomically)

TRE_MEAN_TARGET = 1.0
TRE_P95_TARGET = 2.0
FIRST_SCAN_SECONDS = 10.0
LATER_SCAN_SECONDS = 5.0
LATER_SCAN = "brainshift-later-scan"  # register --previous after an earlier scan of the case
WATCH_LATER_SCAN = "brainshift-watch-later-scan"  # the same two scans in one `brainshift watch` session
STAGES = ["rigid", "classify", "mesh", "surface", "simulate", "warp"]
# BrainShift's default setting (Logic/Common/Configuration.h: mesh 4 mm, 200 active-surface
# iterations; the simulate stage's -ksp_rtol 1e-5), the one a user runs and the variants run.
DEFAULT_MESH_MM = 4.0
DEFAULT_SOLVER_RTOL = 1e-5
DEFAULT_SURFACE_ITERATIONS = 200
DEFAULT_MESH_GRADING = 0.0  # uniform lattice
# elastix.py's rows: chart style and names.
ELASTIX = {
    "elastix rigid": {"color": "tab:green", "marker": "s", "label": "elastix 5 rigid", "name": "elastix rigid"},
    "elastix rigid+bspline": {"color": "tab:purple", "marker": "D", "label": "elastix 5 rigid + B-spline",
                              "name": "elastix rigid + B-spline"},
}


def number(text):
    return float(text) if text not in ("", None) else None


def close(a, b):
    return a is not None and b is not None and abs(a - b) <= 1e-9 * max(abs(a), abs(b), 1e-300)


def default_rigid(r):
    """The rigid registration at its defaults (all samples, 3 levels); older files have no such columns."""
    sampling, levels = number(r.get("rigid_sampling")), number(r.get("rigid_levels"))
    return (sampling is None or close(sampling, 1.0)) and (levels is None or close(levels, 3))


def mesh_grading(r):
    """The row's mesh grading; older files have no such column (uniform)."""
    grading = number(r.get("mesh_grading"))
    return 0.0 if grading is None else grading


def default_setting(rows):
    """The case's brainshift row at BrainShift's default setting; else its only brainshift row (the
    variants of an older run, at another setting); else the default mesh and iterations at the
    loosest tolerance; else None."""
    candidates = [r for r in rows if r["method"] == "brainshift" and default_rigid(r)]
    for r in candidates:
        if (close(number(r["mesh_resolution_mm"]), DEFAULT_MESH_MM) and close(number(r["solver_rtol"]), DEFAULT_SOLVER_RTOL)
                and close(number(r["surface_iterations"]), DEFAULT_SURFACE_ITERATIONS)
                and abs(mesh_grading(r) - DEFAULT_MESH_GRADING) < 1e-9):
            return r
    if len(candidates) == 1:
        return candidates[0]
    near = [r for r in candidates if close(number(r["mesh_resolution_mm"]), DEFAULT_MESH_MM)
            and close(number(r["surface_iterations"]), DEFAULT_SURFACE_ITERATIONS) and number(r["solver_rtol"]) is not None]
    return max(near, key=lambda r: number(r["solver_rtol"])) if near else None


def setting_text(r):
    mesh, rtol, iterations = number(r["mesh_resolution_mm"]), number(r["solver_rtol"]), r["surface_iterations"]
    rigid = [] if default_rigid(r) else [f"rigid {number(r['rigid_sampling']):g} of the samples, "
                                         f"{int(number(r['rigid_levels']))} levels"]
    graded = [f"graded {mesh_grading(r):g}"] if mesh is not None and mesh_grading(r) > 0 else []
    return ", ".join(([f"{mesh:g} mm"] if mesh is not None else []) + graded + ([f"rtol {rtol:.0e}"] if rtol is not None else [])
                     + ([f"{iterations} it."] if iterations else []) + rigid)


def elastix_parameters(name):
    """The '(Key value ...)' entries of update/elastix/<name> (values as strings; {} when missing)."""
    entries = {}
    try:
        with open(os.path.join(os.path.dirname(os.path.realpath(__file__)), "elastix", name)) as f:
            for line in f:
                line = line.split("//", 1)[0].strip()
                if line.startswith("(") and line.endswith(")") and len(line[1:-1].split()) > 1:
                    words = line[1:-1].split()
                    entries[words[0]] = [w.strip('"') for w in words[1:]]
    except OSError:
        pass
    return entries


def bspline_description():
    """What update/elastix/bspline.txt sets, in a few words."""
    p = elastix_parameters("bspline.txt")
    words = []
    if "FinalGridSpacingInPhysicalUnits" in p:
        words.append(f"{float(p['FinalGridSpacingInPhysicalUnits'][0]):g} mm final grid")
    metrics = p.get("Metric", [])
    names = {"AdvancedMattesMutualInformation": "Mattes MI", "TransformBendingEnergyPenalty": "bending energy"}
    terms = []
    for i, metric in enumerate(metrics):
        weight = p.get(f"Metric{i}Weight", ["1"])[0]
        terms.append(names.get(metric, metric) + (f" (weight {float(weight):g})" if len(metrics) > 1 and i > 0 else ""))
    if terms:
        words.append(" plus ".join(terms))
    if "NumberOfResolutions" in p:
        words.append(f"{p['NumberOfResolutions'][0]} levels")
    return ", ".join(words)


def elastix_result(out, case):
    """OUT/runs/<case>/elastix/elastix_result.json (elastix.py), or None."""
    path = os.path.join(out, "runs", case, "elastix", "elastix_result.json")
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def against_elastix(out, rows):
    """The "Against elastix" section: per case with elastix rows, BrainShift's default setting and its
    rigid stage beside elastix rigid and rigid + B-spline, and what the figures say."""
    cases = []
    for r in rows:
        if r["method"] in ELASTIX and r["case"] not in cases:
            cases.append(r["case"])
    if not cases:
        return []

    def mm(r, key):
        value = number(r.get(key)) if r else None
        return value if value is not None and value >= 0 else None  # -1: the case has no such landmarks

    def text(value, digits=2):
        return "" if value is None else f"{value:.{digits}f}"

    def figures(r):
        if mm(r, "tre_mean_mm") is None:
            return "no result"
        return (f"TRE {text(mm(r, 'tre_mean_mm'))} mm mean, {text(mm(r, 'tre_p95_mm'))} p95"
                + (f" in {text(mm(r, 'total_seconds'), 1)} s" if mm(r, "total_seconds") is not None else ""))

    columns = ["case", "method", "setting", "time (s)", "TRE mean", "p95", "max", "craniotomy", "near cavity", "brain",
               "folded voxels"]
    lines = ["## Against elastix", "",
             "elastix 5 on the same images of each case (`update/elastix.py`): fixed = the intraoperative image, moving = "
             "the preoperative one, so its transform maps intraoperative to preoperative points as BrainShift's "
             "intraop_to_preop; rigid (`update/elastix/rigid.txt`: Euler, Mattes MI, 3 levels, adaptive stochastic "
             "gradient descent, geometric-centre start) and rigid then B-spline in one call (`update/elastix/bspline.txt`: "
             f"{bspline_description()}), fixed seeds, `-threads 2`, no mask. "
             "Time: the elastix process (reading the images included; BrainShift's is `register`, files and all); "
             "transformix mapping the landmarks is not counted. TRE as for BrainShift, over the same landmarks; folded "
             "voxels: Jacobian determinant <= 0 on the intraoperative grid.", "",
             table_row(columns), table_row(["---"] * len(columns))]
    sentences = []
    for case in cases:
        of_case = [r for r in rows if r["case"] == case]
        default = default_setting(of_case)
        picked = [("BrainShift", default), ("BrainShift rigid stage", next((r for r in of_case if r["method"] == "rigid"), None))]
        picked += [(style["name"], next((r for r in of_case if r["method"] == method), None)) for method, style in ELASTIX.items()]
        for name, r in picked:
            if r is None:
                continue
            lines.append(table_row([case, name, setting_text(r) if name == "BrainShift" else "", text(mm(r, "total_seconds")),
                                    text(mm(r, "tre_mean_mm")), text(mm(r, "tre_p95_mm")), text(mm(r, "tre_max_mm")),
                                    text(mm(r, "tre_craniotomy_mm")), text(mm(r, "tre_near_cavity_mm")),
                                    text(mm(r, "tre_brain_mm")), r.get("folded_voxels") or ""]))
        rigid = picked[2][1]
        bspline = picked[3][1]
        parts = []
        if default is not None:
            parts.append(f"BrainShift ({setting_text(default)}) {figures(default)}")
        if bspline is not None:
            parts.append(f"elastix rigid + B-spline {figures(bspline)}")
        if rigid is not None:
            own = picked[1][1]
            parts.append(f"elastix rigid {figures(rigid)}" + (f" (BrainShift's rigid stage: {figures(own)})" if own else ""))
        sentence = f"- **{case}**: " + "; ".join(parts) + "."
        if default is not None and bspline is not None:
            verdicts = []
            for key, what in [("tre_mean_mm", "mean"), ("tre_p95_mm", "p95"), ("tre_max_mm", "max")]:
                a, b = mm(default, key), mm(bspline, key)
                if a is not None and b is not None:
                    verdicts.append(f"{what} {'lower' if a < b else 'higher' if a > b else 'equal'} "
                                    f"({a:.2f} against {b:.2f} mm)")
            t, u = mm(default, "total_seconds"), mm(bspline, "total_seconds")
            if verdicts:
                sentence += " Against elastix rigid + B-spline, BrainShift's TRE: " + ", ".join(verdicts) + "."
            if t and u:
                sentence += (f" BrainShift takes {t / u:.2f} of elastix's time ({u / t:.1f}x faster)." if t < u else
                             f" BrainShift takes {t / u:.1f}x elastix's time.")
        result = elastix_result(out, case)
        if result:
            mapped = [f"{m['method']} {m['transformix_points_seconds']:.2f} s" for m in result.get("methods", [])
                      if m.get("transformix_points_seconds") is not None]
            if mapped:
                sentence += " transformix on the landmarks (not counted): " + ", ".join(mapped) + "."
        sentences.append(sentence)
    lines += [""] + sentences + [""]
    return lines


def pareto(points):
    """The points no other point beats in both time and TRE (lower is better in both)."""
    front = []
    for p in sorted(points, key=lambda p: (p[0], p[1])):
        if not front or p[1] < front[-1][1]:
            front.append(p)
    return front


def targets_and_serial_scans(rows):
    """The targets judged on each case's default setting, and the later scan against the first."""
    lines = ["## Targets", ""]
    for case in dict.fromkeys(r["case"] for r in rows):
        chosen = default_setting([r for r in rows if r["case"] == case])
        if chosen is None or number(chosen["tre_mean_mm"]) is None:
            continue
        mean, p95, total = number(chosen["tre_mean_mm"]), number(chosen["tre_p95_mm"]), number(chosen["total_seconds"])
        verdict = "met" if mean <= TRE_MEAN_TARGET and p95 <= TRE_P95_TARGET else "missed"
        near = number(chosen["tre_near_cavity_mm"])
        near_text = f", near the cavity {near:.2f} mm" if near is not None and near >= 0 else ""
        lines.append(f"- {case} ({setting_text(chosen)}): TRE {mean:.2f} mm mean, {p95:.2f} mm p95{near_text}: "
                     f"accuracy target {verdict}; {total:.1f} s")
    later = next((r for r in rows if r["method"] == LATER_SCAN), None)
    watched = next((r for r in rows if r["method"] == WATCH_LATER_SCAN), None)
    first = default_setting([r for r in rows if r["case"] == (later or {}).get("case", "default")])
    if later is None or first is None:
        return lines + [""]
    t_first, t_later = number(first["total_seconds"]), number(later["total_seconds"])
    t_watched = number(watched["total_seconds"]) if watched else None
    lines += ["", "## Serial scans", "",
              "The same scan of the default case registered as a later scan (`register --previous`, after an earlier "
              "scan of the case with a 5 mm shift and the tumour in place): the rigid registration starts from the "
              "earlier alignment, the mesh and the preoperative surface fit are reused (prototypes picked by a user "
              "would be carried forward; the automatic ones are chosen afresh). The same images as the first scan's row: "
              "a difference in TRE is the method's sensitivity to its start (a rigid result 0.02 mm apart changes the "
              "automatic prototypes' sample, hence the classification). \"later, in a watch session\": the same two "
              "scans in one `brainshift watch` process, the preoperative data read once and the finite element worker "
              "served between the scans (its assembled matrix kept, the scan's fixed nodes eliminated anew).", "",
              table_row(["scan", "total (s)"] + STAGES + ["TRE mean", "p95"]), table_row(["---"] * (len(STAGES) + 4))]
    scans = [("first", first), ("later", later)] + ([("later, in a watch session", watched)] if watched else [])
    for name, r in scans:
        lines.append(table_row([name, f"{number(r['total_seconds']):.2f}"]
                               + [f"{number(r[s + '_seconds']):.2f}" if number(r[s + "_seconds"]) is not None else ""
                                  for s in STAGES] + [f"{number(r['tre_mean_mm']):.2f}", f"{number(r['tre_p95_mm']):.2f}"]))
    lines += ["", f"First scan {t_first:.1f} s (target <= {FIRST_SCAN_SECONDS:g} s: "
              f"{'met' if t_first <= FIRST_SCAN_SECONDS else 'missed'}); later scan {t_later:.1f} s (target <= "
              f"{LATER_SCAN_SECONDS:g} s: {'met' if t_later <= LATER_SCAN_SECONDS else 'missed'}), "
              f"{100 * (1 - t_later / t_first):.0f} % less"
              + (f"; in a watch session {t_watched:.1f} s (target: "
                 f"{'met' if t_watched <= LATER_SCAN_SECONDS else 'missed'})" if t_watched is not None else "") + ".", ""]
    return lines


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
    chosen = default_setting(default)
    if chosen is not None and number(chosen["total_seconds"]) is not None and number(chosen["tre_mean_mm"]) is not None:
        axis.scatter(number(chosen["total_seconds"]), number(chosen["tre_mean_mm"]), facecolor="none", edgecolor="black",
                     s=130, linewidth=1.2, label=f"brainshift default setting ({setting_text(chosen)})", zorder=4)
    for r in default:
        if r["method"] == LATER_SCAN and number(r["total_seconds"]) is not None and number(r["tre_mean_mm"]) is not None:
            axis.scatter(number(r["total_seconds"]), number(r["tre_mean_mm"]), color="tab:orange", marker="^", s=60,
                         label="brainshift, a later scan (register --previous)", zorder=4)
        if r["method"] == WATCH_LATER_SCAN and number(r["total_seconds"]) is not None and number(r["tre_mean_mm"]) is not None:
            axis.scatter(number(r["total_seconds"]), number(r["tre_mean_mm"]), color="tab:brown", marker="v", s=60,
                         label="brainshift, a later scan in a watch session", zorder=4)
    elastix = [r for r in default if r["method"] in ELASTIX
               and number(r["total_seconds"]) is not None and number(r["tre_mean_mm"]) is not None]
    for r in elastix:
        style = ELASTIX[r["method"]]
        axis.scatter(number(r["total_seconds"]), number(r["tre_mean_mm"]), color=style["color"], marker=style["marker"],
                     s=55, label=style["label"], zorder=3)
    # The front over every point, the rigid registration and elastix included.
    everything = [(t, e, r) for t, e, r in points] + [(number(r["total_seconds"]), number(r["tre_mean_mm"]), r)
                                                      for r in rigid + elastix]
    everything = [(t, e, r) for t, e, r in everything if t is not None and e is not None]
    front = pareto([(t, e) for t, e, _ in everything])
    if front:
        axis.plot([t for t, _ in front], [e for _, e in front], color="tab:red", linewidth=1.2, marker="o",
                  markerfacecolor="none", markersize=11, label="Pareto front", zorder=2)
    labelled = 0
    for t, e, r in sorted(everything, key=lambda p: p[0]):
        if (t, e) in set(front) and r["method"] == "brainshift":  # stacked: the front's settings are close in time
            axis.annotate(setting_text(r), (t, e), fontsize=7, xytext=(4, -12 - 9 * labelled), textcoords="offset points")
            labelled += 1
    axis.axhline(TRE_MEAN_TARGET, color="grey", linestyle="--", linewidth=0.8, label=f"target {TRE_MEAN_TARGET:g} mm")
    axis.axvline(FIRST_SCAN_SECONDS, color="grey", linestyle=":", linewidth=0.8, label=f"first scan {FIRST_SCAN_SECONDS:g} s")
    times = [t for t, _, _ in everything if t > 0]
    if times and max(times) > 30 * min(times):  # elastix's B-spline is an order of magnitude slower
        axis.set_xscale("log")
        axis.set_xticks([v for v in (1, 2, 5, 10, 20, 50, 100, 200, 500, 1000) if min(times) / 1.5 <= v <= max(times) * 1.5])
        axis.xaxis.set_major_formatter(ticker.FormatStrFormatter("%g"))
        axis.xaxis.set_minor_formatter(ticker.NullFormatter())
    axis.set(xlabel="wall time of register (elastix: of the elastix process) (s)", ylabel="landmark TRE, mean (mm)",
             title="The whole update on the built-in case: accuracy against speed")
    axis.margins(y=0.1)
    axis.grid(True, alpha=0.3)
    axis.legend(fontsize=8)
    fig.tight_layout()
    save_atomically(fig, os.path.join(out, "tre_vs_time.png"))

    columns = ["case", "method", "mesh (mm)", "rtol", "surface it.", "equations", "total (s)", "rigid", "classify", "mesh",
               "surface", "simulate", "solve", "warp", "TRE mean", "p95", "max", "craniotomy", "near cavity", "brain",
               "folded voxels", "rigid samples", "rigid levels", "mesh grading"]
    keys = ["case", "method", "mesh_resolution_mm", "solver_rtol", "surface_iterations", "equations", "total_seconds",
            "rigid_seconds", "classify_seconds", "mesh_seconds", "surface_seconds", "simulate_seconds",
            "simulate_solve_seconds", "warp_seconds", "tre_mean_mm", "tre_p95_mm", "tre_max_mm", "tre_craniotomy_mm",
            "tre_near_cavity_mm", "tre_brain_mm", "folded_voxels", "rigid_sampling", "rigid_levels", "mesh_grading"]

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
             f"<= {FIRST_SCAN_SECONDS:g} s. Pareto-optimal settings of the default case are marked *."
             + (" Rows \"elastix ...\": elastix 5 on the same images (see Against elastix below; total = the elastix "
                "process, the other time columns do not apply)." if any(r["method"] in ELASTIX for r in rows) else ""),
             "",
             table_row(columns), table_row(["---"] * len(columns))]
    for r in rows:
        cells = [cell(k, r.get(k, "")) for k in keys]
        if r["case"] == "default" and (number(r["total_seconds"]), number(r["tre_mean_mm"])) in front_set:
            cells[1] = r["method"] + " *"
        lines.append(table_row(cells))
    lines += ["", "![TRE against time](tre_vs_time.png)", ""]
    lines += targets_and_serial_scans(rows)
    lines += against_elastix(out, rows)
    lines += machine_section(out)
    write_atomically(os.path.join(out, "summary.md"), "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
