#!/usr/bin/env python3
"""The block matches of `demo --scenario` runs against the scenario's truth.

    match_error.py OUTPUT_DIR RUN_DIR...

Each RUN_DIR is a `brainshift demo` output folder that holds `block_matches.vtp` (the matches in
the preoperative frame: the tissue at a block's centre c lies at c + d), the rigid transform
`rigid_intraop_to_preop.tfm` and the case with its truth (`case/truth/intraop_to_preop.h5`,
`case/preop_image.nii.gz`, `case/landmarks.csv`). A match's error is where the truth takes the
point it found back to, against the block's centre: e = T(R^-1(c + d)) - c, with R the run's rigid
transform and T the truth's mapping of intraoperative to preoperative points (the composite
transform of the HDF5 file, its last transform applied first). The same for the surface-driven
prediction the search started from (`PredictedDisplacement`). The truth's mapping is checked on
the case's landmarks first (within 0.05 mm, else the run is refused).

The error is split along the eigenvectors of the block's gradient structure tensor (of the
preoperative image over the block, 9 voxels a side): an edge or a sheet leaves its tangent free
(the aperture problem), and the solve weights a match by that tensor (ImageMatchConstraints.h).

Writes OUTPUT_DIR/match_error.csv (one row per run) and OUTPUT_DIR/match_error.md. Needs numpy,
scipy, h5py, nibabel and VTK's Python modules (match_error.sh installs them).
"""
import csv
import os
import sys

import h5py
import nibabel
import numpy as np
from scipy.ndimage import map_coordinates
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkIOXML import vtkXMLPolyDataReader


def versor_matrix(v):
    x, y, z = v
    w = np.sqrt(max(0.0, 1 - x * x - y * y - z * z))
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def euler_matrix(angles, zyx):
    ax, ay, az = angles
    rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
    rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
    return rz @ ry @ rx if zyx else rz @ rx @ ry  # ITK's Euler3DTransform: Z X Y unless ComputeZYX


def rigid(kind, parameters, fixed):
    """x -> M (x - centre) + centre + t, for ITK's rigid transform types."""
    if kind.startswith('VersorRigid3DTransform'):
        matrix = versor_matrix(parameters[:3])
    elif kind.startswith('Euler3DTransform'):
        matrix = euler_matrix(parameters[:3], len(fixed) > 3 and fixed[3] != 0)
    else:
        raise ValueError('unsupported rigid transform ' + kind)
    centre, t = np.asarray(fixed[:3]), np.asarray(parameters[3:6])
    forward = lambda x: (x - centre) @ matrix.T + centre + t
    inverse = lambda y: (y - centre - t) @ matrix + centre
    return forward, inverse


def read_tfm(path):
    kind = parameters = fixed = None
    for line in open(path):
        if line.startswith('Transform:'):
            kind = line.split()[1]
        elif line.startswith('Parameters:'):
            parameters = [float(v) for v in line.split()[1:]]
        elif line.startswith('FixedParameters:'):
            fixed = [float(v) for v in line.split()[1:]]
    return rigid(kind, parameters, fixed)


def displacement_field(parameters, fixed):
    size = fixed[0:3].astype(int)
    origin, spacing, direction = fixed[3:6], fixed[6:9], fixed[9:18].reshape(3, 3)
    field = parameters.reshape(size[2], size[1], size[0], 3)
    to_index = np.linalg.inv(direction * spacing)  # physical -> continuous index (i, j, k)

    def apply(x):
        index = (x - origin) @ to_index.T
        moved = x.copy()
        for a in range(3):
            moved[:, a] += map_coordinates(field[..., a], [index[:, 2], index[:, 1], index[:, 0]], order=1, mode='nearest')
        return moved
    return apply


def read_truth(path):
    """The HDF5 transform as a function of intraoperative points: a composite's last transform first."""
    with h5py.File(path, 'r') as f:
        group = f['TransformGroup']
        steps = []
        for key in sorted(group, key=int):
            kind = group[key]['TransformType'][0].decode()
            if kind.startswith('CompositeTransform'):
                continue
            parameters = group[key]['TransformParameters'][()]
            fixed = group[key]['TransformFixedParameters'][()]
            if kind.startswith('DisplacementFieldTransform'):
                steps.append(displacement_field(parameters, fixed))
            else:
                steps.append(rigid(kind, parameters, fixed)[0])
    def apply(x):
        for step in reversed(steps):
            x = step(x)
        return x
    return apply


