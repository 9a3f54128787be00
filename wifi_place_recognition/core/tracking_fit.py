"""
Choosing the tracker's parameters on labelled walks (numpy only).

The live filter is :mod:`.tracking`; this module fits its
:class:`~.tracking.TrackingParams` offline, for ``fit_tracking``:

- change rates (floor, building) from the walks' labels and timestamps;
- temperature and minimum interval on the model's class probabilities
  over the walks (walks the model did not train on);
- with positions in the model and the walks: the motion model.

:func:`walk_evidence` computes what the fit needs from a model and a
fingerprint set; :func:`fit_tracking` fits all of it.
"""

from dataclasses import dataclass, replace
import math

import numpy as np

from .evaluation import align
from .tracking import (DEFAULT_TIMEOUT, PlaceTracker, PositionFilter,
                       track_walk, TrackingParams)

#: Log belief of the true class counted at worst (one confident miss).
LOG_FLOOR = math.log(1e-6)
#: The grids searched.
TEMPERATURES = (1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0)
MIN_INTERVALS = (0.0, 5.0, 20.0, 60.0, 200.0)
ACCELERATIONS = (0.001, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0)


# rates, evidence, motion ----------------------------------------------------
def _rate_mle(dt, changed):
    """
    Return the rate of ``P(change in dt) = 1 - exp(-rate dt)`` (MLE).

    With no change at all, half a change over the total time is assumed
    (a change is possible, just rarer than the data can show).
    """
    dt = np.asarray(dt, np.float64)
    changed = np.asarray(changed, bool)
    total = dt.sum()
    if total <= 0:
        raise ValueError('walks span no time: cannot fit change rates')
    if not changed.any():
        return 0.5 / total
    if changed.all():
        raise ValueError('every consecutive pair of scans changes place: '
                         'cannot fit change rates')
    d_change, stay = dt[changed], dt[~changed].sum()

    def slope(rate):    # derivative of the log-likelihood, decreasing
        x = rate * d_change
        return float(np.sum(d_change / np.expm1(np.maximum(x, 1e-300)))
                     - stay)
    low, high = 1e-12, 1e3
    for _ in range(200):
        mid = math.sqrt(low * high)
        if slope(mid) > 0:
            low = mid
        else:
            high = mid
    return math.sqrt(low * high)


def fit_rates(walks, timeout=DEFAULT_TIMEOUT):
    """
    Fit ``floor_rate`` and ``building_rate`` on labelled walks.

    ``walks`` is an iterable of (times, building, floor) arrays in time
    order. Consecutive pairs further apart than ``timeout`` are left out
    (the tracker restarts there). Return (floor_rate, building_rate,
    summary dict).
    """
    dts, building_changed, floor_changed = [], [], []
    for times, building, floor in walks:
        dt = np.diff(np.asarray(times, np.float64))
        keep = (dt >= 0) & (dt <= timeout)
        b = np.diff(np.asarray(building)) != 0
        f = np.diff(np.asarray(floor)) != 0
        dts.append(dt[keep])
        building_changed.append(b[keep])
        floor_changed.append((f & ~b)[keep])
    dt = np.concatenate(dts)
    b = np.concatenate(building_changed)
    f = np.concatenate(floor_changed)
    building_rate = _rate_mle(dt, b)
    floor_rate = _rate_mle(dt[~b], f[~b])
    summary = {'pairs': int(len(dt)),
               'hours': round(float(dt.sum()) / 3600, 3),
               'floor_changes': int(f.sum()),
               'building_changes': int(b.sum())}
    return floor_rate, building_rate, summary


def filtered_scores(params, classes, walks, timeout=DEFAULT_TIMEOUT):
    """
    Return (mean log belief of the true class, accuracy) of tracked walks.

    ``walks`` is a list of (times, true class index, proba) in time order.
    """
    tracker = PlaceTracker(classes, params, timeout)
    log_sum, right, n = 0.0, 0, 0
    for times, truth, proba in walks:
        for track, t in zip(track_walk(tracker, times, proba), truth):
            log_sum += max(math.log(max(track.belief[t], 1e-300)),
                           LOG_FLOOR)
            right += track.index == t
            n += 1
    return log_sum / n, right / n


