"""
Odometry fusion on the robot runs: fused against single scans and odometry.

For every ordered pair of runs of a building (train on one, localise the
other), by the documented commands: ``train_model`` on the training run's
scans, ``fit_odometry`` on the training run's scans and odometry (a copy
of the model), then the test run's scans and odometry in stamp order
through :func:`core.trajectory.fuse_offline` (what classifier_node runs)
with the model's fusion parameters: fitted, and the defaults (drift not
fitted). Started with no prior (the first scan, every heading); seeds
0, 1, 2 of the filter. Also: a kidnapped robot (two runs spliced, the
odometry continuous, the true position jumping) and the recovery time.
Table on stdout, JSON in ``benchmarks/results/fusion.json`` (with one
run's trajectories per building, seed 0, which ``benchmarks/figures.py``
draws).

    python benchmarks/fusion.py [--data ../shared/datasets/robot]
"""

import argparse
from itertools import permutations
import json
import math
from pathlib import Path
import subprocess
import sys
import tempfile

import numpy as np
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.atomic import atomic_write
from wifi_place_recognition.core.evaluation import align
from wifi_place_recognition.core.fusion import Fusion
from wifi_place_recognition.core.particles import FusionParams
from wifi_place_recognition.core.trajectory import (fuse_offline,
                                                    odometry_alone, score)
from wifi_place_recognition.data.fingerprints import read_fingerprints
from wifi_place_recognition.data.poses import read_poses

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / 'benchmarks' / 'results'
DEFAULT_DATA = ROOT.parent / 'shared' / 'datasets' / 'robot'
SEEDS = (0, 1, 2)
#: Where a kidnapped run is cut (share of each run's scans).
SPLICE_AT = 0.5
GOALS = ('ratio <= 0.5, max after 30 s <= 3 m, below 2 m from <= 30 s, '
         'yaw median <= 10 deg, 95 % ellipse 0.90-0.98')


def cli(name, *args):
    """Run a product command; raise with its stderr when it fails."""
    out = subprocess.run([sys.executable, '-m',
                          f'wifi_place_recognition.cli.{name}', *map(str,
                                                                     args)],
                         capture_output=True, text=True)
    if out.returncode:
        raise RuntimeError(f'{name} failed:\n{out.stderr}')
    return out.stdout


class Run:
    """One run's scans, truth at the scans, and odometry."""

    def __init__(self, folder):
        self.name = folder.name
        self.folder = folder
        fp = read_fingerprints(folder / 'scans.csv')
        self.fp = fp
        self.stamps = fp.meta['TIMESTAMP']
        self.xy = fp.position
        self.yaw = fp.meta['YAW']
        self.odometry = read_poses(folder / 'odom.csv')


def models(train, folder):
    """Train on ``train`` and fit its odometry: (plain path, fitted path)."""
    plain = Path(folder) / f'{train.name}.npz'
    fitted = Path(folder) / f'{train.name}-fitted.npz'
    cli('train_model', '--data', train.folder / 'scans.csv', '-o', plain,
        '--quiet')
    cli('fit_odometry', '--model', plain, '--data',
        train.folder / 'scans.csv', '--odometry',
        train.folder / 'odom.csv', '-o', fitted)
    return plain, fitted


def single_scans(model, run):
    """Return the model's single-scan positions of the run's scans."""
    return model.predict_positions(align(model, run.fp))[1]


def localise(params, odometry, stamps, xy, seed):
    """Return the fused (xy, yaw, cov) at every scan."""
    return fuse_offline(odometry, (stamps, xy), Fusion(params, seed=seed))


def pair(train_paths, test):
    """Return the figures of one test run with one training run's models."""
    plain, fitted = (load_model(p) for p in train_paths)
    single = single_scans(plain, test)
    odo_xy, odo_yaw = odometry_alone(test.odometry, test.stamps, test.xy,
                                     test.yaw)
    out = {'single': score(test.stamps, test.xy, single),
           'odometry': score(test.stamps, test.xy, odo_xy, test.yaw,
                             odo_yaw),
           'drift_fitted_deg_per_m': math.degrees(fitted.fusion.drift_mean)}
    for name, params in (('fused_fitted', fitted.fusion),
                         ('fused_default', FusionParams())):
        runs = []
        for seed in SEEDS:
            xy, yaw, cov = localise(params, test.odometry, test.stamps,
                                    single, seed)
            s = score(test.stamps, test.xy, xy, test.yaw, yaw, cov)
            s['ratio'] = s['mean_m'] / out['single']['mean_m']
            runs.append(s)
            if seed == SEEDS[0] and name == 'fused_fitted':
                fused = xy
        out[name] = runs
    out['trajectory'] = {     # seed 0, fitted: for the pictures
        'seconds': np.round(test.stamps - test.stamps[0], 2).tolist(),
        **{k: np.round(v, 2).tolist() for k, v in (
            ('truth', test.xy), ('single', single), ('odometry', odo_xy),
            ('fused', fused))}}
    return out


