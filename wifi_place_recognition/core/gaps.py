"""
Where to survey next: the stretches of a run the survey does not cover.

A run's scans in time order, each judged covered or not: from its true
position (a kept survey scan of its building/floor within ``covered_m``)
when the run has positions, else from the model's coverage probability
(:mod:`wifi_place_recognition.core.coverage`). :func:`gaps` groups the
scans off the survey into stretches (start, end, length driven), the
list a user surveys next.
"""

from dataclasses import dataclass
import math

import numpy as np

#: The shortest stretch ``survey_gaps`` lists by default (scans).
MIN_SCANS = 5


@dataclass(frozen=True)
class Gap:
    """One stretch of a run off the survey."""

    first: int          # index of its first scan (time order)
    last: int           # index of its last scan
    start_s: float      # stamp of the first scan (NaN: no stamps)
    end_s: float        # stamp of the last
    length_m: float     # distance driven along it (NaN: no positions)
    start_xy: tuple     # (x, y) of its first scan (NaN: no positions)
    end_xy: tuple

    @property
    def scans(self):
        """Return how many scans the stretch holds."""
        return self.last - self.first + 1


def gaps(off, stamps=None, xy=None, min_scans=1):
    """
    Return the :class:`Gap` stretches of consecutive scans ``off`` survey.

    ``off``: a boolean per scan, in time order; ``stamps`` (s) and ``xy``
    (m, NaN where unknown) describe them; stretches of fewer than
    ``min_scans`` scans are left out.
    """
    off = np.asarray(off, bool)
    n = len(off)
    stamps = np.full(n, np.nan) if stamps is None else \
        np.asarray(stamps, np.float64)
    xy = np.full((n, 2), np.nan) if xy is None else \
        np.asarray(xy, np.float64)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], off.astype(int),
                                                   [0]])))
    out = []
    for first, end in zip(edges[::2], edges[1::2]):
        last = end - 1
        if end - first < min_scans:
            continue
        path = xy[first:end]
        path = path[np.isfinite(path).all(axis=1)]
        length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()) \
            if len(path) else math.nan
        out.append(Gap(int(first), int(last), float(stamps[first]),
                       float(stamps[last]), length,
                       tuple(map(float, xy[first])),
                       tuple(map(float, xy[last]))))
    return out
