#!/usr/bin/env python3
"""Report of the finite element solve benchmark: report.py OUT (the folder run.sh wrote).

Reads OUT/machine.txt and OUT/simulate_bench.csv (a partial file, from a run still going, is
reported as far as it goes); writes OUT/time_vs_size.png and OUT/summary.md.
"""
import csv
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))
from benchmark_common import (  # noqa: E402  (benchmark_common.py is in the folder above)
    finite, machine_description, machine_section, output_folder, plt, report_missing,
    save_atomically, table_row, write_atomically)
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.ticker import NullFormatter  # noqa: E402
from matplotlib.transforms import blended_transform_factory  # noqa: E402

# Targets of the simulate stage: (equations, seconds). The during-surgery solve (everything
# prepared before surgery reused) and the whole stage (assembly + setup + solve).
SOLVE_TARGETS = [(77511, 0.1), (253308, 0.5)]
STAGE_TARGETS = [(77511, 2.0)]
# The seed paper (Warfield et al. 2000): 77,511 equations in under 10 s on 16 CPUs, with GMRES and
# block Jacobi. A reference, not a target.
PAPER_EQUATIONS, PAPER_SECONDS, PAPER_CPUS = 77511, 10.0, 16
PAPER_SOLVER = "gmres+bjacobi"
PAPER_NAME = "Warfield et al. 2000"
# The sizes brainshift bench simulate measures by default, and the solvers it runs only up to a
# number of equations (memory for the direct factorisation, time for the paper's solver).
DEFAULT_SIZES = [20000, 77511, 253308, 1000000]
SOLVER_LIMITS = {"cholesky+mumps": (300000, "memory of the factorisation"),
                 "gmres+bjacobi": (300000, "too slow")}
# A target at N equations is judged on the size aimed at N equations, else on the measured size
# nearest to N within this factor, else it is not measured.
SIZE_MATCH = 1.3

COLUMNS = ["target_equations", "equations", "tetrahedra", "imposed_nodes", "solver", "ranks",
           "assembly_seconds", "setup_seconds", "solve_seconds", "prepare_wall_seconds",
           "iterations", "relative_residual", "converged"]
SOLVERS = {
    "cg+gamg": ("tab:blue", "conjugate gradients with PETSc's algebraic multigrid (GAMG)"),
    "cg+hypre": ("tab:green", "conjugate gradients with hypre's BoomerAMG multigrid"),
    "gmres+bjacobi": ("tab:orange", "GMRES with block Jacobi, the seed paper's solver"),
    "cholesky+mumps": ("tab:purple", "Cholesky factorisation by MUMPS, kept between scans"),
}
OTHER_COLORS = ["tab:brown", "tab:pink", "tab:olive", "tab:cyan", "tab:gray", "tab:red"]
RANK_STYLES = ["-", (0, (5, 3)), (0, (1, 2)), (0, (6, 2, 1, 2))]
TARGET_COLOR = "crimson"
PAPER_COLOR = "0.35"


def whole_number(value):
    value = finite(value)
    return None if value is None else int(round(value))


# --- the measurements -----------------------------------------------------------------------------
def read_runs(path):
    """[run, ...]: one dict per line of simulate_bench.csv. A run counts ("ok") when it converged
    and its times are known; the times of a failed run are not used."""
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        if reader.fieldnames is None or not set(COLUMNS) <= set(reader.fieldnames):
            sys.exit(f"report.py: {path}: header must have {','.join(COLUMNS)}")
        runs = []
        for line, row in enumerate(reader, start=2):
            if not any((v or "").strip() for v in row.values() if isinstance(v, str)):
                continue
            target = whole_number(row["target_equations"])
            equations = whole_number(row["equations"])
            ranks, converged = whole_number(row["ranks"]), whole_number(row["converged"])
            solver = (row["solver"] or "").strip()
            if None in (target, equations, ranks, converged) or not solver:
                print(f"report.py: {path}:{line}: incomplete line ignored", file=sys.stderr)
                continue
            run = {"target": target, "equations": equations,
                   "tetrahedra": whole_number(row["tetrahedra"]),
                   "imposed": whole_number(row["imposed_nodes"]), "solver": solver, "ranks": ranks,
                   "assembly": finite(row["assembly_seconds"]),
                   "setup": finite(row["setup_seconds"]),
                   "solve": finite(row["solve_seconds"]),
                   "prepare_wall": finite(row["prepare_wall_seconds"]),
                   "iterations": whole_number(row["iterations"]),
                   "residual": finite(row["relative_residual"]), "converged": converged == 1}
            phases = [run["assembly"], run["setup"], run["solve"]]
            run["ok"] = run["converged"] and run["solve"] is not None
            run["whole"] = sum(phases) if run["ok"] and None not in phases else None
            runs.append(run)
    return runs


