"""What the benchmarks' report.py share. Each imports it from the folder above its own:

    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))
    from benchmark_common import ...  # noqa: E402

Importing it chooses matplotlib's Agg backend (no display); plt is matplotlib.pyplot.
"""
import json
import math
import os
import sys
import tempfile

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)


def output_folder():
    """OUT, the one argument of report.py (the folder run.sh wrote); exits when it is not one."""
    if len(sys.argv) != 2:
        sys.exit("usage: report.py OUT")
    out = sys.argv[1]
    if not os.path.isdir(out):
        sys.exit(f"report.py: {out}: not a folder")
    return out


def report_missing(path):
    print(f"report.py: {path} missing", file=sys.stderr)


def load_json(path):
    """The JSON file at path, or None (said on stderr) when there is none."""
    if not os.path.isfile(path):
        report_missing(path)
        return None
    with open(path) as f:
        return json.load(f)


def finite(value):
    """value as a float, or None when it is missing, not a number or infinite."""
    if value is None or isinstance(value, bool):
        return None
    try:
        value = float(value)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None


def machine_description(out):
    """The lines of OUT/machine.txt (written by run.sh), or None when it is missing."""
    path = os.path.join(out, "machine.txt")
    if not os.path.isfile(path):
        return None
    with open(path) as f:
        return f.read().rstrip("\n").split("\n")


def machine_section(out):
    """The summary's "## Machine" section: OUT/machine.txt as a code block."""
    machine = machine_description(out)
    return ["## Machine", "", "```", *(machine if machine is not None else ["machine.txt missing"]),
            "```", ""]


def table_row(cells):
    """A Markdown table row of the cells (strings)."""
    return "| " + " | ".join(cells) + " |"


def write_atomically(path, text):
    fd, temporary = tempfile.mkstemp(dir=os.path.dirname(os.path.abspath(path)), prefix=".tmp-")
    with os.fdopen(fd, "w") as f:
        f.write(text)
    os.replace(temporary, path)


def save_atomically(fig, path):
    """Saves the figure as a PNG at path (100 dpi) and closes it."""
    fd, temporary = tempfile.mkstemp(dir=os.path.dirname(os.path.abspath(path)), prefix=".tmp-",
                                     suffix=".png")
    os.close(fd)
    fig.savefig(temporary, dpi=100)
    plt.close(fig)
    os.replace(temporary, path)


MARGIN_GROUPS = ("tumour-margin", "near-cavity")  # the tumour's margin: in place, or the resection cavity's


def group_mean(tre, names):
    """The mean error (mm) of the first of the landmark groups `names` that an evaluation's TRE
    (`brainshift evaluate --json`'s object, or evaluation.json's per transform) has; None when none."""
    for name in names:
        group = (tre or {}).get("groups", {}).get(name)
        if group:
            return group["mean_mm"]
    return None
