"""
Tracking on real walks: fit the tracking parameters, evaluate on test walks.

``fit`` chooses the parameters of a model file's tracker on TRAINING walks
and writes them into the file (its ``tracking`` section):

- change rates (floor, building) from the walks' labels and timestamps;
- temperature and minimum interval on class probabilities that did not see
  the walks: the model's own when the walks are not its training data
  (WiFine ``val/`` for a model trained on ``train/``), else from
  ``--cross-fit K`` models each trained without a K-th of the walks' phones;
- with a position model and true positions: the motion model (speed from
  the true positions, acceleration noise for the smallest filtered error of
  the model's positions).

``run`` replays each test walk in time order with the model's parameters
and reports tracked against single-scan answers: building+floor accuracy,
spurious switches (per hour and per 100 scans), the delay to follow a real
floor change (scans, seconds), per walk group. Table on stdout, JSON in
``benchmarks/results/tracking-NAME.json``.

    python benchmarks/tracking.py fit --model M.npz --walks TRAIN.csv \
        [--cross-fit 3]
    python benchmarks/tracking.py run --model M.npz --data TEST.csv \
        --name NAME

Walks: one per file (a folder of walks, e.g. WiFine), else the scans of
one USERID and PHONEID; each in TIMESTAMP order.
"""

import argparse
from dataclasses import replace
import json
from pathlib import Path
import sys
import time

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from wifi_place_recognition.core.artifact import (  # noqa: E402
    load_model, save_model)
from wifi_place_recognition.core.atomic import atomic_write  # noqa: E402
from wifi_place_recognition.core.evaluation import align  # noqa: E402
from wifi_place_recognition.core.tracking import (  # noqa: E402
    DEFAULT_TIMEOUT, PlaceTracker, track_walk, TrackingParams)
from wifi_place_recognition.core.tracking_fit import (  # noqa: E402
    fit_evidence, fit_motion, fit_rates)
from wifi_place_recognition.cli.common import (  # noqa: E402
    add_data_arguments, data_options, read_data)
from wifi_place_recognition.data.walks import walk_name, walks  # noqa: E402

RESULTS = Path(__file__).resolve().parent / 'results'


def class_rows(model, building, floor):
    """Return the row in ``model.classes`` of each pair (-1: unknown)."""
    index = {(int(b), int(f)): i for i, (b, f) in enumerate(model.classes)}
    return np.array([index.get((int(b), int(f)), -1)
                     for b, f in zip(building, floor)])


def probabilities(model, fp):
    """
    Return (proba (n, k), usable (n,)): the model's single-scan answers.

    A scan that detects no AP known to the model is not usable (the node
    rejects it); its row of ``proba`` is NaN.
    """
    rssi = align(model, fp)
    usable = np.isfinite(rssi).any(axis=1)
    proba = np.full((len(fp), len(model.classes)), np.nan)
    proba[usable] = model.predict_proba(rssi[usable])
    return proba, usable


def positions(model, fp, usable):
    """Return (xy (n, 2), cov (n, 2, 2)) of usable scans, or (None, None)."""
    if model.position is None:
        return None, None
    xy = np.full((len(fp), 2), np.nan)
    sigma = np.full(len(fp), np.nan)
    _, xy[usable], sigma[usable] = model.predict_positions(
        align(model, fp)[usable])
    return xy, sigma[:, None, None] ** 2 * np.eye(2)


