#!/usr/bin/env python3
"""Report of the tissue classification benchmark: report.py OUT (the folder run.sh wrote).

Reads OUT/machine.txt, OUT/classification_speed.json and OUT/classification_sweep.csv; writes
OUT/dice_vs_noise.png, OUT/dice_vs_bias.png and OUT/summary.md.
"""
import csv
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))
from benchmark_common import (  # noqa: E402  (benchmark_common.py is in the folder above)
    finite, load_json, machine_section, output_folder, plt, report_missing, save_atomically,
    table_row, write_atomically)

# Targets of the classify stage.
KNN_TARGET_SECONDS = 1.0
STAGE_TARGET_SECONDS = 3.0
BRAIN_DICE_TARGET = 0.95
VENTRICLE_DICE_TARGET = 0.80
SURFACE_TARGET_MM = 1.0
# The default case (brainshift demo): the noise sweep holds the bias at DEFAULT_BIAS and the bias
# sweep the noise at DEFAULT_NOISE. classification_speed.json's "noise" and "bias", when present,
# take precedence.
DEFAULT_NOISE = 0.03
DEFAULT_BIAS = 0.2
# The lower end of the zoomed panel of the charts.
ZOOM_LOW = 0.7

COLUMNS = ["variable", "value", "n4", "brain_dice", "ventricle_dice", "parenchyma_dice",
           "brain_surface_distance_mm", "stage_seconds"]
METRICS = COLUMNS[3:]
# (key, short name, test, target text) of each accuracy target.
TARGETS = [
    ("brain_dice", "brain", lambda v: v >= BRAIN_DICE_TARGET,
     f"brain Dice >= {BRAIN_DICE_TARGET:g}"),
    ("ventricle_dice", "ventricles", lambda v: v >= VENTRICLE_DICE_TARGET,
     f"ventricle Dice >= {VENTRICLE_DICE_TARGET:.2f}"),
    ("brain_surface_distance_mm", "surface", lambda v: v <= SURFACE_TARGET_MM,
     f"brain surface distance <= {SURFACE_TARGET_MM:g} mm"),
]
BRAIN_COLOR = "tab:blue"
VENTRICLE_COLOR = "tab:orange"
VARIABLES = {
    "noise": {"axis": "Rician noise sigma (fraction of white matter)", "name": "noise",
              "level": "noise level"},
    "bias": {"axis": "bias field strength (log amplitude)", "name": "bias",
             "level": "bias strength"},
}


def read_sweep(path):
    """{variable: [row, ...]} with rows sorted by value, then n4; metrics None when missing."""
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        if reader.fieldnames is None or not set(COLUMNS) <= set(reader.fieldnames):
            sys.exit(f"report.py: {path}: header must have {','.join(COLUMNS)}")
        sweeps = {}
        for line, row in enumerate(reader, start=2):
            value = finite(row["value"])
            if value is None:
                sys.exit(f"report.py: {path}:{line}: value {row['value']!r} is not a number")
            entry = {"value": value, "n4": int(finite(row["n4"]) or 0)}
            for key in METRICS:
                entry[key] = finite(row[key])
            sweeps.setdefault(row["variable"].strip(), []).append(entry)
    for variable, rows in sweeps.items():
        if variable not in VARIABLES:
            print(f"report.py: {path}: unknown variable {variable!r} ignored", file=sys.stderr)
        rows.sort(key=lambda r: (r["value"], r["n4"]))
    return sweeps


def n4_groups(rows):
    """[(n4, rows with that n4)], N4 off first."""
    return [(n4, [r for r in rows if r["n4"] == n4]) for n4 in sorted({r["n4"] for r in rows})]


def n4_name(n4):
    return "N4 on" if n4 else "N4 off"


# --- charts ---------------------------------------------------------------------------------------
def tick_labels(values):
    """The tested values as tick labels, leaving out those too close to the last one shown."""
    span = (values[-1] - values[0]) or 1.0
    labels, shown = [], None
    for v in values:
        if shown is None or (v - shown) / span >= 0.07:
            labels.append(f"{v:g}")
            shown = v
        else:
            labels.append("")
    return labels


