"""
Accuracy benchmark: recipes against k-NN and a random forest, several seeds.

The default and the paper's recipe against k-NN and a random forest, in one
run; or (``--suite search``) the cross-validation of variants alone.

Protocol (``--suite default``, ``table1``, ``architecture``,
``validation``): each recipe is trained by the documented command
(``train_model``, in a subprocess whose wall time and peak memory are
measured) on the dataset's training part and evaluated by
``evaluate_model`` on its test part. Everything the recipe
chooses (the epoch count, k and the representation of k-NN) is chosen by
grouped cross-validation on the training part: whole devices
(UJIIndoorLoc PHONEID) or whole walks (WiFine files). The test part is only
ever evaluated. Prints a table (mean and min-max over seeds) and writes
JSON. ``--suite validation`` (WiFine) selects on the dataset's validation
part (``train_model --validation``) instead of the folds.

``--suite search`` runs only the cross-validation of each variant (no test
file at all): the selection log of benchmarks/README.md comes from it.
``--suite members`` cross-validates ensembles: in every fold, ``--members``
networks of the default recipe (seeds apart), and the held-out accuracy of
the mean of the first m of them at every epoch: the curve that chooses the
ensemble size (no test file either). ``--suite ideas`` cross-validates
k-NN on the network's learned code, test-time augmentation and per-scan
normalisation against the network itself (no test file).

    python benchmarks/accuracy.py --dataset ujiindoorloc --suite default
    python benchmarks/accuracy.py --dataset wifine --suite default
    python benchmarks/accuracy.py --dataset wifine --suite validation
"""

import argparse
import json
import os
from pathlib import Path
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
from sklearn.ensemble import RandomForestClassifier
from sklearn.neighbors import KNeighborsClassifier, KNeighborsRegressor

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
from wifi_place_recognition.core.atomic import atomic_write  # noqa: E402
from wifi_place_recognition.core.evaluation import (  # noqa: E402
    align, position_errors)
from wifi_place_recognition.core.metrics import (  # noqa: E402
    accuracies, class_index)
from wifi_place_recognition.core.preprocessing import RssiScaler  # noqa
from wifi_place_recognition.data.fingerprints import (  # noqa: E402
    read_fingerprints, ReaderOptions)
from wifi_place_recognition.training.config import (  # noqa: E402
    PAPER, TrainConfig)
from wifi_place_recognition.training.fitting import (  # noqa: E402
    best_epoch, config_scaler, fit_network)
from wifi_place_recognition.training.folds import grouped_folds  # noqa: E402
from wifi_place_recognition.training.selection import (  # noqa: E402
    cross_validate)

WIFINE_OPTIONS = dict(floor_column='floorID', building_column=None,
                      not_detected_marker=-100.0,
                      meta_columns=('num_visible_APs', 'z'))
WIFINE_ARGS = ['--floor-column', 'floorID', '--building-column', 'none',
               '--not-detected-marker', '-100', '--meta-columns',
               'num_visible_APs,z']
DATASETS = {
    'ujiindoorloc': dict(train=['ujiindoorloc/trainingData.csv'],
                         test=['ujiindoorloc/validationData-public.csv'],
                         options={}, args=[]),
    'wifine': dict(train=['wifine/train'], test=['wifine/test'],
                   validation=['wifine/val'], options=WIFINE_OPTIONS,
                   args=WIFINE_ARGS),
}
#: Stands for the dataset's validation part in a recipe's flags.
VALIDATION = '<validation>'


def _flags(overrides):
    out = []
    for key, value in overrides.items():
        flag = '--' + key.replace('_', '-')
        if isinstance(value, tuple):
            value = ','.join(map(str, value))
        out += [flag, str(value)]
    return out


PAPER_FLAGS = _flags(PAPER)
SUITES = {
    'default': {
        'default': [],
        'paper recipe (one network, dBm, no augmentation)': PAPER_FLAGS,
    },
    'table1': {
        'missing 100, per-AP scaling': PAPER_FLAGS + _flags(dict(
            not_detected=100.0, scaling='independent')),
        'missing 100, joint scaling': PAPER_FLAGS + _flags(dict(
            not_detected=100.0)),
        'missing -110, per-AP scaling': PAPER_FLAGS + _flags(dict(
            scaling='independent')),
        'missing -110, joint scaling': PAPER_FLAGS,
    },
    'validation': {
        'default, selection on the validation part': ['--validation',
                                                      VALIDATION],
    },
    'architecture': {
        'SAE 256 + 128-128': PAPER_FLAGS + ['--sae-layers', '256'],
        'SAE 256-128 + 128-128': PAPER_FLAGS + ['--sae-layers', '256,128'],
        'SAE 256-128-64 + 128-128': PAPER_FLAGS,
        'no SAE pre-training': PAPER_FLAGS + ['--sae-epochs', '0'],
    },
}


