"""
Accuracy benchmark: SAE variants and baselines, several seeds, one run.

Protocol: train on ``--train`` (UJIIndoorLoc trainingData.csv), select on
whole phones held out from it (PHONEID), report accuracy on ``--test``
(validationData-public.csv). The test file is only ever evaluated, never
used to choose. Prints a table (mean and min-max over seeds) and writes JSON.

    python benchmarks/accuracy.py --train T.csv --test V.csv [--suite S]

Suites: ``default`` (the default model against 1-NN, k-NN and a random
forest), ``table1`` (the paper's Table 1 input treatments),
``architecture`` (the paper's network comparison), ``search`` (ideas
beyond the paper, for the selection log).
"""

import argparse
import json
from pathlib import Path
import statistics
import sys
import time

import numpy as np
from sklearn.ensemble import RandomForestClassifier
from sklearn.neighbors import KNeighborsClassifier

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from wifi_place_recognition.core.atomic import atomic_write  # noqa: E402
from wifi_place_recognition.data.fingerprints import read_fingerprints  # noqa
from wifi_place_recognition.core.metrics import accuracies  # noqa: E402
from wifi_place_recognition.training.trainer import (  # noqa: E402
    PAPER, split_validation, train, TrainConfig)

PAPER_FIGURES = {'SAE default (paper: 0.92)': 0.92,
                 '1-NN raw, 100 = missing (paper: 0.75)': 0.75}

AUG = dict(augment_offset=10.0, augment_gain=0.1, augment_noise=2.0,
           augment_dropout=0.1)
AUG_EXP = dict(PAPER, **AUG, representation='exponential')
SUITES = {
    'default': {
        'default (augment + exponential + refit)': {},
    },
    'table1': {
        'missing 100, per-AP scaling': dict(PAPER, not_detected=100.0,
                                            scaling='independent'),
        'missing 100, joint scaling': dict(PAPER, not_detected=100.0),
        'missing -110, per-AP scaling': dict(PAPER, scaling='independent'),
        'missing -110, joint scaling': PAPER,
    },
    'architecture': {
        'FC 256-128-64-128-128 (no SAE)': dict(PAPER, sae_epochs=0),
        'FC 256-128 (no SAE)': dict(PAPER, sae_epochs=0, sae_layers=(256,),
                                    classifier_layers=(128,)),
        'SAE 256 + 128-128': dict(PAPER, sae_layers=(256,)),
        'SAE 256-128 + 128-128': dict(PAPER, sae_layers=(256, 128)),
        'SAE 256-128-64 + 128-128': PAPER,
    },
    'search': {
        'paper default': PAPER,
        'augment (offset 10, gain .1, noise 2, drop .1)': dict(PAPER, **AUG),
        'powed': dict(PAPER, representation='powed'),
        'exponential': dict(PAPER, representation='exponential'),
        'augment + powed': dict(PAPER, **AUG, representation='powed'),
        'augment + exponential': dict(PAPER, **AUG,
                                      representation='exponential'),
        'augment, no SAE': dict(PAPER, **AUG, sae_epochs=0),
        'augment, dropout .5': dict(PAPER, **AUG, dropout=0.5),
    },
    'search3': {
        'augment + exponential, EMA 4 epochs': dict(AUG_EXP, ema_epochs=4),
        'augment + exponential, EMA 4 epochs, lr 3e-4': dict(
            AUG_EXP, ema_epochs=4, learning_rate=3e-4),
    },
    'search2': {
        'augment + exponential, ensemble 3': dict(AUG_EXP, ensemble=3),
        'augment + exponential, ensemble 3, refit': dict(AUG_EXP, ensemble=3,
                                                         refit=True),
        'augment + exponential, no SAE': dict(AUG_EXP, sae_epochs=0),
        'stronger augment + exponential': dict(
            AUG_EXP, augment_offset=15.0, augment_gain=0.2,
            augment_noise=3.0, augment_dropout=0.2),
    },
}


def _fill(rssi, value):
    return np.where(np.isnan(rssi), value, rssi)


