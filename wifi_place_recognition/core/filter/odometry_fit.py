"""
Fit the odometry's heading drift on a run with a true pose (numpy only).

A survey recorded with the robot's localiser running (``record_fingerprints``
with ``pose_topic`` and ``odom_topic``) holds, at every scan, the true pose
(x, y, yaw) and beside it the odometry. Over stretches of ``window_m``
metres of travel, the true turn minus the odometry's turn, per metre, is
the odometry's heading drift (wheel odometry often loses a steady angle per
metre); :func:`fit_odometry` returns :class:`.particles.FusionParams` with
that drift as the filter's prior, and a report of what it measured.
A stretch across a gap in the odometry longer than the node's default
``odom_timeout`` (the node does not bridge such a gap either) is left out
and counted: the odometry's turn over the gap is unknown. Between two scans
the true turn gains the whole turns that bring it nearest the odometry's,
so that a robot spinning more than half a turn between slow scans adds no
whole turn of error. Over the stretches in which either turns, the two
turns must agree once the fitted drift is added back.
"""

from dataclasses import replace
import math

import numpy as np

from .angles import TWO_PI, wrap
from .fusion import FusionLimits
from .particles import FusionParams
from .trajectory import inside_span, time_span

#: The least spread given to a fitted drift (rad per m).
MIN_DRIFT_SD = 0.005
#: Stretches needed for a fit.
MIN_WINDOWS = 3
#: The longest odometry gap a stretch may span (s): the node's default
#: ``odom_timeout``.
MAX_GAP_S = FusionLimits().odom_timeout
#: The odometry's distance over the true one, and its drift (rad per m),
#: beyond which it is not this run's odometry in metres and radians.
DISTANCE_RATIO, MAX_DRIFT = (0.5, 2.0), 0.5
#: Over the stretches in which the odometry or the truth turns at least
#: ``TURNING`` rad (when there are ``MIN_TURNS`` or more), the median of
#: how far the odometry's turn, the fitted drift added back, differs from
#: the true one (rad, wrapped) beyond which the two headings are not the
#: same run's in radians (degrees turn 57 times as far).
TURNING, MIN_TURNS, MAX_TURN_MISMATCH = 0.2, 3, 0.5


class FitError(ValueError):
    """A run that cannot fit the odometry; the message says why."""


