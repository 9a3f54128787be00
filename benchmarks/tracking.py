"""
Tracking on real walks: tracked against single-scan answers on test walks.

Each test walk is replayed in time order with a model's tracking
parameters. Reported, tracked against single-scan answers: building+floor
accuracy (overall and per walk), wrong switches (per hour and per 100
scans), the delay to follow a real change of class (scans, seconds), the
position error, the expected calibration error and the risk-coverage
curve of the answers' confidences (the point at 0.5, the node's default
``min_confidence``). With ``--fit-walks`` the parameters are first chosen
on those walks by the product command ``fit_tracking`` (on a copy of the
model). Table on stdout, JSON in ``benchmarks/results/tracking-NAME.json``.

    python benchmarks/tracking.py --model M.npz --data TEST \
        [--fit-walks VAL] --name NAME [reading options]

Walks: one per file (a folder of walks, e.g. WiFine), else the scans of
one USERID and PHONEID; each in TIMESTAMP order.
"""

import argparse
import json
from pathlib import Path
import tempfile

import numpy as np
from wifi_place_recognition.cli import fit_tracking
from wifi_place_recognition.cli.common import (
    add_data_arguments, add_download_arguments, data_options, read_data)
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.atomic import atomic_write
from wifi_place_recognition.core.metrics import (expected_calibration_error,
                                                 risk_coverage)
from wifi_place_recognition.core.tracking import (
    DEFAULT_TIMEOUT, PlaceTracker, track_walk, TrackingParams)
from wifi_place_recognition.core.tracking_fit import walk_evidence
from wifi_place_recognition.data.walks import walk_name, walks

RESULTS = Path(__file__).resolve().parent / 'results'


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
    out['walks'] = len(rows)
    out['walks_tracked_at_least_single'] = float(np.mean(
        [r['tracked_right'] >= r['single_right'] for r in rows]))
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
        confidence = np.concatenate([r[f'{who}_confidence'] for r in rows])
        hits = np.concatenate([r[f'{who}_hits'] for r in rows])
        out[f'{who}_ece'] = expected_calibration_error(confidence, hits)
        out[f'{who}_risk_coverage'] = risk_coverage(confidence, hits)
        point = next(p for p in out[f'{who}_risk_coverage']
                     if p['threshold'] == 0.5)
        out[f'{who}_answered_at_0.5'] = point['coverage']
        out[f'{who}_accuracy_at_0.5'] = point['accuracy']
        if f'{who}_position_errors' in rows[0]:
            e = np.concatenate([r[f'{who}_position_errors'] for r in rows])
            out[f'{who}_position_mean_error_m'] = float(e.mean())
            out[f'{who}_position_median_error_m'] = float(np.median(e))
            out[f'{who}_position_p95_error_m'] = float(np.percentile(e, 95))
    return out


def evaluate_walks(model, fp, params):
    """Replay every walk of ``fp``; return one dict of figures per walk."""
    walk_list = walks(fp)
    e = walk_evidence(model, fp, walk_list)
    tracker = PlaceTracker(model.classes, params)
    rows = []
    for w, name in zip(e.walks, [walk_name(fp, w) for w in walk_list]):
        if not len(w):
            continue
        t, truth = e.times[w], e.truth[w]
        single = e.proba[w].argmax(axis=1)
        tracks = track_walk(tracker, t, e.proba[w],
                            None if e.xy is None else e.xy[w],
                            None if e.cov is None else e.cov[w])
        tracked = np.array([tr.index for tr in tracks])
        gaps = np.diff(t)
        row = {'walk': name, 'scans': len(w),
               'hours': float(gaps[gaps <= DEFAULT_TIMEOUT].sum() / 3600),
               'real_changes': int((truth[1:] != truth[:-1]).sum())}
        confidence = {'single': e.proba[w].max(axis=1),
                      'tracked': np.array([tr.confidence for tr in tracks])}
        for who, answer in (('single', single), ('tracked', tracked)):
            row[f'{who}_right'] = int((answer == truth).sum())
            row[f'{who}_confidence'] = confidence[who].tolist()
            row[f'{who}_hits'] = (answer == truth).tolist()
            row[f'{who}_wrong_switches'], row[f'{who}_switches'] = \
                switches(answer, truth)
            row[f'{who}_delay_scans'], row[f'{who}_delay_s'] = \
                follow_delays(answer, truth, t)
        if e.xy is not None and e.true_xy is not None:
            true_xy = e.true_xy[w]
            row['single_position_errors'] = np.linalg.norm(
                e.xy[w] - true_xy, axis=1).tolist()
            row['tracked_position_errors'] = np.linalg.norm(
                np.array([tr.xy for tr in tracks]) - true_xy,
                axis=1).tolist()
        rows.append(row)
    return rows


