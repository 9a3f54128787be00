"""
The ensemble size: cross-validated accuracy of 1..``--members`` networks.

In every fold, ``--members`` networks of the default recipe (seeds apart),
and the held-out accuracy of the mean of the first m of them at every
epoch: the curve that chooses the ensemble size (no test file).
"""

import sys
import time

import numpy as np
from wifi_place_recognition.training.fitting import (best_epoch,
                                                     config_scaler,
                                                     fit_network)

from .common import default_folds


def members(args, data):
    """Cross-validate ensembles of 1..``--members`` networks; no test file."""
    import torch
    train_fp, classes, y, per_seed = default_folds(data.train, args.seeds)
    runs = []
    for seed, config, held_out in per_seed:
        start = time.perf_counter()
        curves = []     # [fold][m] -> accuracy per epoch of m members
        for k, held in enumerate(held_out):
            scaler = config_scaler(config).fit(train_fp.rssi[~held])
            x = torch.from_numpy(scaler.transform(train_fp.rssi[held]))
            proba = [fit_network(
                train_fp.rssi[~held], torch.from_numpy(y[~held]),
                len(classes), scaler, config, config.epochs,
                config.fold_seed(k) + m, (x, torch.from_numpy(y[held])),
                log=lambda line: None, proba=True)[1]
                for m in range(args.members)]
            proba = np.array(proba)             # (m, epochs, n, k)
            mean = np.cumsum(proba, axis=0)     # first m members
            curves.append((mean.argmax(axis=-1) == y[held]).mean(axis=-1))
        curves = np.array(curves)               # (folds, m, epochs)
        single = curves[:, 0].mean(axis=0)
        epoch = best_epoch(single)
        at = curves[:, :, epoch]
        runs.append({'seed': seed, 'epochs': epoch + 1,
                     'curves': np.round(curves, 5).tolist(),
                     'members_mean': at.mean(axis=0).tolist(),
                     'members_min': at.min(axis=0).tolist(),
                     'members_max': at.max(axis=0).tolist(),
                     'seconds': time.perf_counter() - start})
        print(f'seed {seed}, epoch {epoch + 1} (chosen on one member): '
              'cross-validated building+floor by members: '
              + ', '.join(f'{m + 1}: {v:.4f}'
                          for m, v in enumerate(at.mean(axis=0))),
              file=sys.stderr, flush=True)
    return {'runs': runs}


EXPERIMENTS = {'members': members}
