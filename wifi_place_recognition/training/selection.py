"""
Choosing what the folds (or a validation set) can choose.

Each run fits its own scaler and network on the scans it keeps and scores
the scans it holds out after every epoch (the runs side by side, until
the mean curve stops rising): the epoch count is where the mean held-out
building+floor curve peaks. With positions, each held-out scan is then
placed among the kept scans of its predicted class: that chooses the
k-NN's signal, distance and k, and calibrates the position sigma per
class. Data of one class skips the networks.
"""

from dataclasses import dataclass, replace

import numpy as np
import torch

from ..core.coverage import (COVERED_M, distance_by_place,
                             features as coverage_features, unheard_share)
from ..core.evaluation import align
from ..core.locator import (calibrated_edge_sigma, calibrated_sigma,
                            Locator, METRICS)
from ..core.metrics import expected_calibration_error
from ..core.model import tempered
from ..core.preprocessing import signal, SIGNALS
from .config import SCOPES
from .fitting import best_epoch, config_scaler, training_epochs
from .folds import grouped_folds


#: k of the position k-NN that cross-validation chooses from.
NEIGHBOURS = (1, 3, 5, 7, 9, 11)


@dataclass
class _Split:
    """One selection run: scans to train on, scans to score."""

    fp: object              # the training Fingerprints
    all_y: np.ndarray       # their class indices
    keep: np.ndarray        # mask of the scans the network is trained on
    held_rssi: np.ndarray   # scans held out, on the training AP columns
    held_y: np.ndarray      # their class indices
    held_position: object   # their positions (n, 2), or None

    @property
    def y(self):
        """Return the class indices of the kept scans."""
        return self.all_y[self.keep]


def cross_validate(fp, y, n_classes, config, log=print):
    """
    Return the selection summary: per-fold curves, their mean, the choice.

    Each fold fits its own scaler and network on the scans it keeps and
    scores the groups it holds out after every epoch (building+floor
    accuracy). With positions, each held-out scan is then placed among the
    kept scans of the class predicted at the chosen epoch count: that
    chooses k and calibrates the position sigma per class.
    """
    y = np.asarray(y)
    config = replace(config, batch_size=config.batch_for(len(fp)))
    folds = grouped_folds(fp, y, config.folds, config.grouping, config.seed)
    log(f'cross-validation: {len(folds.held_out)} folds of whole '
        f'{folds.grouping} groups ({folds.groups} groups'
        + (f'; {folds.note}' if folds.note else '') + ')')
    splits = [_Split(fp, y, ~held, fp.rssi[held], y[held],
                     None if fp.position is None else fp.position[held])
              for held in folds.held_out]
    return dict(_select(splits, n_classes, config, log),
                grouping=folds.grouping, note=folds.note,
                groups=folds.groups, never_held_out=folds.never_held_out)


def validate(fp, y, classes, validation, config, log=print):
    """
    Return the selection summary of a separate validation set.

    As :func:`cross_validate`, with one run: the network trained on all of
    ``fp`` scores ``validation`` (Fingerprints of the same building(s))
    after every epoch. Its scans must belong to classes of ``fp``; scans
    without any AP known to ``fp`` are left out.
    """
    rssi = align(fp, validation)
    usable = ~np.isnan(rssi).all(axis=1)
    held_y = validation_classes(validation, classes)
    if not usable.any():
        raise ValueError(f'validation data {validation.source}: no scan '
                         f'detects an AP of the training data')
    position = None
    if fp.position is not None and validation.position is not None:
        if tuple(validation.position_columns) != tuple(fp.position_columns):
            raise ValueError(f'validation data {validation.source}: '
                             f'positions in columns '
                             f'{",".join(validation.position_columns)}, the '
                             f'training data\'s in '
                             f'{",".join(fp.position_columns)}')
        position = validation.position[usable]
    log(f'selection on the validation data: {int(usable.sum())} scans '
        f'({int((~usable).sum())} without a known AP left out)')
    split = _Split(fp, np.asarray(y), np.ones(len(fp), bool), rssi[usable],
                   held_y[usable], position)
    return dict(_select([split], n_classes=len(classes), config=config,
                        log=log),
                grouping='validation', note=validation.source, groups=1,
                never_held_out=[])


def validation_classes(validation, classes):
    """Return each validation scan's class index; refuse an unknown class."""
    index = {(int(b), int(f)): i for i, (b, f) in enumerate(classes)}
    held_y = np.array([index.get((int(b), int(f)), -1) for b, f in
                       zip(validation.building, validation.floor)], np.int64)
    if (held_y < 0).any():
        b, f = (validation.building[held_y < 0][0],
                validation.floor[held_y < 0][0])
        raise ValueError(f'validation data {validation.source}: building '
                         f'{b} floor {f} ({int((held_y < 0).sum())} scans) '
                         f'is not in the training data (if --small-classes '
                         f'drop left it out, leave it out of the '
                         f'validation data too)')
    return held_y


