"""
Choosing what the folds (or a validation set) can choose.

Each run fits its own scaler and network on the scans it keeps and scores
the scans it holds out after every epoch: the epoch count is where the
mean held-out building+floor curve peaks. With positions, each held-out
scan is then placed among the kept scans of its predicted class: that
chooses the k-NN's k and calibrates the position sigma per class.
"""

from dataclasses import dataclass

import numpy as np
import torch

from ..core.locator import calibrated_sigma, Locator
from ..core.scan import ScanMapper
from .fitting import best_epoch, config_scaler, fit_network
from .folds import grouped_folds


#: k of the position k-NN that cross-validation chooses from.
NEIGHBOURS = (3, 5, 7, 10)


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
    def kept(self):
        """Return the Fingerprints trained on (a copy: made when needed)."""
        return self.fp.subset(self.keep)

    @property
    def y(self):
        """Return the class indices of :attr:`kept`."""
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
    rssi = ScanMapper(fp.ap_ids).map_rows(validation.ap_ids, validation.rssi)
    usable = ~np.isnan(rssi).all(axis=1)
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


def _select(splits, n_classes, config, log):
    """Train and score each split; return curves, the choice, positions."""
    runs, fold_info = [], []
    for k, split in enumerate(splits):
        rssi = split.fp.rssi[split.keep]
        scaler = config_scaler(config).fit(rssi)
        held_out = (torch.from_numpy(scaler.transform(split.held_rssi)),
                    torch.from_numpy(split.held_y))
        log(f'fold {k + 1}/{len(splits)}: {len(rssi)} scans train, '
            f'{len(split.held_y)} held out')
        _, predictions = fit_network(
            rssi, torch.from_numpy(split.y), n_classes, scaler, config,
            config.epochs, config.seed + 1000 * (k + 1), held_out, log)
        runs.append((scaler, predictions))
        fold_info.append({'held_out_scans': len(split.held_y),
                          'classes': sorted(set(split.held_y.tolist()))})
    curves = np.array([[(c == split.held_y).mean() for c in predictions]
                       for split, (_, predictions) in zip(splits, runs)])
    mean = curves.mean(axis=0)
    best = best_epoch(mean)
    summary = {'folds': fold_info, 'curves': np.round(curves, 5).tolist(),
               'mean_curve': np.round(mean, 5).tolist(), 'epochs': best + 1,
               'accuracy_mean': float(mean[best]),
               'accuracy_min': float(curves[:, best].min()),
               'accuracy_max': float(curves[:, best].max())}
    if all(s.fp.position is not None and s.held_position is not None
           for s in splits):
        summary.update(_cross_validate_position(
            splits, [(scaler, predictions[best])
                     for scaler, predictions in runs], n_classes, config,
            log))
    return summary


def _cross_validate_position(splits, runs, n_classes, config, log):
    """Return the chosen k, its held-out errors (m) and sigma per class."""
    candidates = (config.neighbours,) if config.neighbours else NEIGHBOURS
    errors = {k: [] for k in candidates}
    predicted = []
    for split, (scaler, classes) in zip(splits, runs):
        locator = reference_locator(split.kept, split.y, n_classes,
                                    scaler)
        inputs = _relative(split.held_rssi, scaler)
        distances = []
        for rssi, x, c in zip(split.held_rssi, inputs, classes):
            columns = np.flatnonzero(~np.isnan(rssi))
            distances.append(locator.distances(columns, x[columns], c))
        for k in candidates:
            xy = np.array([locator.weighted(d, k, c)[0]
                           for d, c in zip(distances, classes)])
            errors[k].append(np.linalg.norm(xy - split.held_position,
                                            axis=1))
        predicted.append(classes)
    mean = {k: float(np.nanmean(np.concatenate(e)))
            for k, e in errors.items()}
    k = min(mean, key=mean.get)
    error = np.concatenate(errors[k])
    placed = np.isfinite(error)
    log(f'position: k={k}, held-out mean error {mean[k]:.2f} m ('
        + ', '.join(f'k={n}: {e:.2f}' for n, e in mean.items()) + ')')
    return {'neighbours': k, 'position_mean_error_m': mean[k],
            'position_median_error_m': float(np.median(error[placed])),
            'sigma_m': calibrated_sigma(
                error[placed], np.concatenate(predicted)[placed],
                n_classes).tolist()}


def _relative(rssi, scaler):
    """Return inputs relative to an empty scan: 0 where nothing detected."""
    return scaler.transform(rssi) - scaler.blank()


def reference_locator(fp, y, n_classes, scaler, neighbours=5,
                      sigma=None):
    """Return a :class:`Locator` of the scans of ``fp`` (class ``y``)."""
    return Locator.build(_relative(fp.rssi, scaler), y, fp.position,
                         n_classes, neighbours, sigma, fp.position_columns)
