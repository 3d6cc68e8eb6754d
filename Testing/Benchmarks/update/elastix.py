#!/usr/bin/env python3
"""elastix 5 on one case of the whole-update benchmark, scored as BrainShift is (standard library only).

  elastix.py CASE_DIR WORK_DIR [--csv OUT/update_bench.csv] [--case NAME] [--threads N]

CASE_DIR is a case folder that `brainshift bench update` (or `brainshift demo`) wrote:
intraop_image.nii.gz, preop_image.nii.gz and landmarks.csv (name, preop_x..z, intraop_x..z, LPS
mm). Two registrations, each one elastix call, timed around the elastix process (reading the
images included), as a user would run them:

  elastix rigid            -p elastix/rigid.txt
  elastix rigid+bspline    -p elastix/rigid.txt -p elastix/bspline.txt

fixed = the intraoperative image, moving = the preoperative image, so elastix's transform maps
intraoperative points to preoperative points (ITK physical space, LPS), the direction of
BrainShift's intraop_to_preop. transformix maps the landmarks' intraoperative points (timed apart,
not counted in the registration's time) and the TRE is |T(intraop) - preop|: mean, p95 (linear
interpolation, as numpy's default) and max over every landmark, and the mean per group (the name's
prefix before its last '-': craniotomy, near-cavity, brain; -1 when the case has none), as
`brainshift bench update` computes them (Logic/Evaluation/LandmarkEvaluation.cxx). For the
B-spline result, transformix's Jacobian determinant on the intraoperative grid counts the folded
voxels (det <= 0), as the warp stage counts BrainShift's.

Writes WORK_DIR/rigid/ and WORK_DIR/rigid_bspline/ (elastix's output and logs), WORK_DIR/points.txt
and WORK_DIR/elastix_result.json (times, TRE, each landmark's error), and replaces this case's elastix
rows in the CSV (atomically; in the columns of update_bench.csv, per-stage columns empty). The CSV
defaults to OUT/update_bench.csv when CASE_DIR is OUT/runs/<case>/case (the case's name then
defaults to <case>); otherwise give --csv, or no CSV is written.
"""
import argparse
import csv
import io
import json
import os
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import time
from array import array

HERE = os.path.dirname(os.path.realpath(__file__))
PARAMETERS = os.path.join(HERE, "elastix")

# The columns of update_bench.csv (Applications/CLI/UpdateBenchCommand.cxx).
COLUMNS = ["case", "method", "mesh_resolution_mm", "solver_rtol", "surface_iterations", "equations", "total_seconds",
           "rigid_seconds", "classify_seconds", "mesh_seconds", "surface_seconds", "simulate_seconds",
           "simulate_solve_seconds", "warp_seconds", "tre_mean_mm", "tre_p95_mm", "tre_max_mm", "tre_craniotomy_mm",
           "tre_near_cavity_mm", "tre_brain_mm", "folded_voxels"]
GROUP_COLUMNS = {"tre_craniotomy_mm": "craniotomy", "tre_near_cavity_mm": "near-cavity", "tre_brain_mm": "brain"}

# method, parameter files (in elastix/), which TransformParameters.<i>.txt is the result, folding counted
METHODS = [
    ("elastix rigid", "rigid", ["rigid.txt"], 0, False),
    ("elastix rigid+bspline", "rigid_bspline", ["rigid.txt", "bspline.txt"], 1, True),
]


class Failure(Exception):
    pass


# --- the landmarks and their errors ---------------------------------------------------------------
def read_landmarks(path):
    """[(name, preop xyz, intraop xyz)] from a case's landmarks.csv."""
    needed = ["name", "preop_x", "preop_y", "preop_z", "intraop_x", "intraop_y", "intraop_z"]
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        missing = [c for c in needed if c not in (reader.fieldnames or [])]
        if missing:
            raise Failure(f"{path}: columns {', '.join(missing)} missing (header: {reader.fieldnames})")
        landmarks = []
        for row in reader:
            try:
                preop = tuple(float(row[f"preop_{a}"]) for a in "xyz")
                intraop = tuple(float(row[f"intraop_{a}"]) for a in "xyz")
            except (TypeError, ValueError):
                raise Failure(f"{path}: line {reader.line_num}: not a landmark: {row}")
            landmarks.append((row["name"], preop, intraop))
    if not landmarks:
        raise Failure(f"{path}: no landmarks")
    return landmarks