def structure_axes(image_path, centres_lps, half=4):
    """Per block: the eigenvectors (columns, weakest first, LPS) of the preoperative image's
    gradient structure tensor over the block."""
    image = nibabel.load(image_path)
    volume = np.asarray(image.dataobj, dtype=np.float64)
    gradients = np.gradient(volume)
    voxel_to_ras = image.affine[:3, :3]
    ras_to_lps = np.diag([-1.0, -1.0, 1.0])
    gradient_to_lps = ras_to_lps @ np.linalg.inv(voxel_to_ras).T  # index gradient -> physical gradient
    ras = centres_lps @ ras_to_lps
    index = np.round((ras - image.affine[:3, 3]) @ np.linalg.inv(voxel_to_ras).T).astype(int)
    axes = np.zeros((len(centres_lps), 3, 3))
    for n, (i, j, k) in enumerate(index):
        window = (slice(i - half, i + half + 1), slice(j - half, j + half + 1), slice(k - half, k + half + 1))
        g = np.stack([component[window].ravel() for component in gradients], 1) @ gradient_to_lps.T
        _, vectors = np.linalg.eigh(g.T @ g)
        axes[n] = vectors
    return axes


def analyse(run):
    case = os.path.join(run, 'case')
    truth = read_truth(os.path.join(case, 'truth', 'intraop_to_preop.h5'))
    landmarks = list(csv.DictReader(open(os.path.join(case, 'landmarks.csv'))))
    preop = np.array([[float(r['preop_' + a]) for a in 'xyz'] for r in landmarks])
    intraop = np.array([[float(r['intraop_' + a]) for a in 'xyz'] for r in landmarks])
    check = np.abs(truth(intraop) - preop).max()
    if check > 0.05:
        raise RuntimeError('%s: the truth read here misses the landmarks by %.3f mm' % (run, check))
    _, rigid_inverse = read_tfm(os.path.join(run, 'rigid_intraop_to_preop.tfm'))
    reader = vtkXMLPolyDataReader()
    reader.SetFileName(os.path.join(run, 'block_matches.vtp'))
    reader.Update()
    matches = reader.GetOutput()
    centres = vtk_to_numpy(matches.GetPoints().GetData()).astype(np.float64)
    found = vtk_to_numpy(matches.GetPointData().GetArray('Displacement'))
    predicted = vtk_to_numpy(matches.GetPointData().GetArray('PredictedDisplacement'))
    kept = vtk_to_numpy(matches.GetPointData().GetArray('Kept')).astype(bool)
    error = truth(rigid_inverse(centres + found)) - centres
    prediction_vector = truth(rigid_inverse(centres + predicted)) - centres
    prediction_error = np.linalg.norm(prediction_vector, axis=1)
    magnitude = np.linalg.norm(error, axis=1)
    axes = structure_axes(os.path.join(case, 'preop_image.nii.gz'), centres)
    along = np.abs(np.einsum('na,nab->nb', error, axes))  # weakest, middle, strongest
    prediction_along = np.abs(np.einsum('na,nab->nb', prediction_vector, axes))
    moved = np.linalg.norm(found - error, axis=1)  # the true displacement at the block, near enough
    row = {'run': os.path.basename(os.path.dirname(os.path.normpath(run))) or run, 'matches': len(centres), 'kept': int(kept.sum()), 'landmark_check_mm': check,
           'error_mean_mm': magnitude.mean(), 'error_median_mm': np.median(magnitude),
           'error_p95_mm': np.percentile(magnitude, 95), 'prediction_error_mean_mm': prediction_error.mean(),
           'weakest_mean_mm': along[:, 0].mean(), 'middle_mean_mm': along[:, 1].mean(), 'strongest_mean_mm': along[:, 2].mean(),
           'weakest_p95_mm': np.percentile(along[:, 0], 95), 'strongest_p95_mm': np.percentile(along[:, 2], 95),
           'prediction_weakest_mean_mm': prediction_along[:, 0].mean(), 'prediction_strongest_mean_mm': prediction_along[:, 2].mean(),
           'kept_error_mean_mm': magnitude[kept].mean() if kept.any() else float('nan'),
           'moved_over_2mm_error_mean_mm': magnitude[moved > 2].mean() if (moved > 2).any() else float('nan')}
    for low, high in [(0, 1), (1, 2), (2, 100)]:
        chosen = (prediction_error >= low) & (prediction_error < high)
        row['error_mean_mm_where_prediction_%g_%g' % (low, high)] = magnitude[chosen].mean() if chosen.any() else float('nan')
        row['share_where_prediction_%g_%g' % (low, high)] = chosen.mean()
    return row


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    rows = []
    for run in sys.argv[2:]:
        rows.append(analyse(run))
        print('%s: %d matches, error mean %.2f / median %.2f / p95 %.2f mm (prediction %.2f); along the weakest / strongest '
              'structure %.2f / %.2f mm (prediction %.2f / %.2f)' % (run, rows[-1]['matches'], rows[-1]['error_mean_mm'], rows[-1]['error_median_mm'],
                                            rows[-1]['error_p95_mm'], rows[-1]['prediction_error_mean_mm'],
                                            rows[-1]['weakest_mean_mm'], rows[-1]['strongest_mean_mm'],
                                            rows[-1]['prediction_weakest_mean_mm'], rows[-1]['prediction_strongest_mean_mm']))
    with open(os.path.join(out, 'match_error.csv'), 'w', newline='') as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    with open(os.path.join(out, 'match_error.md'), 'w') as f:
        f.write('# Block matches against the truth\n\n`Testing/Benchmarks/blockmatching/match_error.sh`; machine in `machine.txt`. '
                'Per run: the matches (kept by the solve), the match error |T(R^-1(c + d)) - c| in mm (mean / median / p95), '
                'the surface-driven prediction\'s error at the same blocks, the error along the block\'s weakest and strongest '
                'structure direction (mean; p95; the prediction\'s mean beside it), and the mean match error where the prediction was off by < 1, 1-2 and > 2 mm '
                '(share of the blocks).\n\n')
        f.write('| run | matches (kept) | match error mean / median / p95 | prediction error mean | weakest direction (prediction) | strongest direction (prediction) '
                '| where the prediction was < 1 / 1-2 / > 2 mm off |\n|---|---:|---|---:|---|---|---|\n')
        for r in rows:
            bins = ' / '.join('%.2f (%.0f %%)' % (r['error_mean_mm_where_prediction_%g_%g' % b], 100 * r['share_where_prediction_%g_%g' % b])
                              for b in [(0, 1), (1, 2), (2, 100)])
            f.write('| %s | %d (%d) | %.2f / %.2f / %.2f | %.2f | %.2f; %.2f (%.2f) | %.2f; %.2f (%.2f) | %s |\n' % (
                r['run'], r['matches'], r['kept'], r['error_mean_mm'],
                r['error_median_mm'], r['error_p95_mm'], r['prediction_error_mean_mm'], r['weakest_mean_mm'], r['weakest_p95_mm'],
                r['prediction_weakest_mean_mm'], r['strongest_mean_mm'], r['strongest_p95_mm'], r['prediction_strongest_mean_mm'], bins))
        means = {k: np.nanmean([r[k] for r in rows]) for k in ('error_mean_mm', 'error_p95_mm', 'prediction_error_mean_mm',
                                                               'weakest_mean_mm', 'strongest_mean_mm',
                                                               'prediction_weakest_mean_mm', 'prediction_strongest_mean_mm')}
        f.write('\nOver the %d runs: match error mean %.2f mm (p95 %.2f), the prediction %.2f; along the weakest structure '
                'direction %.2f (the prediction %.2f), the strongest %.2f (the prediction %.2f).\n' % (len(rows), means['error_mean_mm'], means['error_p95_mm'],
                                                           means['prediction_error_mean_mm'], means['weakest_mean_mm'],
                                                           means['prediction_weakest_mean_mm'], means['strongest_mean_mm'],
                                                           means['prediction_strongest_mean_mm']))


if __name__ == '__main__':
    main()