def _select(splits, n_classes, config, log):
    """Train and score each split; return curves, the choice, positions."""
    fold_info = [{'held_out_scans': len(split.held_y),
                  'classes': sorted(set(split.held_y.tolist()))}
                 for split in splits]
    if n_classes == 1:      # nothing to classify: every scan is the class
        summary = {'folds': fold_info}
        predicted = [np.zeros(len(split.held_y), np.int64)
                     for split in splits]
    else:
        summary, predicted = _select_epochs(splits, n_classes, config, log)
        summary['folds'] = fold_info
    if all(s.fp.position is not None and s.held_position is not None
           for s in splits):
        summary.update(_cross_validate_position(splits, predicted,
                                                n_classes, config, log))
    return summary


def _select_epochs(splits, n_classes, config, log):
    """
    Return the epoch summary and each split's classes at that epoch.

    The splits' networks train side by side, an epoch at a time, until the
    peak of the smoothed mean held-out curve (the centre of its best
    3-epoch window) lies ``config.patience`` epochs back (or
    ``config.epochs`` are done).
    """
    runs = []
    for k, split in enumerate(splits):
        rssi = split.fp.rssi[split.keep]
        scaler = config_scaler(config).fit(rssi)
        held_out = (torch.from_numpy(scaler.transform(split.held_rssi)),
                    torch.from_numpy(split.held_y))
        log(f'fold {k + 1}/{len(splits)}: {len(rssi)} scans train, '
            f'{len(split.held_y)} held out')
        runs.append(training_epochs(
            rssi, torch.from_numpy(split.y), n_classes, scaler, config,
            config.fold_seed(k), held_out,
            lambda line, k=k: log(f'fold {k + 1}{line}'), most=config.epochs))
    predictions = [[] for _ in splits]
    for epoch in range(config.epochs):
        for run, predicted in zip(runs, predictions):
            predicted.append(next(run)[1])
        curves = np.array([[(c == split.held_y).mean() for c in predicted]
                           for split, predicted in zip(splits, predictions)])
        mean = curves.mean(axis=0)
        best = best_epoch(mean)
        if epoch - best >= config.patience:   # best: a window's centre
            log(f'the smoothed held-out mean peaked {config.patience} '
                f'epochs back, at {best + 1}: stopped after {epoch + 1}')
            break
    return ({'curves': np.round(curves, 5).tolist(),
             'mean_curve': np.round(mean, 5).tolist(), 'epochs': best + 1,
             'accuracy_mean': float(mean[best]),
             'accuracy_min': float(curves[:, best].min()),
             'accuracy_max': float(curves[:, best].max())},
            [predicted[best] for predicted in predictions])


