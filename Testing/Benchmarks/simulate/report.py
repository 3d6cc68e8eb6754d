#!/usr/bin/env python3
"""Report of the finite element solve benchmark: report.py OUT (the folder run.sh wrote).

Reads OUT/machine.txt and OUT/simulate_bench.csv (a partial file, from a run still going, is
reported as far as it goes); writes OUT/time_vs_size.png (the size sweep: time against size),
OUT/error_vs_time.png (the tolerance sweep: error against the during-surgery solve time) and
OUT/summary.md.
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
# The sizes brainshift bench simulate measures by default, the solvers it runs only up to a number
# of equations (memory of the direct factorisation), and those it runs on 1 rank only.
DEFAULT_SIZES = [20000, 77511, 253308, 1000000]
SOLVER_LIMITS = {"cholesky+cholmod": (300000, "memory of the factorisation"),
                 "cholesky+mumps": (300000, "memory of the factorisation")}
ONE_RANK_SOLVERS = {"cholesky+cholmod": "CHOLMOD is sequential"}
# A target at N equations is judged on the size aimed at N equations, else on the measured size
# nearest to N within this factor, else it is not measured.
SIZE_MATCH = 1.3
# The error against the reference solution: judged against 1 % of the 1 mm accuracy target, and
# charted (log scale) with the errors below the floor drawn at it (a direct solver's is 0 to 1e-13).
ERROR_BOUND_MM = 0.01
ERROR_BOUND_NAME = "1 % of the 1 mm accuracy target"
ERROR_FLOOR_MM = 1e-12

# The columns brainshift bench simulate writes; a file without the optional ones (an older run) is
# reported without them.
COLUMNS = ["sweep", "target_equations", "equations", "tetrahedra", "imposed_nodes",
           "free_surface_nodes", "mesh_resolution_mm", "solver", "ranks", "rtol",
           "assembly_seconds", "setup_seconds", "solve_seconds", "prepare_wall_seconds",
           "iterations", "relative_residual", "error_mm", "reference", "converged"]
REQUIRED = ["target_equations", "equations", "solver", "ranks", "solve_seconds", "converged"]
SWEEPS = ("size", "rtol")
SOLVERS = {
    "cg+gamg": ("tab:blue", "conjugate gradients with PETSc's algebraic multigrid (GAMG)"),
    "cg+hypre": ("tab:green", "conjugate gradients with hypre's BoomerAMG multigrid"),
    "cg+bjacobi": ("tab:brown", "conjugate gradients with block Jacobi, one block per rank, "
                               "ILU(0) in each (not always positive definite: CG can break down "
                               "on it)"),
    "cg+icc": ("tab:olive", "conjugate gradients with block Jacobi, incomplete Cholesky in each "
                           "block (shifted to stay positive definite)"),
    "gmres+bjacobi": ("tab:orange", f"GMRES with block Jacobi (ILU(0) per rank), the seed paper's "
                                    f"solver ({PAPER_NAME})"),
    "cholesky+cholmod": ("tab:cyan", "Cholesky factorisation by CHOLMOD (SuiteSparse), kept "
                                     "between scans; sequential: 1 rank only"),
    "cholesky+mumps": ("tab:purple", "Cholesky factorisation by MUMPS, kept between scans"),
}
OTHER_COLORS = ["tab:pink", "black", "tab:gray", "tab:red"]
RANK_STYLES = ["-", (0, (5, 3)), (0, (1, 2)), (0, (6, 2, 1, 2))]
TARGET_COLOR = "crimson"
PAPER_COLOR = "0.35"


def whole_number(value):
    value = finite(value)
    return None if value is None else int(round(value))


def is_direct(solver):
    return solver.startswith("cholesky+")


# --- the measurements -----------------------------------------------------------------------------
class UnreadableFile(Exception):
    pass


def read_runs(path):
    """[run, ...]: one dict per line of simulate_bench.csv (an empty file: none). A run counts
    ("ok") when it converged and its solve time is known; the numbers of a failed run are not used.
    Raises UnreadableFile when the header lacks a column the report cannot do without."""
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        if reader.fieldnames is None:
            return []
        fields = [(name or "").strip() for name in reader.fieldnames]
        reader.fieldnames = fields
        missing = [c for c in REQUIRED if c not in fields]
        if missing:
            raise UnreadableFile(f"the header lacks {', '.join(missing)}")
        absent = [c for c in COLUMNS if c not in fields and c not in REQUIRED]
        if absent:
            print(f"report.py: {path}: no column {', '.join(absent)}: reported without",
                  file=sys.stderr)
        runs = []
        unknown = set()
        for line, row in enumerate(reader, start=2):
            def text(column):
                value = row.get(column)
                return value.strip() if isinstance(value, str) else ""

            if not any(text(c) for c in fields):
                continue
            target = whole_number(text("target_equations"))
            equations = whole_number(text("equations"))
            ranks, converged = whole_number(text("ranks")), whole_number(text("converged"))
            solver, sweep = text("solver"), text("sweep") or "size"
            if None in (target, equations, ranks, converged) or not solver:
                print(f"report.py: {path}:{line}: incomplete line ignored", file=sys.stderr)
                continue
            if sweep not in SWEEPS:
                unknown.add(sweep)
            run = {"sweep": sweep, "target": target, "equations": equations,
                   "tetrahedra": whole_number(text("tetrahedra")),
                   "imposed": whole_number(text("imposed_nodes")),
                   "free": whole_number(text("free_surface_nodes")),
                   "resolution": finite(text("mesh_resolution_mm")),
                   "solver": solver, "ranks": ranks, "rtol": finite(text("rtol")),
                   "assembly": finite(text("assembly_seconds")),
                   "setup": finite(text("setup_seconds")),
                   "solve": finite(text("solve_seconds")),
                   "prepare_wall": finite(text("prepare_wall_seconds")),
                   "iterations": whole_number(text("iterations")),
                   "residual": finite(text("relative_residual")),
                   "error": finite(text("error_mm")), "reference": text("reference") or None,
                   "converged": converged == 1}
            if run["error"] is not None and run["error"] < 0:
                run["error"] = None
            phases = [run["assembly"], run["setup"], run["solve"]]
            run["ok"] = run["converged"] and run["solve"] is not None
            run["whole"] = sum(phases) if run["ok"] and None not in phases else None
            runs.append(run)
    if unknown:
        print(f"report.py: {path}: sweep {', '.join(sorted(unknown))} not reported (only "
              f"{' and '.join(SWEEPS)})", file=sys.stderr)
    return runs


def sweep_runs(runs, sweep):
    return [r for r in runs if r["sweep"] == sweep]


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


def first_known(runs, key):
    return next((r[key] for r in runs if r[key] is not None), None)


def group_sizes(runs):
    """[size, ...] by number of equations: the mesh aimed at a number of equations and its runs."""
    by_target = {}
    for r in runs:
        by_target.setdefault(r["target"], []).append(r)
    order = solver_order(runs)
    sizes = []
    for target, mine in by_target.items():
        mine.sort(key=lambda r: (order.index(r["solver"]), r["ranks"],
                                 -(r["rtol"] if r["rtol"] is not None else math.inf)))
        size = {"target": target, "runs": mine, "equations": mine[0]["equations"]}
        for key in ("tetrahedra", "imposed", "free", "resolution", "reference"):
            size[key] = first_known(mine, key)
        sizes.append(size)
    return sorted(sizes, key=lambda s: s["equations"])


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


# --- text -----------------------------------------------------------------------------------------
def seconds(value):
    value = finite(value)
    if value is None:
        return "n/a"
    return f"{value:.3f}" if value < 10 else f"{value:.2f}" if value < 100 else f"{value:.1f}"


def count(value):
    return "n/a" if value is None else f"{value:,}"


def rtol_text(value):
    """1e-06 as 1e-6; None (a direct solver) as a dash."""
    if value is None:
        return "—"
    mantissa, exponent = f"{value:.2e}".split("e")
    mantissa = mantissa.rstrip("0").rstrip(".")
    return f"{mantissa}e{int(exponent)}"


def error_text(value):
    """The error in mm like 3.7e-05 (0 as 0), n/a when unknown; with a digit more when the
    rounding would put it on the other side of the bound (9.99e-03, not 1.0e-02)."""
    if value is None:
        return "n/a"
    if value == 0:
        return "0"
    def misleading(text):
        shown = float(text)
        return value != ERROR_BOUND_MM and (
            shown == ERROR_BOUND_MM or (shown <= ERROR_BOUND_MM) != (value <= ERROR_BOUND_MM))

    digits = 1
    while misleading(f"{value:.{digits}e}") and digits < 6:
        digits += 1
    return f"{value:.{digits}e}"


def rank_text(ranks):
    return f"{ranks} rank{'' if ranks == 1 else 's'}"


def run_name(run):
    return f"{run['solver']} on {rank_text(run['ranks'])}"


def run_text(run, key):
    error = "" if run["error"] is None else f", error {error_text(run['error'])} mm"
    return f"{run_name(run)} ({seconds(run[key])} s{error})"


def per_solver(runs, key):
    """'cg+hypre (1 rank 0.081 s, 2 ranks 0.052 s), ...' or, without key, the rank counts only."""
    parts = {}
    for r in runs:
        text = rank_text(r["ranks"]) + (f" {seconds(r[key])} s" if key else "")
        parts.setdefault(r["solver"], []).append(text)
    return ", ".join(f"{s} ({', '.join(p)})" for s, p in parts.items())


def and_list(items):
    items = list(items)
    if not items:
        return "none"
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def size_name(size):
    return f"{size['target']:,} equations wanted ({size['equations']:,} in the mesh)"


def mesh_text(size):
    """'78,480 equations, 134,301 tetrahedra, lattice mesh at 4.29 mm, ...' from the file."""
    text = f"{size['equations']:,} equations, {count(size['tetrahedra'])} tetrahedra"
    if size["resolution"] is not None:
        text += f", lattice mesh at {size['resolution']:.2f} mm"
    text += f"; {count(size['imposed'])} brain-surface nodes imposed"
    if size["free"] is not None:
        text += f", {size['free']:,} left free"
    if size["reference"]:
        text += f"; reference solution: {size['reference']}"
    return text


def tolerances_text(runs):
    values = sorted({r["rtol"] for r in runs if r["rtol"] is not None}, reverse=True)
    return ", ".join(rtol_text(v) for v in values) if values else "n/a"


def size_sweep_rtol(size_runs):
    """' (the iterative solvers at rtol 1e-6)', or nothing when the file does not say."""
    iterative = [r for r in size_runs if not is_direct(r["solver"]) and r["rtol"] is not None]
    return f" (the iterative solvers at rtol {tolerances_text(iterative)})" if iterative else ""


# --- charts ---------------------------------------------------------------------------------------
def equations_label(value):
    if value >= 1e6:
        return f"{value / 1e6:.3g}M"
    if value >= 1e3:
        return f"{value / 1e3:.3g}k"
    return f"{value:g}"


NOTE = {"fontsize": 7, "textcoords": "offset points", "va": "center",
        "bbox": {"boxstyle": "round,pad=0.15", "facecolor": "white", "edgecolor": "none",
                 "alpha": 0.8}}


def time_chart(path, runs):
    """Time against size (the size sweep's runs)."""
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
    sizes = sorted({r["equations"] for r in runs})
    any_failed = False
    for ax, key, title, ylabel, targets in panels:
        failed_at = blended_transform_factory(ax.transData, ax.transAxes)
        for solver in solvers:
            color = solver_color(solver, solvers)
            for ranks in rank_counts:
                mine = sorted((r for r in runs if r["solver"] == solver and r["ranks"] == ranks),
                              key=lambda r: r["equations"])
                points = [(r["equations"], r[key]) for r in mine
                          if r["ok"] and r[key] is not None and r[key] > 0]  # log scale
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
                        xytext=(8, 0), color=TARGET_COLOR, zorder=6, **NOTE)
        if key == "whole":
            ax.plot([PAPER_EQUATIONS], [PAPER_SECONDS], linestyle="none", marker="*",
                    markersize=13, color=PAPER_COLOR, zorder=5)
            ax.annotate(f"paper: {PAPER_SECONDS:g} s\non {PAPER_CPUS} CPUs",
                        (PAPER_EQUATIONS, PAPER_SECONDS), xytext=(9, 0), color=PAPER_COLOR,
                        zorder=6, **NOTE)
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
    fig.suptitle("BrainShift finite element solve: brain meshes of the built-in case, linear "
                 "tetrahedra, prepared before surgery", fontsize=10)
    save_atomically(fig, path)


