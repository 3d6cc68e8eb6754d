#!/usr/bin/env python3
"""Damages an intraoperative segmentation (labels 0-4, NIfTI) the way a failing classification
would, so that the update built on it is worse than the rigid registration alone:

  damage_labels.py IN OUT shift DX DY DZ   the brain (labels 2, 3, 4) moved by (DX, DY, DZ) mm (grid axes)
  damage_labels.py IN OUT erode MM         the brain eroded by MM mm (its rim becomes background)
  damage_labels.py IN OUT dilate MM        the brain grown by MM mm into the head (label 1) and background
  damage_labels.py IN OUT fill MM          the background within MM mm of the brain (the gap under the
                                           craniotomy, the cavity, the air over the opening) made brain

Needs numpy and scipy (Debian python3-numpy, python3-scipy, in /usr/bin/python3). The header is
kept byte for byte; only the voxels change.
"""
import gzip
import struct
import sys

import numpy as np
from scipy import ndimage

DTYPES = {2: np.uint8, 4: np.int16, 8: np.int32, 16: np.float32, 64: np.float64, 256: np.int8, 512: np.uint16, 768: np.uint32}


def read(path):
    raw = gzip.open(path, 'rb').read() if path.endswith('.gz') else open(path, 'rb').read()
    dims = struct.unpack_from('<8h', raw, 40)
    datatype = struct.unpack_from('<h', raw, 70)[0]
    spacing = struct.unpack_from('<8f', raw, 76)[1:4]
    offset = int(struct.unpack_from('<f', raw, 108)[0])
    shape = dims[1:1 + dims[0]][:3]
    dtype = np.dtype(DTYPES[datatype]).newbyteorder('<')
    count = int(np.prod(shape))
    data = np.frombuffer(raw, dtype=dtype, count=count, offset=offset).reshape(shape, order='F')
    return raw[:offset], data.copy(), np.array(spacing, dtype=float)


def write(path, head, data):
    body = np.asarray(data, dtype=data.dtype).tobytes(order='F')
    with gzip.open(path, 'wb') as f:
        f.write(head + body)


def distance_outside(mask, spacing):
    return ndimage.distance_transform_edt(~mask, sampling=spacing)


def main():
    src, dst, kind = sys.argv[1], sys.argv[2], sys.argv[3]
    head, labels, spacing = read(src)
    brain = np.isin(labels, (2, 3, 4))
    out = labels.copy()
    if kind == 'shift':
        mm = np.array([float(v) for v in sys.argv[4:7]])
        voxels = np.round(mm / spacing).astype(int)
        moved = ndimage.shift(labels * brain, voxels, order=0, mode='constant', cval=0).astype(labels.dtype)
        out[brain] = 1  # where the brain was: head, as a classification that lost it would say
        out[moved > 0] = moved[moved > 0]
    elif kind == 'erode':
        inside = ndimage.distance_transform_edt(brain, sampling=spacing)
        out[brain & (inside <= float(sys.argv[4]))] = 0
    elif kind == 'dilate':
        grow = (~brain) & (distance_outside(brain, spacing) <= float(sys.argv[4]))
        out[grow] = 2
    elif kind == 'fill':
        grow = (labels == 0) & (distance_outside(brain, spacing) <= float(sys.argv[4]))
        out[grow] = 2
    else:
        sys.exit('damage_labels.py: unknown damage ' + kind)
    write(dst, head, out.astype(labels.dtype))
    changed = int(np.count_nonzero(out != labels))
    print(f'{kind} {" ".join(sys.argv[4:])}: {changed} voxels changed of {labels.size}')


if __name__ == '__main__':
    main()