def fit_odometry(odometry, stamps, xy, yaw, params=None, window_m=3.0,
                 names=('the scans', 'the odometry')):
    """
    Return (params, report): ``params`` with the odometry's drift fitted.

    ``odometry``: (m, 4) rows of stamp, x, y, yaw in time order;
    ``stamps``, ``xy``, ``yaw``: the true poses (rows with NaN are left
    out; finite ones outside the odometry's time span are left out and
    counted); ``names``: of the scans and the odometry, for messages.
    ``drift_mean`` becomes the total true-minus-odometry turn over the
    distance driven in the stretches that span no odometry gap longer
    than :data:`MAX_GAP_S`, ``drift_sd`` its standard error over them (at
    least :data:`MIN_DRIFT_SD`). Raises :class:`FitError` naming what is
    wrong: too few stretches, or odometry unlike the run's truth (its
    distance, its drift, or its turns over the stretches).
    """
    params = params or FusionParams()
    run, odometry_name = names
    odometry = np.asarray(odometry, np.float64)
    if odometry.ndim != 2 or odometry.shape[1] != 4 or \
            not np.isfinite(odometry).all():
        raise FitError(f'{odometry_name}: expected rows of finite stamp, x, '
                       f'y, yaw')
    if len(odometry) < 2 or (np.diff(odometry[:, 0]) < 0).any():
        raise FitError(f'{odometry_name}: need two or more poses in time '
                       f'order')
    stamps = np.asarray(stamps, np.float64)
    xy, yaw = np.asarray(xy, np.float64), np.asarray(yaw, np.float64)
    t = odometry[:, 0]
    posed = np.isfinite(stamps) & np.isfinite(xy).all(axis=1) & \
        np.isfinite(yaw)
    ok = posed & inside_span(stamps, t)
    outside = int(posed.sum() - ok.sum())
    spans = (f'{odometry_name} spans {time_span(t)}, the posed scans '
             f'{time_span(stamps[posed])}, {outside} of them outside')
    order = np.argsort(stamps[ok], kind='stable')    # rows in time order
    stamps, xy, yaw = stamps[ok][order], xy[ok][order], yaw[ok][order]
    gaps = np.flatnonzero(np.diff(t) > MAX_GAP_S)

    def across(lo, hi):     # from stamps lo to hi across an odometry gap
        return ((lo[:, None] < t[gaps + 1]) &
                (hi[:, None] > t[gaps])).any(axis=1)
    odo_yaw = np.interp(stamps, t, np.unwrap(odometry[:, 3]))
    odo_xy = np.column_stack([np.interp(stamps, t, odometry[:, 1]),
                              np.interp(stamps, t, odometry[:, 2])])
    steps = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    travelled = np.concatenate([[0.0], np.cumsum(steps)])
    across_gap = across(stamps[:-1], stamps[1:])
    true_yaw = _true_yaw(yaw, odo_yaw)
    odo_steps = np.linalg.norm(np.diff(odo_xy, axis=0), axis=1)
    edges = [0]
    for i in range(1, len(stamps)):
        if travelled[i] - travelled[edges[-1]] >= window_m:
            edges.append(i)
    a, b = np.array(edges[:-1], int), np.array(edges[1:], int)
    kept = ~across(stamps[a], stamps[b])
    skipped = int(len(a) - kept.sum())
    if kept.sum() < MIN_WINDOWS:
        gap_note = f'{skipped} stretch(es) across an odometry gap longer ' \
            f'than {MAX_GAP_S:g} s left out; ' if skipped else ''
        raise FitError(f'{run}: the run covers {travelled[-1]:.1f} m with '
                       f'a true pose inside the odometry\'s time span: '
                       f'{spans}; {gap_note}fitting needs {MIN_WINDOWS} '
                       f'stretches of {window_m:g} m')
    a, b = a[kept], b[kept]
    distance = travelled[b] - travelled[a]
    true_turn, odo_turn = true_yaw[b] - true_yaw[a], odo_yaw[b] - odo_yaw[a]
    turn_error = true_turn - odo_turn
    rates = turn_error / distance
    drift = float(turn_error.sum() / distance.sum())
    ratio = float(odo_steps[~across_gap].sum() / steps[~across_gap].sum())
    if not DISTANCE_RATIO[0] <= ratio <= DISTANCE_RATIO[1]:
        raise FitError(f'{odometry_name}: the odometry drove {ratio:.3g} '
                       f'times the true distance of {run} ({spans}): not '
                       f'this run\'s odometry, or not in metres (fitting '
                       f'needs {DISTANCE_RATIO[0]:g} to '
                       f'{DISTANCE_RATIO[1]:g})')
    _check_turns(true_turn, odo_turn, drift * distance, window_m, run,
                 odometry_name)
    if abs(drift) > MAX_DRIFT:
        raise FitError(f'{odometry_name}: its heading turns unlike the '
                       f'truth of {run} by {math.degrees(drift):.3g} deg '
                       f'per m: not this run\'s odometry, or its yaw not '
                       f'in radians (fitting needs at most '
                       f'{math.degrees(MAX_DRIFT):.3g})')
    spread = float(rates.std(ddof=1) / math.sqrt(len(rates)))
    fitted = replace(params, drift_mean=drift,
                     drift_sd=max(spread, MIN_DRIFT_SD),
                     fit={'method': 'fit_odometry', 'windows': len(rates),
                          'window_m': window_m})
    report = {'scans': int(len(stamps)),
              'scans_outside_odometry': outside,
              'distance_m': float(travelled[-1]),
              'odometry_distance_ratio': ratio,
              'windows': int(len(rates)),
              'windows_across_odometry_gaps': skipped,
              'odometry_gap_limit_s': MAX_GAP_S,
              'drift_deg_per_m': math.degrees(drift),
              'drift_sd_deg_per_m': math.degrees(fitted.drift_sd),
              'window_drift_deg_per_m_sd': math.degrees(
                  float(rates.std(ddof=1)))}
    return fitted, report


def _true_yaw(yaw, odo_yaw):
    """
    Return the true yaw unwrapped, whole turns added as the odometry says.

    Between two scans the true turn gains the whole turns that bring it
    nearest the odometry's (across an odometry gap that only shifts the
    yaw after it: no stretch spans one).
    """
    true_yaw = np.unwrap(yaw)
    turns = np.round((np.diff(odo_yaw) - np.diff(true_yaw)) / TWO_PI)
    return true_yaw + TWO_PI * np.concatenate([[0.0], np.cumsum(turns)])


def _check_turns(true_turn, odo_turn, drifted, window_m, run, odometry_name):
    """
    Refuse odometry whose stretches turn unlike the truth's.

    ``drifted``: each stretch's turn the fitted drift explains. Raises
    :class:`FitError` as :data:`MAX_TURN_MISMATCH` says.
    """
    turning = np.maximum(np.abs(true_turn), np.abs(odo_turn)) >= TURNING
    if turning.sum() < MIN_TURNS:
        return
    apart = float(np.median(np.abs(wrap(
        odo_turn + drifted - true_turn)[turning])))
    if apart <= MAX_TURN_MISMATCH:
        return
    mirrored = float(np.median(np.abs(wrap(odo_turn + true_turn)[turning])))
    why = 'the two turn opposite ways (one yaw is clockwise; REP 103: ' \
        'counter-clockwise is positive)' if mirrored <= MAX_TURN_MISMATCH \
        else 'not this run\'s odometry, or a yaw not in radians'
    raise FitError(
        f'{odometry_name}: in the {int(turning.sum())} stretches of '
        f'{window_m:g} m of {run} in which it or the truth turns '
        f'{TURNING:g} rad or more, its turn (the fitted drift added back) '
        f'differs from the true one by {math.degrees(apart):.3g} deg '
        f'(median): {why} (fitting needs at most '
        f'{math.degrees(MAX_TURN_MISMATCH):.3g})')