def fitted_model(args):
    """Return (model, how its parameters were chosen, fit report or None)."""
    if not args.fit_walks:
        model = load_model(args.model)
        return (model, 'the model file' if model.tracking else 'defaults',
                None)
    with tempfile.TemporaryDirectory() as folder:
        out, report = Path(folder) / 'fitted.npz', Path(folder) / 'fit.json'
        if fit_tracking.main(['--model', str(args.model), '--walks',
                              *args.fit_walks, '-o', str(out), '--report',
                              str(report)] + args.reading) != 0:
            raise SystemExit('fit_tracking failed')
        return (load_model(out), f'fit_tracking on {" ".join(args.fit_walks)}',
                json.loads(report.read_text()))


def run(args):
    """Evaluate tracked against single-scan answers on test walks."""
    model, chosen, fit_report = fitted_model(args)
    reading = argparse.ArgumentParser()
    add_data_arguments(reading)
    add_download_arguments(reading)
    fp = read_data(args.data, data_options(reading.parse_args(args.reading)),
                   'test walks', role='test')
    params = model.tracking or TrackingParams()
    rows = evaluate_walks(model, fp, params)
    summary = _summary(rows)
    print(f'{fp.source}: {len(rows)} walks, {summary["scans"]} scans, '
          f'{summary["hours"]:.2f} h of walking (gaps <= '
          f'{DEFAULT_TIMEOUT:g} s), {summary["real_changes"]} real changes')
    print(f'parameters ({chosen}): '
          f'{ {k: v for k, v in params.to_dict().items() if k != "fit"} }')
    print(f'{"walk":24s} {"scans":>6s} {"single":>7s} {"tracked":>7s} '
          f'{"diff":>6s} {"wrong sw. single/tracked":>25s}')
    for r in rows:
        s, t = r['single_right'] / r['scans'], r['tracked_right'] / r['scans']
        print(f'{r["walk"][:24]:24s} {r["scans"]:6d} {s:7.4f} {t:7.4f} '
              f'{100 * (t - s):+6.1f} {r["single_wrong_switches"]:>12d} / '
              f'{r["tracked_wrong_switches"]:<10d}')
    print(f'\nwalks where tracked >= single: '
          f'{summary["walks_tracked_at_least_single"]:.2f}')
    print(f'{"":32s} {"single":>10s} {"tracked":>10s}')
    for key in ('accuracy', 'ece', 'answered_at_0.5', 'accuracy_at_0.5',
                'wrong_switches_per_hour',
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
           'model': str(args.model), 'params_chosen_by': chosen,
           'params': params.to_dict(), 'fit_report': fit_report,
           'summary': summary,
           'walks': [{k: v for k, v in r.items()
                      if not isinstance(v, list)} for r in rows]}
    path = RESULTS / f'tracking-{args.name}.json'
    with atomic_write(path, 'w') as f:
        json.dump(out, f, indent=1, default=float)
    print(f'\nwritten {path}')


def main():
    """Parse the command line (reading options as fit_tracking's) and run."""
    p = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    p.add_argument('--model', type=Path, required=True)
    p.add_argument('--data', nargs='+', required=True,
                   help='test walks: CSV, folder of walk CSVs')
    p.add_argument('--fit-walks', nargs='+', metavar='PATH',
                   help='choose the parameters on these walks first '
                        '(fit_tracking, same reading options)')
    p.add_argument('--name', required=True,
                   help='results/tracking-NAME.json')
    args, args.reading = p.parse_known_args()
    run(args)


if __name__ == '__main__':
    main()
