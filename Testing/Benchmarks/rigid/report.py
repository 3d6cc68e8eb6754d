#!/usr/bin/env python3
"""Report of the rigid benchmark: report.py OUT (the folder run.sh wrote).

Reads OUT/machine.txt, OUT/full/rigid_accuracy.json, OUT/full/elastix_accuracy.json,
OUT/full/truth_evaluation.json and OUT/capture/capture_range.csv; writes
OUT/capture_range.png, OUT/capture_range.md and OUT/summary.md.
"""
import csv
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))
from benchmark_common import (  # noqa: E402  (benchmark_common.py is in the folder above)
    load_json, machine_section, output_folder, plt, report_missing, save_atomically, table_row,
    write_atomically)
from matplotlib.patches import Rectangle  # noqa: E402

CRITERION = "success: head TRE max \u2264 1 mm and rotation error \u2264 0.5\u00b0"
CRITERION_MD = "success: head TRE max <= 1 mm and rotation error <= 0.5 degrees"


def number(text):
    value = float(text)
    return int(value) if value.is_integer() else value


def read_capture_range(path):
    """{(rotation, translation): cell} with cell counts, and the sorted axes."""
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        needed = {"rotation_degrees", "translation_mm", "trial", "success", "trustworthy"}
        if reader.fieldnames is None or not needed <= set(reader.fieldnames):
            sys.exit(f"report.py: {path}: header must have {', '.join(sorted(needed))}")
        cells = {}
        for row in reader:
            key = (number(row["rotation_degrees"]), number(row["translation_mm"]))
            cell = cells.setdefault(key, {"trials": 0, "successes": 0, "failures": 0,
                                          "detected": 0, "silent": 0, "false_alarms": 0})
            success = int(float(row["success"])) == 1
            trustworthy = int(float(row["trustworthy"])) == 1
            cell["trials"] += 1
            if success:
                cell["successes"] += 1
                cell["false_alarms"] += not trustworthy
            else:
                cell["failures"] += 1
                cell["detected"] += not trustworthy
                cell["silent"] += trustworthy
    if not cells:
        sys.exit(f"report.py: {path}: no runs")
    rotations = sorted({r for r, _ in cells})
    translations = sorted({t for _, t in cells})
    return cells, rotations, translations


def totals(cells):
    keys = ("trials", "successes", "failures", "detected", "silent", "false_alarms")
    return {k: sum(c[k] for c in cells.values()) for k in keys}


def capture_range_png(path, cells, rotations, translations, size):
    rows, cols = len(rotations), len(translations)
    nan = float("nan")
    rate = [[nan] * cols for _ in range(rows)]
    detection = [[nan] * cols for _ in range(rows)]
    for i, r in enumerate(rotations):
        for j, t in enumerate(translations):
            c = cells.get((r, t))
            if c and c["trials"]:
                rate[i][j] = c["successes"] / c["trials"]
                if c["failures"]:
                    detection[i][j] = c["detected"] / c["failures"]

    fig, axes = plt.subplots(1, 2, figsize=(9, 4.5), dpi=100, constrained_layout=True)
    cmap = plt.get_cmap("RdYlGn").copy()
    cmap.set_bad("#d9d9d9")
    panels = [
        (axes[0], rate, "success rate (successes/trials)"),
        (axes[1], detection, "failure detection (flagged untrustworthy/failures)"),
    ]
    for ax, grid, label in panels:
        image = ax.imshow(grid, cmap=cmap, vmin=0, vmax=1, aspect="auto")
        ax.set_xticks(range(cols), [f"{t:g}" for t in translations])
        ax.set_yticks(range(rows), [f"{r:g}" for r in rotations])
        ax.set_xlabel("initial translation (mm)")
        ax.set_ylabel("initial rotation (degrees)")
        ax.set_title(label, fontsize=9)
        fig.colorbar(image, ax=ax, shrink=0.8, label="fraction")
    box = {"boxstyle": "round,pad=0.15", "facecolor": "white", "alpha": 0.7, "linewidth": 0}
    for i, r in enumerate(rotations):
        for j, t in enumerate(translations):
            c = cells.get((r, t))
            if not c:
                continue
            if c["silent"]:
                for ax in axes:
                    ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, hatch="xx",
                                           edgecolor="black", linewidth=0))
            silent = f" ({c['silent']}!)" if c["silent"] else ""
            axes[0].text(j, i, f"{c['successes']}/{c['trials']}{silent}", ha="center",
                         va="center", fontsize=7, bbox=box)
            text = f"{c['detected']}/{c['failures']}" if c["failures"] else "\u2014"
            axes[1].text(j, i, text, ha="center", va="center", fontsize=7,
                         bbox=box if c["failures"] else None)
    fig.suptitle(f"BrainShift rigid capture range, {size} case ({CRITERION})\n"
                 "hatched, (k!): k silent failures (failed but reported trustworthy); "
                 "grey \u2014: no failures", fontsize=9)
    save_atomically(fig, path)


