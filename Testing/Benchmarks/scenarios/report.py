#!/usr/bin/env python3
"""The hard scenarios' table and charts (Testing/Benchmarks/scenarios/run.sh writes the runs).

  report.py OUT

Reads OUT/runs/<scenario>/<variant>/ (a `brainshift demo` folder: evaluation.json, report.json,
case/case.json; true-labels: evaluation-true-labels.json and report.json) and, where present,
OUT/runs/<scenario>/elastix/elastix_result.json. Writes OUT/scenarios.csv (one row per scenario and
method), OUT/summary.md (the table, the targets met, the verdicts of the trust assessment),
OUT/tre_vs_shift.png (TRE mean against the shift, one series per method, and the craniotomy and
tumour-margin groups) and OUT/tre_vs_time.png (TRE against the update's wall time).
"""
import csv
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

VARIANT_NAMES = {"once": "BrainShift (default)", "refined": "BrainShift, refine 2 passes"}
MARGIN_GROUPS = ("tumour-margin", "near-cavity")  # the tumour's margin: in place, or the resection cavity's
TARGET_MEAN, TARGET_P95, TARGET_GROUP = 1.0, 2.0, 1.5


def load(path):
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def group_mean(tre, names):
    for name in names:
        g = (tre or {}).get("groups", {}).get(name)
        if g:
            return g["mean_mm"]
    return None


def row_of(scenario, method, tre, case, seconds=None, extra=None):
    p = case["parameters"]
    row = {"scenario": scenario, "method": method, "shift_mm": p["shift_mm"], "craniotomy": p["craniotomy"],
           "resection": p["resection"], "contrast": p.get("contrast", "t1"), "tumour": p.get("tumour_appearance", ""),
           "gap": p.get("gap", "dark"), "noise": p["noise_fraction"], "bias": p["bias_strength"],
           "truth": p.get("truth", "kinematic"),
           "tre_mean_mm": tre["mean_mm"] if tre else None, "tre_p95_mm": tre["p95_mm"] if tre else None,
           "tre_max_mm": tre["max_mm"] if tre else None,
           "tre_craniotomy_mm": group_mean(tre, ("craniotomy",)), "tre_margin_mm": group_mean(tre, MARGIN_GROUPS),
           "tre_brain_mm": group_mean(tre, ("brain",)), "tre_head_mm": group_mean(tre, ("head",)),
           "wall_seconds": seconds}
    row.update(extra or {})
    return row


def stage_seconds(report):
    if not report:
        return None
    return sum(s.get("wall_seconds", 0) for s in report.get("stages", {}).values())


def rows_of_scenario(out, scenario):
    folder = os.path.join(out, "runs", scenario)
    rows = []
    case = None
    for variant in ("once", "refined"):
        evaluation = load(os.path.join(folder, variant, "evaluation.json"))
        report = load(os.path.join(folder, variant, "report.json"))
        case = load(os.path.join(folder, variant, "case", "case.json")) or case
        if not evaluation or not case:
            continue
        t = evaluation["transforms"]
        if variant == "once":
            rows.append(row_of(scenario, "rigid (BrainShift)", t.get("brainshift_rigid"), case))
        c = evaluation.get("classification", {})
        s = evaluation.get("surface", {})
        trust = (report or {}).get("trust", {})
        refine = (report or {}).get("stages", {}).get("refine", {})
        extra = {"brain_dice": c.get("brain_dice"), "ventricle_dice": c.get("ventricle_dice"),
                 "brain_surface_distance_mm": c.get("brain_surface_distance_mm"),
                 "surface_moving_error_mm": s.get("moving_mean_error_mm"),
                 "boundary_residual_mm": s.get("residual_to_true_boundary_mm"),
                 "trust": trust.get("nonrigid"), "refine_passes": refine.get("passes"),
                 "tumour_resected_decided": ((report or {}).get("stages", {}).get("classify", {}) or {}).get("tumour_resected")}
        rows.append(row_of(scenario, VARIANT_NAMES[variant], t.get("brainshift"), case,
                           stage_seconds(report), extra))
        if "brainshift_rejected_update" in t:
            rows.append(row_of(scenario, "BrainShift, " + variant + ", the update set aside", t["brainshift_rejected_update"], case))
    if case is None:
        return rows
    truth_labels = load(os.path.join(folder, "true-labels", "evaluation-true-labels.json"))
    if truth_labels:
        rows.append(row_of(scenario, "BrainShift, true labels (ceiling)", truth_labels, case,
                           stage_seconds(load(os.path.join(folder, "true-labels", "report.json")))))
    elastix = load(os.path.join(folder, "elastix", "elastix_result.json"))
    for m in (elastix or {}).get("methods", []):
        rows.append(row_of(scenario, m["method"], m["tre"], case, m.get("elastix_seconds")))
    return rows


