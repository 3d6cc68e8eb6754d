#!/usr/bin/env python3
"""Block matching's settings against time (Testing/Benchmarks/blockmatching/run.sh writes the runs).

  report.py OUT

Reads OUT/runs/<scenario>/<setting>/ (surface-only: a `brainshift demo` folder; the others a
`register` folder with evaluation-landmarks.json). The time of a setting is the sum of its stages'
wall seconds in report.json (the whole update, files included), the simulate stage's alone beside
it. Writes OUT/settings.csv, OUT/summary.md and OUT/tre_vs_time.png (TRE mean against the update's
time, one panel per scenario, the Pareto front drawn).
"""
import csv
import io
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))
from benchmark_common import (  # noqa: E402  (benchmark_common.py is in the folder above)
    load_json, machine_section, output_folder, plt, save_atomically, write_atomically)


def row_of(scenario, setting, folder):
    report = load_json(os.path.join(folder, "report.json"))
    if setting == "surface-only":
        evaluation = (load_json(os.path.join(folder, "evaluation.json")) or {}).get("transforms", {}).get("brainshift")
    else:
        evaluation = load_json(os.path.join(folder, "evaluation-landmarks.json"))
    if not report or not evaluation:
        return None
    stages = report.get("stages", {})
    simulate = stages.get("simulate", {})
    matching = simulate.get("block_matching", {})
    groups = evaluation.get("groups", {})
    margin = groups.get("tumour-margin", groups.get("near-cavity", {}))
    return {
        "scenario": scenario,
        "setting": setting,
        "tre_mean_mm": evaluation["mean_mm"],
        "tre_p95_mm": evaluation["p95_mm"],
        "tre_max_mm": evaluation["max_mm"],
        "craniotomy_mm": groups.get("craniotomy", {}).get("mean_mm"),
        "margin_mm": margin.get("mean_mm"),
        "brain_mm": groups.get("brain", {}).get("mean_mm"),
        "update_seconds": sum(s.get("wall_seconds", 0) for s in stages.values() if isinstance(s, dict)),
        "simulate_seconds": simulate.get("wall_seconds"),
        "matches": matching.get("constraints"),
        "kept": matching.get("kept"),
        "solves": matching.get("solves"),
        "trust": (report.get("trust") or {}).get("nonrigid"),
    }


def pareto(rows):
    front, best = [], float("inf")
    for r in sorted(rows, key=lambda r: (r["update_seconds"], r["tre_mean_mm"])):
        if r["tre_mean_mm"] < best:
            front.append(r)
            best = r["tre_mean_mm"]
    return front


def main(out):
    runs = os.path.join(out, "runs")
    rows = []
    for scenario in sorted(os.listdir(runs)):
        if scenario == "configs" or not os.path.isdir(os.path.join(runs, scenario)):
            continue
        for setting in sorted(os.listdir(os.path.join(runs, scenario))):
            folder = os.path.join(runs, scenario, setting)
            if os.path.isdir(folder):
                row = row_of(scenario, setting, folder)
                if row:
                    rows.append(row)
    if not rows:
        sys.exit("report.py: no runs in " + runs)
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=list(rows[0].keys()))
    writer.writeheader()
    writer.writerows(rows)
    write_atomically(os.path.join(out, "settings.csv"), text.getvalue())
    scenarios = sorted({r["scenario"] for r in rows})
    fmt = lambda v: "" if v is None else (f"{v:.2f}" if isinstance(v, float) else str(v))
    lines = ["# Block matching: settings against time", "",
             "`Testing/Benchmarks/blockmatching/run.sh`; machine in `machine.txt`. TRE in mm over the case's landmarks; "
             "seconds: the whole update (every stage's wall time, files included) and the simulate stage alone. "
             "Pareto: on the front of TRE mean against the update's time (*).", ""]
    lines.append("| scenario | setting | TRE mean / p95 / max | craniotomy | margin | brain | update s | simulate s | matches | kept | solves | trust | Pareto |")
    lines.append("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|---|")
    for scenario in scenarios:
        mine = [r for r in rows if r["scenario"] == scenario]
        front = {r["setting"] for r in pareto(mine)}
        for r in sorted(mine, key=lambda r: r["update_seconds"]):
            lines.append(f"| {scenario} | {r['setting']} | {r['tre_mean_mm']:.2f} / {r['tre_p95_mm']:.2f} / {r['tre_max_mm']:.2f} | "
                         f"{fmt(r['craniotomy_mm'])} | {fmt(r['margin_mm'])} | {fmt(r['brain_mm'])} | {r['update_seconds']:.1f} | "
                         f"{fmt(r['simulate_seconds'])} | {fmt(r['matches'])} | {fmt(r['kept'])} | {fmt(r['solves'])} | {fmt(r['trust'])} | "
                         f"{'*' if r['setting'] in front else ''} |")
    # Mean over the scenarios, per setting: the default is chosen on this.
    lines += ["", "Mean over the scenarios:", "", "| setting | TRE mean | TRE p95 | update s |", "|---|---:|---:|---:|"]
    settings = sorted({r["setting"] for r in rows})
    for setting in settings:
        mine = [r for r in rows if r["setting"] == setting]
        if len(mine) != len(scenarios):
            continue
        n = len(mine)
        lines.append(f"| {setting} | {sum(r['tre_mean_mm'] for r in mine) / n:.3f} | {sum(r['tre_p95_mm'] for r in mine) / n:.3f} | "
                     f"{sum(r['update_seconds'] for r in mine) / n:.1f} |")
    lines += [""] + machine_section(out)
    write_atomically(os.path.join(out, "summary.md"), "\n".join(lines) + "\n")
    fig, axes = plt.subplots(1, len(scenarios), figsize=(4.5 * len(scenarios), 4), squeeze=False)
    for axis, scenario in zip(axes[0], scenarios):
        mine = [r for r in rows if r["scenario"] == scenario]
        for r in mine:
            colour = "grey" if r["setting"] == "surface-only" else ("red" if r["setting"] == "default" else "tab:blue")
            axis.scatter(r["update_seconds"], r["tre_mean_mm"], color=colour)
            axis.annotate(r["setting"], (r["update_seconds"], r["tre_mean_mm"]), fontsize=6)
        front = pareto(mine)
        axis.plot([r["update_seconds"] for r in front], [r["tre_mean_mm"] for r in front], "k--", linewidth=0.8)
        axis.set_title(scenario, fontsize=9)
        axis.set_xlabel("update time (s)")
        axis.set_ylabel("TRE mean (mm)")
    fig.tight_layout()
    save_atomically(fig, os.path.join(out, "tre_vs_time.png"))


if __name__ == "__main__":
    main(output_folder())
