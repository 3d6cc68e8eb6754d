#!/usr/bin/env python3
"""Seeded fuzz run of the brainshift command line (issue 18): corrupted inputs of the small built-in
case, each fed to the subcommand that reads it, checked for what the command line promises.

    fuzz.py --brainshift BIN --demo DEMO_DIR --work WORK_DIR --output-dir OUT [--seed N] [--inputs N]

DEMO_DIR is the output folder of `brainshift demo --size small` (its case/ subfolder holds the case).
Input i is made from random.Random("SEED:i") alone: the same seed and index give the same input.
Kinds (in turn): the intraoperative NIfTI's header, its voxels, its gzip stream (each to `rigid`); the
labels' NIfTI (to `mesh`); the landmark CSV and the rigid .tfm (to `evaluate`); the JSON
configuration (to `mesh --config`, every fifth to `simulate --config`, which starts the MPI worker);
the .mrml scene (to `bench read-scene`, the host-free scene reader).

Checked on each run: the exit status is 0, 1 or 2 (no signal, no other status, no hang); on failure
exactly one error line on stderr (lines that start with "warning: " are not errors); no process left in the run's session (the finite element worker's
process group included); no `.tmp-*` file left; a refused run (2) leaves no output folder behind;
no zero-length output; the input file unchanged. Writes OUT/runs.csv and OUT/summary.json.
"""
import argparse
import csv
import gzip
import hashlib
import json
import math
import os
import random
import re
import shutil
import signal
import struct
import subprocess
import sys
import time

KINDS = ["nifti-header", "nifti-data", "nifti-gzip", "labels", "landmarks", "transform", "config", "scene"]
if os.environ.get("FUZZ_KINDS"):  # a subset, for a closer look: FUZZ_KINDS=scene,config
    KINDS = os.environ["FUZZ_KINDS"].split(",")
TIMEOUT_S = 180

# NIfTI-1 header fields worth breaking: (offset, struct format).
NIFTI_FIELDS = [(0, "<i"), (40, "<h"), (42, "<h"), (44, "<h"), (46, "<h"), (70, "<h"), (72, "<h"), (76, "<f"),
                (80, "<f"), (84, "<f"), (88, "<f"), (108, "<f"), (112, "<f"), (116, "<f"), (252, "<h"),
                (254, "<h"), (256, "<f"), (260, "<f"), (264, "<f"), (268, "<f"), (280, "<f"), (284, "<f"),
                (296, "<f"), (308, "<f"), (320, "<f"), (344, "<4s")]
INTS = [0, 1, -1, 2, 3, 4, 7, 8, 16, 64, 255, 256, 511, 768, 32767, -32768]
FLOATS = [0.0, -0.0, 1.0, -1.0, float("nan"), float("inf"), float("-inf"), 1e-30, 1e30, 3.4e38, -1e6, 1e6, 0.5]
WEIRD_TEXT = ["nan", "NaN", "inf", "-inf", "1e308", "-1e308", "1e-320", "", "abc", "-0", "0x10", "1,5", "\u00e9",
              "9" * 400, "\x00", "\"", "'", ",", ";", "{", "}", "[", "]", "<", ">", "&", "\\", "\n", "..", "/"]


def mutate_bytes(rng, data):
    data = bytearray(data)
    for _ in range(rng.randint(1, 3)):
        if not data:
            break
        op = rng.choice(["flip", "set", "truncate", "insert", "delete", "duplicate"])
        i = rng.randrange(len(data))
        if op == "flip":
            for _ in range(rng.randint(1, 8)):
                j = rng.randrange(len(data))
                data[j] ^= 1 << rng.randrange(8)
        elif op == "set":
            n = rng.randint(1, 16)
            data[i:i + n] = bytes([rng.choice([0, 0xFF, 0x7F, 0x80, rng.randrange(256)])] * n)[:len(data) - i]
        elif op == "truncate":
            del data[i:]
        elif op == "insert":
            data[i:i] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 64)))
        elif op == "delete":
            del data[i:i + rng.randint(1, 256)]
        else:
            n = rng.randint(1, 256)
            data[i:i] = data[i:i + n]
    return bytes(data), op