def _measured(argv):
    """Run ``argv``; return (CompletedProcess-like, seconds, peak MiB)."""
    start = time.perf_counter()
    with tempfile.TemporaryFile('w+') as out, \
            tempfile.TemporaryFile('w+') as err:
        proc = subprocess.Popen(argv, stdout=out, stderr=err,
                                env=os.environ.copy())
        _, status, usage = os.wait4(proc.pid, 0)
        seconds = time.perf_counter() - start
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read(), err.read()
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f'{" ".join(map(str, argv))} failed:\n{stderr}')
    return stdout, seconds, usage.ru_maxrss / 1024


def train_and_test(flags, seed, paths, data, folder):
    """Train by the documented command; return the test figures."""
    model = Path(folder) / f'model-{seed}.npz'
    cli = [sys.executable, '-m', 'wifi_place_recognition.cli.']
    flags = [f for flag in flags for f in (
        paths['validation'] if flag == VALIDATION else [flag])]
    _, seconds, peak = _measured(
        [cli[0], cli[1], cli[2] + 'train_model', '--data', *paths['train'],
         *data['args'], '-o', model, '--seed', str(seed), '--quiet',
         *flags])
    stdout, _, _ = _measured(
        [cli[0], cli[1], cli[2] + 'evaluate_model', '--model', model,
         '--data', *paths['test'], *data['args'], '--json'])
    result = json.loads(stdout)
    result.pop('confusion')
    result.update(train_seconds=seconds, train_peak_mib=peak)
    return result


def _representations(train, test):
    for name in ('dbm', 'powed', 'exponential'):
        scaler = RssiScaler(-110.0, 'joint', name).fit(train.rssi)
        yield name, scaler.transform(train.rssi), scaler.transform(test)


def knn_baselines(train_fp, test_fp, seed, folds=4):
    """
    Return {name: test figures} of k-NN and a random forest.

    k (1-11) and the representation of k-NN are chosen by grouped
    cross-validation on the training data, separately for the class
    (building+floor accuracy) and the position (mean error).
    """
    train_fp = train_fp.subset(~train_fp.empty_rows)
    classes, y = class_index(train_fp.building, train_fp.floor)
    split = grouped_folds(train_fp, y, folds, seed=seed).held_out
    test_rssi = align(train_fp, test_fp)
    ks = (1, 3, 5, 7, 11)
    best_class, best_pos = (-1, None), (np.inf, None)
    for rep, _, _ in _representations(train_fp, test_rssi):
        for k in ks:
            acc, err = [], []
            for held in split:
                scaler = RssiScaler(-110.0, 'joint', rep).fit(
                    train_fp.rssi[~held])
                x_tr = scaler.transform(train_fp.rssi[~held])
                x_te = scaler.transform(train_fp.rssi[held])
                knn = KNeighborsClassifier(k, weights='distance')
                acc.append((knn.fit(x_tr, y[~held]).predict(x_te)
                            == y[held]).mean())
                if train_fp.position is not None:
                    reg = KNeighborsRegressor(k, weights='distance')
                    reg.fit(x_tr, train_fp.position[~held])
                    err.append(np.linalg.norm(
                        reg.predict(x_te) - train_fp.position[held],
                        axis=1).mean())
            if np.mean(acc) > best_class[0]:
                best_class = (np.mean(acc), (rep, k))
            if err and np.mean(err) < best_pos[0]:
                best_pos = (np.mean(err), (rep, k))
    out = {}
    rep, k = best_class[1]
    scaler = RssiScaler(-110.0, 'joint', rep).fit(train_fp.rssi)
    x_tr, x_te = scaler.transform(train_fp.rssi), scaler.transform(test_rssi)
    knn = KNeighborsClassifier(k, weights='distance').fit(x_tr, y)
    predicted = classes[knn.predict(x_te)]
    name = f'k-NN (k={k}, {rep}; k/representation by CV)'
    out[name] = accuracies(test_fp.building, test_fp.floor, predicted[:, 0],
                           predicted[:, 1])
    if best_pos[1] is not None:
        rep, k = best_pos[1]
        scaler = RssiScaler(-110.0, 'joint', rep).fit(train_fp.rssi)
        reg = KNeighborsRegressor(k, weights='distance').fit(
            scaler.transform(train_fp.rssi), train_fp.position)
        xy = reg.predict(scaler.transform(test_rssi))
        out[name].update(position_errors(
            test_fp, predicted[:, 0], predicted[:, 1], xy,
            np.full(len(xy), np.nan)))
        del out[name]['position_in_95_ellipse']  # k-NN gives no sigma
        out[name]['position_knn'] = f'k={k}, {rep}'
    scaler = RssiScaler(-110.0, 'joint', 'dbm').fit(train_fp.rssi)
    forest = RandomForestClassifier(100, random_state=seed, n_jobs=1)
    forest.fit(scaler.transform(train_fp.rssi), y)
    predicted = classes[forest.predict(scaler.transform(test_rssi))]
    out['random forest (100 trees, -110 dBm)'] = accuracies(
        test_fp.building, test_fp.floor, predicted[:, 0], predicted[:, 1])
    return out


