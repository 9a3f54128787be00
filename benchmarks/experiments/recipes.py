"""
Recipes trained by the documented commands and tested, against baselines.

Each recipe is trained by ``train_model`` (in a subprocess whose wall time
and peak memory are measured) on the dataset's training part and evaluated
by ``evaluate_model`` on its test part; everything it chooses is chosen on
the training part (grouped folds) or, with ``--validation``, on the
validation part. The ``default`` suite adds k-NN and a random forest.
"""

import sys
import tempfile

import numpy as np
from sklearn.ensemble import RandomForestClassifier
from sklearn.neighbors import KNeighborsClassifier, KNeighborsRegressor
from wifi_place_recognition.core.evaluation import align, position_errors
from wifi_place_recognition.core.metrics import accuracies, class_index
from wifi_place_recognition.core.preprocessing import RssiScaler
from wifi_place_recognition.training.config import PAPER
from wifi_place_recognition.training.folds import grouped_folds

from runs import summary, train_and_test

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

#: What each suite answers (``--help``).
QUESTIONS = {
    'default': 'Test the default and the paper recipe, k-NN, a forest.',
    'table1': "Test the paper's Table 1: missing value and scaling.",
    'validation': 'Test the default recipe selected on the validation part.',
    'architecture': "Test the paper's networks: SAE depth, no pre-training.",
}
KEYS = ('building_floor_accuracy', 'building_accuracy', 'floor_accuracy',
        'position_mean_error_m', 'position_median_error_m',
        'position_penalised_mean_error_m', 'position_in_95_ellipse',
        'train_seconds', 'train_peak_mib')


def run_suite(suite, args, data):
    """Train and test the recipes of ``suite`` at every seed; the table."""
    if suite == 'validation' and not data.paths['validation']:
        raise SystemExit(f'{data.name} has no validation part')
    test_fp = data.test()
    protocol = dict(test=data.paths['test'], test_sha256=test_fp.sha256)
    if suite == 'validation':
        protocol.update(validation=data.paths['validation'])
    runs = {}
    with tempfile.TemporaryDirectory() as folder:
        for seed in args.seeds:
            for name, flags in SUITES[suite].items():
                if args.recipes and name.split(' ')[0] not in args.recipes:
                    continue
                flags = [f for flag in flags for f in (
                    data.paths['validation'] if flag == VALIDATION
                    else [flag])]
                r = train_and_test(flags, seed, data.paths['train'],
                                   data.paths['test'], data.args, folder)
                runs.setdefault(name, []).append(r)
                print(f'{name} seed {seed}: test building+floor '
                      f'{r["building_floor_accuracy"]:.4f}, '
                      f'{r["train_seconds"]:.0f} s, '
                      f'{r["train_peak_mib"]:.0f} MiB', file=sys.stderr,
                      flush=True)
            if suite == 'default' and not args.no_baselines:
                for name, r in knn_baselines(data.train, test_fp,
                                             seed).items():
                    runs.setdefault(name, []).append(r)
    table = {name: {k: summary([r.get(k) for r in rs]) for k in KEYS}
             for name, rs in runs.items()}
    print_table(dict(protocol, dataset=data.name, train=data.paths['train'],
                     seeds=args.seeds), table)
    return dict(protocol, table=table, runs=runs)


def _suite(suite):
    def run(args, data):
        return run_suite(suite, args, data)
    run.__doc__ = QUESTIONS[suite]
    return run


EXPERIMENTS = {suite: _suite(suite) for suite in SUITES}


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


def print_table(protocol, table):
    """Print the table of test figures (mean, min-max over seeds)."""
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
