"""
Panel benchmark: the default on every dataset, baselines, published figures.

``run`` (the judge of every default): for each dataset of the panel
(TUT1, TUT2, TUT5, TUT6, TUT7, DSI1, UJIIndoorLoc, WiFine, and the robot
runs: one run of a site to train, another to test) and each seed,
the default is trained by the documented command (``train_model`` with no
option beyond the dataset's format flags, in a subprocess whose wall time
and peak memory are measured) on the training part and scored by
``evaluate_model`` on the test part. Its ``cv_*`` figures are what the
model's own selection measured on held-out training scans (grouped folds):
the score defaults are chosen on. Baselines in the same run: k-NN with
Euclidean and Sorensen (Bray-Curtis) distances over the positive-dBm,
powed and exponential representations, the representation, distance and
k (1-11) chosen by grouped 4-fold cross-validation on the training part
(folds of seed 0; k-NN is deterministic, so it runs once), separately for
building+floor and for position; a random forest (100 trees, -110 dBm)
per seed. The test part is only ever evaluated.

The table and JSON also give the probabilities' calibration on the test
part: the model's temperature, the expected calibration error (10 bins of
the top-class probability), the share of scans answered at the node's
default ``min_confidence`` and their building+floor accuracy; the JSON
holds each run's reliability table and whole risk-coverage curve
(thresholds 0-1 by 0.01), which ``plots`` draws, a row per dataset
(``results/panel-reliability.png`` from ``panel.json``,
``results/panel-large-reliability.png`` from ``panel-large.json``). The
robot runs' figures are in ``results/panel-robot.json``.

``cv``: the cross-validation of recipe variants alone (no test file):
``--variants '{"name": {TrainConfig overrides}}'``; prints the held-out
building+floor and position per dataset, mean over seeds.

    python benchmarks/panel.py run
    python benchmarks/panel.py run --datasets tut1,tut2 --seeds 0
    python benchmarks/panel.py cv --variants '{"b64": {"batch_size": 64}}'
    python benchmarks/panel.py plots --json benchmarks/results/panel.json
"""

import argparse
import json
from pathlib import Path
import sys
import tempfile
import time

import numpy as np
from sklearn.ensemble import RandomForestClassifier

from wifi_place_recognition.core.atomic import atomic_write
from wifi_place_recognition.core.evaluation import align
from wifi_place_recognition.core.metrics import accuracies, class_index
from wifi_place_recognition.core.locator import METRICS
from wifi_place_recognition.core.preprocessing import signal, SIGNALS
from wifi_place_recognition.ros.classifier_parameters import PARAMETERS
from wifi_place_recognition.training.config import TrainConfig
from wifi_place_recognition.training.folds import grouped_folds

from datasets import DATASETS, PANEL, PUBLISHED, read, ROBOT
from runs import summary, train_and_test

ROOT = Path(__file__).resolve().parent.parent
ALL = PANEL + ('ujiindoorloc', 'wifine') + tuple(ROBOT)
KS = (1, 3, 5, 7, 9, 11)


def neighbours(ref, queries, metric, kmax=max(KS)):
    """Return (indices, distances) of each query's ``kmax`` nearest refs."""
    kmax = min(kmax, len(ref))
    ref_sum = ref.sum(axis=1)
    ref_sq = (ref.astype(np.float64) ** 2).sum(axis=1)
    idx = np.empty((len(queries), kmax), np.int64)
    dist = np.empty((len(queries), kmax))
    for i, q in enumerate(queries):
        cols = np.flatnonzero(q)
        block, qv = ref[:, cols], q[cols]
        if metric == 'euclidean':
            d = ref_sq + float(qv @ qv) - 2 * (block @ qv)
            d = np.sqrt(np.fmax(d, 0))
        else:
            total = ref_sum + qv.sum()
            common = np.minimum(block, qv).sum(axis=1)
            d = np.where(total > 0, 1 - 2 * common / np.where(
                total > 0, total, 1), 1.0)
        part = np.argpartition(d, kmax - 1)[:kmax]
        part = part[np.argsort(d[part], kind='stable')]
        idx[i], dist[i] = part, d[part]
    return idx, dist


