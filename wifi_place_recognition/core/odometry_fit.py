"""
Fit the odometry's heading drift on a run with a true pose (numpy only).

A survey recorded with the robot's localiser running (``record_fingerprints``
with ``pose_topic`` and ``odom_topic``) holds, at every scan, the true pose
(x, y, yaw) and beside it the odometry. Over stretches of ``window_m``
metres of travel, the true turn minus the odometry's turn, per metre, is
the odometry's heading drift (wheel odometry often loses a steady angle per
metre); :func:`fit_odometry` returns :class:`.particles.FusionParams` with
that drift as the filter's prior, and a report of what it measured.
"""

from dataclasses import replace
import math

import numpy as np

from .particles import FusionParams

#: The least spread given to a fitted drift (rad per m).
MIN_DRIFT_SD = 0.005
#: Stretches needed for a fit.
MIN_WINDOWS = 3


class FitError(ValueError):
    """A run that cannot fit the odometry; the message says why."""


def fit_odometry(odometry, stamps, xy, yaw, params=None, window_m=3.0):
    """
    Return (params, report): ``params`` with the odometry's drift fitted.

    ``odometry``: (m, 4) rows of stamp, x, y, yaw in time order;
    ``stamps``, ``xy``, ``yaw``: the true poses (rows with NaN are left
    out). ``drift_mean`` becomes the total true-minus-odometry turn over
    the distance driven, ``drift_sd`` its standard error over the
    stretches (at least :data:`MIN_DRIFT_SD`).
    """
    params = params or FusionParams()
    odometry = np.asarray(odometry, np.float64)
    if odometry.ndim != 2 or odometry.shape[1] != 4 or \
            not np.isfinite(odometry).all():
        raise FitError('odometry: expected rows of finite stamp, x, y, yaw')
    if len(odometry) < 2 or (np.diff(odometry[:, 0]) < 0).any():
        raise FitError('odometry: need two or more poses in time order')
    stamps = np.asarray(stamps, np.float64)
    ok = np.isfinite(stamps) & np.isfinite(xy).all(axis=1) & \
        np.isfinite(yaw) & (stamps >= odometry[0, 0]) & \
        (stamps <= odometry[-1, 0])
    order = np.argsort(stamps[ok], kind='stable')    # rows in time order
    stamps, xy = stamps[ok][order], np.asarray(xy)[ok][order]
    yaw = np.asarray(yaw)[ok][order]
    t = odometry[:, 0]
    odo_yaw = np.interp(stamps, t, np.unwrap(odometry[:, 3]))
    odo_xy = np.column_stack([np.interp(stamps, t, odometry[:, 1]),
                              np.interp(stamps, t, odometry[:, 2])])
    true_yaw = np.unwrap(yaw)
    travelled = np.concatenate(
        [[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    odo_travelled = np.concatenate(
        [[0.0], np.cumsum(np.linalg.norm(np.diff(odo_xy, axis=0), axis=1))])
    edges = [0]
    for i in range(1, len(stamps)):
        if travelled[i] - travelled[edges[-1]] >= window_m:
            edges.append(i)
    if len(edges) - 1 < MIN_WINDOWS:
        raise FitError(f'the run covers {travelled[-1]:.1f} m with a true '
                       f'pose inside the odometry\'s time span: fitting '
                       f'needs {MIN_WINDOWS} stretches of {window_m:g} m')
    a, b = np.array(edges[:-1]), np.array(edges[1:])
    distance = travelled[b] - travelled[a]
    turn_error = (true_yaw[b] - true_yaw[a]) - (odo_yaw[b] - odo_yaw[a])
    rates = turn_error / distance
    drift = float(turn_error.sum() / distance.sum())
    spread = float(rates.std(ddof=1) / math.sqrt(len(rates)))
    fitted = replace(params, drift_mean=drift,
                     drift_sd=max(spread, MIN_DRIFT_SD),
                     fit={'method': 'fit_odometry', 'windows': len(rates),
                          'window_m': window_m})
    report = {'scans': int(len(stamps)),
              'distance_m': float(travelled[-1]),
              'odometry_distance_ratio': float(odo_travelled[-1] /
                                               travelled[-1]),
              'windows': int(len(rates)),
              'drift_deg_per_m': math.degrees(drift),
              'drift_sd_deg_per_m': math.degrees(fitted.drift_sd),
              'window_drift_deg_per_m_sd': math.degrees(
                  float(rates.std(ddof=1)))}
    return fitted, report