def dice_chart(path, rows, variable, title, default_value):
    fig, axes = plt.subplots(1, 2, figsize=(8, 4.5), dpi=100, constrained_layout=True)
    groups = n4_groups(rows)
    values = sorted({r["value"] for r in rows})
    nan = float("nan")
    for panel, ax in enumerate(axes):
        for n4, group in groups:
            x = [r["value"] for r in group]
            solid = n4 == 0
            for key, color, label in (("brain_dice", BRAIN_COLOR, "brain Dice"),
                                      ("ventricle_dice", VENTRICLE_COLOR, "ventricle Dice")):
                y = [nan if r[key] is None else r[key] for r in group]
                if len(groups) > 1:
                    label = f"{label}, {n4_name(n4)}"
                ax.plot(x, y, color=color, linewidth=1.8, linestyle="-" if solid else (0, (4, 2)),
                        marker="o" if solid else "s", markersize=5,
                        markerfacecolor=color if solid else "white", label=label)
        for target, color, label in ((BRAIN_DICE_TARGET, BRAIN_COLOR, "brain target"),
                                     (VENTRICLE_DICE_TARGET, VENTRICLE_COLOR, "ventricle target")):
            ax.axhline(target, color=color, linewidth=1, linestyle=(0, (8, 4)), alpha=0.6,
                       label=f"{label} {target:.2f}")
        if default_value is not None and values and values[0] <= default_value <= values[-1]:
            ax.axvline(default_value, color="0.5", linewidth=0.8, linestyle=":",
                       label="default case")
        ax.set_xlabel(VARIABLES[variable]["axis"])
        ax.set_xticks(values, tick_labels(values))
        ax.tick_params(labelsize=8)
        ax.grid(True, linewidth=0.4, alpha=0.5)
        if panel == 0:
            ax.set_ylim(0, 1.01)
            ax.set_ylabel("Dice against the true intraoperative labels")
            ax.set_title("full range", fontsize=9)
            ax.legend(loc="lower left", fontsize=7, framealpha=0.9)
        else:
            ax.set_ylim(ZOOM_LOW, 1.005)
            ax.set_title(f"near the targets (from {ZOOM_LOW:g})", fontsize=9)
    fig.suptitle(title, fontsize=10)
    save_atomically(fig, path)


# --- summary --------------------------------------------------------------------------------------
def fmt(value, digits=3):
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    value = finite(value)
    return "n/a" if value is None else f"{value:.{digits}f}"


def met(value, test):
    value = finite(value)
    return "n/a" if value is None else ("yes" if test(value) else "**no**")


def missed_targets(row):
    missed = [name for key, name, test, _ in TARGETS if row[key] is not None and not test(row[key])]
    unknown = [name for key, name, _, _ in TARGETS if row[key] is None]
    text = ", ".join(missed) or "none"
    return text + (f" ({', '.join(unknown)} not measured)" if unknown else "")


def where_met(rows, test, key=None):
    """How a target fares along a sweep: (last value before the first miss or None, the first miss
    or None, the metric there, values met again after it, largest value tested). A row counts as
    meeting it when test(row) holds; key names the metric to quote (None: nothing to quote)."""
    known = [r for r in rows if r is not None]
    first_miss = next((r for r in known if not test(r)), None)
    if first_miss is None:
        return None, None, None, [], known[-1]["value"] if known else None
    before = [r["value"] for r in known if r["value"] < first_miss["value"] and test(r)]
    again = [r["value"] for r in known if r["value"] > first_miss["value"] and test(r)]
    quoted = first_miss[key] if key else None
    return (before[-1] if before else None), first_miss["value"], quoted, again, known[-1]["value"]