def _weights(dist, k):
    w = 1 / np.fmax(dist[:, :k], 1e-9)
    return w / w.sum(axis=1, keepdims=True)


def knn_predict(idx, dist, k, y=None, xy=None, n_classes=None):
    """Return distance-weighted class votes (or positions) for ``k``."""
    w = _weights(dist, k)
    if xy is not None:
        return (w[:, :, None] * xy[idx[:, :k]]).sum(axis=1)
    votes = np.zeros((len(idx), n_classes))
    np.add.at(votes, (np.arange(len(idx))[:, None], y[idx[:, :k]]), w)
    return votes.argmax(axis=1)


def knn_baselines(train_fp, test_fp):
    """
    Return {name: test figures} of the k-NN chosen by cross-validation.

    One k-NN for the class (held-out building+floor), one for the position
    (held-out mean error), each over representation x distance x k.
    """
    fp = train_fp.subset(~train_fp.empty_rows)
    classes, y = class_index(fp.building, fp.floor)
    held = grouped_folds(fp, y, 4, seed=0).held_out
    test_rssi = align(fp, test_fp)
    scores = {}
    for rep in SIGNALS:
        x = signal(fp.rssi, rep)
        for metric in METRICS:
            right = {k: 0 for k in KS}
            error = {k: 0.0 for k in KS}
            for mask in held:
                idx, dist = neighbours(x[~mask], x[mask], metric)
                for k in KS:
                    right[k] += (knn_predict(idx, dist, k, y[~mask],
                                             n_classes=len(classes))
                                 == y[mask]).sum()
                    if fp.position is not None:
                        error[k] += np.linalg.norm(
                            knn_predict(idx, dist, k,
                                        xy=fp.position[~mask])
                            - fp.position[mask], axis=1).sum()
            n = sum(int(m.sum()) for m in held)
            for k in KS:
                scores[rep, metric, k] = (right[k] / n, error[k] / n)
    out = {}
    rep, metric, k = max(scores, key=lambda c: scores[c][0])
    x, t = signal(fp.rssi, rep), signal(test_rssi, rep)
    idx, dist = neighbours(x, t, metric)
    predicted = classes[knn_predict(idx, dist, k, y,
                                    n_classes=len(classes))]
    out[f'k-NN class ({metric}, {rep}, k={k}; by CV)'] = dict(
        accuracies(test_fp.building, test_fp.floor, predicted[:, 0],
                   predicted[:, 1]), cv_building_floor=scores[
                       rep, metric, k][0])
    if fp.position is not None and test_fp.position is not None:
        rep, metric, k = min(scores, key=lambda c: scores[c][1])
        x, t = signal(fp.rssi, rep), signal(test_rssi, rep)
        idx, dist = neighbours(x, t, metric)
        xy = knn_predict(idx, dist, k, xy=fp.position)
        error = np.linalg.norm(xy - test_fp.position, axis=1)
        out[f'k-NN position ({metric}, {rep}, k={k}; by CV)'] = {
            'position_mean_error_m': float(error.mean()),
            'position_median_error_m': float(np.median(error)),
            'cv_position_mean_error_m': scores[rep, metric, k][1]}
        five = min(5, len(fp))
        idx, dist = neighbours(signal(fp.rssi, 'positive'),
                               signal(test_rssi, 'positive'),
                               'euclidean', five)
        xy = knn_predict(idx, dist, five, xy=fp.position)
        out['k-NN position (euclidean, dBm, k=5)'] = {
            'position_mean_error_m': float(np.linalg.norm(
                xy - test_fp.position, axis=1).mean())}
    return out


def forest(train_fp, test_fp, seed):
    """Return the test figures of a random forest: 100 trees on dBm."""
    fp = train_fp.subset(~train_fp.empty_rows)
    classes, y = class_index(fp.building, fp.floor)
    test_rssi = align(fp, test_fp)
    model = RandomForestClassifier(100, random_state=seed, n_jobs=1)
    model.fit(signal(fp.rssi, 'positive'), y)
    predicted = classes[model.predict(signal(test_rssi, 'positive'))]
    return accuracies(test_fp.building, test_fp.floor, predicted[:, 0],
                      predicted[:, 1])