def fit_evidence(params, classes, walks,
                 temperatures=TEMPERATURES, min_intervals=MIN_INTERVALS,
                 timeout=DEFAULT_TIMEOUT):
    """
    Choose ``temperature`` and ``min_interval`` on walks (grid search).

    ``walks`` as for :func:`filtered_scores`, with probabilities from a
    model that did not train on them. The choice is the best tracked
    accuracy (the answer the node publishes), ties broken by the mean log
    belief of the true class (a proper score: it rewards a belief that is
    right and confident, and punishes one that is confidently wrong).
    Return (params with the choice, grid as a list of dicts).
    """
    grid = []
    for temperature in temperatures:
        for min_interval in min_intervals:
            candidate = replace(params, temperature=temperature,
                                min_interval=min_interval)
            score, accuracy = filtered_scores(candidate, classes, walks,
                                              timeout)
            grid.append({'temperature': temperature,
                         'min_interval': min_interval,
                         'accuracy': round(accuracy, 6),
                         'mean_log_belief': round(score, 6)})
    best = max(grid, key=lambda g: (g['accuracy'], g['mean_log_belief']))
    return replace(params, temperature=best['temperature'],
                   min_interval=best['min_interval']), grid


def _tracked_position_error(params, walks, timeout):
    """Return the mean error (m) of the filtered positions of ``walks``."""
    track = PositionFilter(params)
    total, n = 0.0, 0
    for times, xy, cov, truth in walks:
        track.reset()
        last = None
        for t, z, c, true in zip(times, xy, cov, truth):
            if last is not None and 0 <= t - last <= timeout:
                track.predict(t - last)
            else:
                track.reset()
            track.update(z, c)
            total += math.hypot(track.state[0] - true[0],
                                track.state[1] - true[1])
            n += 1
            last = t
    return total / n


def fit_motion(params, walks, timeout=DEFAULT_TIMEOUT,
               accelerations=ACCELERATIONS):
    """
    Choose ``speed_sd`` and ``acceleration_noise`` on walks with positions.

    ``walks``: list of (times, predicted xy (n, 2), their cov (n, 2, 2),
    true xy (n, 2)), predictions from a model that did not train on them.
    ``speed_sd`` is the root mean square true speed per axis between
    consecutive scans; ``acceleration_noise`` the grid value whose filtered
    positions have the smallest mean error (single-scan position errors of
    neighbouring scans are alike, so the motion model that describes the
    true walk best is not the one that filters best). Return (params with
    the choice, grid as a list of dicts).
    """
    speeds = []
    for times, _, _, truth in walks:
        dt = np.diff(np.asarray(times, np.float64))
        keep = dt > 0
        speeds.append((np.diff(np.asarray(truth, np.float64), axis=0)[keep]
                       / dt[keep, None]).ravel())
    speeds = np.concatenate(speeds) if speeds else np.empty(0)
    if not len(speeds):
        raise ValueError('no consecutive scans with positions')
    base = replace(params, speed_sd=float(np.sqrt(np.mean(speeds ** 2))))
    grid = [{'acceleration_noise': a, 'mean_error_m': round(
        _tracked_position_error(replace(base, acceleration_noise=a), walks,
                                timeout), 4)} for a in accelerations]
    best = min(grid, key=lambda g: g['mean_error_m'])
    return replace(base, acceleration_noise=best['acceleration_noise']), grid


# from a model and fingerprints ---------------------------------------------
@dataclass(frozen=True)
class FitOptions:
    """What :func:`fit_tracking` searches (grids) and its restart gap."""

    timeout: float = DEFAULT_TIMEOUT
    temperatures: tuple = TEMPERATURES
    min_intervals: tuple = MIN_INTERVALS
    accelerations: tuple = ACCELERATIONS


@dataclass(frozen=True)
class WalkEvidence:
    """
    A model's single-scan answers over labelled walks.

    Arrays are by scan of the fingerprint set: ``times`` (n,), ``truth``
    (n,) the row of the true class in ``classes`` (-1: a class the model
    lacks), ``proba`` (n, k) (NaN rows: scans the model cannot use), and
    with positions ``xy`` (n, 2), ``cov`` (n, 2, 2), ``true_xy`` (n, 2)
    (else None). ``walks``: index arrays of usable scans, in time order.
    """

    classes: np.ndarray
    times: np.ndarray
    truth: np.ndarray
    proba: np.ndarray
    walks: list
    xy: np.ndarray = None
    cov: np.ndarray = None
    true_xy: np.ndarray = None