def target_clause(rows, key, test, text, digits, level):
    measured = [r for r in rows if r[key] is not None]
    if not measured:
        return f"{text} not measured"
    last_met, miss, quoted, again, largest = where_met(measured, lambda r: test(r[key]), key)
    if miss is None:
        return f"{text} at every {level} tested (up to {largest:g})"
    if last_met is None:
        clause = f"{text} missed already at {miss:g} ({quoted:.{digits}f})"
    else:
        clause = f"{text} up to {last_met:g} ({quoted:.{digits}f} at {miss:g})"
    if again:
        clause += f" and met again at {', '.join(f'{v:g}' for v in again)}"
    return clause


def sweep_sentence(variable, rows):
    """One sentence: where the targets stop being met along the sweep, per N4 setting."""
    name, level = VARIABLES[variable]["name"], VARIABLES[variable]["level"]
    groups = n4_groups(rows)
    parts = []
    for n4, group in groups:
        def all_met(r):
            return all(r[key] is not None and test(r[key]) for key, _, test, _ in TARGETS)
        last_met, miss, _, again, largest = where_met(group, all_met)
        if miss is None:
            lead = f"all targets are met at every {level} tested (up to {largest:g})"
        elif last_met is None and not again:
            lead = f"the targets are not all met at any {level} tested"
        elif last_met is None:
            lead = (f"the targets are not all met at {name} {miss:g}, only at "
                    f"{', '.join(f'{v:g}' for v in again)}")
        else:
            lead = f"all targets are met up to {name} {last_met:g} and not from {miss:g}"
            if again:
                lead += f" (again at {', '.join(f'{v:g}' for v in again)})"
        prefix = f"with {n4_name(n4)}, " if len(groups) > 1 or variable == "bias" else ""
        if miss is None:
            parts.append(prefix + lead)
            continue
        clauses = [target_clause(group, key, test, text, 2 if key.endswith("_mm") else 3, level)
                   for key, _, test, text in TARGETS]
        parts.append(f"{prefix}{lead}: {', '.join(clauses)}")
    sentence = "; ".join(parts)
    return sentence[0].upper() + sentence[1:] + "."


def sweep_table(variable, rows):
    with_n4 = variable == "bias" or len({r["n4"] for r in rows}) > 1
    head = [VARIABLES[variable]["name"]] + (["N4"] if with_n4 else []) + [
        "brain Dice", "ventricle Dice", "parenchyma Dice", "brain surface distance (mm)",
        "stage seconds", "targets missed"]
    lines = [table_row(head), "|" + "---:|" * (len(head) - 1) + "---|"]
    for r in rows:
        cells = [f"{r['value']:g}"] + (["on" if r["n4"] else "off"] if with_n4 else []) + [
            fmt(r["brain_dice"]), fmt(r["ventricle_dice"]), fmt(r["parenchyma_dice"]),
            fmt(r["brain_surface_distance_mm"], 2), fmt(r["stage_seconds"], 2), missed_targets(r)]
        lines.append(table_row(cells))
    return lines