KEYS = ('building_floor_accuracy', 'building_accuracy', 'cv_building_floor',
        'position_mean_error_m', 'position_median_error_m',
        'cv_position_mean_error_m', 'position_in_95_ellipse', 'epochs',
        'train_seconds', 'train_peak_mib', 'temperature', 'ece',
        'answered_at_default', 'accuracy_at_default')
#: The node's default min_confidence: its answers at or above it are OK
#: (may change ~/current_place).
MIN_CONFIDENCE = dict((name, default) for name, default, _ in
                      PARAMETERS)['min_confidence']


def _calibration_figures(result):
    """Add the ECE and the risk-coverage point at the node's default."""
    c = result.get('calibration')
    if c is None:
        return result
    point = next(p for p in c['risk_coverage']
                 if abs(p['threshold'] - MIN_CONFIDENCE) < 1e-9)
    result.update(temperature=c['temperature'], ece=c['ece'],
                  answered_at_default=point['coverage'],
                  accuracy_at_default=point['accuracy'])
    return result


def run(args):
    """Train and test the default and the baselines on every dataset."""
    results = {}
    for name in args.datasets:
        data = DATASETS[name]
        train_fp, test_fp = read(args.root, name, 'train'), \
            read(args.root, name, 'test')
        paths = {part: [str(args.root / p) for p in data[part]]
                 for part in ('train', 'test')}
        runs = {}
        with tempfile.TemporaryDirectory() as folder:
            for seed in args.seeds:
                try:
                    r = _calibration_figures(train_and_test(
                        args.flags, seed, paths['train'], paths['test'],
                        data['args'], folder))
                except RuntimeError as e:
                    r = {'refused': str(e).strip().splitlines()[-1]}
                runs.setdefault('default', []).append(r)
                print(f'{name} seed {seed}: '
                      + ', '.join(f'{k} {r[k]:.4g}' for k in KEYS
                                  if isinstance(r.get(k), float))
                      + (f' refused: {r["refused"]}' if 'refused' in r
                         else ''), file=sys.stderr, flush=True)
                if len(set(zip(train_fp.building, train_fp.floor))) > 1:
                    runs.setdefault('random forest (100 trees, dBm)',
                                    []).append(forest(train_fp, test_fp,
                                                      seed))
        if not args.no_knn:
            for method, r in knn_baselines(train_fp, test_fp).items():
                runs[method] = [r]
        results[name] = {
            'train': paths['train'], 'test': paths['test'],
            'train_sha256': train_fp.sha256, 'test_sha256': test_fp.sha256,
            'published_best': PUBLISHED.get(name, (None, None))[0],
            'published_knn': PUBLISHED.get(name, (None, None))[1],
            'table': {m: {k: summary([r.get(k) for r in rs]) for k in KEYS}
                      for m, rs in runs.items()},
            'runs': runs}
        _print_dataset(name, results[name])
    _print_panel(results)
    return {'seeds': args.seeds, 'flags': args.flags, 'datasets': results}