def solver_order(runs):
    known = [s for s in SOLVERS if any(r["solver"] == s for r in runs)]
    return known + sorted({r["solver"] for r in runs} - set(SOLVERS))


def solver_color(solver, solvers):
    if solver in SOLVERS:
        return SOLVERS[solver][0]
    others = [s for s in solvers if s not in SOLVERS]
    return OTHER_COLORS[others.index(solver) % len(OTHER_COLORS)]


def rank_style(ranks, rank_counts):
    return RANK_STYLES[rank_counts.index(ranks) % len(RANK_STYLES)]


def group_sizes(runs):
    """[size, ...] by number of equations: the mesh aimed at a number of equations and its runs."""
    sizes = {}
    for r in runs:
        size = sizes.setdefault(r["target"], {"target": r["target"], "equations": r["equations"],
                                              "tetrahedra": r["tetrahedra"],
                                              "imposed": r["imposed"], "runs": []})
        size["runs"].append(r)
    order = solver_order(runs)
    for size in sizes.values():
        size["runs"].sort(key=lambda r: (order.index(r["solver"]), r["ranks"]))
    return sorted(sizes.values(), key=lambda s: s["equations"])


def size_for(sizes, equations):
    """The measured size a target at this many equations is judged on, or None."""
    for size in sizes:
        if size["target"] == equations:
            return size
    near = [s for s in sizes if 1 / SIZE_MATCH <= s["equations"] / equations <= SIZE_MATCH]
    return min(near, key=lambda s: abs(math.log(s["equations"] / equations)), default=None)


def fastest(size, key):
    """The runs of a size that count, fastest first by key ("solve" or "whole")."""
    return sorted((r for r in size["runs"] if r["ok"] and r[key] is not None), key=lambda r: r[key])


def read_nproc(out):
    for line in machine_description(out) or []:
        if line.startswith("nproc:"):
            return whole_number(line.split(":", 1)[1])
    return None


# --- chart ----------------------------------------------------------------------------------------
def equations_label(value):
    if value >= 1e6:
        return f"{value / 1e6:.3g}M"
    if value >= 1e3:
        return f"{value / 1e3:.3g}k"
    return f"{value:g}"


