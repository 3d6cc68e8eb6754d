#!/usr/bin/env python3
"""One row of runs.csv from a run's folder: record.py CSV FOLDER SIZE CASE VARIANT EXIT_STATUS.
The update's TRE (update_tre.json: the update shown, or the one set aside when rejected) against
the rigid transform's (rigid_tre.json), and the trust assessment's verdict and figures (report.json)."""
import csv
import json
import os
import sys

COLUMNS = ['size', 'case', 'variant', 'exit', 'trust', 'update_tre_mean', 'rigid_tre_mean', 'update_tre_p95',
           'rigid_tre_p95', 'update_worse', 'boundary_update', 'boundary_rigid', 'interior_update', 'interior_rigid',
           'moved_voxels', 'moved_update', 'moved_rigid', 'unmatched_share', 'surface_residual_mm', 'folded_share',
           'reasons']


def load(path):
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def main():
    table, folder, size, case, variant, status = sys.argv[1:7]
    row = dict.fromkeys(COLUMNS, '')
    row.update(size=size, case=case, variant=variant, exit=status)
    report = load(os.path.join(folder, 'report.json')) or {}
    trust = report.get('trust')
    update, rigid = load(os.path.join(folder, 'update_tre.json')), load(os.path.join(folder, 'rigid_tre.json'))
    if trust and update and rigid:
        row.update(trust=trust['nonrigid'], update_tre_mean=round(update['mean_mm'], 3), rigid_tre_mean=round(rigid['mean_mm'], 3),
                   update_tre_p95=round(update['p95_mm'], 3), rigid_tre_p95=round(rigid['p95_mm'], 3),
                   update_worse=int(update['mean_mm'] > rigid['mean_mm']),
                   boundary_update=round(trust['near_boundary']['update'], 4), boundary_rigid=round(trust['near_boundary']['rigid'], 4),
                   interior_update=round(trust['interior']['update'], 4), interior_rigid=round(trust['interior']['rigid'], 4),
                   moved_voxels=trust['moved']['voxels'], moved_update=round(trust['moved']['update'], 4),
                   moved_rigid=round(trust['moved']['rigid'], 4), unmatched_share=round(trust['unmatched_surface_node_share'], 4),
                   folded_share=round(trust['folded_voxel_share'], 5), reasons=' | '.join(trust['reasons']))
        surface = report.get('stages', {}).get('surface', {})
        row['surface_residual_mm'] = round(surface.get('mean_residual_mm', float('nan')), 3)
    else:
        row['trust'] = 'no update'
        log = os.path.join(folder, 'log.txt')
        if os.path.exists(log):
            lines = [l.strip() for l in open(log) if l.startswith('brainshift:')]
            row['reasons'] = lines[-1] if lines else ''
    new = not os.path.exists(table)
    with open(table, 'a', newline='') as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        if new:
            writer.writeheader()
        writer.writerow(row)
    print(f"{size} {case} {variant}: exit {status}, {row['trust']}, TRE update {row['update_tre_mean']} rigid {row['rigid_tre_mean']}")


if __name__ == '__main__':
    main()
