#!/usr/bin/env bash
# Meshing benchmark: the backends (lattice with snapped boundary nodes, uniform and graded; CGAL Mesh_3) on the
# built-in full brain's preoperative labels at 1.5, 2, 3, 4, 5 and 6 mm: wall time, nodes,
# tetrahedra, dihedral angles and each tissue's volume error against its voxels.
#
#   Testing/Benchmarks/mesh/run.sh [OUTPUT_DIR]
#
# OUTPUT_DIR defaults to Testing/Benchmarks/results/mesh. The brainshift binary is taken from
# $BRAINSHIFT_BUILD_DIR/bin (default build/bin). Writes into OUTPUT_DIR: machine.txt,
# mesh_benchmark.csv (brainshift bench mesh), summary.md and mesh_time_quality.png.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# shellcheck source=SCRIPTDIR/../common.sh
source "$here/../common.sh"
out=${1:-$root/Testing/Benchmarks/results/mesh}

ensure_matplotlib
require_brainshift
prepare_output machine.txt mesh_benchmark.csv summary.md mesh_time_quality.png
write_machine_description

run "$brainshift" bench mesh --size full --resolutions 6,5,4,3,2,1.5 --backends lattice,graded,cgal --output-dir "$out"
[ -f "$out/mesh_benchmark.csv" ] || die "$out/mesh_benchmark.csv missing: brainshift bench mesh did not write it"

run "$python" "$here/report.py" "$out"
say "done: $out/summary.md, $out/mesh_time_quality.png"
