"""
Training the SAE + classifier with torch (Nowicki & Wietrzykowski, 2017).

Each network's encoder is first trained as a stacked autoencoder on
reconstruction; the decoder is dropped, a classifier (softmax over every
building/floor class seen) is put on top and the whole network fine-tuned
with cross-entropy and Adam. How many epochs is chosen by grouped K-fold
cross-validation (:mod:`.selection`): one curve of held-out building+floor
accuracy per fold, the epoch count where their mean peaks. Then the
ensemble's members are trained on all scans for that many epochs.
"""

import contextlib
import time
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
from torch import nn

from ..core.metrics import class_index
from ..core.model import PlaceModel, PositionHead, R95
from ..core.preprocessing import RssiScaler
from ..data.fingerprints import check_trainable
from .augment import ScanAugmenter
from .network import PlaceNet
from .selection import grouped_folds


@dataclass
class TrainReport:
    """What happened during training, for the summary and provenance."""

    epochs: int = 0               # fine-tuning epochs of the members
    selection: dict = field(default_factory=dict)  # cross-validation
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
    """Network inputs of the training scans, augmented anew each epoch."""

    def __init__(self, rssi, scaler, config, seed):
        self.scaler = scaler
        self.augmenter = ScanAugmenter(rssi, config, seed) \
            if config.augmenting else None
        self.fixed = None if self.augmenter else \
            torch.from_numpy(scaler.transform(rssi))
        self.batch_size = config.batch_size
        self.generator = torch.Generator().manual_seed(seed)

    def epoch(self):
        """Yield (indices, inputs) mini-batches of one shuffled epoch."""
        x = self.fixed if self.augmenter is None else \
            torch.from_numpy(self.scaler.transform(self.augmenter()))
        order = torch.randperm(len(x), generator=self.generator)
        for idx in torch.split(order, self.batch_size):
            yield idx, x[idx]


def _score(net, held_out):
    """Return the held-out predicted classes and position errors (units)."""
    x, _, position = held_out
    net.eval()
    with torch.no_grad():
        if position is None:
            predicted, error = net(x).argmax(dim=1), None
        else:
            logits, xy = net.both(x)
            predicted = logits.argmax(dim=1)
            error = torch.linalg.vector_norm(xy - position, dim=1).numpy()
    net.train()
    return predicted.numpy(), error


def fit_network(rssi, targets, n_classes, scaler, config, epochs, seed,
                held_out=None, log=print):
    """
    Train one network on ``rssi`` (NaN = not detected).

    ``targets`` = (class indices, scaled positions or None). With
    ``held_out`` = (inputs, class indices, scaled positions or None), also
    return, after every epoch, the held-out predicted classes and position
    errors. Returns (net, [(classes, errors)] per epoch).
    """
    y, position = targets
    with _torch_state(config.threads, seed):
        inputs = _Inputs(rssi, scaler, config, seed)
        net = PlaceNet(rssi.shape[1], n_classes, config,
                       position=position is not None)
        sae = net.autoencoder()
        optimiser = torch.optim.Adam(sae.parameters(),
                                     lr=config.learning_rate)
        for epoch in range(1, config.sae_epochs + 1):
            total = 0.0
            for _, x in inputs.epoch():
                optimiser.zero_grad()
                loss = nn.functional.mse_loss(sae(x), x)
                loss.backward()
                optimiser.step()
                total += loss.item() * len(x)
            log(f'  sae epoch {epoch:3d}/{config.sae_epochs}  '
                f'reconstruction mse {total / len(rssi):.4f}')
        optimiser = torch.optim.Adam(net.parameters(),
                                     lr=config.learning_rate)
        scores = []
        for epoch in range(1, epochs + 1):
            total = 0.0
            for idx, x in inputs.epoch():
                optimiser.zero_grad()
                if position is None:
                    loss = nn.functional.cross_entropy(net(x), y[idx])
                else:
                    logits, xy = net.both(x)
                    loss = nn.functional.cross_entropy(logits, y[idx]) + \
                        config.position_weight * \
                        nn.functional.mse_loss(xy, position[idx])
                loss.backward()
                optimiser.step()
                total += loss.item() * len(idx)
            line = f'  epoch {epoch:3d}/{epochs}  loss {total / len(rssi):.4f}'
            if held_out is not None:
                scores.append(_score(net, held_out))
                right = (scores[-1][0] == held_out[1].numpy()).mean()
                line += f'  held-out building+floor {right:.4f}'
            log(line)
        net.eval()
    return net, scores


class _Positions:
    """Coordinates as network targets: relative to an origin, scaled."""

    def __init__(self, xy):
        self.origin = xy.mean(axis=0)
        self.scale = float(np.sqrt(((xy - self.origin) ** 2).mean())) or 1.0

    def targets(self, xy):
        return torch.from_numpy(((xy - self.origin) / self.scale)
                                .astype(np.float32))