def summary(values):
    """Return mean, min, max (and the values) of a list of numbers."""
    values = [v for v in values if v is not None]
    if not values:
        return None
    return {'mean': statistics.fmean(values), 'min': min(values),
            'max': max(values), 'values': values}


def search(args, train_fp):
    """Cross-validate each variant of ``--variants`` (JSON); no test file."""
    variants = json.loads(Path(args.variants).read_text())
    train_fp = train_fp.subset(~train_fp.empty_rows)
    classes, y = class_index(train_fp.building, train_fp.floor)
    import torch
    y = torch.from_numpy(y)
    runs = []
    for name, overrides in variants.items():
        for seed in args.seeds:
            config = TrainConfig(**dict(overrides, seed=seed))
            start = time.perf_counter()
            s = cross_validate(train_fp, y, len(classes), config,
                               log=lambda line: None)
            curves = np.asarray(s['curves'])
            runs.append({
                'variant': name, 'overrides': overrides, 'seed': seed,
                'cv_accuracy_at_choice': s['accuracy_mean'],
                'cv_accuracy_plateau': float(curves[:, 1:].mean()),
                'fold_plateaus': curves[:, 1:].mean(axis=1).tolist(),
                'epochs': s['epochs'],
                'position_mean_error_m': s.get('position_mean_error_m'),
                'seconds': time.perf_counter() - start})
            r = runs[-1]
            print(f'{name:40s} seed {seed}: plateau '
                  f'{r["cv_accuracy_plateau"]:.4f} (folds '
                  + ' '.join(f'{v:.3f}' for v in r['fold_plateaus'])
                  + f'), position {r["position_mean_error_m"] or 0:.2f} m, '
                  f'{r["seconds"]:.0f} s', file=sys.stderr, flush=True)
    return {'runs': runs}


def _default_folds(train_fp, seeds):
    """
    Return (scans, classes, y, [(seed, config, held-out masks)]).

    The training scans that detect an AP, their classes, and the default
    recipe's folds at each seed.
    """
    train_fp = train_fp.subset(~train_fp.empty_rows)
    classes, y = class_index(train_fp.building, train_fp.floor)
    per_seed = []
    for seed in seeds:
        config = TrainConfig(seed=seed)
        per_seed.append((seed, config, grouped_folds(
            train_fp, y, config.folds, config.grouping, seed).held_out))
    return train_fp, classes, y, per_seed


def members(args, train_fp):
    """Cross-validate ensembles of 1..``--members`` networks; no test file."""
    import torch
    train_fp, classes, y, per_seed = _default_folds(train_fp, args.seeds)
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
                seed + 1000 * (k + 1) + m, (x, torch.from_numpy(y[held])),
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


def ideas(args, train_fp, epochs=8, copies=8):
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
    train_fp, classes, y, per_seed = _default_folds(train_fp, args.seeds)
    runs = []
    for seed, config, held_out in per_seed:
        scores = {}
        for k, held in enumerate(held_out):
            kept_rssi, held_rssi = train_fp.rssi[~held], train_fp.rssi[held]
            fold_seed = seed + 1000 * (k + 1)
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