def class_rows(classes, building, floor):
    """Return the row in ``classes`` of each (building, floor) (-1: none)."""
    index = {(int(b), int(f)): i for i, (b, f) in enumerate(classes)}
    return np.array([index.get((int(b), int(f)), -1)
                     for b, f in zip(building, floor)], np.int64)


def walk_evidence(model, fp, walks):
    """
    Return the :class:`WalkEvidence` of ``model`` on ``fp``'s ``walks``.

    ``walks`` are index arrays in time order (``data.walks.walks``); ``fp``
    needs labels and a TIMESTAMP. Scans that detect no AP known to the model
    (the node rejects them) are left out of the walks.
    """
    rssi = align(model, fp)
    usable = np.isfinite(rssi).any(axis=1)
    proba = np.full((len(fp), len(model.classes)), np.nan)
    xy = cov = true_xy = None
    if model.position is None:
        proba[usable] = model.predict_proba(rssi[usable])
    else:
        xy = np.full((len(fp), 2), np.nan)
        sigma = np.full(len(fp), np.nan)
        proba[usable], xy[usable], sigma[usable] = \
            model.predict_positions(rssi[usable])
        cov = sigma[:, None, None] ** 2 * np.eye(2)
        true_xy = fp.position
    return WalkEvidence(
        np.asarray(model.classes), np.asarray(fp.meta['TIMESTAMP'],
                                              np.float64),
        class_rows(model.classes, fp.building, fp.floor), proba,
        [w[usable[w]] for w in walks], xy, cov, true_xy)


def fit_tracking(evidence, options=FitOptions()):
    """
    Fit every tracking parameter on ``evidence``; return (params, report).

    Raise ValueError naming what is wrong when the walks cannot fit them:
    labels the model does not know, or no two scans of a walk within
    ``options.timeout`` of each other. ``report['summary']`` holds the
    walks' figures (scans, rates, single-scan and tracked building+floor
    accuracy with the choice), the rest the grids searched.
    """
    e = evidence
    lacking = [w for w in e.walks if (e.truth[w] < 0).any()]
    if lacking:
        rows = np.concatenate([w[e.truth[w] < 0] for w in lacking])
        raise ValueError(f'{len(rows)} scans have a building/floor the model '
                         f'does not know (first: row {int(rows[0])}): '
                         f'label the walks with the model\'s classes')
    gaps = [np.diff(e.times[w]) for w in e.walks]
    if not any(((g >= 0) & (g <= options.timeout)).any() for g in gaps):
        raise ValueError(
            f'no two scans of a walk are within {options.timeout:g} s of '
            f'each other ({len(e.walks)} walk(s), '
            f'{sum(len(w) for w in e.walks)} usable scans): record walks '
            f'of several scans')
    floor_rate, building_rate, rates = fit_rates(
        [(e.times[w], e.classes[e.truth[w], 0], e.classes[e.truth[w], 1])
         for w in e.walks], options.timeout)
    params = TrackingParams(floor_rate=floor_rate,
                            building_rate=building_rate)
    params, grid = fit_evidence(
        params, e.classes, [(e.times[w], e.truth[w], e.proba[w])
                            for w in e.walks],
        options.temperatures, options.min_intervals, options.timeout)
    chosen = [g for g in grid if g['temperature'] == params.temperature
              and g['min_interval'] == params.min_interval][0]
    scans = np.concatenate(e.walks)
    summary = {'walks': len(e.walks), 'scans': int(len(scans)),
               'rates': rates,
               'single_accuracy': float(np.mean(
                   e.proba[scans].argmax(axis=1) == e.truth[scans])),
               'tracked_accuracy': chosen['accuracy']}
    report = {'summary': summary, 'evidence_grid': grid}
    if e.xy is not None and e.true_xy is not None:
        params, report['motion_grid'] = fit_motion(
            params, [(e.times[w], e.xy[w], e.cov[w], e.true_xy[w])
                     for w in e.walks], options.timeout,
            options.accelerations)
    return params, report