def mutate_nifti_header(rng, raw):
    raw = bytearray(raw)
    changed = []
    for _ in range(rng.randint(1, 3)):
        offset, fmt = rng.choice(NIFTI_FIELDS)
        if fmt == "<4s":
            value = rng.choice([b"n+1\x00", b"ni1\x00", b"n+2\x00", b"\x00\x00\x00\x00", b"XXXX"])
        elif fmt == "<f":
            value = rng.choice(FLOATS + [rng.uniform(-1e3, 1e3)])
        else:
            value = rng.choice(INTS + [rng.randint(-40000, 40000) % 65536 - 32768])
        struct.pack_into(fmt, raw, offset, value)
        changed.append(f"{offset}={value!r}")
    return bytes(raw), "header " + " ".join(changed)


def nifti_payload_offset(raw):
    offset = struct.unpack_from("<f", raw, 108)[0]
    return int(offset) if math.isfinite(offset) and 352 <= offset < len(raw) else 352


def mutate_nifti_data(rng, raw):
    raw = bytearray(raw)
    start = nifti_payload_offset(raw)
    op = rng.choice(["fill", "nan", "truncate", "append", "noise"])
    if op == "truncate":
        del raw[rng.randrange(start, len(raw)):]
    elif op == "append":
        raw += bytes(rng.randrange(256) for _ in range(rng.randint(1, 4096)))
    elif op == "nan":  # float32 NaN and inf patterns (or huge integers) over a run of voxels
        i = rng.randrange(start, len(raw) - 4)
        pattern = rng.choice([struct.pack("<f", float("nan")), struct.pack("<f", float("inf")), b"\xff\xff\xff\x7f"])
        n = rng.randint(1, 20000)
        raw[i:i + 4 * n] = (pattern * n)[:len(raw) - i]
    elif op == "fill":  # everything one value, or everything zero but a run
        value = rng.choice([0, 1, 0x40, 0xFF])
        raw[start:] = bytes([value]) * (len(raw) - start)
    else:
        for _ in range(rng.randint(1, 1000)):
            raw[rng.randrange(start, len(raw))] = rng.randrange(256)
    return bytes(raw), "data " + op


def mutate_text(rng, text):
    lines = text.split("\n")
    ops = []
    for _ in range(rng.randint(1, 3)):
        op = rng.choice(["delete-line", "duplicate-line", "swap-lines", "number", "cut", "junk", "truncate", "field"])
        ops.append(op)
        if not lines:
            lines = [""]
        i = rng.randrange(len(lines))
        if op == "delete-line":
            del lines[i]
        elif op == "duplicate-line":
            lines.insert(i, lines[i])
        elif op == "swap-lines":
            j = rng.randrange(len(lines))
            lines[i], lines[j] = lines[j], lines[i]
        elif op == "number":
            numbers = list(re.finditer(r"-?\d+(\.\d+)?([eE][-+]?\d+)?", lines[i]))
            if numbers:
                m = rng.choice(numbers)
                lines[i] = lines[i][:m.start()] + rng.choice(WEIRD_TEXT) + lines[i][m.end():]
        elif op == "cut":
            j = rng.randrange(len(lines[i]) + 1)
            lines[i] = lines[i][:j] + lines[i][j + rng.randint(1, 20):]
        elif op == "junk":
            j = rng.randrange(len(lines[i]) + 1)
            lines[i] = lines[i][:j] + "".join(rng.choice(WEIRD_TEXT) for _ in range(rng.randint(1, 4))) + lines[i][j:]
        elif op == "truncate":
            joined = "\n".join(lines)
            lines = joined[:rng.randrange(len(joined) + 1)].split("\n")
        else:  # a field separator or attribute quote removed or doubled
            for sep in [",", "\"", "=", ":"]:
                if sep in lines[i]:
                    k = [m.start() for m in re.finditer(re.escape(sep), lines[i])]
                    j = rng.choice(k)
                    lines[i] = lines[i][:j] + (sep * 2 if rng.random() < 0.5 else "") + lines[i][j + 1:]
                    break
    return "\n".join(lines), " ".join(ops)