def fmt(v, digits=2):
    return "" if v is None else (f"{v:.{digits}f}" if isinstance(v, float) else str(v))


def main():
    out = sys.argv[1]
    scenarios = sorted(d for d in os.listdir(os.path.join(out, "runs")) if os.path.isdir(os.path.join(out, "runs", d)))
    scenarios.sort(key=lambda s: (s != "default", s))
    rows = [r for s in scenarios for r in rows_of_scenario(out, s)]
    columns = list(rows[0].keys()) if rows else []
    for r in rows:
        for k in r:
            if k not in columns:
                columns.append(k)
    with open(os.path.join(out, "scenarios.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns)
        w.writeheader()
        w.writerows(rows)

    lines = ["# The hard scenarios", "",
             "`Testing/Benchmarks/scenarios/run.sh`; machine in `machine.txt`. TRE in mm over the case's landmarks "
             "(mean / p95 / max); groups: craniotomy, tumour margin (the tumour in place, or the resection cavity), "
             "brain elsewhere, head. Targets: mean <= 1.0, p95 <= 2.0, craniotomy and margin <= 1.5.", "",
             "| scenario | shift | contrast | resection | method | TRE mean / p95 / max | craniotomy | margin | brain | head | brain Dice | trust | s |",
             "|---|---:|---|---|---|---|---:|---:|---:|---:|---:|---|---:|"]
    for r in rows:
        tre = f"{fmt(r['tre_mean_mm'])} / {fmt(r['tre_p95_mm'])} / {fmt(r['tre_max_mm'])}"
        lines.append(f"| {r['scenario']} | {fmt(r['shift_mm'], 0)} | {r['contrast']} | {'yes' if r['resection'] else 'no'} | "
                     f"{r['method']} | {tre} | {fmt(r['tre_craniotomy_mm'])} | {fmt(r['tre_margin_mm'])} | "
                     f"{fmt(r['tre_brain_mm'])} | {fmt(r['tre_head_mm'])} | {fmt(r.get('brain_dice'), 3)} | "
                     f"{r.get('trust') or ''} | {fmt(r['wall_seconds'], 1)} |")
    lines += ["", "## Targets met (mean <= 1.0 and p95 <= 2.0 mm)", "",
              "| method | scenarios | met | craniotomy and margin <= 1.5 mm |", "|---|---:|---:|---:|"]
    for method in sorted({r["method"] for r in rows}):
        subset = [r for r in rows if r["method"] == method and r["tre_mean_mm"] is not None]
        met = sum(1 for r in subset if r["tre_mean_mm"] <= TARGET_MEAN and r["tre_p95_mm"] <= TARGET_P95)
        groups = sum(1 for r in subset if (r["tre_craniotomy_mm"] or 0) <= TARGET_GROUP and (r["tre_margin_mm"] or 0) <= TARGET_GROUP)
        lines.append(f"| {method} | {len(subset)} | {met} | {groups} |")
    with open(os.path.join(out, "summary.md"), "w") as f:
        f.write("\n".join(lines) + "\n")

    methods = [m for m in ["rigid (BrainShift)", "BrainShift (default)", "BrainShift, refine 2 passes",
                           "BrainShift, true labels (ceiling)", "elastix rigid+bspline"] if any(r["method"] == m for r in rows)]
    fig, axes = plt.subplots(1, 3, figsize=(16, 5))
    for ax, key, title in zip(axes, ["tre_mean_mm", "tre_craniotomy_mm", "tre_margin_mm"],
                              ["all landmarks", "craniotomy", "tumour margin"]):
        for i, m in enumerate(methods):
            pts = [(r["shift_mm"] + 0.25 * (i - len(methods) / 2), r[key]) for r in rows if r["method"] == m and r[key] is not None]
            if pts:
                ax.scatter(*zip(*pts), label=m, s=18)
        ax.axhline(TARGET_MEAN if key == "tre_mean_mm" else TARGET_GROUP, color="grey", lw=0.8, ls="--")
        ax.set_xlabel("shift (mm)")
        ax.set_ylabel("TRE mean (mm)")
        ax.set_title(title)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "tre_vs_shift.png"), dpi=90)
    fig, ax = plt.subplots(figsize=(7, 5))
    for m in methods:
        pts = [(r["wall_seconds"], r["tre_mean_mm"]) for r in rows if r["method"] == m and r["wall_seconds"] and r["tre_mean_mm"] is not None]
        if pts:
            ax.scatter(*zip(*pts), label=m, s=18)
    ax.set_xscale("log")
    ax.set_xlabel("wall seconds of the update (stages summed; elastix: its run)")
    ax.set_ylabel("TRE mean (mm)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "tre_vs_time.png"), dpi=90)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
