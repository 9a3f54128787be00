"""
Training the SAE + classifier with torch (Nowicki & Wietrzykowski, 2017).

Each network's encoder is first trained as a stacked autoencoder on
reconstruction; the decoder is dropped, a classifier (softmax over every
building/floor class seen) is put on top and the whole network fine-tuned
with cross-entropy and Adam. How many epochs is chosen by grouped K-fold
cross-validation (:mod:`.selection`): one curve of held-out building+floor
accuracy per fold, the epoch count where their mean peaks; or by the curve
of a separate validation set. Then the ensemble's members are trained on
all scans for that many epochs.
"""

import contextlib
import time
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
from torch import nn

from ..core.metrics import class_index
from ..core.locator import calibrated_sigma, Locator
from ..core.model import PlaceModel
from ..core.preprocessing import RssiScaler
from ..core.scan import ScanMapper
from ..data.fingerprints import check_trainable
from .augment import ScanAugmenter
from .network import PlaceNet, SparseBatch
from .selection import grouped_folds


@dataclass
class TrainReport:
    """What happened during training, for the summary and provenance."""

    epochs: int = 0               # fine-tuning epochs of the members
    selection: dict = field(default_factory=dict)  # folds or validation
    train_samples: int = 0
    dropped_empty: int = 0
    seconds: float = 0.0


@contextlib.contextmanager
def _torch_state(threads, seed):
    """Seed torch (and set its threads) inside, restore both after."""
    before = torch.get_num_threads()
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        if threads:
            torch.set_num_threads(threads)
        try:
            yield
        finally:
            torch.set_num_threads(before)


class _Inputs:
    """
    Network inputs of the training scans, augmented anew each epoch.

    Kept sparse (the detected readings, relative to a scan that detects
    nothing): an epoch's augmentation and scaling touch a few dozen
    readings per scan, and batches are :class:`SparseBatch`.
    """

    def __init__(self, rssi, scaler, config, seed):
        self.scaler = scaler
        self.n = len(rssi)
        self.blank = scaler.blank()
        self.augmenter = ScanAugmenter(rssi, config, seed) \
            if config.augmenting else None
        if self.augmenter is None:
            rows, cols = np.nonzero(~np.isnan(rssi))
            self.fixed = self._entries(rows, cols, rssi[rows, cols])
        self.batch_size = config.batch_size
        self.generator = torch.Generator().manual_seed(seed)

    def _entries(self, rows, cols, dbm):
        """Return (row starts, columns, relative inputs) of sorted readings."""
        starts = np.searchsorted(rows, np.arange(self.n + 1))
        inputs = self.scaler.transform(dbm, cols) - self.blank[cols]
        return starts, cols.astype(np.int64), inputs.astype(np.float32)

    def epoch(self):
        """Yield (indices, SparseBatch) mini-batches of one shuffled epoch."""
        starts, cols, inputs = self.fixed if self.augmenter is None else \
            self._entries(*self.augmenter.readings())
        blank = torch.from_numpy(self.blank)
        order = torch.randperm(self.n, generator=self.generator)
        for idx in torch.split(order, self.batch_size):
            first = starts[idx.numpy()]
            lengths = starts[idx.numpy() + 1] - first
            entries = _ranges(first, lengths)
            offsets = np.cumsum(lengths) - lengths
            yield idx, SparseBatch(torch.from_numpy(cols[entries]),
                                   torch.from_numpy(offsets),
                                   torch.from_numpy(inputs[entries]), blank)


def _ranges(starts, lengths):
    """Return the indices of the ranges [start, start + length), joined."""
    offsets = np.cumsum(lengths) - lengths
    return np.repeat(starts - offsets, lengths) + np.arange(lengths.sum())


def _predicted(net, x, proba):
    """Return the classes ``net`` predicts for ``x`` (or probabilities)."""
    net.eval()
    with torch.no_grad():
        logits = net(x)
        out = torch.softmax(logits, dim=1) if proba else logits.argmax(dim=1)
    net.train()
    return out.numpy()