def mutate_json(rng, document):
    """A value somewhere in the document replaced: wrong type, out of range, absurd."""
    paths = []

    def walk(node, path):
        if isinstance(node, dict):
            for k, v in node.items():
                paths.append(path + [k])
                walk(v, path + [k])
        elif isinstance(node, list):
            for k, v in enumerate(node):
                paths.append(path + [k])
                walk(v, path + [k])

    changed = []
    for _ in range(rng.randint(1, 3)):
        paths.clear()
        walk(document, [])  # afresh: an earlier change may have replaced a subtree
        if not paths:
            break
        path = rng.choice(paths)
        parent = document
        for k in path[:-1]:
            parent = parent[k]
        value = rng.choice([None, True, "x", "", [], {}, 0, -1, 1e-12, 1e12, 1e308, -1e308, 2**63, 0.5, 1, 3, 255, 1e6,
                            "-ksp_type cg", "-pc_type lu -ksp_max_it 1", "-ksp_rtol 1e300"])
        if rng.random() < 0.15 and isinstance(parent, dict):
            parent["unknown_" + str(rng.randrange(100))] = value
        else:
            try:
                parent[path[-1]] = value
            except (KeyError, IndexError, TypeError):
                continue
        changed.append("/".join(map(str, path)) + "=" + json.dumps(value)[:40])
    return document, "json " + " ".join(changed)


def read_gz(path):
    with gzip.open(path, "rb") as f:
        return f.read()


def write_gz(path, raw):
    with open(path, "wb") as f:
        f.write(gzip.compress(raw, compresslevel=1, mtime=0))


class Case:
    def __init__(self, demo):
        self.demo = demo
        self.case = os.path.join(demo, "case")
        self.preop = os.path.join(self.case, "preop_image.nii.gz")
        self.labels = os.path.join(self.case, "preop_labels.nii.gz")
        self.intraop = os.path.join(self.case, "intraop_image.nii.gz")
        self.landmarks = os.path.join(self.case, "landmarks.csv")
        self.transform = os.path.join(demo, "intraop_to_preop.h5")
        self.rigid = os.path.join(demo, "rigid_intraop_to_preop.tfm")
        self.scene = os.path.join(demo, "scene.mrml")
        self.intraop_raw = read_gz(self.intraop)
        self.labels_raw = read_gz(self.labels)


