#!/usr/bin/env python3
"""The session benchmark's report (run.sh): OUT/session.csv (one row per repeat and step: the
preparation and each scan, with every stage's seconds and each scan's landmark TRE) and
OUT/summary.md (the medians against issue 17's targets).

    report.py OUT REPEATS
"""
import csv
import os
import statistics
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from benchmark_common import finite, load_json, machine_section, table_row, write_atomically  # noqa: E402

SHIFTS = [5, 10, 15]
STAGES = ["rigid", "classify", "mesh", "surface", "simulate", "refine", "warp"]
PREPARATION = ["mesh", "preoperative_surface", "worker"]
TARGETS = {1: 7.0, 2: 3.0, 3: 3.0}


def rows_of(out, repeat):
    session = os.path.join(out, "runs", "session-%d" % repeat)
    rows = []
    prepared = load_json(os.path.join(session, "preoperative", "report.json")) or {}
    stages = prepared.get("stages", {})
    row = {"repeat": repeat, "step": "preparation", "shift_mm": "", "outcome": "prepared" if stages else "missing"}
    for stage in PREPARATION:
        row[stage + "_s"] = finite(stages.get(stage, {}).get("wall_seconds"))
    row["wall_s"] = sum(v for v in (row[s + "_s"] for s in PREPARATION) if v is not None)
    rows.append(row)
    watch = load_json(os.path.join(session, "watch.json")) or {}
    for number, shift in enumerate(SHIFTS, start=1):
        scan = os.path.join(session, "scan-%02d" % number)
        report = load_json(os.path.join(scan, "report.json")) or {}
        tre = load_json(os.path.join(scan, "landmark_tre.json")) or {}
        listed = watch.get("scans", [])
        entry = listed[number - 1] if len(listed) >= number else {}
        row = {"repeat": repeat, "step": "scan %d" % number, "shift_mm": shift, "outcome": entry.get("outcome", "missing"),
               "trust": entry.get("trust", ""), "wall_s": finite(report.get("scan_wall_seconds")),
               "tre_mean_mm": finite(tre.get("mean_mm")), "tre_p95_mm": finite(tre.get("p95_mm"))}
        for stage in STAGES:
            row[stage + "_s"] = finite(report.get("stages", {}).get(stage, {}).get("wall_seconds"))
        rows.append(row)
    return rows


def median(values):
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def fmt(value, digits=2):
    return "" if value is None else "%.*f" % (digits, value)


def main():
    out, repeats = sys.argv[1], int(sys.argv[2])
    rows = [row for repeat in range(1, repeats + 1) for row in rows_of(out, repeat)]
    fields = ["repeat", "step", "shift_mm", "outcome", "trust", "wall_s", "tre_mean_mm", "tre_p95_mm"] + \
        [s + "_s" for s in PREPARATION] + [s + "_s" for s in STAGES if s + "_s" not in [p + "_s" for p in PREPARATION]]
    with open(os.path.join(out, "session.csv.tmp"), "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: ("" if row.get(k) is None else row.get(k)) for k in fields})
    os.replace(os.path.join(out, "session.csv.tmp"), os.path.join(out, "session.csv"))

    lines = ["# One session in the operating room (`Testing/Benchmarks/session/run.sh`)", "",
             "`brainshift watch` on the full built-in case (the logic the host's Intraoperative update module runs): "
             "the preparation before surgery, then three scans of the same patient at 5, 10 and 15 mm of shift. "
             "Median of %d repeats; seconds from the image to the warped volumes and the scene, files and all; "
             "landmark TRE of each scan against its own truth. Targets (issue 17): the first scan <= 7 s, a later one <= 3 s." % repeats, ""]
    prep = [r for r in rows if r["step"] == "preparation"]
    lines += ["## Before surgery", "", table_row(["step", "median s"]), table_row(["---", "---:"])]
    for stage, label in zip(PREPARATION, ["mesh", "preoperative brain boundary", "served worker (start, partition, assembly)"]):
        lines.append(table_row([label, fmt(median([r[stage + "_s"] for r in prep]))]))
    lines.append(table_row(["all", fmt(median([r["wall_s"] for r in prep]))]))
    lines += ["", "## The scans", "",
              table_row(["scan", "shift mm", "outcomes", "median s", "target s", "met"] + STAGES + ["TRE mean / p95 mm"]),
              table_row(["---", "---:", "---", "---:", "---:", "---"] + ["---:"] * len(STAGES) + ["---"])]
    for number, shift in enumerate(SHIFTS, start=1):
        scans = [r for r in rows if r["step"] == "scan %d" % number]
        wall = median([r["wall_s"] for r in scans])
        outcomes = ", ".join(sorted({"%s (%s)" % (r["outcome"], r["trust"]) for r in scans}))
        met = "" if wall is None else ("yes" if wall <= TARGETS[number] else "no")
        lines.append(table_row(["%d" % number, "%d" % shift, outcomes, fmt(wall, 1), fmt(TARGETS[number], 0), met] +
                               [fmt(median([r[s + "_s"] for r in scans])) for s in STAGES] +
                               ["%s / %s" % (fmt(median([r["tre_mean_mm"] for r in scans])), fmt(median([r["tre_p95_mm"] for r in scans])))]))
    lines += [""] + machine_section(out)
    write_atomically(os.path.join(out, "summary.md"), "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