def fit_network(rssi, y, n_classes, scaler, config, epochs, seed,
                held_out=None, log=print, proba=False):
    """
    Train one network on ``rssi`` (NaN = not detected) and class indices.

    With ``held_out`` = (inputs, class indices), also return the held-out
    predicted classes after every epoch (with ``proba``, their class
    probabilities). Returns (net, [per-epoch arrays]).
    """
    with _torch_state(config.threads, seed):
        inputs = _Inputs(rssi, scaler, config, seed)
        net = PlaceNet(rssi.shape[1], n_classes, config)
        sae = net.autoencoder()
        optimiser = torch.optim.Adam(sae.parameters(),
                                     lr=config.learning_rate)
        for epoch in range(1, config.sae_epochs + 1):
            total = 0.0
            for _, x in inputs.epoch():
                optimiser.zero_grad()
                loss = nn.functional.mse_loss(sae(x), x.dense())
                loss.backward()
                optimiser.step()
                total += loss.item() * len(x.offsets)
            log(f'  sae epoch {epoch:3d}/{config.sae_epochs}  '
                f'reconstruction mse {total / len(rssi):.4f}')
        optimiser = torch.optim.Adam(net.parameters(),
                                     lr=config.learning_rate)
        predictions = []
        for epoch in range(1, epochs + 1):
            total = 0.0
            for idx, x in inputs.epoch():
                optimiser.zero_grad()
                loss = nn.functional.cross_entropy(net(x), y[idx])
                loss.backward()
                optimiser.step()
                total += loss.item() * len(idx)
            line = f'  epoch {epoch:3d}/{epochs}  loss {total / len(rssi):.4f}'
            if held_out is not None:
                predictions.append(_predicted(net, held_out[0], proba))
                classes = predictions[-1].argmax(axis=1) if proba else \
                    predictions[-1]
                right = (classes == held_out[1].numpy()).mean()
                line += f'  held-out building+floor {right:.4f}'
            log(line)
        net.eval()
    return net, predictions


def best_epoch(mean, window=3):
    """
    Return the index of the best epoch of a mean held-out curve.

    The curve is smoothed over ``window`` epochs first: single epochs move
    by more than the curve does over many (fold and epoch noise).
    """
    if len(mean) < window:
        return int(np.argmax(mean))
    smooth = np.convolve(mean, np.ones(window) / window, mode='valid')
    return int(np.argmax(smooth)) + window // 2


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
        locator = _locator(split.kept, split.y, n_classes, scaler)
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


def _locator(fp, y, n_classes, scaler, neighbours=5, sigma=None):
    """Return a :class:`Locator` of the scans of ``fp`` (class ``y``)."""
    return Locator.build(_relative(fp.rssi, scaler), y, fp.position,
                         n_classes, neighbours, sigma, fp.position_columns)


def config_scaler(config):
    """Return the (unfitted) scaler of a training configuration."""
    return RssiScaler(config.not_detected, config.scaling,
                      config.representation)


def train(fp, config, log=print, validation=None):
    """
    Train on :class:`Fingerprints`; return (PlaceModel, nets, report).

    The epoch count (and the position's k and sigma) is chosen on
    ``validation`` (Fingerprints) when given, else by grouped
    cross-validation with ``config.folds``, else ``config.epochs`` is
    used; then ``config.ensemble`` networks (seeds ``seed``, ``seed + 1``
    …) are trained on all scans of ``fp``.
    """
    start = time.perf_counter()
    check_trainable(fp)
    report = TrainReport()
    usable = ~fp.empty_rows
    report.dropped_empty = int((~usable).sum())
    fp = fp.subset(usable)
    report.train_samples = len(fp)
    classes, y = class_index(fp.building, fp.floor)
    y = torch.from_numpy(y)
    report.epochs = config.epochs
    if validation is not None:
        report.selection = validate(fp, y.numpy(), classes, validation,
                                    config, log)
    elif config.folds:
        report.selection = cross_validate(fp, y, len(classes), config, log)
    if report.selection:
        report.epochs = report.selection['epochs']
        s = report.selection
        log(f'held-out building+floor {s["accuracy_mean"]:.4f} '
            + (f'({s["accuracy_min"]:.4f}-{s["accuracy_max"]:.4f} over '
               f'folds) ' if len(s['folds']) > 1 else '')
            + f'at {report.epochs} epochs')
    scaler = config_scaler(config).fit(fp.rssi)
    nets = []
    for k in range(config.ensemble):
        log(f'member {k + 1}/{config.ensemble}: all {len(fp)} scans, '
            f'{report.epochs} epochs')
        nets.append(fit_network(fp.rssi, y, len(classes), scaler, config,
                                report.epochs, config.seed + k,
                                log=log)[0])
    position = None
    if fp.position is not None and 'sigma_m' in report.selection:
        position = _locator(fp, y.numpy(), len(classes), scaler,
                            report.selection['neighbours'],
                            report.selection['sigma_m'])
    elif fp.position is not None:
        log('no position output: its uncertainty is calibrated on held-out '
            'scans with positions (none with folds 0, or validation data '
            'without positions)')
    report.seconds = time.perf_counter() - start
    provenance = {
        'config': asdict(config),
        'training_data': {'source': fp.source, 'sha256': fp.sha256,
                          'scans': len(fp), 'dropped_empty':
                          report.dropped_empty, 'clipped_cells': fp.clipped},
        'selection': {k: v for k, v in report.selection.items()
                      if k != 'curves'},
        'validation_data': None if validation is None else {
            'source': validation.source, 'sha256': validation.sha256,
            'scans': len(validation)},
        'epochs': report.epochs,
        'train_seconds': round(report.seconds, 2),
        'versions': {'torch': torch.__version__, 'numpy': np.__version__},
        'created': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime()),
    }
    model = PlaceModel(fp.ap_ids, scaler,
                       [net.frozen_layers() for net in nets], classes,
                       provenance, position=position)
    return model, nets, report
