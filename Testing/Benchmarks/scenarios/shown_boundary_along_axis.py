#!/usr/bin/python3
"""The brain boundary the update shows under the craniotomy, along the line of sight.

For each run folder (a `brainshift demo --scenario` output: displacement_intraop_to_preop.nrrd and the case
in `case/`): lines parallel to the craniotomy's axis (within 30 mm of it, 1 mm apart, in the intraoperative
space through the case's true rigid motion) are followed inward from 40 mm outside the craniotomy's centre.
On each, where the true intraoperative brain (labels 2-4) begins is compared with where the update shows
brain: the preoperative labels at x = y + d(y), d the written field. Positive: the shown brain begins
above the true one (preoperative brain left in the gap, or the sinking under-compensated). Unlike
evaluation.json's closest-point distances, an island of brain shown in the gap counts in full here, and
so does a steep wall a little misplaced.

    shown_boundary_along_axis.py [--truth-main-piece] RUN_DIR ...

prints per run: lines, signed mean, mean |d| and p95 |d| in mm, and the same in the rings 0-10, 10-20,
20-25 and 25-30 mm from the axis. --truth-main-piece: the true brain is its largest connected piece
(face-connected voxels of labels 2-4); the pieces apart from it (where a finite element truth folds,
its inverted field carries preoperative brain into the gap) are counted, their volume printed, and left
out. Needs numpy, scipy and nibabel.
"""
import os
import re
import sys

import nibabel as nib
import numpy as np
from scipy import ndimage

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from classification_boundary import craniotomy_lines, first_entries, sample_lines  # noqa: E402


def read_vector_nrrd(path):
    """A raw little-endian float vector NRRD (as the warp writes it): the array [z, y, x, component],
    the index-to-LPS matrix (columns: the index axes) and the origin."""
    raw = open(path, 'rb').read()
    head, _, data = raw.partition(b'\n\n')
    fields = {}
    for line in head.decode().splitlines()[1:]:
        if ':' in line and not line.startswith('#'):
            key, value = line.split(':', 1)
            fields[key.strip()] = value.strip()
    if fields.get('encoding') != 'raw' or fields.get('type') != 'float' or fields.get('endian', 'little') != 'little':
        raise SystemExit(f"{path}: not a raw little-endian float NRRD")
    sizes = [int(v) for v in fields['sizes'].split()]
    directions = [tuple(float(x) for x in m.split(',')) for m in re.findall(r'\(([^)]*)\)', fields['space directions'])]
    origin = np.array([float(x) for x in re.findall(r'\(([^)]*)\)', fields['space origin'])[0].split(',')])
    return np.frombuffer(data, dtype='<f4').reshape(sizes[::-1]), np.array(directions).T, origin


def main_piece(labels, voxel_ml):
    """The labels with the brain (2-4) outside its largest face-connected piece set to 0; the pieces
    (label volume, 0 outside the brain) and the largest one's label; how many pieces were apart from
    it and their volume in ml."""
    brain = (labels >= 2) & (labels <= 4)
    pieces, count = ndimage.label(brain)
    if count <= 1:
        return labels, pieces, 1, 0, 0.0
    sizes = ndimage.sum(brain, pieces, range(1, count + 1))
    largest = 1 + int(np.argmax(sizes))
    apart = brain & (pieces != largest)
    kept = labels.copy()
    kept[apart] = 0
    return kept, pieces, largest, count - 1, float(apart.sum()) * voxel_ml


def pieces_entered_first(pieces, largest, ras_to_voxel, starts, axis, step, length):
    """Of the pieces apart from the largest, those some line enters first (and how many lines)."""
    v = sample_lines(pieces, ras_to_voxel, starts, axis, step, length)
    inside = v > 0
    first = v[np.arange(len(starts)), inside.argmax(1)]
    first = first[inside.any(1) & (first != largest)]
    return len(np.unique(first)), len(first)


def measure(run, step=0.25, length=90.0, truth_main_piece=False):
    starts, axis, radius = craniotomy_lines(run)
    truth = nib.load(os.path.join(run, 'case', 'truth', 'intraop_labels.nii.gz'))
    true_labels = np.asarray(truth.dataobj).astype(np.int16)
    apart = None
    if truth_main_piece:
        true_labels, pieces, largest, count, ml = main_piece(true_labels, abs(np.linalg.det(truth.affine[:3, :3])) / 1000.0)
        apart = (count, ml) + pieces_entered_first(pieces, largest, np.linalg.inv(truth.affine), starts, axis, step, length)
    true_entry = first_entries(true_labels, np.linalg.inv(truth.affine), starts, axis, step, length)

    field, index_to_lps, origin = read_vector_nrrd(os.path.join(run, 'displacement_intraop_to_preop.nrrd'))
    preop = nib.load(os.path.join(run, 'case', 'preop_labels.nii.gz'))
    s = np.arange(0.0, length, step)
    y = (starts[:, None, :] - s[None, :, None] * axis[None, None, :]).reshape(-1, 3)
    index = np.linalg.solve(index_to_lps, (y - origin).T)[::-1]  # z, y, x
    x = y + np.stack([ndimage.map_coordinates(field[..., k], index, order=1, mode='nearest') for k in range(3)], 1)
    ras_to_voxel = np.linalg.inv(preop.affine)
    voxels = ras_to_voxel[:3, :3] @ (x * np.array([-1, -1, 1])).T + ras_to_voxel[:3, 3:4]
    labels = ndimage.map_coordinates(np.asarray(preop.dataobj).astype(np.int16), voxels, order=0, mode='constant', cval=0)
    brain = ((labels >= 2) & (labels <= 4)).reshape(len(starts), len(s))
    shown_entry = np.where(brain.any(1), brain.argmax(1) * step, np.nan)
    d = true_entry - shown_entry
    measured = ~np.isnan(d)
    return d[measured], radius[measured], apart


def summary(d):
    return f"signed {d.mean():+.2f} mm, mean |d| {np.abs(d).mean():.2f} mm, p95 {np.percentile(np.abs(d), 95):.2f} mm"


if __name__ == '__main__':
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main_only = '--truth-main-piece' in sys.argv[1:]
    runs = [a for a in sys.argv[1:] if a != '--truth-main-piece']
    if not runs:
        sys.exit(__doc__)
    for run in runs:
        d, radius, apart = measure(run, truth_main_piece=main_only)
        if apart is not None:
            print(f"{run}: {apart[0]} pieces of the truth's brain apart from the largest ({apart[1]:.2f} ml), left out; "
                  f"{apart[2]} of them entered first by {apart[3]} lines")
        print(f"{run}: {len(d)} lines, {summary(d)}")
        for low, high in [(0, 10), (10, 20), (20, 25), (25, 31)]:
            within = (radius >= low) & (radius < high)
            if within.any():
                print(f"  {low:2d}-{high:2d} mm from the axis: {within.sum():5d} lines, {summary(d[within])}")