def cv(args):
    """Cross-validate recipe variants on every dataset (no test file)."""
    from wifi_place_recognition.training.selection import cross_validate
    variants = json.loads(args.variants or '{"default": {}}')
    out = {}
    for name in args.datasets:
        fp = read(args.root, name, 'train')
        fp = fp.subset(~fp.empty_rows)
        classes, y = class_index(fp.building, fp.floor)
        for variant, overrides in variants.items():
            for seed in args.seeds:
                start = time.perf_counter()
                s = cross_validate(fp, y, len(classes), TrainConfig(
                    **dict(overrides, seed=seed)), log=lambda *a: None)
                row = {'cv_building_floor': s['accuracy_mean'],
                       'cv_position_mean_error_m':
                           s.get('position_mean_error_m'),
                       'epochs': s['epochs'],
                       'seconds': time.perf_counter() - start,
                       'mean_curve': s['mean_curve']}
                out.setdefault(name, {}).setdefault(variant, []).append(row)
                print(f'{name} {variant} seed {seed}: '
                      f'b+f {row["cv_building_floor"]:.4f} pos '
                      f'{row["cv_position_mean_error_m"] or float("nan"):.2f}'
                      f' epochs {row["epochs"]} {row["seconds"]:.0f} s',
                      file=sys.stderr, flush=True)
    print('\n| variant | ' + ' | '.join(out) + ' | mean |')
    print('|---' * (len(out) + 2) + '|')
    for variant in variants:
        cells, means = [], []
        for name in out:
            rows = out[name][variant]
            acc = np.mean([r['cv_building_floor'] for r in rows])
            pos = [r['cv_position_mean_error_m'] for r in rows
                   if r['cv_position_mean_error_m'] is not None]
            means.append(acc)
            cells.append(f'{acc:.4f}' + (f' / {np.mean(pos):.2f} m'
                                         if pos else ''))
        print(f'| {variant} | ' + ' | '.join(cells)
              + f' | {np.mean(means):.4f} |')
    return {'seeds': args.seeds, 'variants': variants, 'datasets': out}


def _cell(s, fmt='.4f'):
    if s is None:
        return '-'
    if s['min'] == s['max']:
        return f'{s["mean"]:{fmt}}'
    return f'{s["mean"]:{fmt}} ({s["min"]:{fmt}}-{s["max"]:{fmt}})'


def _print_dataset(name, result):
    print(f'\n{name}: train {result["train"]}, test {result["test"]}; '
          f'mean (min-max) over seeds; published best '
          f'{result["published_best"]}, published k-NN '
          f'{result["published_knn"]}')
    print('| method | test b+f | test building | CV b+f | position mean (m)'
          ' | CV position (m) | in 95% circle | temperature | ECE | '
          f'answered at p >= {MIN_CONFIDENCE:g} | their b+f | epochs | '
          'train s | peak MiB |')
    print('|---' * 14 + '|')
    for method, row in result['table'].items():
        print(f'| {method} | {_cell(row["building_floor_accuracy"])} | '
              f'{_cell(row["building_accuracy"])} | '
              f'{_cell(row["cv_building_floor"])} | '
              f'{_cell(row["position_mean_error_m"], ".2f")} | '
              f'{_cell(row["cv_position_mean_error_m"], ".2f")} | '
              f'{_cell(row["position_in_95_ellipse"], ".3f")} | '
              f'{_cell(row["temperature"], ".2f")} | '
              f'{_cell(row["ece"])} | '
              f'{_cell(row["answered_at_default"], ".3f")} | '
              f'{_cell(row["accuracy_at_default"])} | '
              f'{_cell(row["epochs"], ".0f")} | '
              f'{_cell(row["train_seconds"], ".0f")} | '
              f'{_cell(row["train_peak_mib"], ".0f")} |')


def _best(table, prefix, key, pick):
    rows = [row[key]['mean'] for m, row in table.items()
            if m.startswith(prefix) and row.get(key)]
    return pick(rows) if rows else None


def _print_panel(results):
    print('\n| dataset | default b+f | published best | best k-NN b+f (CV) '
          '| forest b+f | default position (m) | best k-NN position (CV) '
          f'| in 95% circle | ECE | answered at p >= {MIN_CONFIDENCE:g} | '
          'their b+f | train s |')
    print('|---' * 12 + '|')
    for name, r in results.items():
        t, d = r['table'], r['table']['default']
        cells = [_best(t, 'k-NN class', 'building_floor_accuracy', max),
                 _best(t, 'random', 'building_floor_accuracy', max),
                 _best(t, 'k-NN position (', 'position_mean_error_m', min)]
        knn, rf, knn_xy = ('-' if v is None else f'{v:.4f}' for v in cells)
        print(f'| {name} | {_cell(d["building_floor_accuracy"])} | '
              f'{r["published_best"] or "-"} | {knn} | {rf} | '
              f'{_cell(d["position_mean_error_m"], ".2f")} | {knn_xy} | '
              f'{_cell(d["position_in_95_ellipse"], ".3f")} | '
              f'{_cell(d["ece"])} | '
              f'{_cell(d["answered_at_default"], ".3f")} | '
              f'{_cell(d["accuracy_at_default"])} | '
              f'{_cell(d["train_seconds"], ".0f")} |')


