#!/usr/bin/env python3
"""Report of the meshing benchmark: report.py OUT (the folder run.sh wrote).

Reads OUT/machine.txt and OUT/mesh_benchmark.csv; writes OUT/mesh_time_quality.png (wall time and
minimum dihedral angle against nodes, per backend) and OUT/summary.md.
"""
import csv
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))
from benchmark_common import (  # noqa: E402  (benchmark_common.py is in the folder above)
    machine_section, output_folder, plt, report_missing, save_atomically, table_row,
    write_atomically)

# Targets of the mesh stage (issue 5).
MIN_DIHEDRAL_TARGET = 10.0
VOLUME_ERROR_TARGET = 0.03  # at 1.5-2 mm
SECONDS_TARGET = 5.0  # the lattice, at about 25,800 nodes


def number(text):
    return float(text) if text not in ("", None) else None


def main():
    out = output_folder()
    path = os.path.join(out, "mesh_benchmark.csv")
    if not os.path.exists(path):
        report_missing(path)
        sys.exit(1)
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    fig, (time_axis, angle_axis) = plt.subplots(1, 2, figsize=(11, 4.2))
    for backend, marker in (("lattice", "o"), ("graded", "^"), ("cgal", "s")):
        done = [r for r in rows if r["backend"] == backend and r["nodes"]]
        nodes = [number(r["nodes"]) for r in done]
        time_axis.plot(nodes, [number(r["seconds"]) for r in done], marker=marker, label=backend)
        angle_axis.plot(nodes, [number(r["min_dihedral_degrees"]) for r in done], marker=marker, label=backend)
    time_axis.set(xscale="log", yscale="log", xlabel="nodes", ylabel="wall time (s)", title="Meshing time")
    angle_axis.axhline(MIN_DIHEDRAL_TARGET, color="grey", linestyle="--", label=f"target {MIN_DIHEDRAL_TARGET:g} deg")
    angle_axis.set(xscale="log", xlabel="nodes", ylabel="minimum dihedral (degrees)", title="Element quality")
    for axis in (time_axis, angle_axis):
        axis.grid(True, alpha=0.3)
        axis.legend()
    fig.tight_layout()
    save_atomically(fig, os.path.join(out, "mesh_time_quality.png"))

    lines = ["# Meshing benchmark", "",
             "The built-in full brain's preoperative labels (1 mm voxels), tissues 2 (parenchyma), "
             "3 (ventricles), 4 (tumour). Volume error: mesh volume / voxel volume - 1. An empty row: "
             "a tissue vanished at that resolution (InputError). lattice: the uniform Kuhn lattice; graded: the "
             "same lattice graded (the resolution at every tissue interface and the brain's surface, cubes up to "
             "4 times larger inside, grading 1 mm per mm); cgal: CGAL Mesh_3.", "",
             table_row(["backend", "resolution (mm)", "time (s)", "nodes", "tetrahedra", "min dihedral",
                        "max dihedral", "inverted", "error 2", "error 3", "error 4"]),
             table_row(["---"] * 11)]
    for r in rows:
        if not r["nodes"]:
            lines.append(table_row([r["backend"], r["resolution_mm"], f"{number(r['seconds']):.2f}",
                                    "tissue vanished", "", "", "", "", "", "", ""]))
            continue
        lines.append(table_row([r["backend"], r["resolution_mm"], f"{number(r['seconds']):.2f}", r["nodes"],
                                r["tetrahedra"], f"{number(r['min_dihedral_degrees']):.1f}",
                                f"{number(r['max_dihedral_degrees']):.1f}", r["inverted"]]
                               + [f"{100 * number(r[k]):+.1f} %" for k in
                                  ("volume_error_2", "volume_error_3", "volume_error_4")]))
    lines += ["", f"Targets: minimum dihedral >= {MIN_DIHEDRAL_TARGET:g} degrees, no inverted element, "
              f"volume within {100 * VOLUME_ERROR_TARGET:g} % at 1.5-2 mm, lattice <= {SECONDS_TARGET:g} s "
              "at about 25,800 nodes.", "", "![time and quality](mesh_time_quality.png)", ""]
    lines += machine_section(out)
    write_atomically(os.path.join(out, "summary.md"), "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