def cross_validate(fp, y, n_classes, config, log=print):
    """
    Return the selection summary: per-fold curves, their mean, the choice.

    Each fold fits its own scaler and network on the scans it keeps and
    scores the groups it holds out after every epoch: building+floor
    accuracy, and with positions the error in metres, whose per-class 95th
    percentiles at the chosen epoch calibrate the position sigma.
    """
    folds = grouped_folds(fp, y.numpy(), config.folds, config.grouping,
                          config.seed)
    log(f'cross-validation: {len(folds.held_out)} folds of whole '
        f'{folds.grouping} groups ({folds.groups} groups'
        + (f'; {folds.note}' if folds.note else '') + ')')
    positions = _positions(fp, config)
    runs, fold_info = [], []
    for k, held in enumerate(folds.held_out):
        scaler = _scaler(config).fit(fp.rssi[~held])
        target = None if positions is None else \
            positions.targets(fp.position)
        held_out = (torch.from_numpy(scaler.transform(fp.rssi[held])),
                    y[held], None if target is None else target[held])
        log(f'fold {k + 1}/{len(folds.held_out)}: {int((~held).sum())} '
            f'scans train, {int(held.sum())} held out')
        _, scores = fit_network(
            fp.rssi[~held], (y[~held], None if target is None else
                             target[~held]),
            n_classes, scaler, config, config.epochs,
            config.seed + 1000 * (k + 1), held_out, log)
        runs.append((held, scores))
        fold_info.append({'held_out_scans': int(held.sum()),
                          'classes': sorted(set(y[held].tolist()))})
    truth = y.numpy()
    curves = np.array([[(c == truth[held]).mean() for c, _ in scores]
                       for held, scores in runs])
    mean = curves.mean(axis=0)
    best = int(np.argmax(mean))
    if positions is not None:  # of the epochs as accurate, the best placed
        error = np.mean([[e.mean() for _, e in scores]
                         for _, scores in runs], axis=0)
        tied = np.flatnonzero(mean >= mean[best] - ACCURACY_TIE)
        best = int(tied[np.argmin(error[tied])])
    summary = {'grouping': folds.grouping, 'note': folds.note,
               'groups': folds.groups, 'never_held_out': folds.never_held_out,
               'folds': fold_info, 'curves': np.round(curves, 5).tolist(),
               'mean_curve': np.round(mean, 5).tolist(), 'epochs': best + 1,
               'accuracy_mean': float(mean[best]),
               'accuracy_min': float(curves[:, best].min()),
               'accuracy_max': float(curves[:, best].max())}
    if positions is not None:
        errors = np.concatenate([s[best][1] for _, s in runs]) * \
            positions.scale
        predicted = np.concatenate([s[best][0] for _, s in runs])
        summary.update(position_mean_error_m=float(errors.mean()),
                       position_median_error_m=float(np.median(errors)),
                       sigma_m=_calibrated_sigma(errors, predicted,
                                                 n_classes).tolist())
    return summary


#: Mean held-out accuracies this close count as equal when choosing the
#: epoch count on position error (below the fold-to-fold noise).
ACCURACY_TIE = 0.002

def _calibrated_sigma(errors, predicted, n_classes, min_scans=30):
    """
    Return a sigma (m) per class: its held-out 95th percentile error / R95.

    A class predicted for fewer than ``min_scans`` held-out scans gets the
    value of all scans.
    """
    overall = np.quantile(errors, 0.95) / R95
    sigma = np.full(n_classes, overall)
    for c in range(n_classes):
        mine = errors[predicted == c]
        if len(mine) >= min_scans:
            sigma[c] = np.quantile(mine, 0.95) / R95
    return np.maximum(sigma, 0.1)


def _training_sigma(nets, x, target, n_classes):
    x = torch.from_numpy(x)
    scores = [_score(net, (x, None, target)) for net in nets]
    return _calibrated_sigma(np.mean([e for _, e in scores], axis=0),
                             scores[0][0], n_classes)


def _positions(fp, config):
    if fp.position is None or not config.position_weight:
        return None
    return _Positions(fp.position)


def _scaler(config):
    return RssiScaler(config.not_detected, config.scaling,
                      config.representation)


def train(fp, config, log=print):
    """
    Train on :class:`Fingerprints`; return (PlaceModel, nets, report).

    With ``config.folds`` the epoch count is chosen by grouped
    cross-validation, else ``config.epochs`` is used; then
    ``config.ensemble`` networks (seeds ``seed``, ``seed + 1`` …) are
    trained on all scans.
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
    if config.folds:
        report.selection = cross_validate(fp, y, len(classes), config, log)
        report.epochs = report.selection['epochs']
        s = report.selection
        log(f'cross-validated building+floor {s["accuracy_mean"]:.4f} '
            f'({s["accuracy_min"]:.4f}-{s["accuracy_max"]:.4f} over folds) '
            f'at {report.epochs} epochs')
    positions = _positions(fp, config)
    target = None if positions is None else positions.targets(fp.position)
    scaler = _scaler(config).fit(fp.rssi)
    nets = []
    for k in range(config.ensemble):
        log(f'member {k + 1}/{config.ensemble}: all {len(fp)} scans, '
            f'{report.epochs} epochs')
        nets.append(fit_network(fp.rssi, (y, target), len(classes), scaler,
                                config, report.epochs, config.seed + k,
                                log=log)[0])
    report.seconds = time.perf_counter() - start
    provenance = {
        'config': asdict(config),
        'training_data': {'source': fp.source, 'sha256': fp.sha256,
                          'scans': len(fp), 'dropped_empty':
                          report.dropped_empty, 'clipped_cells': fp.clipped},
        'selection': {k: v for k, v in report.selection.items()
                      if k != 'curves'},
        'epochs': report.epochs,
        'train_seconds': round(report.seconds, 2),
        'versions': {'torch': torch.__version__, 'numpy': np.__version__},
        'created': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime()),
    }
    position = None
    if positions is not None:
        sigma = report.selection.get('sigma_m')
        if sigma is None:  # nothing held out: training errors (optimistic)
            sigma = _training_sigma(nets, scaler.transform(fp.rssi), target,
                                    len(classes)) * positions.scale
            provenance['position_sigma'] = 'training scans (no folds)'
        position = PositionHead(
            positions.origin, positions.scale, len(config.sae_layers),
            [net.frozen_position() for net in nets],
            np.asarray(sigma, np.float32), fp.position_columns)
    model = PlaceModel(fp.ap_ids, scaler,
                       [net.frozen_layers() for net in nets], classes,
                       provenance, position=position)
    return model, nets, report