def summary_md(path, out, speed, sweeps, noise, bias, charts):
    lines = ["# Tissue classification benchmark", "", *machine_section(out)]

    s = speed or {}
    size = s.get("size", "full")
    runs = s.get("runs", "n/a")
    lines += [f"## Speed ({size} case)", ""]
    if speed is None:
        lines += ["classification_speed.json missing.", ""]
    else:
        def per_run(key):
            return ", ".join(fmt(v, 3) for v in s.get(key) or []) or "n/a"
        lines += [
            f"The classify stage on the default case (noise {noise:g}, bias {bias:g}), median of "
            f"{runs} run{'' if runs == 1 else 's'}.",
            "",
            "| | median | target | met | each run |",
            "|---|---:|---:|---|---|",
            f"| k-NN classification (s) | {fmt(s.get('knn_seconds_median'))} | "
            f"<= {KNN_TARGET_SECONDS:g} | "
            f"{met(s.get('knn_seconds_median'), lambda v: v <= KNN_TARGET_SECONDS)} | "
            f"{per_run('knn_seconds')} |",
            f"| whole classify stage (s) | {fmt(s.get('stage_seconds_median'))} | "
            f"<= {STAGE_TARGET_SECONDS:g} | "
            f"{met(s.get('stage_seconds_median'), lambda v: v <= STAGE_TARGET_SECONDS)} | "
            f"{per_run('stage_seconds')} |",
            f"| voxels | {s.get('voxels', 'n/a')} | | | |",
            f"| k-NN queries | {s.get('knn_queries', 'n/a')} | | | |",
            "",
        ]

    lines += [f"## Accuracy on the default case ({size} case)", ""]
    if speed is None:
        lines += ["classification_speed.json missing.", ""]
    else:
        lines += [
            f"Noise {noise:g}, bias {bias:g}, against the case's true intraoperative labels "
            "(`truth/intraop_labels.nii.gz`); brain = labels 2, 3, 4 (parenchyma, ventricles, "
            "tumour), ventricles = label 3.",
            "",
            "| | measured | target | met |",
            "|---|---:|---:|---|",
            f"| brain Dice | {fmt(s.get('brain_dice'))} | >= {BRAIN_DICE_TARGET:g} | "
            f"{met(s.get('brain_dice'), TARGETS[0][2])} |",
            f"| ventricle Dice | {fmt(s.get('ventricle_dice'))} | "
            f">= {VENTRICLE_DICE_TARGET:.2f} | "
            f"{met(s.get('ventricle_dice'), TARGETS[1][2])} |",
            f"| brain surface distance (mm) | {fmt(s.get('brain_surface_distance_mm'), 2)} | "
            f"<= {SURFACE_TARGET_MM:g} | "
            f"{met(s.get('brain_surface_distance_mm'), TARGETS[2][2])} |",
            "",
        ]

    sections = [
        ("noise", "Noise sweep",
         f"Rician noise sigma as a fraction of white matter; bias fixed at {bias:g}, N4 off.",
         "dice_vs_noise.png"),
        ("bias", "Bias field sweep",
         f"Bias field strength (log amplitude); noise fixed at {noise:g}; N4 bias correction off "
         "and on.", "dice_vs_bias.png"),
    ]
    for variable, heading, description, chart in sections:
        lines += [f"## {heading}", ""]
        rows = sweeps.get(variable) if sweeps is not None else None
        if not rows:
            lines += [("classification_sweep.csv missing." if sweeps is None
                       else f"No `{variable}` rows in classification_sweep.csv."), ""]
            continue
        lines += [description + (f" Chart: [{chart}]({chart})." if chart in charts else ""), "",
                  sweep_sentence(variable, rows), "", *sweep_table(variable, rows), ""]
    write_atomically(path, "\n".join(lines))


def main():
    out = output_folder()
    speed = load_json(os.path.join(out, "classification_speed.json"))
    noise = finite((speed or {}).get("noise"))
    noise = DEFAULT_NOISE if noise is None else noise
    bias = finite((speed or {}).get("bias"))
    bias = DEFAULT_BIAS if bias is None else bias
    size = (speed or {}).get("size", "full")

    sweeps = None
    charts = []
    csv_path = os.path.join(out, "classification_sweep.csv")
    if os.path.isfile(csv_path):
        sweeps = read_sweep(csv_path)
        if sweeps.get("noise"):
            dice_chart(os.path.join(out, "dice_vs_noise.png"), sweeps["noise"], "noise",
                       f"BrainShift tissue classification, {size} case: Dice against Rician noise "
                       f"(bias {bias:g}, N4 off)", noise)
            charts.append("dice_vs_noise.png")
        if sweeps.get("bias"):
            dice_chart(os.path.join(out, "dice_vs_bias.png"), sweeps["bias"], "bias",
                       f"BrainShift tissue classification, {size} case: Dice against bias field "
                       f"(noise {noise:g}; N4 off solid, on dashed)", bias)
            charts.append("dice_vs_bias.png")
    else:
        report_missing(csv_path)
    summary_md(os.path.join(out, "summary.md"), out, speed, sweeps, noise, bias, charts)
    print(f"wrote {os.path.join(out, 'summary.md')}" + "".join(f", {c}" for c in charts))


if __name__ == "__main__":
    main()