def statistics(errors):
    """mean, p95 (linear between order statistics, as LandmarkEvaluation.cxx and numpy) and max."""
    ordered = sorted(errors)
    position = 0.95 * (len(ordered) - 1)
    below = int(position)
    above = min(below + 1, len(ordered) - 1)
    p95 = ordered[below] + (position - below) * (ordered[above] - ordered[below])
    return {"mean_mm": sum(ordered) / len(ordered), "p95_mm": p95, "max_mm": ordered[-1], "count": len(ordered)}


def group_of(name):
    """The name's prefix before its last '-' ("near-cavity-03" -> "near-cavity"), or None."""
    dash = name.rfind("-")
    return name[:dash] if dash > 0 else None


def evaluate(landmarks, mapped):
    pairs = []
    groups = {}
    for (name, preop, _), point in zip(landmarks, mapped):
        error = sum((p - q) ** 2 for p, q in zip(point, preop)) ** 0.5
        pairs.append({"name": name, "error_mm": error})
        group = group_of(name)
        if group is not None:
            groups.setdefault(group, []).append(error)
    result = statistics([p["error_mm"] for p in pairs])
    result["groups"] = {g: statistics(e) for g, e in sorted(groups.items())}
    result["pairs"] = pairs
    return result


# --- elastix and transformix ----------------------------------------------------------------------
def tail(path, lines=25):
    try:
        with open(path, errors="replace") as f:
            return "".join(f.readlines()[-lines:])
    except OSError:
        return f"({path} missing)\n"


def run_tool(command, log_path, what, logs):
    """Runs command (output to log_path); its wall seconds. Raises Failure with the logs' tail."""
    start = time.monotonic()
    with open(log_path, "w") as log:
        try:
            status = subprocess.run(command, stdout=log, stderr=subprocess.STDOUT).returncode
        except OSError as error:
            raise Failure(f"{what}: cannot run {command[0]}: {error}")
    seconds = time.monotonic() - start
    if status != 0:
        shown = "".join(f"--- last lines of {p}:\n{tail(p)}" for p in logs)
        raise Failure(f"{what} failed (exit status {status}): {' '.join(command)}\n{shown}")
    return seconds


def run_elastix(elastix, case_dir, parameter_files, out, threads):
    shutil.rmtree(out, ignore_errors=True)
    os.makedirs(out)
    command = [elastix, "-f", os.path.join(case_dir, "intraop_image.nii.gz"),
               "-m", os.path.join(case_dir, "preop_image.nii.gz")]
    for p in parameter_files:
        command += ["-p", p]
    command += ["-out", out, "-threads", str(threads)]
    logs = [os.path.join(out, "elastix.log"), os.path.join(out, "stdout.txt")]
    seconds = run_tool(command, os.path.join(out, "stdout.txt"), "elastix", logs)
    for i in range(len(parameter_files)):
        if not os.path.isfile(os.path.join(out, f"TransformParameters.{i}.txt")):
            raise Failure(f"elastix wrote no TransformParameters.{i}.txt in {out}\n--- last lines of "
                          f"{logs[0]}:\n{tail(logs[0])}")
    return seconds


def write_points(path, landmarks):
    """transformix's input point file: physical (LPS mm) intraoperative points."""
    lines = ["point", str(len(landmarks))] + [" ".join(repr(v) for v in intraop) for _, _, intraop in landmarks]
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


OUTPUT_POINT = re.compile(r"OutputPoint\s*=\s*\[([^\]]*)\]")


def read_output_points(path, count):
    points = []
    with open(path) as f:
        for line in f:
            match = OUTPUT_POINT.search(line)
            if match:
                values = [float(v) for v in match.group(1).split()]
                if len(values) != 3:
                    raise Failure(f"{path}: not a 3D point: {line.strip()}")
                points.append(tuple(values))
    if len(points) != count:
        raise Failure(f"{path}: {len(points)} output points for {count} landmarks")
    return points


def run_transformix(transformix, transform, arguments, out, threads, product):
    shutil.rmtree(out, ignore_errors=True)
    os.makedirs(out)
    command = [transformix, "-tp", transform, *arguments, "-out", out, "-threads", str(threads)]
    logs = [os.path.join(out, "transformix.log"), os.path.join(out, "stdout.txt")]
    seconds = run_tool(command, os.path.join(out, "stdout.txt"), "transformix", logs)
    path = os.path.join(out, product)
    if not os.path.isfile(path):
        raise Failure(f"transformix wrote no {product} in {out}\n--- last lines of {logs[0]}:\n{tail(logs[0])}")
    return path, seconds


