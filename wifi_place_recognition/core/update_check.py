"""
A candidate model against the model in use, and the APs that came and went.

A model rebuilt from the survey plus the scans a robot recorded since must
not be worse than the one in use where it matters now: on the newest
recorded scans, held out of its training (:func:`newest`). :func:`verdict`
compares the two models' scores (:func:`judged`): building+floor accuracy
on every held-out scan, mean position error on those taken where the
candidate learned (:func:`position_judges`), each with a small
tolerance. :func:`ap_changes` lists the APs of the model in use not heard
in the recorded scans for longer than a window (retired or moved: they
stop counting) and the APs heard that it does not know (new).
:func:`off_survey` says which recorded scans are new ground: whether an
update is worth building.
"""

from dataclasses import dataclass

import numpy as np

from .coverage import COVERED_M, distance_by_place
from .evaluation import evaluate
from .scan import normalize_ap_id

#: The share of the recorded scans held out (the newest).
HOLDOUT_SHARE = 0.2
#: Fewer held-out scans than this judge nothing.
MIN_HELD_OUT = 10
#: The scores a report keeps (those :func:`.evaluation.evaluate` has).
SCORES = ('samples', 'building_accuracy', 'building_floor_accuracy',
          'position_mean_error_m', 'position_median_error_m',
          'position_p95_error_m')


@dataclass(frozen=True)
class Tolerance:
    """How much worse than the model in use a candidate may be."""

    accuracy: float = 0.02      # building+floor accuracy it may lose
    position_m: float = 0.25    # metres of mean position error it may add


def newest(stamps, n, share=HOLDOUT_SHARE):
    """
    Return a boolean mask of the newest ``share`` of ``n`` scans.

    ``stamps``: the scans' times (s), or None for their order (the last
    rows newest). At least one scan is held out, at most all but one.
    """
    order = np.arange(n) if stamps is None else \
        np.argsort(np.asarray(stamps, np.float64), kind='stable')
    k = min(max(1, int(round(share * n))), max(n - 1, 1))
    mask = np.zeros(n, bool)
    mask[order[n - k:]] = True
    return mask


def scores(result):
    """Return the figures of an evaluation a report keeps."""
    return {k: result[k] for k in SCORES if k in result}


def verdict(in_use, candidate, tolerance=Tolerance()):
    """
    Return (acceptable, reason): the candidate's scores against the in-use.

    ``in_use``, ``candidate``: :func:`scores` on the same held-out scans.
    Refused: building+floor accuracy lower by more than the tolerance, a
    mean position error larger by more than the tolerance, or no position
    where the model in use has one.
    """
    worse = []
    a, b = in_use['building_floor_accuracy'], \
        candidate['building_floor_accuracy']
    if b < a - tolerance.accuracy:
        worse.append(f'building+floor accuracy {b:.4f} against {a:.4f} '
                     f'(tolerance {tolerance.accuracy})')
    key = 'position_mean_error_m'
    if key in in_use and key not in candidate:
        worse.append('no position output, the model in use has one')
    elif key in in_use and \
            candidate[key] > in_use[key] + tolerance.position_m:
        worse.append(f'mean position error {candidate[key]:.2f} m against '
                     f'{in_use[key]:.2f} m (tolerance '
                     f'{tolerance.position_m} m)')
    if worse:
        return False, 'worse than the model in use on the held-out scans: ' \
            + '; '.join(worse)
    return True, 'not worse than the model in use on the held-out scans'


def ap_changes(model_aps, recorded_aps, rssi, stamps, window_s):
    """
    Return the APs that went silent and the new ones, as a dict.

    ``model_aps``: the model in use's AP identifiers; ``recorded_aps``,
    ``rssi`` (n, m; NaN: not heard), ``stamps`` (n,) or None: the recorded
    scans. ``silent``: the model's APs not heard in the last ``window_s``
    seconds of the recording (each with when it was last heard, None:
    never), judged only when the recording spans the window; ``new``: APs
    heard that the model does not have.
    """
    heard = np.isfinite(rssi)
    index = {}
    for j, ap in enumerate(recorded_aps):
        index.setdefault(normalize_ap_id(ap), []).append(j)
    known = {normalize_ap_id(ap) for ap in model_aps}
    new = sorted(ap for ap in recorded_aps
                 if normalize_ap_id(ap) not in known and
                 heard[:, index[normalize_ap_id(ap)]].any())
    result = {'window_s': window_s, 'recorded_span_s': None,
              'silent': [], 'new': new}
    if stamps is None or not len(stamps):
        result['note'] = 'the recorded scans have no times: silent APs ' \
            'not judged'
        return result
    stamps = np.asarray(stamps, np.float64)
    end = float(stamps.max())
    result['recorded_span_s'] = end - float(stamps.min())
    if result['recorded_span_s'] < window_s:
        result['note'] = 'the recording spans less than the window: ' \
            'silent APs not judged'
        return result
    for ap in model_aps:
        columns = index.get(normalize_ap_id(ap), [])
        times = stamps[heard[:, columns].any(axis=1)] if columns else []
        last = float(times.max()) if len(times) else None
        if last is None or last < end - window_s:
            result['silent'].append({'ap': ap, 'last_heard': last})
    return result


def off_survey(recorded, survey):
    """
    Return which recorded scans are new ground (a boolean mask).

    Farther than :data:`.coverage.COVERED_M` from every survey scan of
    their building and floor. ``recorded``, ``survey``: fingerprints with
    positions (``building``, ``floor``, ``position``).
    """
    for name, scans in (('recorded', recorded), ('survey', survey)):
        if scans.position is None:
            raise ValueError(f'the {name} scans have no positions (X, Y): '
                             f'new ground cannot be told')
    return distance_by_place(
        recorded.position, np.column_stack([recorded.building,
                                            recorded.floor]),
        survey.position, np.column_stack([survey.building,
                                          survey.floor])) > COVERED_M


def position_judges(held, learned):
    """
    Return which held-out scans judge the position (a boolean mask).

    Those within :data:`.coverage.COVERED_M` of a scan of their building
    and floor the candidate learned from (``learned``: fingerprints, the
    survey and the recorded scans it was trained on): elsewhere neither
    model has been and their errors there differ by chance (a stretch the
    robot drove only at the end of its recording). All of them when fewer
    than :data:`MIN_HELD_OUT` are, or without positions.
    """
    n = len(held.building)
    if held.position is None or any(p.position is None for p in learned):
        return np.ones(n, bool)
    mask = np.zeros(n, bool)
    for part in learned:
        mask |= ~off_survey(held, part)
    return mask if mask.sum() >= MIN_HELD_OUT else np.ones(n, bool)


def judged(model, held, judges):
    """
    Return the scores of ``model`` on the held-out scans.

    Building and floor on all of ``held``, the position on those of the
    mask ``judges`` (:func:`position_judges`).
    """
    out = scores(evaluate(model, held))
    if judges.all():
        return out
    where = scores(evaluate(model, held.subset(judges)))
    out.update({k: v for k, v in where.items() if k.startswith('position')})
    out['position_samples'] = int(judges.sum())
    return out