def main():
    """Run a suite; print the table; write JSON."""
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--datasets', type=Path,
                   default=ROOT.parent / 'shared' / 'datasets',
                   help='folder holding ujiindoorloc/ and wifine/')
    p.add_argument('--dataset', choices=sorted(DATASETS),
                   default='ujiindoorloc')
    p.add_argument('--suite', choices=sorted(SUITES) + ['search', 'members',
                                                        'ideas'],
                   default='default')
    p.add_argument('--members', type=int, default=5,
                   help='members: the largest ensemble cross-validated')
    p.add_argument('--variants', help='search: JSON {name: overrides}')
    p.add_argument('--seeds', type=lambda s: [int(v) for v in s.split(',')],
                   default=[0, 1, 2])
    p.add_argument('--no-baselines', action='store_true')
    p.add_argument('--recipes', type=lambda s: s.split(','), default=None,
                   help='run only the recipes whose names start with these '
                        'comma-separated words (default suite: default, '
                        'paper)')
    p.add_argument('--out', type=Path, default=None)
    args = p.parse_args()
    data = DATASETS[args.dataset]
    paths = {part: [str(args.datasets / f) for f in data.get(part, [])]
             for part in ('train', 'test', 'validation')}
    if args.suite == 'validation' and not paths['validation']:
        p.error(f'{args.dataset} has no validation part')
    out = args.out or ROOT / 'benchmarks' / 'results' / \
        f'{args.dataset}-{args.suite}.json'
    options = ReaderOptions(**data['options'])
    train_fp = read_fingerprints(paths['train'], options=options)
    protocol = {'dataset': args.dataset, 'train': paths['train'],
                'train_sha256': train_fp.sha256, 'seeds': args.seeds}
    if args.suite in ('search', 'members', 'ideas'):
        result = {'search': search, 'members': members,
                  'ideas': ideas}[args.suite](args, train_fp)
        _write(out, dict(protocol, test=None, **result))
        return
    test_fp = read_fingerprints(paths['test'], role='test', options=options)
    protocol.update(test=paths['test'], test_sha256=test_fp.sha256)
    if args.suite == 'validation':
        protocol.update(validation=paths['validation'])
    runs = {}
    with tempfile.TemporaryDirectory() as folder:
        for seed in args.seeds:
            for name, flags in SUITES[args.suite].items():
                if args.recipes and name.split(' ')[0] not in args.recipes:
                    continue
                r = train_and_test(flags, seed, paths, data, folder)
                runs.setdefault(name, []).append(r)
                print(f'{name} seed {seed}: test building+floor '
                      f'{r["building_floor_accuracy"]:.4f}, '
                      f'{r["train_seconds"]:.0f} s, '
                      f'{r["train_peak_mib"]:.0f} MiB', file=sys.stderr,
                      flush=True)
            if args.suite == 'default' and not args.no_baselines:
                for name, r in knn_baselines(train_fp, test_fp,
                                             seed).items():
                    runs.setdefault(name, []).append(r)
    keys = ('building_floor_accuracy', 'building_accuracy',
            'floor_accuracy', 'position_mean_error_m',
            'position_median_error_m', 'position_penalised_mean_error_m',
            'position_in_95_ellipse', 'train_seconds', 'train_peak_mib')
    table = {name: {k: summary([r.get(k) for r in rs]) for k in keys}
             for name, rs in runs.items()}
    _print_table(protocol, table)
    _write(out, dict(protocol, table=table, runs=runs))


def _print_table(protocol, table):
    print(f'\n{protocol["dataset"]}: train {protocol["train"]}, test '
          f'{protocol["test"]}, seeds {protocol["seeds"]}; mean (min-max)')

    def cell(s, fmt='.4f'):
        if s is None:
            return '-'
        return f'{s["mean"]:{fmt}} ({s["min"]:{fmt}}-{s["max"]:{fmt}})'
    print('| method | test building+floor | test building | position mean '
          'error (m) | penalised (m) | in 95% circle | train s | peak MiB |')
    print('|---|---|---|---|---|---|---|---|')
    for name, row in table.items():
        print(f'| {name} | {cell(row["building_floor_accuracy"])} | '
              f'{cell(row["building_accuracy"])} | '
              f'{cell(row["position_mean_error_m"], ".2f")} | '
              f'{cell(row["position_penalised_mean_error_m"], ".2f")} | '
              f'{cell(row["position_in_95_ellipse"], ".3f")} | '
              f'{cell(row["train_seconds"], ".0f")} | '
              f'{cell(row["train_peak_mib"], ".0f")} |')


def _write(out, content):
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(out, 'w') as f:
        json.dump(content, f, indent=1)
    print(f'wrote {out}')


if __name__ == '__main__':
    main()