def folding(path):
    """(voxels with det <= 0, voxels, smallest det) of transformix's spatialJacobian.nii (NIfTI-1)."""
    with open(path, "rb") as f:
        data = f.read()
    endian = "<" if struct.unpack("<i", data[:4])[0] == 348 else ">"
    if struct.unpack(endian + "i", data[:4])[0] != 348:
        raise Failure(f"{path}: not an uncompressed NIfTI-1 file")
    dims = struct.unpack(endian + "8h", data[40:56])
    datatype = struct.unpack(endian + "h", data[70:72])[0]
    offset = int(struct.unpack(endian + "f", data[108:112])[0])
    voxels = 1
    for d in dims[1:1 + dims[0]]:
        voxels *= d
    codes = {16: "f", 64: "d"}
    if datatype not in codes:
        raise Failure(f"{path}: NIfTI datatype {datatype}, expected float or double")
    values = array(codes[datatype])
    values.frombytes(data[offset:offset + voxels * values.itemsize])
    if (endian == "<") != (sys.byteorder == "little"):
        values.byteswap()
    return sum(1 for v in values if v <= 0), voxels, min(values)


def transform_line(path):
    with open(path) as f:
        return next((line.strip() for line in f if line.startswith("(TransformParameters ")), "")


# --- the table ------------------------------------------------------------------------------------
def number(value):
    return f"{value:.6g}"


def csv_row(case, method, seconds, tre, folded):
    row = {c: "" for c in COLUMNS}
    row.update(case=case, method=method, total_seconds=number(seconds), tre_mean_mm=number(tre["mean_mm"]),
               tre_p95_mm=number(tre["p95_mm"]), tre_max_mm=number(tre["max_mm"]))
    for column, group in GROUP_COLUMNS.items():
        row[column] = number(tre["groups"][group]["mean_mm"]) if group in tre["groups"] else "-1"
    if folded is not None:
        row["folded_voxels"] = str(folded)
    return row


def write_atomically(path, text):
    fd, temporary = tempfile.mkstemp(dir=os.path.dirname(os.path.abspath(path)), prefix=".tmp-")
    with os.fdopen(fd, "w", newline="") as f:
        f.write(text)
    os.replace(temporary, path)


def merge_rows(path, rows):
    """The CSV at path with these rows in place of its rows of the same case and method (after the
    case's other rows); created with update_bench.csv's header when missing."""
    header, existing = COLUMNS, []
    if os.path.exists(path):
        with open(path, newline="") as f:
            reader = csv.DictReader(f)
            header = reader.fieldnames or COLUMNS
            existing = list(reader)
        missing = [c for c in COLUMNS if c not in header]
        if missing:
            raise Failure(f"{path}: columns {', '.join(missing)} missing: not an update_bench.csv")
    replaced = {(r["case"], r["method"]) for r in rows}
    kept = [r for r in existing if (r.get("case"), r.get("method")) not in replaced]
    case = rows[0]["case"]
    at = max((i + 1 for i, r in enumerate(kept) if r.get("case") == case), default=len(kept))
    merged = kept[:at] + rows + kept[at:]
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=header, lineterminator="\n", extrasaction="ignore", restval="")
    writer.writeheader()
    writer.writerows(merged)
    write_atomically(path, text.getvalue())


# --- main -----------------------------------------------------------------------------------------
def arguments():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("case_dir", help="the case folder (intraop_image.nii.gz, preop_image.nii.gz, landmarks.csv)")
    parser.add_argument("work_dir", help="where elastix's and transformix's output goes")
    parser.add_argument("--csv", help="update_bench.csv to put the rows in (default: OUT/update_bench.csv "
                        "when CASE_DIR is OUT/runs/<case>/case)")
    parser.add_argument("--case", help="the case's name in the CSV (default: <case> of OUT/runs/<case>/case, "
                        "else the name of CASE_DIR's parent)")
    parser.add_argument("--threads", type=int, default=2, help="elastix's and transformix's -threads (default 2)")
    parser.add_argument("--parameters", default=PARAMETERS, help="folder of rigid.txt and bspline.txt")
    parser.add_argument("--elastix", default="elastix", help="the elastix program")
    parser.add_argument("--transformix", default="transformix", help="the transformix program")
    return parser.parse_args()