def cross_fit_probabilities(model, fp, folds, options, log):
    """
    Return out-of-fold probabilities for ``fp`` in ``model``'s classes.

    The phones (PHONEID) are dealt into ``folds`` groups; each group is
    predicted by a network trained (torch, ``options`` over the trainer's
    defaults, one member, no selection, no position output) on the other
    phones.
    """
    from wifi_place_recognition.training.config import TrainConfig
    from wifi_place_recognition.training.trainer import train
    phones = np.unique(fp.meta['PHONEID'])
    order = np.random.default_rng(0).permutation(len(phones))
    proba = np.full((len(fp), len(model.classes)), np.nan)
    config = TrainConfig(**dict(dict(folds=0, ensemble=1), **options))
    for k in range(folds):
        held = np.isin(fp.meta['PHONEID'], phones[order[k::folds]])
        log(f'cross-fit {k + 1}/{folds}: phones '
            f'{sorted(int(p) for p in phones[order[k::folds]])} held out '
            f'({int(held.sum())} scans)')
        start = time.perf_counter()
        fold_model = train(fp.subset(~held), config, log=lambda s: None)[0]
        p, usable = probabilities(fold_model, fp.subset(held))
        columns = class_rows(model, *fold_model.classes.T)
        rows = np.flatnonzero(held)
        proba[rows] = 0.0
        proba[rows[:, None], columns[None, :]] = p
        proba[rows[~usable]] = np.nan
        log(f'  {time.perf_counter() - start:.0f} s')
    return proba, np.isfinite(proba).all(axis=1)


# fit -------------------------------------------------------------------------
def fit(args):
    """Choose the tracking parameters on training walks; write them."""
    model = load_model(args.model)
    fp = read_data(args.walks, data_options(args), 'training walks')
    walk_list = walks(fp)
    times = fp.meta['TIMESTAMP']
    floor_rate, building_rate, rates = fit_rates(
        [(times[w], fp.building[w], fp.floor[w]) for w in walk_list],
        DEFAULT_TIMEOUT)
    params = TrackingParams(floor_rate=floor_rate, building_rate=building_rate)
    print(f'rates: floor {floor_rate:.3g}/s, building {building_rate:.3g}/s '
          f'({rates})', flush=True)
    if args.cross_fit:
        options = json.loads(args.train_options)
        proba, usable = cross_fit_probabilities(
            model, fp, args.cross_fit, options,
            lambda s: print(s, flush=True))
        evidence = f'{args.cross_fit}-fold cross-fit over phones ' \
                   f'(trainer defaults + {options})'
    else:
        proba, usable = probabilities(model, fp)
        evidence = f'the model itself ({args.model.name}; the walks are ' \
                   f'not its training data)'
    truth = class_rows(model, fp.building, fp.floor)
    evidence_walks = []
    for w in walk_list:
        w = w[usable[w] & (truth[w] >= 0)]
        evidence_walks.append((times[w], truth[w], proba[w]))
    params, grid = fit_evidence(params, model.classes, evidence_walks)
    best = max(grid, key=lambda g: (g['accuracy'], g['mean_log_belief']))
    print(f'evidence: temperature {params.temperature:g}, min interval '
          f'{params.min_interval:g} s (tracked accuracy on the walks '
          f'{best["accuracy"]:.4f})', flush=True)
    motion = 'defaults (no position model or no true positions)'
    if model.position is not None and fp.position is not None:
        xy, cov = positions(model, fp, usable)
        used = [w[usable[w]] for w in walk_list]
        params, motion_grid = fit_motion(params, [
            (times[w], xy[w], cov[w], fp.position[w]) for w in used])
        motion = f'{args.model.name} positions on the walks' + \
            (' (in-sample)' if args.cross_fit else '')
        grid += motion_grid
        print(f'motion: speed sd {params.speed_sd:.3g} m/s, acceleration '
              f'noise {params.acceleration_noise:g} m^2/s^3', flush=True)
    model.tracking = replace(params, fit={
        'walks': fp.source, 'walks_sha256': fp.sha256,
        'rates': rates, 'evidence': evidence, 'motion': motion,
        'created': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())})
    save_model(model, args.model)
    print(f'{args.model}: tracking section written', flush=True)
    if args.grid:
        with atomic_write(args.grid, 'w') as f:
            json.dump(grid, f, indent=1)


# run -------------------------------------------------------------------------
def switches(answer, truth):
    """Return (switches onto a wrong class, all switches) of one walk."""
    changed = answer[1:] != answer[:-1]
    return int((changed & (answer[1:] != truth[1:])).sum()), \
        int(changed.sum())


