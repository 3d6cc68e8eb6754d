#!/usr/bin/env python3
"""summary.md from runs.csv: the confusion table of the trust assessment (updates worse than the
rigid registration alone: rejected? better: accepted?), per size and in all, and every run."""
import csv
import os
import sys


def table(rows):
    worse = [r for r in rows if r['update_worse'] == '1']
    better = [r for r in rows if r['update_worse'] == '0']
    def count(group, verdict):
        return sum(1 for r in group if r['trust'] == verdict)
    lines = ['| update against rigid (landmark TRE mean) | runs | trusted | doubtful | rejected |', '|---|---:|---:|---:|---:|']
    for label, group in (('worse than rigid', worse), ('better than rigid', better)):
        lines.append(f"| {label} | {len(group)} | {count(group, 'trusted')} | {count(group, 'doubtful')} | {count(group, 'rejected')} |")
    accepted = count(better, 'trusted') + count(better, 'doubtful')
    lines.append('')
    lines.append(f"worse updates rejected: {count(worse, 'rejected')} of {len(worse)}; "
                 f"better updates accepted (trusted or doubtful): {accepted} of {len(better)}"
                 + (f" ({100.0 * accepted / len(better):.0f} %)" if better else ''))
    close = [r for r in rows if abs(float(r['update_tre_mean']) - float(r['rigid_tre_mean'])) < 0.1]
    if close:
        verdicts = ', '.join(f"{r['case']} {r['variant']}: {float(r['update_tre_mean']) - float(r['rigid_tre_mean']):+.3f} mm, "
                             f"{r['trust']}" for r in close)
        lines.append('')
        lines.append(f'within 0.1 mm of the rigid TRE (a tie rather than better or worse): {len(close)} ({verdicts})')
    return lines


def main():
    out = sys.argv[1]
    with open(os.path.join(out, 'runs.csv')) as f:
        rows = list(csv.DictReader(f))
    scored = [r for r in rows if r['trust'] in ('trusted', 'doubtful', 'rejected')]
    md = ['# Trust assessment of the non-rigid update', '',
          'Made by `Testing/Benchmarks/trust/run.sh` (machine: machine.txt). Each run: a built-in case, registered with its',
          'own classification, the true labels, or a damaged segmentation; scored by landmark TRE of the update (the one set',
          'aside when rejected) against the rigid transform alone. "worse" = larger mean TRE than the rigid result.', '']
    for size in sorted({r['size'] for r in scored}):
        md += [f'## {size} case', ''] + table([r for r in scored if r['size'] == size]) + ['']
    md += ['## all sizes', ''] + table(scored) + ['']
    missing = [r for r in rows if r not in scored]
    if missing:
        md += [f'{len(missing)} runs gave no update (a stage failed before the warp):', '']
        md += [f"- {r['size']} {r['case']} {r['variant']}: exit {r['exit']} {r['reasons']}" for r in missing] + ['']
    md += ['## every run', '', '| size | case | segmentation | verdict | TRE update / rigid (mm) | eta^2 boundary update / rigid | '
           'eta^2 moved update / rigid (voxels) | unmatched | reasons |', '|---|---|---|---|---|---|---|---|---|']
    for r in scored:
        md.append(f"| {r['size']} | {r['case']} | {r['variant']} | {r['trust']} | {r['update_tre_mean']} / {r['rigid_tre_mean']} | "
                  f"{r['boundary_update']} / {r['boundary_rigid']} | {r['moved_update']} / {r['moved_rigid']} ({r['moved_voxels']}) | "
                  f"{r['unmatched_share']} | {r['reasons']} |")
    with open(os.path.join(out, 'summary.md'), 'w') as f:
        f.write('\n'.join(md) + '\n')
    print('\n'.join(md[:40]))


if __name__ == '__main__':
    main()
