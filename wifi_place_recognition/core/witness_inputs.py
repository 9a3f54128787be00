"""
The witness's inputs checked: a stamped pose, or why it cannot be judged.

Nothing here raises on input: a refused pose or scan comes back with a
reason (or None), which the caller counts.
"""

from dataclasses import dataclass
import math

import numpy as np

#: A pose's covariance is positive definite when every eigenvalue of its
#: correlation matrix (the diagonal scaled to 1) exceeds this.
MIN_SCALED_EIGENVALUE = 1e-9


@dataclass
class Pose:
    """A stamped pose in a frame: x, y (m), yaw (rad), cov 3x3 (x, y, yaw)."""

    stamp: float
    frame: str
    xy: np.ndarray
    yaw: float
    cov: np.ndarray

    @classmethod
    def of(cls, stamp, frame, xy, yaw, cov):
        """Return a Pose of plain values (floats, float arrays)."""
        return cls(float(stamp), frame, np.asarray(xy, np.float64),
                   float(yaw), np.asarray(cov, np.float64))

    @property
    def sd(self):
        """Return the position's largest standard deviation (m)."""
        (a, _), (b, c) = self.cov[:2, :2].tolist()   # lower triangle
        return math.sqrt((a + c) / 2 + math.hypot((a - c) / 2, b))

    @property
    def yaw_sd(self):
        """Return the yaw's standard deviation (rad)."""
        return math.sqrt(self.cov[2, 2])


def pose_problem(stamp, xy, yaw, cov):
    """
    Return why a pose cannot be judged, or None.

    ``cov``: 3x3 over x, y, yaw; it must be finite, symmetric and positive
    definite (the yaw's variance may be huge: unknown).
    """
    values = [stamp, *np.ravel(xy), yaw]
    if not all(map(math.isfinite, values)):
        return (f'stamp, x, y, yaw = {stamp}, {", ".join(map(str, xy))}, '
                f'{yaw} is not finite')
    cov = np.asarray(cov, np.float64)
    if cov.shape != (3, 3) or not np.isfinite(cov).all():
        return f'covariance {np.round(cov, 6).tolist()} is not finite'
    c = cov.tolist()    # plain floats: this runs on every pose
    if any(abs(c[i][j] - c[j][i]) > 1e-9 + 1e-6 * abs(c[j][i])
           for i, j in ((0, 1), (0, 2), (1, 2), (1, 0), (2, 0), (2, 1))):
        return f'covariance {np.round(cov, 6).tolist()} is not symmetric'
    if not (min(c[0][0], c[1][1], c[2][2]) > 0 and
            _above(c, MIN_SCALED_EIGENVALUE)):
        # the yaw row scaled to 1, so an unknown yaw (1e6) does not swamp x, y
        scale = 1 / np.sqrt(np.maximum(np.diag(cov), 1e-300))
        low = float(np.linalg.eigvalsh(cov * np.outer(scale, scale)).min())
        return (f'covariance x, y, yaw diagonal {np.diag(cov).tolist()} is '
                f'not positive definite (smallest scaled eigenvalue '
                f'{low:.3g})')
    return None


def _above(c, floor):
    """
    Return True if every eigenvalue of the correlation matrix of c > floor.

    ``c``: a symmetric 3x3 (nested lists) with a positive diagonal; scaled
    to a unit diagonal (so an unknown yaw, 1e6, does not swamp x, y), its
    eigenvalues all exceed ``floor`` when the pivots of its LDL'
    factorisation less ``floor`` on the diagonal are all positive.
    """
    s = [1 / math.sqrt(c[i][i]) for i in range(3)]
    a = [[c[i][j] * s[i] * s[j] - floor * (i == j) for j in range(3)]
         for i in range(3)]
    d0 = a[0][0]
    if d0 <= 0:
        return False
    d1 = a[1][1] - a[1][0] ** 2 / d0
    if d1 <= 0:
        return False
    r = a[2][1] - a[2][0] * a[1][0] / d0
    return a[2][2] - a[2][0] ** 2 / d0 - r ** 2 / d1 > 0


def coverage_is_valid(coverage):
    """Return True if a scan's coverage probability is in 0-1 or NaN (none)."""
    return math.isnan(coverage) or 0 <= coverage <= 1


def mismatch_is_valid(mismatch):
    """Return True if a scan's relative mismatch is finite >= 0 or NaN."""
    return math.isnan(mismatch) or 0 <= mismatch < math.inf


def scan_is_valid(stamp, xy, sigma, coverage, mismatch=math.nan):
    """
    Return True if a scan's stamp, x, y and sigma (m, >= 0) are finite.

    Its coverage probability and relative mismatch too must be valid
    (:func:`coverage_is_valid`, :func:`mismatch_is_valid`).
    """
    values = [stamp, *np.ravel(xy), sigma]
    return len(values) == 4 and all(map(math.isfinite, values)) and \
        sigma >= 0 and coverage_is_valid(coverage) and \
        mismatch_is_valid(mismatch)
