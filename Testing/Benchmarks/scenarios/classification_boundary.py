#!/usr/bin/python3
"""The classification's own brain boundary under the craniotomy, against the truth's.

For each run folder (a `brainshift demo --scenario` output, or any folder holding `intraop_labels.nii.gz`
and the case in `case/`): lines parallel to the craniotomy's axis (within 30 mm of it, 1 mm apart, in the
intraoperative space through the case's true rigid motion) are followed inward from 40 mm outside the
craniotomy's centre; where each first enters brain (labels 2-4) in the truth and in the classification
is compared. Positive: the classified boundary lies outside the true one (fluid or air called brain).

    classification_boundary.py RUN_DIR[::LABELS.nii.gz] ...

prints per run: rays, signed mean, mean |d| and p95 |d| in mm. Needs numpy, scipy and nibabel.
"""
import json
import os
import sys

import nibabel as nib
import numpy as np
from scipy import ndimage


def euler_transform(path):
    """R, centre, translation of an ITK Euler3DTransform file (x -> R (x - c) + c + t)."""
    lines = open(path).read().splitlines()
    p = [float(v) for line in lines if line.startswith('Parameters:') for v in line.split()[1:]]
    fixed = [float(v) for line in lines if line.startswith('FixedParameters:') for v in line.split()[1:]]
    ax, ay, az = p[:3]
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ rx @ ry, np.array(fixed[:3]), np.array(p[3:6])


def sample_lines(volume, ras_to_voxel, starts_lps, axis, step=0.25, length=90.0):
    """`volume` (nearest voxel, 0 outside) every `step` mm along each line from its start along
    minus `axis`: an array of lines x samples."""
    s = np.arange(0.0, length, step)
    points = starts_lps[:, None, :] - s[None, :, None] * axis[None, None, :]
    ras = (points * np.array([-1, -1, 1])).reshape(-1, 3).T
    voxels = ras_to_voxel[:3, :3] @ ras + ras_to_voxel[:3, 3:4]
    return ndimage.map_coordinates(volume, voxels, order=0, mode='constant', cval=0).reshape(len(starts_lps), len(s))


def first_entries(labels, ras_to_voxel, starts_lps, axis, step=0.25, length=90.0):
    v = sample_lines(labels, ras_to_voxel, starts_lps, axis, step, length)
    brain = (v >= 2) & (v <= 4)
    return np.where(brain.any(1), brain.argmax(1) * step, np.nan)


def craniotomy_lines(run):
    """The lines' starts (40 mm outside the craniotomy's centre, within 30 mm of its axis, 1 mm apart;
    intraoperative LPS), the axis (outward: the lines run along minus it) and each line's distance
    from the axis."""
    figures = json.load(open(os.path.join(run, 'case', 'case.json')))['figures']
    r, c, t = euler_transform(os.path.join(run, 'case', 'truth', 'rigid_intraop_to_preop.tfm'))
    centre = np.linalg.solve(r, np.array(figures['craniotomy_centre_lps']) - c - t) + c  # preop -> intraop
    axis = np.linalg.solve(r, np.array(figures['craniotomy_axis_lps']))
    axis /= np.linalg.norm(axis)
    u = np.cross(axis, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(axis, u)
    grid = np.arange(-30.0, 31.0, 1.0)
    gu, gw = np.meshgrid(grid, grid)
    inside = gu ** 2 + gw ** 2 <= 900
    starts = centre + 40 * axis + gu[inside][:, None] * u + gw[inside][:, None] * w
    return starts, axis, np.hypot(gu[inside], gw[inside])


def measure(run, labels_file=None):
    starts, axis, _ = craniotomy_lines(run)
    truth = nib.load(os.path.join(run, 'case', 'truth', 'intraop_labels.nii.gz'))
    classified = nib.load(labels_file or os.path.join(run, 'intraop_labels.nii.gz'))
    d = (first_entries(np.asarray(truth.dataobj).astype(np.int16), np.linalg.inv(truth.affine), starts, axis) -
         first_entries(np.asarray(classified.dataobj).astype(np.int16), np.linalg.inv(classified.affine), starts, axis))
    d = d[~np.isnan(d)]
    return len(d), d.mean(), np.abs(d).mean(), np.percentile(np.abs(d), 95)


if __name__ == '__main__':
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    for argument in sys.argv[1:]:
        run, _, labels = argument.partition('::')
        rays, signed, mean_abs, p95 = measure(run, labels or None)
        print(f"{run}: {rays} rays, signed {signed:+.2f} mm, mean |d| {mean_abs:.2f} mm, p95 {p95:.2f} mm")
