#!/usr/bin/env python3
"""elastix's rigid result for the rigid benchmark (standard library only).

  elastix_result.py convert TransformParameters.0.txt OUT.tfm
      elastix EulerTransform -> ITK transform file (Euler3DTransform_double_3_3).
  elastix_result.py compare --transform T.tfm --truth TRUTH.tfm --evaluation E.json
                            --wall-seconds S [S ...] --json OUT.json
      rotation and translation error of T against the true rigid, head TRE from
      `brainshift evaluate --json`, wall seconds; written in the keys of
      rigid_accuracy.json.

elastix's transform maps fixed (intraoperative) points to moving (preoperative) points,
the direction of rigid_intraop_to_preop, and both use LPS millimetres, so the
parameters carry over unchanged: T(x) = R (x - c) + c + t with ITK's Euler angles
(ComputeZYX false: R = Rz Rx Ry; true: R = Rz Ry Rx).
"""
import argparse
import json
import math
import os
import statistics
import sys
import tempfile


def read_elastix_parameters(path):
    """The '(Key value ...)' entries of an elastix parameter file, values as strings."""
    entries = {}
    with open(path) as f:
        for line in f:
            line = line.split("//", 1)[0].strip()
            if not (line.startswith("(") and line.endswith(")")):
                continue
            words = line[1:-1].split()
            if words:
                entries[words[0]] = [w.strip('"') for w in words[1:]]
    return entries


def read_itk_euler(path):
    """(angles, translation, centre, compute_zyx) of an ITK Euler3DTransform text file."""
    kind = parameters = fixed = None
    with open(path) as f:
        for line in f:
            key, _, value = line.partition(":")
            if key.strip() == "Transform":
                kind = value.strip()
            elif key.strip() == "Parameters":
                parameters = [float(v) for v in value.split()]
            elif key.strip() == "FixedParameters":
                fixed = [float(v) for v in value.split()]
    if kind is None or not kind.startswith("Euler3DTransform") or parameters is None \
            or len(parameters) != 6 or fixed is None or len(fixed) < 3:
        sys.exit(f"{path}: not an ITK Euler3DTransform file")
    zyx = len(fixed) > 3 and fixed[3] != 0
    return parameters[:3], parameters[3:], fixed[:3], zyx


def write_atomically(path, text):
    folder = os.path.dirname(os.path.abspath(path))
    fd, temporary = tempfile.mkstemp(dir=folder, prefix=".tmp-")
    with os.fdopen(fd, "w") as f:
        f.write(text)
    os.replace(temporary, path)


def convert(parameter_file, output):
    p = read_elastix_parameters(parameter_file)
    if p.get("Transform") != ["EulerTransform"]:
        sys.exit(f"{parameter_file}: Transform is {p.get('Transform')}, expected EulerTransform")
    if p.get("InitialTransformParametersFileName", ["NoInitialTransform"]) != ["NoInitialTransform"]:
        sys.exit(f"{parameter_file}: has an initial transform; only a single Euler transform is converted")
    values = [float(v) for v in p["TransformParameters"]]
    centre = [float(v) for v in p["CenterOfRotationPoint"]]
    if len(values) != 6 or len(centre) != 3:
        sys.exit(f"{parameter_file}: expected 6 parameters and a 3D centre of rotation")
    zyx = p.get("ComputeZYX", ["false"])[0].lower() == "true"
    write_atomically(output, "#Insight Transform File V1.0\n#Transform 0\n"
                     "Transform: Euler3DTransform_double_3_3\n"
                     f"Parameters: {' '.join(repr(v) for v in values)}\n"
                     f"FixedParameters: {' '.join(repr(v) for v in centre)} {1 if zyx else 0}\n")


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def rotation(angles, zyx):
    """ITK Euler3DTransform's rotation matrix."""
    cx, cy, cz = (math.cos(a) for a in angles)
    sx, sy, sz = (math.sin(a) for a in angles)
    rx = [[1, 0, 0], [0, cx, -sx], [0, sx, cx]]
    ry = [[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]]
    rz = [[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]]
    return matmul(rz, matmul(ry, rx)) if zyx else matmul(rz, matmul(rx, ry))


def apply(transform, point):
    angles, translation, centre, zyx = transform
    r = rotation(angles, zyx)
    d = [point[i] - centre[i] for i in range(3)]
    return [sum(r[i][k] * d[k] for k in range(3)) + centre[i] + translation[i] for i in range(3)]


def rotation_error_degrees(a, b):
    """Angle of Ra Rb^T."""
    ra, rb = rotation(a[0], a[3]), rotation(b[0], b[3])
    trace = sum(ra[i][k] * rb[i][k] for i in range(3) for k in range(3))
    return math.degrees(math.acos(max(-1.0, min(1.0, (trace - 1.0) / 2.0))))


def translation_error_mm(a, b):
    """|Ta(c) - Tb(c)| at the true transform's centre c: the difference of the translations
    once both transforms are expressed about that centre."""
    c = b[2]
    pa, pb = apply(a, c), apply(b, c)
    return math.dist(pa, pb)


def compare(args):
    estimate = read_itk_euler(args.transform)
    truth = read_itk_euler(args.truth)
    with open(args.evaluation) as f:
        evaluation = json.load(f)
    head = evaluation.get("groups", {}).get("head")
    if head is None:
        sys.exit(f"{args.evaluation}: no 'head' landmark group")
    result = {
        "method": "elastix",
        "runs": len(args.wall_seconds),
        "wall_seconds_median": statistics.median(args.wall_seconds),
        "wall_seconds": args.wall_seconds,
        "head_tre_mean_mm": head["mean_mm"],
        "head_tre_max_mm": head["max_mm"],
        "rotation_error_degrees": rotation_error_degrees(estimate, truth),
        "translation_error_mm": translation_error_mm(estimate, truth),
        "tre_mean_mm": evaluation["mean_mm"],
        "transform": os.path.basename(args.transform),
    }
    write_atomically(args.json, json.dumps(result, indent=2) + "\n")
    print(f"elastix: head TRE mean {result['head_tre_mean_mm']:.3f} mm, "
          f"max {result['head_tre_max_mm']:.3f} mm, rotation error "
          f"{result['rotation_error_degrees']:.3f} deg, translation error "
          f"{result['translation_error_mm']:.3f} mm, wall {result['wall_seconds_median']:.2f} s")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    c = sub.add_parser("convert", help="elastix TransformParameters.0.txt -> ITK .tfm")
    c.add_argument("parameters")
    c.add_argument("output")
    m = sub.add_parser("compare", help="errors of an Euler .tfm against the true rigid")
    m.add_argument("--transform", required=True)
    m.add_argument("--truth", required=True)
    m.add_argument("--evaluation", required=True, help="brainshift evaluate --json output")
    m.add_argument("--wall-seconds", type=float, nargs="+", required=True)
    m.add_argument("--json", required=True)
    args = parser.parse_args()
    if args.command == "convert":
        convert(args.parameters, args.output)
    else:
        compare(args)


if __name__ == "__main__":
    main()