def markdown_grid(rotations, translations, cell_text):
    lines = [table_row(["rotation (deg) \\ translation (mm)", *(f"{t:g}" for t in translations)]),
             "|---:|" + "---:|" * len(translations)]
    for r in rotations:
        lines.append(table_row([f"{r:g}", *(cell_text(r, t) for t in translations)]))
    return lines


def percent(numerator, denominator):
    return f"{100.0 * numerator / denominator:.0f} %" if denominator else "n/a"


def capture_range_md(path, cells, rotations, translations, size):
    def success(r, t):
        c = cells.get((r, t))
        if not c:
            return ""
        return f"{c['successes']}/{c['trials']}" + (" !" if c["silent"] else "")

    def detection(r, t):
        c = cells.get((r, t))
        if not c:
            return ""
        return f"{c['detected']}/{c['failures']}" if c["failures"] else "-"

    s = totals(cells)
    lines = [
        f"# Rigid capture range ({size} case)",
        "",
        f"Initial misalignment: rotation (rows) and translation (columns); {CRITERION_MD}.",
        "",
        "Successes / trials; `!` marks a cell with a silent failure (failed but reported "
        "trustworthy).",
        "",
        *markdown_grid(rotations, translations, success),
        "",
        "Failure detection: failures flagged untrustworthy / failures (`-`: no failures).",
        "",
        *markdown_grid(rotations, translations, detection),
        "",
        f"Overall: {s['successes']}/{s['trials']} successes ({percent(s['successes'], s['trials'])}); "
        f"{s['failures']} failures, of which {s['detected']} detected and {s['silent']} silent; "
        f"{s['false_alarms']} successes flagged untrustworthy.",
        "",
    ]
    write_atomically(path, "\n".join(lines))


def fmt(value, digits=3):
    if value is None:
        return "n/a"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (int, float)):
        return f"{value:.{digits}f}"
    return str(value)