def _cross_validate_position(splits, predicted, n_classes, config, log):
    """
    Return the chosen signal, distance and k, held-out errors, sigmas.

    Each held-out scan is placed among the kept scans of its predicted
    class in every candidate space; the space and k with the least mean
    error win, and their errors calibrate the sigma of each class: of
    the held-out scans within :data:`COVERED_M` of a kept scan of their
    class (a fold also holds out stretches no kept scan covers, which
    made the circle too wide where the robot is, inside the survey).
    Those off the survey calibrate how much an answer at the survey's
    edge is widened (:func:`.locator.calibrated_edge_sigma`; all
    held-out scans when fewer than :data:`MIN_COVERED` are off it).
    """
    ks = (config.neighbours,) if config.neighbours else NEIGHBOURS
    spaces = _spaces(config)
    errors, nearest = {}, {}
    for split, classes in zip(splits, predicted):
        keep = split.keep
        detected = [np.flatnonzero(~np.isnan(r)) for r in split.held_rssi]
        for rep, metric, scope in spaces:
            locator = Locator.build(
                split.fp.rssi[keep], split.y, split.fp.position[keep],
                n_classes, representation=rep, metric=metric,
                group=_groups(split.fp, split.all_y, n_classes, scope))
            xy, near = zip(*(locator.positions(locator.distances(
                cols, signal(rssi[cols], rep), c), ks, c)
                for rssi, cols, c in zip(split.held_rssi, detected,
                                         classes)))
            xy = np.array(xy)
            nearest.setdefault((rep, metric, scope), []).append(
                np.array(near))
            for i, k in enumerate(ks):
                errors.setdefault((rep, metric, scope, k), []).append(
                    np.linalg.norm(xy[:, i] - split.held_position, axis=1))
    mean = {key: float(np.nanmean(np.concatenate(e)))
            for key, e in errors.items()}
    best = min(mean, key=mean.get)
    rep, metric, scope, k = best
    error = np.concatenate(errors[best])
    placed = np.isfinite(error)
    calibrating = placed & np.concatenate([_covered(s) for s in splits])
    if calibrating.sum() < MIN_COVERED:
        calibrating = placed
    log(f'position: {metric} distance over the {rep} signal among the '
        f'{scope}\'s references, k={k}, held-out mean error '
        f'{mean[best]:.2f} m; sigma from {int(calibrating.sum())} of '
        f'{int(placed.sum())} held-out scans')
    sigma = calibrated_sigma(
        error[calibrating],
        np.concatenate(nearest[rep, metric, scope])[calibrating],
        np.concatenate(predicted)[calibrating], n_classes)
    examples, circle, mismatch = _held_out_answers(
        splits, predicted, n_classes, (rep, metric, scope), k, sigma)
    off = np.isfinite(circle[0]) & ~examples[1]
    which = 'off the survey'
    if off.sum() < MIN_COVERED:
        off, which = np.isfinite(circle[0]), 'placed (too few off the survey)'
    edge = calibrated_edge_sigma(*circle[:, off])
    log(f'position: an answer at the survey\'s edge widened by {edge:.2f} '
        f'm (calibrated on {int(off.sum())} held-out scans {which})')
    usual, judged = usual_mismatch(mismatch, examples[1])
    log(f'position: the usual mismatch on covered ground {usual:.2f} dB '
        f'(of {judged} held-out scans; 0: too few, not known)')
    return {'neighbours': k, 'position_representation': rep,
            'position_metric': metric, 'position_scope': scope,
            'position_mean_error_m': mean[best],
            'position_median_error_m': float(np.median(error[placed])),
            'sigma_calibration_scans': int(calibrating.sum()),
            'sigma_m': sigma.tolist(), 'edge_sigma_m': edge,
            'edge_calibration_scans': int(off.sum()),
            'usual_mismatch_db': usual, 'usual_mismatch_scans': judged,
            COVERAGE_EXAMPLES: examples}


#: The key of the selection summary that carries the held-out scans'
#: coverage features and labels to training (not kept in the model file).
COVERAGE_EXAMPLES = 'coverage_examples'


def _held_out_answers(splits, predicted, n_classes, space, k, sigma):
    """
    Return the held-out scans' coverage examples and circle figures.

    Each held-out scan placed among the kept scans of its fold, in the
    chosen space, with the calibrated sigma: (features, covered, fold)
    of every one (``features`` of
    :mod:`wifi_place_recognition.core.coverage`), the rows error (m),
    sigma (m) and one-sidedness of its answer (NaN where none), and its
    mismatch (dB, :meth:`.locator.Locator.mismatch`).
    """
    rep, metric, scope = space
    x, covered, fold, circle, mismatch = [], [], [], [], []
    for f, (split, classes) in enumerate(zip(splits, predicted)):
        keep = split.keep
        locator = Locator.build(
            split.fp.rssi[keep], split.y, split.fp.position[keep],
            n_classes, k, sigma, representation=rep, metric=metric,
            group=_groups(split.fp, split.all_y, n_classes, scope))
        for rssi, c, truth in zip(split.held_rssi, classes,
                                  split.held_position):
            cols = np.flatnonzero(~np.isnan(rssi))
            distance = locator.distances(cols, signal(rssi[cols], rep), c)
            x.append(coverage_features(locator, distance, c,
                                       unheard_share(locator, cols, c)))
            xy, scan_sigma = locator.weighted(distance, k, c)
            circle.append((float(np.linalg.norm(xy - truth)), scan_sigma,
                           locator.one_sidedness(xy, c)))
            mismatch.append(locator.mismatch(cols, rssi[cols], c, distance))
        covered.append(_covered(split))
        fold.append(np.full(len(split.held_y), f))
    return ((np.array(x), np.concatenate(covered), np.concatenate(fold)),
            np.array(circle, np.float64).reshape(-1, 3).T,
            np.array(mismatch, np.float64))


def usual_mismatch(mismatch, covered):
    """
    Return (the usual mismatch dB, of how many held-out scans).

    The median mismatch of the held-out scans on covered ground, at least
    :data:`MIN_USUAL_MISMATCH_DB`; 0 when fewer than :data:`MIN_COVERED`
    have one (not known: the filter then does not weigh scans by it).
    """
    judged = np.isfinite(mismatch) & np.asarray(covered, bool)
    if judged.sum() < MIN_COVERED:
        return 0.0, int(judged.sum())
    return (max(float(np.median(mismatch[judged])), MIN_USUAL_MISMATCH_DB),
            int(judged.sum()))