def make_input(rng, kind, case, folder, config_text):
    """Writes the corrupted input into folder; returns (input path, command args, output folder, mutation)."""
    out = os.path.join(folder, "out")
    if kind in ("nifti-header", "nifti-data", "nifti-gzip"):
        path = os.path.join(folder, "intraop_image.nii.gz")
        if kind == "nifti-header":
            raw, what = mutate_nifti_header(rng, case.intraop_raw)
            write_gz(path, raw)
        elif kind == "nifti-data":
            raw, what = mutate_nifti_data(rng, case.intraop_raw)
            write_gz(path, raw)
        else:
            with open(case.intraop, "rb") as f:
                data, what = mutate_bytes(rng, f.read())
            what = "gzip " + what
            with open(path, "wb") as f:
                f.write(data)
        return path, ["rigid", "--preop-image", case.preop, "--intraop-image", path, "--output-dir", out], out, what
    if kind == "labels":
        path = os.path.join(folder, "preop_labels.nii.gz")
        if rng.random() < 0.5:
            raw, what = mutate_nifti_header(rng, case.labels_raw)
        else:
            raw, what = mutate_nifti_data(rng, case.labels_raw)
        write_gz(path, raw)
        return path, ["mesh", "--preop-labels", path, "--output-dir", out], out, what
    if kind in ("landmarks", "transform"):
        source = case.landmarks if kind == "landmarks" else case.rigid
        with open(source, encoding="utf-8") as f:
            text, what = mutate_text(rng, f.read())
        path = os.path.join(folder, os.path.basename(source))
        with open(path, "w", encoding="utf-8", errors="surrogateescape") as f:
            f.write(text)
        os.makedirs(out)
        if kind == "landmarks":
            args = ["evaluate", "--transform", case.transform, "--landmarks", path, "--json", os.path.join(out, "tre.json")]
        else:
            args = ["evaluate", "--transform", path, "--landmarks", case.landmarks, "--json", os.path.join(out, "tre.json")]
        return path, args, out, "text " + what
    if kind == "config":
        path = os.path.join(folder, "config.json")
        if rng.random() < 0.6:
            document, what = mutate_json(rng, json.loads(config_text))
            text = json.dumps(document)
        else:
            text, what = mutate_text(rng, config_text)
            what = "text " + what
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
        if rng.random() < 0.2:  # the finite element worker: a bad configuration must not leave it behind
            os.makedirs(out)
            for name in ("mesh.vtu", "brain_surface.vtp"):
                shutil.copy(os.path.join(case.demo, name), out)
            return path, ["simulate", "--output-dir", out, "--config", path], out, what
        return path, ["mesh", "--preop-labels", case.labels, "--output-dir", out, "--config", path], out, what
    # scene: the demo's scene beside links to its data files, the scene text corrupted
    scene_folder = os.path.join(folder, "scene")
    os.makedirs(scene_folder)
    for name in os.listdir(case.demo):  # its data files and case/ (the scene refers to the case's images)
        if name != "scene.mrml":
            os.symlink(os.path.join(case.demo, name), os.path.join(scene_folder, name))
    with open(case.scene, encoding="utf-8") as f:
        text = f.read()
    if rng.random() < 0.5:  # well-formed XML, values gone wrong: the reader's checks, not the parser's
        attributes = list(re.finditer(r'(\w+)="([^"]*)"', text))
        changed = []
        for _ in range(rng.randint(1, 3)):
            m = rng.choice(attributes)
            value = rng.choice(["", "nan", "inf", "-1", "0", "1e308", "x" * 5000, "vtkMRMLNoSuchNode1", "a;b;c",
                                " ".join(["1"] * 15), " ".join(["nan"] * 16), "storage:;display:;", "&amp;&lt;"])
            start, end = m.span(2)
            text = text[:start] + value + text[end:]
            changed.append(f"{m.group(1)}={value[:20]}")
            attributes = list(re.finditer(r'(\w+)="([^"]*)"', text))
        what = "attributes " + " ".join(changed)
    else:
        text, what = mutate_text(rng, text)
    if rng.random() < 0.3:  # a file name that leads somewhere else
        text = re.sub(r'fileName="[^"]*"', rng.choice(['fileName=""', 'fileName="/etc/passwd"', 'fileName="../../x.nii.gz"',
                                                       'fileName="missing.vtp"', 'fileName="scene.mrml"']), text, count=1)
        what += " fileName"
    path = os.path.join(scene_folder, "scene.mrml")
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)
    return path, ["bench", "read-scene", "--scene", path], None, what