def summary_md(path, out, accuracy, elastix, truth, capture):
    lines = ["# Rigid registration benchmark", "", *machine_section(out)]

    bs = accuracy or {}
    el = elastix or {}
    size = bs.get("size", "full")
    truth_head = (truth or {}).get("groups", {}).get("head", {})
    lines += [
        f"## Accuracy and speed ({size} case)",
        "",
        "Intraoperative image registered to the preoperative image (`full/case/`); TRE on the "
        "`head-` landmarks, where only the rigid motion applies. Rotation and translation errors "
        "against `case/truth/rigid_intraop_to_preop.tfm`. elastix 5: Euler transform, Mattes "
        "mutual information, the same 3-level pyramid (`rigid/elastix_rigid.txt`).",
        "",
        "| | BrainShift | elastix 5 | true rigid |",
        "|---|---:|---:|---:|",
        f"| head TRE mean (mm) | {fmt(bs.get('head_tre_mean_mm'))} | "
        f"{fmt(el.get('head_tre_mean_mm'))} | {fmt(truth_head.get('mean_mm'))} |",
        f"| head TRE max (mm) | {fmt(bs.get('head_tre_max_mm'))} | "
        f"{fmt(el.get('head_tre_max_mm'))} | {fmt(truth_head.get('max_mm'))} |",
        f"| rotation error (degrees) | {fmt(bs.get('rotation_error_degrees'))} | "
        f"{fmt(el.get('rotation_error_degrees'))} | 0 |",
        f"| translation error (mm) | {fmt(bs.get('translation_error_mm'))} | "
        f"{fmt(el.get('translation_error_mm'))} | 0 |",
        f"| wall seconds, median | {fmt(bs.get('wall_seconds_median'), 2)} | "
        f"{fmt(el.get('wall_seconds_median'), 2)} | |",
        f"| runs | {bs.get('runs', 'n/a')} | {el.get('runs', 'n/a')} | |",
        f"| reported trustworthy | {fmt(bs.get('trustworthy'))} | | |",
        f"| final metric (NMI) | {fmt(bs.get('nmi'), 4)} | | |",
        "",
    ]
    b_time, e_time = bs.get("wall_seconds_median"), el.get("wall_seconds_median")
    if b_time and e_time:
        faster = "faster" if b_time < e_time else "slower"
        ratio = e_time / b_time if b_time < e_time else b_time / e_time
        lines += [f"Time ratio elastix / BrainShift: {e_time / b_time:.2f} "
                  f"(BrainShift {ratio:.2f}x {faster}).", ""]
    lines += ["Rotation error: the angle of R_estimate R_truth^T. Translation error: "
              "|T_estimate(c) - T_truth(c)| at the true transform's centre of rotation c. "
              "elastix's wall time is measured around the `elastix` process (reading the images "
              "included; elastix uses all cores).", ""]

    lines += ["## Capture range", ""]
    if capture:
        cells, _, _, csize = capture
        s = totals(cells)
        lines += [
            f"{csize} case, {CRITERION_MD}: {s['successes']}/{s['trials']} successes "
            f"({percent(s['successes'], s['trials'])}); {s['failures']} failures, "
            f"{s['detected']} detected (flagged untrustworthy), **{s['silent']} silent**. "
            "Grid: [capture_range.md](capture_range.md), chart: "
            "[capture_range.png](capture_range.png).",
            "",
        ]
    else:
        lines += ["capture/capture_range.csv missing.", ""]
    write_atomically(path, "\n".join(lines))


def main():
    out = output_folder()
    accuracy = load_json(os.path.join(out, "full", "rigid_accuracy.json"))
    elastix = load_json(os.path.join(out, "full", "elastix_accuracy.json"))
    truth = load_json(os.path.join(out, "full", "truth_evaluation.json"))

    capture = None
    csv_path = os.path.join(out, "capture", "capture_range.csv")
    if os.path.isfile(csv_path):
        cells, rotations, translations = read_capture_range(csv_path)
        size = (load_json(os.path.join(out, "capture", "rigid_accuracy.json"))
                if os.path.isfile(os.path.join(out, "capture", "rigid_accuracy.json"))
                else None)
        size = (size or {}).get("size", "small")
        capture = (cells, rotations, translations, size)
        capture_range_png(os.path.join(out, "capture_range.png"), cells, rotations, translations,
                          size)
        capture_range_md(os.path.join(out, "capture_range.md"), cells, rotations, translations,
                         size)
    else:
        report_missing(csv_path)
    summary_md(os.path.join(out, "summary.md"), out, accuracy, elastix, truth, capture)
    print(f"wrote {os.path.join(out, 'summary.md')}"
          + (", capture_range.md, capture_range.png" if capture else ""))


if __name__ == "__main__":
    main()