# Where each iterative solver's rtol notes go (offset points, alignment), so that neighbouring
# lines' notes fall on different sides.
RTOL_NOTE_PLACES = [((5, 4), "left", "bottom"), ((-5, -4), "right", "top"),
                    ((5, -4), "left", "top"), ((-5, 4), "right", "bottom")]


def accuracy_chart(path, size, runs, direct):
    """Error against the during-surgery solve time at one size: the iterative solvers' lines
    through their tolerances (runs, the rtol sweep) and the direct solvers' points (direct, the
    size sweep's runs at the same size). Returns True when any error is drawn at the floor."""
    solvers = solver_order(runs + direct)
    rank_counts = sorted({r["ranks"] for r in runs + direct})
    several_ranks = len(rank_counts) > 1
    fig, ax = plt.subplots(figsize=(8, 6), dpi=100)
    floored = False
    handles = []
    lines = sorted({(r["solver"], r["ranks"]) for r in runs},
                   key=lambda p: (solvers.index(p[0]), p[1]))
    for number, (solver, ranks) in enumerate(lines):
        color = solver_color(solver, solvers)
        mine = sorted((r for r in runs if r["solver"] == solver and r["ranks"] == ranks
                       and r["ok"] and r["error"] is not None and r["solve"] > 0),
                      key=lambda r: -(r["rtol"] if r["rtol"] is not None else 0))
        if not mine:
            continue
        xs = [r["solve"] for r in mine]
        ys = [max(r["error"], ERROR_FLOOR_MM) for r in mine]
        floored = floored or any(r["error"] < ERROR_FLOOR_MM for r in mine)
        label = solver + (f", {rank_text(ranks)}" if several_ranks else "")
        ax.plot(xs, ys, color=color, linewidth=1.5, marker="o", markersize=4.5,
                linestyle=rank_style(ranks, rank_counts), label=label)
        handles.append(Line2D([], [], color=color, linewidth=1.5, marker="o", markersize=4.5,
                              linestyle=rank_style(ranks, rank_counts), label=label))
        offset, ha, va = RTOL_NOTE_PLACES[number % len(RTOL_NOTE_PLACES)]
        for r, x, y in zip(mine, xs, ys):
            if r["rtol"] is not None:
                ax.annotate(rtol_text(r["rtol"]), (x, y), xytext=offset, textcoords="offset points",
                            fontsize=6.5, color=color, ha=ha, va=va)
    direct = [r for r in direct if r["solve"] > 0]  # log scale
    for marker, r in zip(["s", "D", "^", "P", "X"] * 4, direct):
        color = solver_color(r["solver"], solvers)
        floored = floored or r["error"] < ERROR_FLOOR_MM
        label = f"{r['solver']}, {rank_text(r['ranks'])} (direct)"
        ax.plot([r["solve"]], [max(r["error"], ERROR_FLOOR_MM)], linestyle="none", marker=marker,
                markersize=8, color=color, markeredgecolor="0.15", zorder=4)
        handles.append(Line2D([], [], linestyle="none", marker=marker, markersize=7, color=color,
                              markeredgecolor="0.15", label=label))
    across = blended_transform_factory(ax.transAxes, ax.transData)
    ax.axhline(ERROR_BOUND_MM, color=TARGET_COLOR, linestyle="--", linewidth=1.0)
    # The lines run from upper left (fast, loose) to lower right: the notes go on the left.
    ax.text(0.01, ERROR_BOUND_MM, f"{ERROR_BOUND_NAME} ({ERROR_BOUND_MM:g} mm)", transform=across,
            ha="left", va="bottom", fontsize=7.5, color=TARGET_COLOR)
    if floored:
        ax.axhline(ERROR_FLOOR_MM, color="0.5", linestyle=":", linewidth=0.8)
        ax.text(0.99, ERROR_FLOOR_MM, f"errors below {ERROR_FLOOR_MM:g} mm drawn at "
                f"{ERROR_FLOOR_MM:g} mm", transform=across, ha="right", va="bottom", fontsize=7,
                color="0.35")
    ax.set_xscale("log")
    ax.set_yscale("log")
    low, high = ax.get_ylim()
    ax.set_ylim(min(low, ERROR_FLOOR_MM / 3 if floored else low), max(high, ERROR_BOUND_MM * 3))
    ax.set_xlabel("during-surgery solve (s)")
    ax.set_ylabel("error: largest nodal distance to the reference (mm)")
    ax.tick_params(labelsize=8)
    ax.grid(True, which="major", linewidth=0.4, alpha=0.5)
    ax.grid(True, which="minor", linewidth=0.3, alpha=0.25)
    ranks_title = (rank_text(rank_counts[0]) if len(rank_counts) == 1 else
                   "ranks " + ", ".join(str(n) for n in rank_counts))
    ax.set_title(f"{size_name(size)}, {ranks_title}\niterative solvers through their tolerances "
                 "(annotated with the rtol)"
                 + (f"; reference solution: {size['reference']}" if size["reference"] else ""),
                 fontsize=8)
    # The legend goes under the chart: the lines cross the panel from corner to corner.
    columns = 3
    rows = -(-len(handles) // columns)
    fig.subplots_adjust(left=0.1, right=0.98, top=0.86, bottom=0.13 + 0.035 * rows)
    fig.legend(handles=handles, loc="lower center", ncol=columns, fontsize=7.5, frameon=False,
               bbox_to_anchor=(0.5, 0.0), columnspacing=2.0, handlelength=2.6)
    fig.suptitle("BrainShift finite element solve: error against time over the solver tolerance",
                 fontsize=10)
    save_atomically(fig, path)
    return floored


# --- summary --------------------------------------------------------------------------------------
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


def not_measured(size, solvers_anywhere, rank_counts):
    """What is not in a size's runs although the file has it elsewhere, with the reason when
    the benchmark skips it on purpose: ['cholesky+mumps (run only up to ...)', ...]."""
    notes = []
    for s in solvers_anywhere:
        limit = SOLVER_LIMITS.get(s)
        mine = {r["ranks"] for r in size["runs"] if r["solver"] == s}
        if not mine:
            if limit and size["equations"] > limit[0]:
                notes.append(f"{s} (run only up to {limit[0]:,} equations: {limit[1]})")
            else:
                notes.append(s)
            continue
        wanted = [n for n in rank_counts if n == 1 or s not in ONE_RANK_SOLVERS]
        notes += [f"{s} on {rank_text(n)}" for n in wanted if n not in mine]
    return notes


def size_table(size, solvers_anywhere, rank_counts):
    lines = ["| solver | ranks | rtol | assembly (s) | setup (s) | solve (s) | whole (s) | "
             "prepare, wall (s) | iterations | relative residual | error (mm) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    best = {key: (fastest(size, key) or [None])[0] for key in ("solve", "whole")}
    for r in size["runs"]:
        if not r["ok"]:
            cells = ["**failed**"] + ["—"] * 7
        else:
            def timed(key):
                text = seconds(r[key])
                return f"**{text}**" if best[key] is r else text
            error = error_text(r["error"])
            if r["error"] == 0 and r["reference"] and r["reference"] == r["solver"]:
                error += " (the reference)"
            cells = [seconds(r["assembly"]), seconds(r["setup"]), timed("solve"), timed("whole"),
                     seconds(r["prepare_wall"]), count(r["iterations"]),
                     "n/a" if r["residual"] is None else f"{r['residual']:.1e}", error]
        lines.append(table_row([r["solver"], str(r["ranks"]), rtol_text(r["rtol"]), *cells]))
    lines.append("")
    notes = not_measured(size, solvers_anywhere, rank_counts)
    if notes:
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


def all_targets(sizes):
    """[(key, equations, limit, size)] of the targets whose size is measured."""
    judged = []
    for key, targets in (("solve", SOLVE_TARGETS), ("whole", STAGE_TARGETS)):
        for equations, limit in targets:
            size = size_for(sizes, equations)
            if size is not None:
                judged.append((key, equations, limit, size))
    return judged


def target_name(key, equations, limit):
    what = "during-surgery solve" if key == "solve" else "whole stage"
    return f"{what} <= {limit:g} s at {equations:,}"


def best_two(size, key):
    """The fastest run of a size by key and the fastest of another solver (or None)."""
    ranked = fastest(size, key)
    if not ranked:
        return None, None
    return ranked[0], next((r for r in ranked[1:] if r["solver"] != ranked[0]["solver"]), None)


def default_solver(sizes, solvers_anywhere, rank_counts):
    """The default solver section: at each size the fastest during surgery (everything prepared
    before surgery) and for the whole stage run once, each with the next solver; which solver and
    rank count meets each target measured, and every one."""
    lines = ["## Default solver", ""]
    if not sizes:
        return lines + ["No run of the size sweep in the file yet.", ""]
    during = [(s, best_two(s, "solve")[0]) for s in sizes]
    stage = [(s, best_two(s, "whole")[0]) for s in sizes]
    text = (winners_sentence(during, "during surgery (prepared: the solve alone)") + " " +
            winners_sentence(stage, "for the whole stage run once (assembly + setup + solve)"))
    lines += [text, ""]
    for size in sizes:
        solve_best, solve_next = best_two(size, "solve")
        whole_best, whole_next = best_two(size, "whole")
        if solve_best is None:
            failed = [r for r in size["runs"] if not r["ok"]]
            lines.append(f"- {size_name(size)}: no run counts"
                         + (f" (failed: {per_solver(failed, None)})." if failed else "."))
            continue
        row = f"- {size_name(size)}: fastest during surgery {run_text(solve_best, 'solve')}"
        if solve_next:
            row += f", next solver {run_text(solve_next, 'solve')}"
        if whole_best is not None:
            row += f"; fastest whole stage {run_text(whole_best, 'whole')}"
            if whole_next:
                row += f", next solver {run_text(whole_next, 'whole')}"
        absent = not_measured(size, solvers_anywhere, rank_counts)
        if absent:
            row += f" (not measured at this size: {', '.join(absent)})"
        lines.append(row + ".")
    lines.append("")

    judged = all_targets(sizes)
    if not judged:
        return lines + ["No target's size is measured yet.", ""]
    every = [r for s in sizes for r in s["runs"]]
    order = solver_order(every)
    pairs = sorted({(r["solver"], r["ranks"]) for r in every},
                   key=lambda p: (order.index(p[0]), p[1]))

    def meets(pair, key, limit, size):
        return any(r["ok"] and r[key] is not None and r[key] <= limit
                   for r in size["runs"] if (r["solver"], r["ranks"]) == pair)

    for key, equations, limit, size in judged:
        met = [f"{s} on {rank_text(n)}" for s, n in pairs if meets((s, n), key, limit, size)]
        where = ("" if size["target"] == equations
                 else f" (judged at {size['equations']:,} equations)")
        lines.append(f"- {target_name(key, equations, limit)}{where}: "
                     + (f"met by {and_list(met)}." if met else "met by no solver."))
    scores = [(sum(meets(p, k, limit, s) for k, _, limit, s in judged),
               f"{p[0]} on {rank_text(p[1])}") for p in pairs]
    everything = [name for met, name in scores if met == len(judged)]
    if everything:
        text = f"Every target measured is met by {and_list(everything)}."
    else:
        most = max((met for met, _ in scores), default=0)
        text = "No solver and rank count meets every target measured" + (
            f"; {most} of {len(judged)} {'is' if most == 1 else 'are'} met by "
            f"{and_list([n for m, n in scores if m == most])}." if most else ".")
    unmeasured = [target_name(k, e, limit) for k, targets in (("solve", SOLVE_TARGETS),
                                                               ("whole", STAGE_TARGETS))
                  for e, limit in targets if size_for(sizes, e) is None]
    if unmeasured:
        text += f" Not measured yet: {and_list(unmeasured)}."
    return lines + ["", text, ""]


def loosest_within(runs):
    """The run of the loosest rtol whose error is within the bound, or None."""
    within = [r for r in runs if r["ok"] and r["error"] is not None and r["rtol"] is not None
              and r["error"] <= ERROR_BOUND_MM]
    return max(within, key=lambda r: r["rtol"], default=None)


def repeat_sentence(size_runs, rtol_runs):
    """How much the tolerance sweep's repeats of size-sweep runs (same size, solver, ranks, rtol)
    differ in solve time from them, or None when there is no repeat."""
    def key(r):
        return (r["target"], r["solver"], r["ranks"], f"{r['rtol']:.6g}")
    first = {key(r): r for r in size_runs if r["ok"] and r["rtol"] is not None and r["solve"]}
    pairs = [(first[key(r)], r) for r in rtol_runs
             if r["ok"] and r["rtol"] is not None and r["solve"] and key(r) in first]
    if not pairs:
        return None
    changes = [(b["solve"] / a["solve"] - 1, a, b) for a, b in pairs]
    change, a, b = max(changes, key=lambda c: abs(c[0]))
    same = all(a["iterations"] == b["iterations"] for a, b in pairs)
    smallest = min(abs(c[0]) for c in changes)
    text = (f"The tolerance sweep repeats {len(pairs)} run{'' if len(pairs) == 1 else 's'} of the "
            f"size sweep (same mesh, solver, ranks and rtol"
            f"{', and the same iterations' if same else ''}): ")
    if len(pairs) == 1:
        text += f"its during-surgery solve time differs by {100 * abs(change):.0f} % ("
    else:
        text += (f"their during-surgery solve times differ by {100 * smallest:.0f} % to "
                 f"{100 * abs(change):.0f} % (the most: ")
    return (text + f"{a['solver']}, {seconds(a['solve'])} s in the size sweep, "
            f"{seconds(b['solve'])} s in the tolerance sweep), the run-to-run variation of the "
            f"times here.")


def accuracy_section(sizes, size_runs, rtol_runs, chart):
    """The accuracy against time section; chart: (the target of the size error_vs_time.png shows,
    whether any error is drawn at the floor), or None without the chart."""
    lines = ["## Accuracy against time", ""]
    if not rtol_runs:
        return lines + ["No tolerance sweep in the file (no sweep=rtol line yet).", ""]
    sweep_sizes = group_sizes(rtol_runs)
    for sweep in sweep_sizes:
        runs = sweep["runs"]
        direct = direct_points(sizes, sweep, runs)
        rank_counts = sorted({r["ranks"] for r in runs})
        ranks_text = and_list([rank_text(n) for n in rank_counts])
        text = (f"At {size_name(sweep)}, {ranks_text}: each iterative solver over rtol "
                f"{tolerances_text(runs)}; {mesh_text(sweep)}. Error: the largest distance "
                f"between a node's displacement and the reference solution's, in mm.")
        text += (f" The direct solvers are their runs of the size sweep at this size on "
                 f"{ranks_text}." if direct else
                 " No direct solver of the size sweep at this size to compare with.")
        if chart is not None:
            chart_target, floored = chart
            text += " Chart: [error_vs_time.png](error_vs_time.png)"
            if chart_target != sweep["target"]:
                text += f" (it shows the sweep at {chart_target:,} equations wanted)"
            elif floored:
                below = [f"{r['solver']} {error_text(r['error'])} mm" for r in runs + direct
                         if r["ok"] and r["error"] is not None and r["error"] < ERROR_FLOOR_MM]
                text += (f"; errors below {ERROR_FLOOR_MM:g} mm are drawn at "
                         f"{ERROR_FLOOR_MM:g} ({and_list(below)})")
            text += "."
        lines += [text, ""]
        lines.append(f"The loosest rtol whose error is within {ERROR_BOUND_MM:g} mm "
                     f"({ERROR_BOUND_NAME}), per iterative solver:")
        lines.append("")
        solvers = solver_order(runs)
        for solver in solvers:
            for ranks in rank_counts:
                mine = [r for r in runs if r["solver"] == solver and r["ranks"] == ranks]
                if not mine:
                    continue
                name = solver + ("" if len(rank_counts) == 1 else f" on {rank_text(ranks)}")
                best = loosest_within(mine)
                failed = [rtol_text(r["rtol"]) for r in mine if not r["ok"]]
                if best is not None:
                    row = (f"- {name}: rtol {rtol_text(best['rtol'])} (error "
                           f"{error_text(best['error'])} mm; solve {seconds(best['solve'])} s, "
                           f"whole {seconds(best['whole'])} s, {count(best['iterations'])} "
                           f"iterations)")
                else:
                    known = [r for r in mine if r["ok"] and r["error"] is not None]
                    smallest = min(known, key=lambda r: r["error"], default=None)
                    row = (f"- {name}: none of the tolerances measured" +
                           (f" (smallest error {error_text(smallest['error'])} mm at rtol "
                            f"{rtol_text(smallest['rtol'])})" if smallest else ""))
                if failed:
                    row += f"; failed at rtol {', '.join(failed)}"
                lines.append(row + ".")
        lines.append("")
        candidates = sorted((r for r in runs + direct if r["ok"] and r["error"] is not None
                             and r["error"] <= ERROR_BOUND_MM), key=lambda r: r["solve"])
        if candidates:
            top = candidates[0]
            other = next((r for r in candidates[1:] if r["solver"] != top["solver"]), None)
            text = (f"Fastest during-surgery solve within {ERROR_BOUND_MM:g} mm at this size: "
                    f"{run_name(top)}"
                    + (f" at rtol {rtol_text(top['rtol'])}" if top["rtol"] is not None else "")
                    + f" ({seconds(top['solve'])} s, error {error_text(top['error'])} mm)")
            if other:
                text += (f"; next solver {run_name(other)}"
                         + (f" at rtol {rtol_text(other['rtol'])}" if other["rtol"] is not None
                            else "")
                         + f" ({seconds(other['solve'])} s, error {error_text(other['error'])} mm)")
            lines += [text + ".", ""]
        else:
            lines += [f"No run at this size is within {ERROR_BOUND_MM:g} mm.", ""]
        repeat = repeat_sentence(size_runs, runs)
        if repeat:
            lines += [repeat, ""]
        for solver in solvers:
            for ranks in rank_counts:
                mine = [r for r in runs if r["solver"] == solver and r["ranks"] == ranks]
                if mine:
                    heading = solver + ("" if len(rank_counts) == 1 else f" on {rank_text(ranks)}")
                    if len(sweep_sizes) > 1:
                        heading += f" at {sweep['target']:,} equations wanted"
                    lines += accuracy_table(heading, mine)
    return lines


def direct_points(sizes, sweep, runs):
    """The direct solvers' size-sweep runs at the sweep's size and rank counts that count."""
    size = next((s for s in sizes if s["target"] == sweep["target"]), None)
    if size is None:
        return []
    rank_counts = {r["ranks"] for r in runs}
    return [r for r in size["runs"] if is_direct(r["solver"]) and r["ranks"] in rank_counts
            and r["ok"] and r["error"] is not None]


def accuracy_table(heading, runs):
    best = loosest_within(runs)
    lines = [f"### {heading}", "",
             "| rtol | iterations | solve (s) | whole (s) | error (mm) |",
             "|---:|---:|---:|---:|---:|"]
    for r in sorted(runs, key=lambda r: -(r["rtol"] if r["rtol"] is not None else math.inf)):
        rtol = rtol_text(r["rtol"])
        if r is best:
            rtol = f"**{rtol}**"
        if not r["ok"]:
            lines.append(table_row([rtol, "**failed**", "—", "—", "—"]))
            continue
        lines.append(table_row([rtol, count(r["iterations"]), seconds(r["solve"]),
                                seconds(r["whole"]), error_text(r["error"])]))
    if best is not None:
        lines += ["", f"In bold: the loosest rtol within {ERROR_BOUND_MM:g} mm."]
    return lines + [""]


def summary_md(path, out, runs, charts, problem=None):
    lines = ["# Finite element solve benchmark", "", *machine_section(out)]

    runs = runs or []
    size_runs, rtol_runs = sweep_runs(runs, "size"), sweep_runs(runs, "rtol")
    sizes = group_sizes(size_runs)
    solvers = solver_order(runs)
    sweep_targets = sorted({r["target"] for r in rtol_runs})
    size_rtol = size_sweep_rtol(size_runs)
    chart_links = " ".join(f"[{name}]({name})" for name in charts)
    lines += ["## What is measured", "",
              "The linear elastic model of the simulate stage on the brain of the built-in case "
              "(Colin27-based): the preoperative brain (parenchyma 3000 Pa, Poisson's ratio "
              "0.45; ventricles 100 Pa, 0.3; tumour 10 kPa, 0.45) meshed by the lattice mesher "
              "(linear tetrahedra) at the resolution that gives about the number of equations "
              "wanted; boundary conditions from the active surface moved onto the true "
              "intraoperative brain: most brain-surface nodes imposed, some left free (the "
              "resected tumour, outside the image, unmatched). Each run, for each size, solver "
              "and number of MPI ranks, is a prepared session: *assembly* (partition, assembly, "
              "elimination of the imposed values) and *setup* (the preconditioner, or the direct "
              "factorisation) happen before surgery; *solve* is the during-surgery solve for a "
              "second set of surface values (the surface sunk 20 % further), everything else "
              "reused (an iterative solver starts from the imposed values, zero inside); "
              "*whole* = assembly + setup + solve, the stage run once; *prepare, wall* is the "
              "preparation as the caller saw it, process start included. Each solution is "
              "compared with a reference solution of the same problem (*reference*: a direct "
              "CHOLMOD factorisation up to 300,000 equations, else CG + GAMG at rtol 1e-12; 1 "
              "rank): *error* is the largest distance between a node's displacement and the "
              "reference's, in mm. Two sweeps: *size* (every solver and rank count at each size"
              + (f", {size_rtol[2:-1]}" if size_rtol else "") + ") and *rtol* ("
              + (f"at {and_list([f'{t:,}' for t in sweep_targets])} equations wanted, each "
                 f"iterative solver over rtol {tolerances_text(rtol_runs)}, on "
                 f"{and_list([rank_text(n) for n in sorted({r['ranks'] for r in rtol_runs})])}"
                 if rtol_runs else "not in the file yet")
              + "). The fastest solve and whole stage at each size are in bold."
              + (f" Charts: {chart_links}." if charts else ""), ""]
    for s in solvers:
        lines.append(f"- {s}: {SOLVERS[s][1]}" if s in SOLVERS else f"- {s}")
    lines.append("")
    if problem is not None:
        lines += [f"simulate_bench.csv unreadable: {problem}.", ""]
        write_atomically(path, "\n".join(lines))
        return
    if not runs:
        lines += ["simulate_bench.csv has no runs yet." if os.path.isfile(
            os.path.join(out, "simulate_bench.csv")) else "simulate_bench.csv missing.", ""]
        write_atomically(path, "\n".join(lines))
        return
    missing = [n for n in DEFAULT_SIZES if all(s["target"] != n for s in sizes)]
    if missing:
        measured = ", ".join(f"{s['target']:,}" for s in sizes)
        absent = ", ".join(f"{n:,}" for n in missing)
        lines += [(f"**Partial:** sizes of the size sweep so far: {measured} equations wanted; "
                   if sizes else "**Partial:** no run of the size sweep in the file yet; ")
                  + f"not in the file: {absent} (not asked for, or the run is still going).", ""]

    nproc = read_nproc(out)
    lines += ["## Targets", "", f"Judged on the size sweep{size_rtol}.", ""]
    lines += [target_line(sizes, "solve", "During-surgery solve", e, s) for e, s in SOLVE_TARGETS]
    lines += [target_line(sizes, "whole", "Whole stage", e, s) for e, s in STAGE_TARGETS]
    lines += [paper_line(sizes, nproc), ""]

    lines += default_solver(sizes, solver_order(size_runs), sorted({r["ranks"] for r in size_runs}))

    lines += accuracy_section(sizes, size_runs, rtol_runs, charts.get("error_vs_time.png"))

    lines += ["## Times by size", ""]
    if not sizes:
        lines += ["No run of the size sweep in the file yet.", ""]
    rank_counts = sorted({r["ranks"] for r in size_runs})
    size_solvers = solver_order(size_runs)
    for size in sizes:
        resolution = "" if size["resolution"] is None else f" (mesh at {size['resolution']:.2f} mm)"
        lines += [f"### {size['target']:,} equations wanted{resolution}", "",
                  mesh_text(size) + ".", "", *size_table(size, size_solvers, rank_counts)]
    write_atomically(path, "\n".join(lines))


def accuracy_chart_size(rtol_runs):
    """The size of the tolerance sweep that error_vs_time.png shows: the one with most runs."""
    sweep_sizes = group_sizes(rtol_runs)
    return max(sweep_sizes, key=lambda s: (len(s["runs"]), -s["equations"]), default=None)


def main():
    out = output_folder()
    runs = None
    problem = None
    charts = {}
    csv_path = os.path.join(out, "simulate_bench.csv")
    if os.path.isfile(csv_path):
        try:
            runs = read_runs(csv_path)
        except (UnreadableFile, csv.Error, UnicodeDecodeError) as e:
            problem = str(e)
            print(f"report.py: {csv_path}: {problem}", file=sys.stderr)
        size_runs, rtol_runs = sweep_runs(runs or [], "size"), sweep_runs(runs or [], "rtol")
        if size_runs:
            time_chart(os.path.join(out, "time_vs_size.png"), size_runs)
            charts["time_vs_size.png"] = None
        chart_size = accuracy_chart_size(rtol_runs)
        if chart_size is not None:
            sizes = group_sizes(size_runs)
            plotted = [r for r in chart_size["runs"] if r["ok"] and r["error"] is not None]
            direct = direct_points(sizes, chart_size, chart_size["runs"])
            if plotted or direct:
                floored = accuracy_chart(os.path.join(out, "error_vs_time.png"), chart_size,
                                         plotted, direct)
                charts["error_vs_time.png"] = (chart_size["target"], floored)
    else:
        report_missing(csv_path)
    summary_md(os.path.join(out, "summary.md"), out, runs, charts, problem)
    print(f"wrote {os.path.join(out, 'summary.md')}" + "".join(f", {c}" for c in charts))
    if problem is not None:
        sys.exit(1)


if __name__ == "__main__":
    main()