def follow_delays(answer, truth, times):
    """
    Return (scans, seconds) to follow each real change of class.

    Counted from the first scan on the new class: 1 scan / 0 s = followed
    at once. A change not followed before the next one (or the walk's end)
    is NaN.
    """
    starts = np.flatnonzero(truth[1:] != truth[:-1]) + 1
    ends = list(starts[1:]) + [len(truth)]
    scans, seconds = [], []
    for start, end in zip(starts, ends):
        hit = np.flatnonzero(answer[start:end] == truth[start])
        scans.append(hit[0] + 1 if len(hit) else np.nan)
        seconds.append(times[start + hit[0]] - times[start] if len(hit)
                       else np.nan)
    return scans, seconds


def _summary(rows):
    """Sum a list of per-walk dicts into one (ratios recomputed)."""
    total = {k: sum(r[k] for r in rows) for k in
             ('scans', 'single_right', 'tracked_right', 'hours',
              'single_wrong_switches', 'tracked_wrong_switches',
              'single_switches', 'tracked_switches', 'real_changes')}
    delays = {k: [d for r in rows for d in r[k]] for k in
              ('single_delay_scans', 'single_delay_s', 'tracked_delay_scans',
               'tracked_delay_s')}
    out = dict(total)
    for who in ('single', 'tracked'):
        out[f'{who}_accuracy'] = total[f'{who}_right'] / total['scans']
        wrong = total[f'{who}_wrong_switches']
        out[f'{who}_wrong_switches_per_hour'] = wrong / total['hours'] \
            if total['hours'] else None
        out[f'{who}_wrong_switches_per_100_scans'] = \
            100 * wrong / total['scans']
        for unit in ('scans', 's'):
            d = np.array(delays[f'{who}_delay_{unit}'], float)
            out[f'{who}_median_delay_{unit}'] = \
                float(np.nanmedian(d)) if np.isfinite(d).any() else None
        out[f'{who}_changes_not_followed'] = int(
            np.isnan(np.array(delays[f'{who}_delay_scans'], float)).sum())
        if f'{who}_position_errors' in rows[0]:
            e = np.concatenate([r[f'{who}_position_errors'] for r in rows])
            out[f'{who}_position_mean_error_m'] = float(e.mean())
            out[f'{who}_position_median_error_m'] = float(np.median(e))
            out[f'{who}_position_p95_error_m'] = float(np.percentile(e, 95))
    return out


def evaluate_walks(model, fp, params):
    """Replay every walk of ``fp``; return one dict of figures per walk."""
    proba, usable = probabilities(model, fp)
    xy, cov = positions(model, fp, usable)
    truth = class_rows(model, fp.building, fp.floor)
    times = fp.meta['TIMESTAMP']
    tracker = PlaceTracker(model.classes, params)
    rows = []
    for w in walks(fp):
        w = w[usable[w]]
        if not len(w):
            continue
        t = times[w]
        single = proba[w].argmax(axis=1)
        tracks = track_walk(tracker, t, proba[w],
                            None if xy is None else xy[w],
                            None if cov is None else cov[w])
        tracked = np.array([tr.index for tr in tracks])
        gaps = np.diff(t)
        row = {'walk': walk_name(fp, w), 'scans': len(w),
               'hours': float(gaps[gaps <= DEFAULT_TIMEOUT].sum() / 3600),
               'real_changes': int((truth[w][1:] != truth[w][:-1]).sum())}
        for who, answer in (('single', single), ('tracked', tracked)):
            row[f'{who}_right'] = int((answer == truth[w]).sum())
            row[f'{who}_wrong_switches'], row[f'{who}_switches'] = \
                switches(answer, truth[w])
            row[f'{who}_delay_scans'], row[f'{who}_delay_s'] = \
                follow_delays(answer, truth[w], t)
        if xy is not None and fp.position is not None:
            true_xy = fp.position[w]
            row['single_position_errors'] = np.linalg.norm(
                xy[w] - true_xy, axis=1).tolist()
            row['tracked_position_errors'] = np.linalg.norm(
                np.array([tr.xy for tr in tracks]) - true_xy,
                axis=1).tolist()
        rows.append(row)
    return rows