def session_processes(sid):
    """Processes of the session `sid` (the run's, and its workers' process groups within it)."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                stat = f.read()
        except OSError:
            continue
        fields = stat[stat.rfind(")") + 2:].split()
        if int(fields[3]) == sid and fields[0] != "Z":
            found.append(int(entry))
    return found


def sha256(path):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def run_one(brainshift, args, env):
    start = time.monotonic()
    process = subprocess.Popen([brainshift] + args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                               start_new_session=True, env=env)
    hung = False
    try:
        _, err = process.communicate(timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        hung = True
        os.killpg(process.pid, signal.SIGKILL)
        _, err = process.communicate()
    seconds = time.monotonic() - start
    time.sleep(0.05)  # a worker's last exit
    left = session_processes(process.pid)
    for pid in left:
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
    return process.returncode, err.decode("utf-8", "replace"), seconds, hung, left


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--brainshift", required=True)
    parser.add_argument("--demo", required=True)
    parser.add_argument("--work", required=True)
    parser.add_argument("--output-dir", required=True)
    parser.add_argument("--config", required=True, help="the default configuration (Resources/Configurations/default.json)")
    parser.add_argument("--seed", type=int, default=18)
    parser.add_argument("--inputs", type=int, default=300)
    options = parser.parse_args()

    case = Case(os.path.abspath(options.demo))
    with open(options.config, encoding="utf-8") as f:
        config_text = f.read()
    case_files = {p: sha256(os.path.join(case.case, p)) for p in os.listdir(case.case)
                  if os.path.isfile(os.path.join(case.case, p))}
    shutil.rmtree(os.path.join(options.output_dir, "failing-inputs"), ignore_errors=True)
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    rows, problems = [], []
    counts = {"inputs": 0, "exit_0": 0, "exit_1": 0, "exit_2": 0, "crashes": 0, "hangs": 0, "orphans": 0,
              "partial_files": 0, "stderr_not_one_line": 0, "refused_output_left": 0, "inputs_modified": 0}
    by_kind = {}
    for i in range(options.inputs):
        rng = random.Random(f"{options.seed}:{i}")
        kind = KINDS[i % len(KINDS)]
        folder = os.path.join(options.work, f"input-{i:04d}")
        shutil.rmtree(folder, ignore_errors=True)
        os.makedirs(folder)
        path, args, out, what = make_input(rng, kind, case, folder, config_text)
        out_existed = out is not None and os.path.exists(out)
        before = sha256(path)
        status, err, seconds, hung, left = run_one(options.brainshift, args, env)
        lines = [line for line in err.split("\n") if line.strip()]
        findings = []
        counts["inputs"] += 1
        if hung:
            counts["hangs"] += 1
            findings.append(f"hang: killed after {TIMEOUT_S} s")
        elif status in (0, 1, 2):
            counts[f"exit_{status}"] += 1
        else:
            counts["crashes"] += 1
            findings.append(f"crash: exit status {status}" + (f" (signal {-status})" if status < 0 else ""))
        errors = [line for line in lines if not line.startswith("warning: ")]  # warnings are not errors
        if status != 0 and len(errors) != 1:
            counts["stderr_not_one_line"] += 1
            findings.append(f"{len(errors)} error lines on stderr")
        if left:
            counts["orphans"] += len(left)
            findings.append(f"{len(left)} processes left")
        temporaries = [os.path.join(d, n) for d, _, names in os.walk(folder) for n in names if n.startswith(".tmp-")]
        empty = [os.path.join(out, n) for n in os.listdir(out)
                 if os.path.isfile(os.path.join(out, n)) and os.path.getsize(os.path.join(out, n)) == 0] \
            if out and os.path.isdir(out) else []
        if temporaries or empty:
            counts["partial_files"] += len(temporaries) + len(empty)
            findings.append("partial files: " + " ".join(os.path.basename(p) for p in temporaries + empty))
        if status == 2 and out and not out_existed and os.path.exists(out):
            counts["refused_output_left"] += 1
            findings.append("a refused run left its output folder")
        if sha256(path) != before:
            counts["inputs_modified"] += 1
            findings.append("the input was modified")
        k = by_kind.setdefault(kind, {"inputs": 0, "exit_0": 0, "exit_1": 0, "exit_2": 0, "other": 0, "seconds": 0.0})
        k["inputs"] += 1
        k[f"exit_{status}" if status in (0, 1, 2) and not hung else "other"] += 1
        k["seconds"] += seconds
        rows.append({"input": i, "kind": kind, "command": args[0] if args[0] != "bench" else "bench read-scene",
                     "mutation": what, "status": status, "seconds": f"{seconds:.2f}",
                     "stderr": (errors or lines or [""])[0][:300], "findings": "; ".join(findings)})
        if findings:
            problems.append(rows[-1])
            kept = os.path.join(options.output_dir, "failing-inputs")
            os.makedirs(kept, exist_ok=True)
            shutil.copy(path, os.path.join(kept, f"input-{i:04d}-{os.path.basename(path)}"))
            print(f"input {i} ({kind}, {what}): {'; '.join(findings)}; stderr: {err.strip()[:500]}", file=sys.stderr)
        shutil.rmtree(folder, ignore_errors=True)
    for name, digest in case_files.items():
        if sha256(os.path.join(case.case, name)) != digest:
            counts["inputs_modified"] += 1
            problems.append({"input": "case", "findings": f"the case's {name} was modified"})

    os.makedirs(options.output_dir, exist_ok=True)
    with open(os.path.join(options.output_dir, "runs.csv"), "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0].keys()) if rows else ["input"])
        writer.writeheader()
        writer.writerows(rows)
    summary = {"seed": options.seed, "counts": counts, "by_kind": by_kind, "problems": problems}
    with open(os.path.join(options.output_dir, "summary.json"), "w", encoding="utf-8") as f:
        json.dump(summary, f, indent=2)
        f.write("\n")
    print(json.dumps(counts))
    bad = sum(counts[k] for k in ("crashes", "hangs", "orphans", "partial_files", "stderr_not_one_line",
                                  "refused_output_left", "inputs_modified"))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