def spliced(a, b, single_a, single_b):
    """
    Return run ``a``'s first part then ``b``'s second, odometry continuous.

    (stamps, truth xy, truth yaw, single xy, odometry, splice stamp): ``b``
    is shifted in time to follow ``a``, its odometry moved rigidly so
    that it continues ``a``'s where the two meet.
    """
    i = int(len(a.stamps) * SPLICE_AT)
    j = int(len(b.stamps) * SPLICE_AT)
    cut_a, cut_b = a.stamps[i], b.stamps[j]
    shift = cut_a + 1.0 - cut_b
    oa = a.odometry[a.odometry[:, 0] < cut_a + 1.0]
    ob = b.odometry[b.odometry[:, 0] >= cut_b].copy()
    ob[:, 0] += shift
    turn = oa[-1, 3] - ob[0, 3]
    c, s = math.cos(turn), math.sin(turn)
    dx, dy = ob[:, 1] - ob[0, 1], ob[:, 2] - ob[0, 2]
    ob[:, 1] = oa[-1, 1] + c * dx - s * dy
    ob[:, 2] = oa[-1, 2] + s * dx + c * dy
    ob[:, 3] = ob[:, 3] + turn
    ob = ob[ob[:, 0] > oa[-1, 0]]
    stamps = np.concatenate([a.stamps[:i], b.stamps[j:] + shift])
    return (stamps, np.concatenate([a.xy[:i], b.xy[j:]]),
            np.concatenate([a.yaw[:i], b.yaw[j:]]),
            np.concatenate([single_a[:i], single_b[j:]]),
            np.concatenate([oa, ob]), cut_a + 1.0)


def kidnap(params, a, b, single_a, single_b):
    """Return the recovery figures of ``a`` spliced onto ``b``, per seed."""
    stamps, true_xy, true_yaw, single, odometry, cut = spliced(
        a, b, single_a, single_b)
    jump = float(np.linalg.norm(true_xy[np.searchsorted(stamps, cut)] -
                                true_xy[np.searchsorted(stamps, cut) - 1]))
    out = []
    for seed in SEEDS:
        xy, yaw, _ = localise(params, odometry, stamps, single, seed)
        error = np.linalg.norm(xy - true_xy, axis=1)
        after = stamps >= cut
        above = np.flatnonzero(after & (error >= 2.0))
        recovered = 0.0 if not len(above) else (
            float(stamps[above[-1] + 1] - cut) if above[-1] + 1 < len(stamps)
            else math.inf)
        out.append({'jump_m': jump, 'recovered_below_2m_after_s': recovered,
                    'mean_after_60s_m': float(
                        error[after & (stamps >= cut + 60)].mean())})
    return out


def summary_line(name, figures):
    """Return a table row: single, odometry, fused (mean of seeds)."""
    def mean(runs, key):
        return float(np.mean([r[key] for r in runs]))
    fit, default = figures['fused_fitted'], figures['fused_default']
    return (f'{name:22s} {figures["single"]["mean_m"]:7.2f} '
            f'{figures["odometry"]["mean_m"]:8.2f} {mean(fit, "mean_m"):7.2f}'
            f' {mean(fit, "ratio"):6.2f} '
            f'{max(r["max_after_settle_m"] for r in fit):6.2f} '
            f'{max(r["below_2m_from_s"] for r in fit):6.0f} '
            f'{mean(fit, "yaw_median_deg_after_settle"):6.1f} '
            f'{mean(fit, "in_95_ellipse"):6.3f} | '
            f'{mean(default, "mean_m"):7.2f} {mean(default, "ratio"):6.2f} '
            f'{max(r["max_after_settle_m"] for r in default):6.2f} '
            f'{mean(default, "in_95_ellipse"):6.3f}')


def main():
    """Run every pair of every building; print the table, write JSON."""
    p = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    p.add_argument('--data', type=Path, default=DEFAULT_DATA)
    p.add_argument('--out', type=Path, default=RESULTS / 'fusion.json')
    args = p.parse_args()
    results = {'protocol': __doc__.strip(), 'seeds': SEEDS, 'goals': GOALS,
               'pairs': {}, 'kidnap': {}}
    print(f'{"test <- train":22s} {"single":>7s} {"odometry":>8s} '
          f'{"fused":>7s} {"ratio":>6s} {"max30":>6s} {"<2m@":>6s} '
          f'{"yaw":>6s} {"ellip":>6s} | default: {"fused":>7s} '
          f'{"ratio":>6s} {"max30":>6s} {"ellip":>6s}')
    with tempfile.TemporaryDirectory() as folder:
        for site in sorted(d for d in args.data.iterdir() if d.is_dir()):
            runs = [Run(r) for r in sorted(site.iterdir())
                    if (r / 'odom.csv').exists()]
            trained = {r.name: models(r, folder) for r in runs}
            for k, (train, test) in enumerate(permutations(runs, 2)):
                name = f'{test.name} <- {train.name}'
                results['pairs'][name] = figures = pair(trained[train.name],
                                                        test)
                if k:       # one trajectory per building, for the picture
                    del figures['trajectory']
                print(summary_line(name, figures), flush=True)
            for a, b in permutations(runs, 2):
                # a third run's model; with two runs, a's (b is unseen)
                train = ([r for r in runs if r not in (a, b)] or [a])[0]
                plain, fitted = (load_model(m) for m in trained[train.name])
                result = kidnap(fitted.fusion, a, b, single_scans(plain, a),
                                single_scans(plain, b))
                results['kidnap'][f'{a.name} then {b.name} '
                                  f'(model {train.name})'] = result
                print(f'kidnap {a.name} -> {b.name} (model {train.name}): '
                      f'jump {result[0]["jump_m"]:.1f} m, below 2 m after '
                      + ', '.join(f'{r["recovered_below_2m_after_s"]:.0f}'
                                  for r in result) + ' s', flush=True)
    with atomic_write(args.out, 'w') as f:
        json.dump(results, f, indent=1)
    print(f'wrote {args.out}')


if __name__ == '__main__':
    main()