def sklearn_baselines(train_fp, test_fp, held, seed):
    """Return {name: (held-out scores, test scores, seconds)}."""
    models = {
        '1-NN raw, 100 = missing': (lambda: KNeighborsClassifier(1), 100.0),
        '5-NN, -110 = missing': (lambda: KNeighborsClassifier(5), -110.0),
        'random forest (100 trees), -110': (
            lambda: RandomForestClassifier(100, random_state=seed,
                                           n_jobs=-1), -110.0),
    }
    labels = train_fp.building * 100 + train_fp.floor
    out = {}
    for name, (make, fill) in models.items():
        start = time.perf_counter()
        x = _fill(train_fp.rssi, fill)
        held_pred = make().fit(x[~held], labels[~held]).predict(x[held])
        test_pred = make().fit(x, labels).predict(_fill(test_fp.rssi, fill))
        out[name] = (
            accuracies(train_fp.building[held], train_fp.floor[held],
                       held_pred // 100, held_pred % 100),
            accuracies(test_fp.building, test_fp.floor, test_pred // 100,
                       test_pred % 100),
            time.perf_counter() - start)
    return out


def summary(values):
    """Return mean, min, max of a list."""
    return {'mean': statistics.fmean(values), 'min': min(values),
            'max': max(values)}


def main():
    """Run the suite; print the table; write JSON."""
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--train', required=True)
    p.add_argument('--test', required=True)
    p.add_argument('--suite', choices=sorted(SUITES), default='default')
    p.add_argument('--seeds', type=int, nargs='+', default=[0, 1, 2])
    p.add_argument('--baselines', action=argparse.BooleanOptionalAction,
                   default=None, help='default: on for the default suite')
    p.add_argument('--out', type=Path, default=None)
    p.add_argument('--only', nargs='+', default=None, metavar='N',
                   help='run only these variants (numbers, from 0)')
    p.add_argument('--threads', type=int, default=0)
    args = p.parse_args()
    variants = list(SUITES[args.suite].items())
    if args.only:
        variants = [variants[int(i)] for i in args.only]
    out = args.out or Path(__file__).parent / 'results' / f'{args.suite}.json'
    train_fp = read_fingerprints(args.train)
    test_fp = read_fingerprints(args.test, role='test')
    runs = {}

    def record(name, seed, held_scores, test_scores, seconds):
        runs.setdefault(name, []).append({
            'seed': seed, 'held_out': held_scores, 'test': test_scores,
            'seconds': seconds})
        print(f'  {name:42s} seed {seed}: held-out '
              f'{held_scores["building_floor_accuracy"]:.4f}  test '
              f'{test_scores["building_floor_accuracy"]:.4f}  '
              f'({seconds:.1f} s)', file=sys.stderr, flush=True)

    for seed in args.seeds:
        for name, overrides in variants:
            config = TrainConfig(seed=seed, threads=args.threads,
                                 **overrides)
            model, _, report = train(train_fp, config, log=lambda s: None)
            b, f, _, _ = model.predict(test_fp.rssi)
            record(name, seed, report.validation,
                   accuracies(test_fp.building, test_fp.floor, b, f),
                   report.seconds)
        if args.baselines or (args.baselines is None and
                              args.suite == 'default'):
            held = split_validation(train_fp, TrainConfig(seed=seed))
            for name, result in sklearn_baselines(
                    train_fp, test_fp, held, seed).items():
                record(name, seed, *result)

    table = {}
    for name, seed_runs in runs.items():
        table[name] = {
            'held_out_building_floor': summary(
                [r['held_out']['building_floor_accuracy'] for r in seed_runs]),
            'test_building_floor': summary(
                [r['test']['building_floor_accuracy'] for r in seed_runs]),
            'test_building': summary(
                [r['test']['building_accuracy'] for r in seed_runs]),
            'test_floor': summary(
                [r['test']['floor_accuracy'] for r in seed_runs]),
            'seconds_median': statistics.median(
                r['seconds'] for r in seed_runs),
        }
    print(f'\ntrain {train_fp.source} ({len(train_fp)} scans), test '
          f'{test_fp.source} ({len(test_fp)} scans), seeds {args.seeds}')
    print('building+floor accuracy, mean (min-max) over seeds; held-out = '
          'whole phones of the training file')
    print(f'| {"variant":42s} | held-out phones      | test               '
          f'  | test building | train s |')
    print(f'|{"-" * 44}|{"-" * 22}|{"-" * 22}|{"-" * 15}|{"-" * 9}|')

    def cell(s):
        return f'{s["mean"]:.4f} ({s["min"]:.3f}-{s["max"]:.3f})'
    for name, row in table.items():
        print(f'| {name:42s} | {cell(row["held_out_building_floor"])} | '
              f'{cell(row["test_building_floor"])} | '
              f'{row["test_building"]["mean"]:.4f}        | '
              f'{row["seconds_median"]:7.1f} |')
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(out, 'w') as f:
        json.dump({'protocol': {'train': train_fp.source,
                                'train_sha256': train_fp.sha256,
                                'test': test_fp.source,
                                'test_sha256': test_fp.sha256,
                                'seeds': args.seeds,
                                'selection': 'whole phones (PHONEID) held '
                                             'out of the training file'},
                   'paper': PAPER_FIGURES, 'table': table, 'runs': runs}, f,
                  indent=1)
    print(f'wrote {out}')


if __name__ == '__main__':
    main()
