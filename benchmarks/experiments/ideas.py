"""
Other uses of the trained network, cross-validated (no test file).

k-NN on the network's learned code, test-time augmentation and per-scan
normalisation against the network itself.
"""

import sys

import numpy as np
from sklearn.neighbors import KNeighborsClassifier
from wifi_place_recognition.training.fitting import config_scaler, fit_network

from .common import default_folds


def _fold_network(kept_rssi, y, n_classes, config, epochs, seed):
    """Return (scaler, net): one network trained on a fold's kept scans."""
    import torch
    scaler = config_scaler(config).fit(kept_rssi)
    net, _ = fit_network(kept_rssi, torch.from_numpy(y), n_classes, scaler,
                         config, epochs, seed, log=lambda line: None)
    return scaler, net


def _strongest_at(rssi, level=-30.0, floor=-110.0):
    """Return scans shifted so that their strongest reading is ``level``."""
    out = rssi + (level - np.nanmax(rssi, axis=1, keepdims=True))
    out[out < floor] = np.nan
    return out


def ideas(args, data, epochs=8, copies=8):
    """
    Cross-validate other uses of the trained network; no test file.

    In every fold one default network (``epochs``: the default's choice
    at seed 0) scores the held-out phones three ways: its own softmax,
    k-NN on its learned code (the encoder's output; k 1, 5, 11,
    distance-weighted), and test-time augmentation (its softmax averaged
    over the scan and ``copies`` phone-like variations of it). A second
    network is trained and scored on per-scan normalised scans (each
    shifted so that its strongest reading is -30 dBm).
    """
    import torch
    from wifi_place_recognition.training.augment import ScanAugmenter
    train_fp, classes, y, per_seed = default_folds(data.train, args.seeds)
    runs = []
    for seed, config, held_out in per_seed:
        scores = {}
        for k, held in enumerate(held_out):
            kept_rssi, held_rssi = train_fp.rssi[~held], train_fp.rssi[held]
            fold_seed = config.fold_seed(k)
            scaler, net = _fold_network(kept_rssi, y[~held], len(classes),
                                        config, epochs, fold_seed)
            with torch.no_grad():
                x_kept = torch.from_numpy(scaler.transform(kept_rssi))
                x_held = torch.from_numpy(scaler.transform(held_rssi))
                proba = torch.softmax(net(x_held), dim=1).numpy()
                code_kept = net.encode(x_kept).numpy()
                code_held = net.encode(x_held).numpy()
                augmenter = ScanAugmenter(held_rssi, config, seed)
                tta = proba.copy()
                for _ in range(copies):
                    rows, cols, dbm = augmenter.readings()
                    copy = np.full(held_rssi.shape, np.nan, np.float32)
                    copy[rows, cols] = dbm
                    tta += torch.softmax(net(torch.from_numpy(
                        scaler.transform(copy))), dim=1).numpy()
            truth = y[held]
            scaler_n, net_n = _fold_network(
                _strongest_at(kept_rssi), y[~held], len(classes), config,
                epochs, fold_seed)
            with torch.no_grad():
                normalised = net_n(torch.from_numpy(scaler_n.transform(
                    _strongest_at(held_rssi)))).argmax(1).numpy()
            fold = {'network': (proba.argmax(1) == truth).mean(),
                    'network, per-scan normalised': (normalised == truth)
                    .mean(),
                    'test-time augmentation': (tta.argmax(1) == truth)
                    .mean()}
            for n in (1, 5, 11):
                knn = KNeighborsClassifier(n, weights='distance')
                fold[f'k-NN on the code, k={n}'] = (knn.fit(
                    code_kept, y[~held]).predict(code_held) == truth).mean()
            for name, value in fold.items():
                scores.setdefault(name, []).append(float(value))
        runs.append({'seed': seed, 'epochs': epochs, 'folds': scores})
        print(f'seed {seed}: ' + ', '.join(
            f'{name} {np.mean(v):.4f}' for name, v in scores.items()),
            file=sys.stderr, flush=True)
    return {'runs': runs}


EXPERIMENTS = {'ideas': ideas}