def time_chart(path, runs):
    solvers = solver_order(runs)
    rank_counts = sorted({r["ranks"] for r in runs})
    # The legend goes under both panels: the lines climb from lower left to upper right and fill
    # any corner of a panel at one size or another.
    fig, axes = plt.subplots(1, 2, figsize=(9, 4.5), dpi=100)
    panels = [
        (axes[0], "solve", "during surgery: the solve for a new scan", "solve time (s)",
         SOLVE_TARGETS),
        (axes[1], "whole", "whole stage: assembly + setup + solve",
         "assembly + setup + solve (s)", STAGE_TARGETS),
    ]
    note = {"fontsize": 7, "textcoords": "offset points", "va": "center",
            "bbox": {"boxstyle": "round,pad=0.15", "facecolor": "white", "edgecolor": "none",
                     "alpha": 0.8}}
    sizes = sorted({r["equations"] for r in runs})
    any_failed = False
    for ax, key, title, ylabel, targets in panels:
        failed_at = blended_transform_factory(ax.transData, ax.transAxes)
        for solver in solvers:
            color = solver_color(solver, solvers)
            for ranks in rank_counts:
                mine = sorted((r for r in runs if r["solver"] == solver and r["ranks"] == ranks),
                              key=lambda r: r["equations"])
                points = [(r["equations"], r[key]) for r in mine if r["ok"] and r[key] is not None]
                if points:
                    one = ranks == rank_counts[0]
                    ax.plot([p[0] for p in points], [p[1] for p in points], color=color,
                            linewidth=1.6, linestyle=rank_style(ranks, rank_counts), marker="o",
                            markersize=4.5, markerfacecolor=color if one else "white")
                failed = [r["equations"] for r in mine if not r["ok"]]
                if failed:
                    any_failed = True
                    ax.plot(failed, [0.03] * len(failed), transform=failed_at, color=color,
                            linestyle="none", marker="x", markersize=7, markeredgewidth=1.6,
                            clip_on=False)
        for equations, limit in targets:
            ax.plot([equations], [limit], linestyle="none", marker="v", markersize=10,
                    color=TARGET_COLOR, zorder=5)
            ax.annotate(f"target <= {limit:g} s\nat {equations:,}", (equations, limit),
                        xytext=(8, 0), color=TARGET_COLOR, zorder=6, **note)
        if key == "whole":
            ax.plot([PAPER_EQUATIONS], [PAPER_SECONDS], linestyle="none", marker="*",
                    markersize=13, color=PAPER_COLOR, zorder=5)
            ax.annotate(f"paper: {PAPER_SECONDS:g} s\non {PAPER_CPUS} CPUs",
                        (PAPER_EQUATIONS, PAPER_SECONDS), xytext=(9, 0), color=PAPER_COLOR,
                        zorder=6, **note)
        ax.set_xscale("log")
        ax.set_yscale("log")
        # Ticks at the sizes measured (and the targets' sizes when none is near them).
        ticks = list(sizes)
        for equations in [e for e, _ in targets] + ([PAPER_EQUATIONS] if key == "whole" else []):
            if all(abs(math.log(t / equations)) > math.log(SIZE_MATCH) for t in ticks):
                ticks.append(equations)
        ax.set_xticks(sorted(ticks), [equations_label(t) for t in sorted(ticks)])
        ax.xaxis.set_minor_formatter(NullFormatter())
        low, high = ax.get_xlim()
        ax.set_xlim(low, high * 1.6)  # room for the notes right of the markers
        ax.set_xlabel("equations (3 per mesh node)")
        ax.set_ylabel(ylabel)
        ax.set_title(title, fontsize=9)
        ax.tick_params(labelsize=8)
        ax.grid(True, which="major", linewidth=0.4, alpha=0.5)
        ax.grid(True, which="minor", linewidth=0.3, alpha=0.25)
    handles = ([Line2D([], [], color=solver_color(s, solvers), linewidth=1.8, label=s)
                for s in solvers] +
               [Line2D([], [], color="0.2", linewidth=1.2, linestyle=rank_style(n, rank_counts),
                       marker="o", markersize=4,
                       markerfacecolor="0.2" if n == rank_counts[0] else "white",
                       label=rank_text(n)) for n in rank_counts] +
               [Line2D([], [], linestyle="none", marker="v", markersize=8, color=TARGET_COLOR,
                       label="target (at most)"),
                Line2D([], [], linestyle="none", marker="*", markersize=10, color=PAPER_COLOR,
                       label=f"{PAPER_NAME} ({PAPER_CPUS} CPUs)")])
    if any_failed:
        handles.append(Line2D([], [], color="0.2", linestyle="none", marker="x", markersize=6,
                              markeredgewidth=1.4, label="failed run"))
    columns = 4
    rows = -(-len(handles) // columns)
    fig.subplots_adjust(left=0.075, right=0.985, top=0.87, bottom=0.14 + 0.04 * rows, wspace=0.24)
    fig.legend(handles=handles, loc="lower center", ncol=columns, fontsize=7.5, frameon=False,
               bbox_to_anchor=(0.5, 0.0), columnspacing=2.0, handlelength=2.6)
    fig.suptitle("BrainShift finite element solve: brain-sized ellipsoid phantom, linear "
                 "tetrahedra, prepared before surgery", fontsize=10)
    save_atomically(fig, path)


# --- summary --------------------------------------------------------------------------------------
def seconds(value):
    value = finite(value)
    if value is None:
        return "n/a"
    return f"{value:.3f}" if value < 10 else f"{value:.2f}" if value < 100 else f"{value:.1f}"


def count(value):
    return "n/a" if value is None else f"{value:,}"


def rank_text(ranks):
    return f"{ranks} rank{'' if ranks == 1 else 's'}"


def run_text(run, key):
    return f"{run['solver']} on {rank_text(run['ranks'])} ({seconds(run[key])} s)"


def per_solver(runs, key):
    """'cg+hypre (1 rank 0.081 s, 2 ranks 0.052 s), ...' or, without key, the rank counts only."""
    parts = {}
    for r in runs:
        text = rank_text(r["ranks"]) + (f" {seconds(r[key])} s" if key else "")
        parts.setdefault(r["solver"], []).append(text)
    return ", ".join(f"{s} ({', '.join(p)})" for s, p in parts.items())


def size_name(size):
    return f"{size['target']:,} equations wanted ({size['equations']:,} in the mesh)"


def target_line(sizes, key, what, equations, limit):
    head = f"- **{what} <= {limit:g} s at {equations:,} equations**"
    size = size_for(sizes, equations)
    if size is None:
        return f"{head}: not measured (no size near {equations:,} equations in the file)."
    on = (f"on the mesh aimed at it ({size['equations']:,} equations)"
          if size["target"] == equations
          else f"on the nearest size measured ({size['equations']:,} equations)")
    counted = [r for r in size["runs"] if r["ok"] and r[key] is not None]
    met = [r for r in counted if r[key] <= limit]
    missed = [r for r in counted if r[key] > limit]
    failed = [r for r in size["runs"] if not r["ok"]]
    parts = [f"met by {per_solver(met, key)}" if met else "**met by no solver**"]
    if missed:
        parts.append(f"missed by {per_solver(missed, key)}")
    if failed:
        parts.append(f"failed: {per_solver(failed, None)}")
    return f"{head}, {on}: {'; '.join(parts)}."


def paper_line(sizes, nproc):
    head = (f"- Reference, {PAPER_NAME}: {PAPER_EQUATIONS:,} equations in under "
            f"{PAPER_SECONDS:g} s on {PAPER_CPUS} CPUs ({PAPER_SOLVER})")
    size = size_for(sizes, PAPER_EQUATIONS)
    if size is None:
        return f"{head}: no size near {PAPER_EQUATIONS:,} equations measured here."
    cores = f"{nproc} CPU{'' if nproc == 1 else 's'} (nproc)" if nproc else "this machine"
    counted = fastest(size, "whole")
    within = [r for r in counted if r["whole"] < PAPER_SECONDS]
    text = f"{head}. Here, with {cores} and {size['equations']:,} equations, the whole stage "
    text += (f"takes under {PAPER_SECONDS:g} s with {per_solver(within, 'whole')}" if within
             else f"takes under {PAPER_SECONDS:g} s with no solver")
    paper = [r for r in size["runs"] if r["solver"] == PAPER_SOLVER]
    if paper:
        text += "; the paper's solver: " + ", ".join(
            f"{rank_text(r['ranks'])} {seconds(r['whole'])} s whole, {seconds(r['solve'])} s "
            f"during surgery" if r["ok"] else f"{rank_text(r['ranks'])} failed" for r in paper)
    return text + "."


def size_table(size, solvers_anywhere):
    lines = ["| solver | ranks | assembly (s) | setup (s) | solve (s) | whole (s) | "
             "prepare, wall (s) | iterations | relative residual |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    best = {key: (fastest(size, key) or [None])[0] for key in ("solve", "whole")}
    for r in size["runs"]:
        if not r["ok"]:
            cells = ["**failed**"] + ["—"] * 6
        else:
            def timed(key):
                text = seconds(r[key])
                return f"**{text}**" if best[key] is r else text
            cells = [seconds(r["assembly"]), seconds(r["setup"]), timed("solve"), timed("whole"),
                     seconds(r["prepare_wall"]), count(r["iterations"]),
                     "n/a" if r["residual"] is None else f"{r['residual']:.1e}"]
        lines.append(table_row([r["solver"], str(r["ranks"]), *cells]))
    lines.append("")
    absent = [s for s in solvers_anywhere if not any(r["solver"] == s for r in size["runs"])]
    if absent:
        notes = []
        for s in absent:
            limit = SOLVER_LIMITS.get(s)
            if limit and size["equations"] > limit[0]:
                notes.append(f"{s} (run only up to {limit[0]:,} equations: {limit[1]})")
            else:
                notes.append(s)
        lines += [f"Not measured at this size: {', '.join(notes)}.", ""]
    return lines


def winners_sentence(per_size, what):
    """One sentence on which solver is fastest by key over the sizes: [(size, run or None)]."""
    measured = [(size, run) for size, run in per_size if run is not None]
    if not measured:
        return f"No run counts, so no solver is fastest {what}."
    names = {run["solver"] for _, run in measured}
    if len(names) == 1:
        only = names.pop()
        every = "every size measured" if len(measured) > 1 else "the only size measured"
        return f"Fastest {what}: {only} at {every}."
    by_solver = {}
    for size, run in measured:
        by_solver.setdefault(run["solver"], []).append(f"{size['equations']:,}")
    return (f"The fastest solver {what} depends on the size: " +
            "; ".join(f"{solver} at {and_list(where)} equations"
                      for solver, where in by_solver.items()) + ".")


def and_list(items):
    items = list(items)
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def all_targets(sizes):
    """[(key, equations, limit, size)] of the targets whose size is measured."""
    judged = []
    for key, targets in (("solve", SOLVE_TARGETS), ("whole", STAGE_TARGETS)):
        for equations, limit in targets:
            size = size_for(sizes, equations)
            if size is not None:
                judged.append((key, equations, limit, size))
    return judged


def default_solver(sizes):
    """The default solver paragraph: the fastest at each size during surgery and for the whole
    stage, and the solvers that meet every target measured."""
    lines = ["## Default solver", ""]
    during = [(s, (fastest(s, "solve") or [None])[0]) for s in sizes]
    stage = [(s, (fastest(s, "whole") or [None])[0]) for s in sizes]
    text = (winners_sentence(during, "during surgery") + " " +
            winners_sentence(stage, "for the whole stage"))
    judged = all_targets(sizes)
    if judged:
        pairs = sorted({(r["solver"], r["ranks"]) for s in sizes for r in s["runs"]},
                       key=lambda p: (solver_order([r for s in sizes for r in s["runs"]])
                                      .index(p[0]), p[1]))
        meeting = []
        for solver, ranks in pairs:
            def meets(key, limit, size):
                mine = [r for r in size["runs"] if r["solver"] == solver and r["ranks"] == ranks]
                return any(r["ok"] and r[key] is not None and r[key] <= limit for r in mine)
            met = sum(meets(key, limit, size) for key, _, limit, size in judged)
            meeting.append((met, f"{solver} on {rank_text(ranks)}"))
        names = ", ".join(f"{'solve' if k == 'solve' else 'whole stage'} <= {limit:g} s at "
                          f"{e:,}" for k, e, limit, _ in judged)
        everything = [name for met, name in meeting if met == len(judged)]
        text += f" Every target measured ({names}) is met by "
        if everything:
            text += and_list(everything) + "."
        else:
            most = max((met for met, _ in meeting), default=0)
            text += "**no solver**" + (
                f"; {most} of {len(judged)} by {and_list([n for m, n in meeting if m == most])}."
                if most else ".")
        if len(judged) < len(SOLVE_TARGETS) + len(STAGE_TARGETS):
            text += " (Not every target's size is measured yet.)"
    lines += [text, ""]
    for size, (_, solve_best), (_, whole_best) in zip(sizes, during, stage):
        if solve_best is None:
            lines.append(f"- {size_name(size)}: no run counts.")
            continue
        solve = fastest(size, "solve")
        row = f"- {size_name(size)}: fastest during surgery {run_text(solve_best, 'solve')}"
        runner_up = next((r for r in solve[1:] if r["solver"] != solve_best["solver"]), None)
        if runner_up:
            row += f", next solver {run_text(runner_up, 'solve')}"
        row += f"; fastest for the whole stage {run_text(whole_best, 'whole')}."
        lines.append(row)
    return lines + [""]


def summary_md(path, out, runs, chart):
    lines = ["# Finite element solve benchmark", "", *machine_section(out)]

    sizes = group_sizes(runs or [])
    solvers = solver_order(runs or [])
    lines += ["## What is measured", "",
              "The linear elastic model of the simulate stage on a brain-sized ellipsoid phantom "
              "(semi-axes 70, 85, 60 mm; linear tetrahedra; its surface nodes imposed, a sag under "
              "a craniotomy), at each size for each solver and number of MPI ranks, as a prepared "
              "session: *assembly* (partition, assembly, elimination of the imposed values) and "
              "*setup* (the multigrid hierarchy or the direct factorisation) happen before "
              "surgery; *solve* is the during-surgery solve for a new set of surface values, "
              "everything else reused; *whole* = assembly + setup + solve; *prepare, wall* is the "
              "whole preparation as the caller saw it, process start included. The fastest solve "
              "and whole stage at each size are in bold."
              + (" Chart: [time_vs_size.png](time_vs_size.png)." if chart else ""), ""]
    for s in solvers:
        lines.append(f"- {s}: {SOLVERS[s][1]}" if s in SOLVERS else f"- {s}")
    lines.append("")
    if runs is None:
        lines += ["simulate_bench.csv missing.", ""]
        write_atomically(path, "\n".join(lines))
        return
    if not sizes:
        lines += ["simulate_bench.csv has no runs yet.", ""]
        write_atomically(path, "\n".join(lines))
        return
    missing = [n for n in DEFAULT_SIZES if all(s["target"] != n for s in sizes)]
    if missing:
        measured = ", ".join(f"{s['target']:,}" for s in sizes)
        absent = ", ".join(f"{n:,}" for n in missing)
        lines += [f"**Partial:** sizes measured so far: {measured} equations wanted; not in the "
                  f"file: {absent} (not asked for, or the run is still going).", ""]

    nproc = read_nproc(out)
    lines += ["## Targets", ""]
    lines += [target_line(sizes, "solve", "During-surgery solve", e, s) for e, s in SOLVE_TARGETS]
    lines += [target_line(sizes, "whole", "Whole stage", e, s) for e, s in STAGE_TARGETS]
    lines += [paper_line(sizes, nproc), ""]

    lines += default_solver(sizes)

    lines += ["## Times by size", ""]
    for size in sizes:
        lines += [f"### {size['target']:,} equations wanted", "",
                  f"{size['equations']:,} equations, {count(size['tetrahedra'])} tetrahedra, "
                  f"{count(size['imposed'])} imposed nodes.", "",
                  *size_table(size, solvers)]
    write_atomically(path, "\n".join(lines))


def main():
    out = output_folder()
    runs = None
    chart = False
    csv_path = os.path.join(out, "simulate_bench.csv")
    if os.path.isfile(csv_path):
        runs = read_runs(csv_path)
        if runs:
            time_chart(os.path.join(out, "time_vs_size.png"), runs)
            chart = True
    else:
        report_missing(csv_path)
    summary_md(os.path.join(out, "summary.md"), out, runs, chart)
    print(f"wrote {os.path.join(out, 'summary.md')}" + (", time_vs_size.png" if chart else ""))


if __name__ == "__main__":
    main()