#: The least usual mismatch (dB) a survey is given. RSSI comes in 1 dB
#: steps and fades by several from one scan to the next: held-out scans
#: that repeat the kept ones more closely (a survey that scanned each
#: place many times in a row) would make every scan of another day sound
#: off. Every survey at hand learned 2.6 dB or more
#: (``benchmarks/coverage_check.py``), so this moves none of them.
MIN_USUAL_MISMATCH_DB = 2.0


#: The sigma is calibrated on held-out scans taken within COVERED_M of a
#: kept scan of their building/floor (the surveyed area, where a robot is
#: placed); unless fewer than MIN_COVERED are.
MIN_COVERED = 30


def _covered(split):
    """Return which held-out scans lie within COVERED_M of a kept one."""
    return distance_by_place(split.held_position, split.held_y,
                             split.fp.position[split.keep],
                             split.y) <= COVERED_M


def _groups(fp, y, n_classes, scope):
    """Return the reference group of each class for ``scope``."""
    if scope == 'floor':
        return np.arange(n_classes)
    building = np.zeros(n_classes, np.int64)
    building[y] = fp.building
    return np.unique(building, return_inverse=True)[1].reshape(-1)


def _spaces(config):
    """Return the (signal, distance, scope) the position CV chooses from."""
    signals = (config.position_representation,) \
        if config.position_representation else SIGNALS
    metrics = (config.position_metric,) if config.position_metric \
        else METRICS
    scopes = (config.position_scope,) if config.position_scope else SCOPES
    return [(r, m, s) for r in signals for m in metrics for s in scopes]


def reference_locator(fp, y, n_classes, selection):
    """Return the :class:`Locator` of ``fp`` (class ``y``) as selected."""
    return Locator.build(fp.rssi, y, fp.position, n_classes,
                         selection['neighbours'], selection['sigma_m'],
                         fp.position_columns,
                         selection['position_representation'],
                         selection['position_metric'],
                         _groups(fp, y, n_classes,
                                 selection['position_scope']),
                         selection['edge_sigma_m'],
                         selection['usual_mismatch_db'])


#: The temperatures :func:`fit_temperature` chooses from (bounds): it
#: never sharpens (a set of held-out scans all right would ask for 0).
TEMPERATURES = (1.0, 20.0)


def fit_temperature(log_proba, y):
    """
    Return the temperature T that best fits held-out scans.

    ``log_proba`` (n, k): log class probabilities of held-out scans of
    classes ``y``; T minimises the mean negative log-likelihood of
    softmax(log_proba / T) (convex in 1 / T: found by bisection of its
    slope), within :data:`TEMPERATURES`.
    """
    log_proba = np.asarray(log_proba, np.float64)
    own = log_proba[np.arange(len(y)), y]

    def rising(beta):       # the NLL grows with beta = 1 / T here
        z = beta * log_proba
        p = np.exp(z - z.max(axis=1, keepdims=True))
        p /= p.sum(axis=1, keepdims=True)
        return ((p * log_proba).sum(axis=1) - own).mean() > 0

    low, high = 1 / TEMPERATURES[1], 1 / TEMPERATURES[0]
    if not rising(high):
        return TEMPERATURES[0]
    if rising(low):
        return TEMPERATURES[1]
    for _ in range(60):
        beta = np.sqrt(low * high)
        if rising(beta):
            high = beta
        else:
            low = beta
    return float(1 / np.sqrt(low * high))


def calibrate(model, validation):
    """
    Return the temperature of ``model``'s probabilities, fitted on data.

    The model's own probabilities of the ``validation`` scans (those
    detecting an AP of the model; the whole ensemble, as deployed) fit a
    temperature on top of the model's (temperatures multiply); the
    summary also gives their negative log-likelihood and expected
    calibration error before and after.
    """
    rssi = align(model, validation)
    usable = ~np.isnan(rssi).all(axis=1)
    y = validation_classes(validation, model.classes)[usable]
    proba = model.predict_proba(rssi[usable])
    log_proba = np.log(np.maximum(proba, np.finfo(np.float64).tiny))
    temperature = fit_temperature(log_proba, y)
    summary = {'temperature': model.temperature * temperature, 'fitted_on':
               f'validation data {validation.source}',
               'scans': int(usable.sum())}
    for name, t in (('before', 1.0), ('after', temperature)):
        p = tempered(proba, t)
        summary[f'nll_{name}'] = float(-np.log(np.maximum(
            p[np.arange(len(y)), y], np.finfo(np.float64).tiny)).mean())
        summary[f'ece_{name}'] = expected_calibration_error(
            p.max(axis=1), p.argmax(axis=1) == y)
    return summary