def main():
    a = arguments()
    case_dir = os.path.abspath(a.case_dir)
    work = os.path.abspath(a.work_dir)
    for f in ["intraop_image.nii.gz", "preop_image.nii.gz", "landmarks.csv"]:
        if not os.path.isfile(os.path.join(case_dir, f)):
            raise Failure(f"{os.path.join(case_dir, f)} missing: not a case folder")
    for p in ["rigid.txt", "bspline.txt"]:
        if not os.path.isfile(os.path.join(a.parameters, p)):
            raise Failure(f"{os.path.join(a.parameters, p)} missing")
    for tool in [a.elastix, a.transformix]:
        if shutil.which(tool) is None:
            raise Failure(f"{tool} not found: install elastix 5 (Debian: apt-get install elastix)")
    parent = os.path.dirname(case_dir)
    in_bench = os.path.basename(case_dir) == "case" and os.path.basename(os.path.dirname(parent)) == "runs"
    case = a.case or os.path.basename(parent)
    table = a.csv or (os.path.join(os.path.dirname(os.path.dirname(parent)), "update_bench.csv") if in_bench else None)

    landmarks = read_landmarks(os.path.join(case_dir, "landmarks.csv"))
    os.makedirs(work, exist_ok=True)
    points = os.path.join(work, "points.txt")
    write_points(points, landmarks)
    version = subprocess.run([a.elastix, "--version"], capture_output=True, text=True).stdout.strip()

    results, rows = [], []
    for method, folder, files, index, count_folds in METHODS:
        out = os.path.join(work, folder)
        print(f"  {case}, {method}: elastix -threads {a.threads} -p {' -p '.join(files)}", flush=True)
        seconds = run_elastix(a.elastix, case_dir, [os.path.join(a.parameters, f) for f in files], out, a.threads)
        transform = os.path.join(out, f"TransformParameters.{index}.txt")
        output_points, transformix_seconds = run_transformix(a.transformix, transform, ["-def", points],
                                                             os.path.join(out, "points"), a.threads, "outputpoints.txt")
        tre = evaluate(landmarks, read_output_points(output_points, len(landmarks)))
        folded = None
        result = {"method": method, "parameter_files": files, "transform": os.path.relpath(transform, work),
                  "elastix_seconds": seconds, "transformix_points_seconds": transformix_seconds}
        if count_folds:
            jacobian, _ = run_transformix(a.transformix, transform, ["-jac", "all"], os.path.join(out, "jacobian"),
                                          a.threads, "spatialJacobian.nii")
            folded, voxels, smallest = folding(jacobian)
            os.remove(jacobian)  # 15 MB; the count is what stays
            result.update(folded_voxels=folded, grid_voxels=voxels, minimum_jacobian=smallest)
        if index > 0:  # the rigid stage of the chained run should be the rigid run's (fixed seed)
            result["rigid_stage_as_rigid_run"] = (transform_line(os.path.join(out, "TransformParameters.0.txt")) ==
                                                  transform_line(os.path.join(work, "rigid", "TransformParameters.0.txt")))
        result["tre"] = tre
        results.append(result)
        rows.append(csv_row(case, method, seconds, tre, folded))
        groups = ", ".join(f"{g} {s['mean_mm']:.2f}" for g, s in tre["groups"].items())
        print(f"  {case}, {method}: TRE {tre['mean_mm']:.2f} mm mean, {tre['p95_mm']:.2f} p95, {tre['max_mm']:.2f} max "
              f"({groups}); elastix {seconds:.1f} s, transformix {transformix_seconds:.2f} s"
              + (f", {folded} folded voxels" if folded is not None else ""), flush=True)
        if result.get("rigid_stage_as_rigid_run") is False:
            print(f"  note: the rigid stage of {method} differs from the rigid run's (compare "
                  f"{folder}/TransformParameters.0.txt with rigid/TransformParameters.0.txt)", flush=True)

    write_atomically(os.path.join(work, "elastix_result.json"), json.dumps(
        {"case": case, "case_dir": case_dir, "elastix": version, "threads": a.threads,
         "parameters": os.path.abspath(a.parameters), "methods": results}, indent=2) + "\n")
    if table:
        merge_rows(table, rows)
        print(f"  {case}: {len(rows)} rows in {table}", flush=True)


if __name__ == "__main__":
    try:
        main()
    except Failure as failure:
        sys.exit(f"elastix.py: {failure}")
