"""
Pose CSVs: odometry beside a run's scans, or its true poses.

One row per pose: ``TIMESTAMP`` (s), ``X``, ``Y`` (m), ``YAW`` (rad, counter-
clockwise from the frame's x axis); other columns (covariances) are
ignored. ``record_fingerprints`` writes odometry in this format, and the
robot runs of the shared datasets have it (``odom.csv``, ``poses.csv``).
"""

import csv
import io

import numpy as np

from .files import DataError, decode

#: The columns a pose CSV needs, in the order :func:`read_poses` returns.
POSE_COLUMNS = ('TIMESTAMP', 'X', 'Y', 'YAW')
#: A localiser's x, y, yaw covariance (m^2, rad^2) beside its poses.
COVARIANCE_COLUMNS = ('COV_XX', 'COV_XY', 'COV_YY', 'COV_YAWYAW')


def read_poses(path, columns=POSE_COLUMNS):
    """
    Return the poses of a CSV: float64 (n, 4) rows of stamp, x, y, yaw.

    ``columns``: the columns read, in this order (e.g. with
    :data:`COVARIANCE_COLUMNS` too: (n, 8) rows).

    Raises :class:`DataError` naming the file, row and column of a missing
    or repeated pose column (case ignored), a value that is not a finite
    number, or a stamp earlier than the row before (equal stamps are kept).
    """
    try:
        with open(path, 'rb') as f:
            raw = f.read()
    except OSError as exc:
        raise DataError(f'{path}: cannot read ({exc.strerror})') from None
    rows = csv.reader(io.StringIO(decode(raw, path)))
    header = [h.strip() for h in next(rows, [])]
    index = {}
    for j, h in enumerate(header):
        key = h.upper()
        if key in columns and key in index:
            raise DataError(f'{path}: columns {index[key] + 1} and {j + 1} '
                            f'are both {key} (case ignored)')
        index.setdefault(key, j)
    missing = [c for c in columns if c not in index]
    if missing:
        raise DataError(f'{path}: no column(s) {", ".join(missing)} (a pose '
                        f'CSV has {",".join(columns)})')
    names, columns = columns, [index[c] for c in columns]
    out = []
    for line, row in enumerate(rows, start=2):
        if not row:
            continue
        if len(row) != len(header):
            raise DataError(f'{path}: row {line} has {len(row)} fields, the '
                            f'header has {len(header)}')
        values = []
        for name, j in zip(names, columns):
            try:
                value = float(row[j])
            except ValueError:
                value = float('nan')
            if not np.isfinite(value):
                raise DataError(f'{path}: row {line}, column {name}: value '
                                f'{row[j]!r} is not a finite number')
            values.append(value)
        if out and values[0] < out[-1][0]:
            raise DataError(f'{path}: row {line}, column TIMESTAMP: '
                            f'{values[0]!r} is earlier than the row before')
        out.append(values)
    if not out:
        raise DataError(f'{path}: no poses after the header')
    return np.array(out, np.float64)