def run(args):
    """Evaluate tracked against single-scan answers on test walks."""
    model = load_model(args.model)
    fp = read_data(args.data, data_options(args), 'test walks',
                   role='test')
    params = model.tracking or TrackingParams()
    rows = evaluate_walks(model, fp, params)
    summary = _summary(rows)
    print(f'{fp.source}: {len(rows)} walks, {summary["scans"]} scans, '
          f'{summary["hours"]:.2f} h of walking (gaps <= '
          f'{DEFAULT_TIMEOUT:g} s), {summary["real_changes"]} real changes')
    print(f'parameters: {params.to_dict()}')
    print(f'{"walk":24s} {"scans":>6s} {"single":>7s} {"tracked":>7s} '
          f'{"diff":>6s} {"wrong sw. single/tracked":>25s}')
    for r in rows:
        s, t = r['single_right'] / r['scans'], r['tracked_right'] / r['scans']
        print(f'{r["walk"][:24]:24s} {r["scans"]:6d} {s:7.4f} {t:7.4f} '
              f'{100 * (t - s):+6.1f} {r["single_wrong_switches"]:>12d} / '
              f'{r["tracked_wrong_switches"]:<10d}')
    print()
    print(f'{"":32s} {"single":>10s} {"tracked":>10s}')
    for key in ('accuracy', 'wrong_switches_per_hour',
                'wrong_switches_per_100_scans', 'median_delay_scans',
                'median_delay_s', 'changes_not_followed',
                'position_mean_error_m', 'position_median_error_m',
                'position_p95_error_m'):
        if f'single_{key}' not in summary:
            continue
        values = [summary[f'{who}_{key}'] for who in ('single', 'tracked')]
        print(f'{key.replace("_", " "):32s} ' + ' '.join(
            f'{v:10.4f}' if isinstance(v, float) else f'{v!s:>10s}'
            for v in values))
    out = {'data': fp.source, 'data_sha256': fp.sha256,
           'model': str(args.model), 'params': params.to_dict(),
           'summary': summary,
           'walks': [{k: v for k, v in r.items()
                      if not isinstance(v, list)} for r in rows]}
    path = RESULTS / f'tracking-{args.name}.json'
    with atomic_write(path, 'w') as f:
        json.dump(out, f, indent=1, default=float)
    print(f'\nwritten {path}')


def main():
    """Parse the command line and run ``fit`` or ``run``."""
    p = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    sub = p.add_subparsers(dest='command', required=True)
    f = sub.add_parser('fit', help='choose the tracking parameters on '
                                   'training walks, write them into --model')
    f.add_argument('--model', type=Path, required=True)
    f.add_argument('--walks', nargs='+', required=True,
                   help='training walks: CSV, folder of walk CSVs')
    f.add_argument('--cross-fit', type=int, default=0, metavar='K',
                   help='class probabilities from K models each trained '
                        'without a K-th of the phones (for walks the model '
                        'trained on)')
    f.add_argument('--train-options', default='{}',
                   help='JSON: TrainConfig overrides for --cross-fit')
    f.add_argument('--grid', type=Path,
                   help='write the evidence grid (JSON) here')
    r = sub.add_parser('run', help='evaluate on test walks')
    r.add_argument('--model', type=Path, required=True)
    r.add_argument('--data', nargs='+', required=True,
                   help='test walks: CSV, folder of walk CSVs')
    r.add_argument('--name', required=True,
                   help='results/tracking-NAME.json')
    for parser in (f, r):
        add_data_arguments(parser)
    args = p.parse_args()
    args.download = False
    (fit if args.command == 'fit' else run)(args)


if __name__ == '__main__':
    main()
