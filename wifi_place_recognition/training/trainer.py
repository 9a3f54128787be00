"""
Training a place model (Nowicki & Wietrzykowski, 2017) and its provenance.

How many epochs is chosen by grouped K-fold cross-validation or by the
curve of a separate validation set (:mod:`.selection`); then the
ensemble's members (:mod:`.fitting`) are trained on all scans for that many
epochs.
"""

import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import torch

from ..core.metrics import class_index
from ..core.model import PlaceModel
from ..data.fingerprints import check_trainable
from .fitting import config_scaler, fit_network
from .coverage import fit_coverage
from .selection import (calibrate, COVERAGE_EXAMPLES, cross_validate,
                        reference_locator, validate)

#: Why a model trained without validation data keeps temperature 1.
NOT_FITTED = ('nothing: without validation data the probabilities are the '
              'ensemble\'s own (a temperature fitted on the folds\' '
              'held-out scans, single networks on stretches no kept scan '
              'covers, over-softened them on every dataset measured)')


@dataclass
class TrainReport:
    """What happened during training, for the summary and provenance."""

    epochs: int = 0               # fine-tuning epochs of the members
    selection: dict = field(default_factory=dict)  # folds or validation
    train_samples: int = 0
    dropped_empty: int = 0
    seconds: float = 0.0


def train(fp, config, log=print, validation=None):
    """
    Train on :class:`Fingerprints`; return (PlaceModel, nets, report).

    The epoch count (and the position's k-NN and sigma, and the
    probabilities' temperature) is chosen on ``validation``
    (Fingerprints) when given, else (no temperature) by grouped
    cross-validation with ``config.folds``, else ``config.epochs`` is
    used; then ``config.ensemble`` networks (seeds ``seed``, ``seed + 1``
    …) are trained on all scans of ``fp``. Data of one building/floor
    class makes a position-only model: no network (``nets`` empty).
    """
    start = time.perf_counter()
    check_trainable(fp)
    report = TrainReport()
    usable = ~fp.empty_rows
    report.dropped_empty = int((~usable).sum())
    fp = fp.subset(usable)
    report.train_samples = len(fp)
    config = replace(config, batch_size=config.batch_for(len(fp)))
    classes, y = class_index(fp.building, fp.floor)
    y = torch.from_numpy(y)
    one_class = len(classes) == 1
    report.epochs = 0 if one_class else config.epochs
    if validation is not None:
        report.selection = validate(fp, y.numpy(), classes, validation,
                                    config, log)
    elif config.folds:
        report.selection = cross_validate(fp, y, len(classes), config, log)
    if one_class:
        log(f'one building/floor class ({classes[0][0]}, {classes[0][1]}): '
            f'a position-only model, no network')
    elif report.selection:
        report.epochs = report.selection['epochs']
        s = report.selection
        log(f'held-out building+floor {s["accuracy_mean"]:.4f} '
            + (f'({s["accuracy_min"]:.4f}-{s["accuracy_max"]:.4f} over '
               f'folds) ' if len(s['folds']) > 1 else '')
            + f'at {report.epochs} epochs')
    scaler = config_scaler(config).fit(fp.rssi)
    nets = []
    for k in range(0 if one_class else config.ensemble):
        log(f'member {k + 1}/{config.ensemble}: all {len(fp)} scans, '
            f'{report.epochs} epochs')
        nets.append(fit_network(fp.rssi, y, len(classes), scaler, config,
                                report.epochs, config.seed + k,
                                log=log)[0])
    position = coverage = None
    examples = report.selection.pop(COVERAGE_EXAMPLES, None)
    if fp.position is not None and 'sigma_m' in report.selection:
        position = reference_locator(fp, y.numpy(), len(classes),
                                     report.selection)
        coverage = fit_coverage(*examples, log=log)
    elif one_class:
        raise ValueError('a one-class model is position-only: its position '
                         'uncertainty is calibrated on held-out scans, so '
                         'it needs --folds >= 2 or --validation data with '
                         'positions')
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
                       provenance, position=position, coverage=coverage)
    if validation is not None and nets:
        c = provenance['calibration'] = calibrate(model, validation)
        model.temperature = c['temperature']
        log(f'probabilities: temperature {c["temperature"]:.3f} fitted on '
            f'{c["scans"]} validation scans (expected calibration error '
            f'{c["ece_before"]:.4f} -> {c["ece_after"]:.4f})')
    else:
        provenance['calibration'] = {'temperature': 1.0,
                                     'fitted_on': NOT_FITTED}
    return model, nets, report
