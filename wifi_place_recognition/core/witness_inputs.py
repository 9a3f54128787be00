"""
The witness's inputs checked: a stamped pose, or why it cannot be judged.

Nothing here raises on input: a refused pose or scan comes back with a
reason (or None), which the caller counts.
"""

from dataclasses import dataclass
import math

import numpy as np


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
        return math.sqrt(max(np.linalg.eigvalsh(self.cov[:2, :2])))

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
    if not np.allclose(cov, cov.T, rtol=1e-6, atol=1e-9):
        return f'covariance {np.round(cov, 6).tolist()} is not symmetric'
    # the yaw row scaled to 1, so an unknown yaw (1e6) does not swamp x, y
    scale = 1 / np.sqrt(np.maximum(np.diag(cov), 1e-300))
    low = float(np.linalg.eigvalsh(cov * np.outer(scale, scale)).min())
    if not (np.diag(cov) > 0).all() or low <= 1e-9:
        return (f'covariance x, y, yaw diagonal {np.diag(cov).tolist()} is '
                f'not positive definite (smallest scaled eigenvalue '
                f'{low:.3g})')
    return None


def coverage_is_valid(coverage):
    """Return True if a scan's coverage probability is in 0-1 or NaN (none)."""
    return math.isnan(coverage) or 0 <= coverage <= 1


def scan_is_valid(stamp, xy, sigma, coverage):
    """
    Return True if a scan's stamp, x, y and sigma (m, >= 0) are finite.

    Its coverage probability too must be valid (:func:`coverage_is_valid`).
    """
    values = [stamp, *np.ravel(xy), sigma]
    return len(values) == 4 and all(map(math.isfinite, values)) and \
        sigma >= 0 and coverage_is_valid(coverage)