def plots(args):
    """
    Draw each dataset's reliability diagram and risk-coverage curve.

    From a ``run`` JSON (``--json``): one PNG beside it,
    ``<json stem>-reliability.png``, a row per dataset of several classes
    (every seed of the default).
    """
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot
    result = json.loads(args.json.read_text())
    names = [name for name, r in result['datasets'].items()
             if len(r['runs']['default'][0].get('classes', ())) > 1]
    figure, axes = pyplot.subplots(len(names), 2, squeeze=False,
                                   figsize=(9, 3.3 * len(names)))
    for name, (left, right) in zip(names, axes):
        left.plot([0, 1], [0, 1], color='grey', lw=0.8)
        for seed, run in zip(result['seeds'],
                             result['datasets'][name]['runs']['default']):
            c = run['calibration']
            rows = c['reliability']
            left.plot([b['confidence'] for b in rows],
                      [b['accuracy'] for b in rows], 'o-', ms=3,
                      label=f'seed {seed}: ECE {c["ece"]:.3f}, '
                            f'T {c["temperature"]:.2f}')
            curve = [p for p in c['risk_coverage'] if p['coverage'] > 0]
            line, = right.plot([p['coverage'] for p in curve],
                               [p['accuracy'] for p in curve], lw=1)
            point = _calibration_figures(dict(run))
            right.plot(point['answered_at_default'],
                       point['accuracy_at_default'], 'o',
                       color=line.get_color())
        left.set(xlabel='confidence (top class, 10 bins)',
                 ylabel='building+floor right', xlim=(0, 1), ylim=(0, 1),
                 title=f'{name}: reliability')
        left.legend(fontsize=7, loc='upper left')
        right.set(xlabel='share of scans answered (confidence >= t)',
                  ylabel='building+floor right among them',
                  title=f'{name}: risk-coverage (dot: t = '
                        f'{MIN_CONFIDENCE:g})')
        right.ticklabel_format(useOffset=False, style='plain')
    figure.tight_layout()
    out = args.json.with_name(f'{args.json.stem}-reliability.png')
    figure.savefig(out, dpi=80)
    print(f'wrote {out}')


def main():
    """Run the benchmark; print tables; write JSON."""
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('mode', choices=('run', 'cv', 'plots'))
    p.add_argument('--root', type=Path,
                   default=ROOT.parent / 'shared' / 'datasets',
                   help='folder holding panel/, ujiindoorloc/, wifine/, robot/')
    p.add_argument('--datasets', type=lambda s: s.split(','),
                   default=list(ALL))
    p.add_argument('--seeds', type=lambda s: [int(v) for v in s.split(',')],
                   default=[0, 1, 2])
    p.add_argument('--flags', default='',
                   help='run: extra train_model flags (a variant), quoted')
    p.add_argument('--variants', help='cv: JSON {name: overrides}')
    p.add_argument('--no-knn', action='store_true',
                   help='run: skip the k-NN baselines')
    p.add_argument('--out', type=Path)
    p.add_argument('--json', type=Path,
                   default=ROOT / 'benchmarks' / 'results' / 'panel.json',
                   help='plots: the run JSON to draw from')
    args = p.parse_args()
    if args.mode == 'plots':
        return plots(args)
    unknown = set(args.datasets) - set(DATASETS)
    if unknown:
        p.error(f'unknown datasets {sorted(unknown)}; known: {sorted(ALL)}')
    args.flags = args.flags.split()
    result = {'run': run, 'cv': cv}[args.mode](args)
    out = args.out or ROOT / 'benchmarks' / 'results' / \
        f'panel-{args.mode}.json'
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(out, 'w') as f:
        json.dump(result, f, indent=1, default=float)
    print(f'wrote {out}')


if __name__ == '__main__':
    main()
