"""
Where the survey never went: candidate ideas against the default.

Not the package's code: ideas for issue 35 scored on the fusion
benchmark's protocol (``benchmarks/fusion.py``: every ordered pair of a
building's runs, trained on one by ``train_model`` + ``fit_odometry``,
the other localised; the full survey and survey holes; a test scan
farther than 3 m from every kept training scan is "in a hole"), filter
seeds ``--seeds`` (default 0), the fitted odometry.

- **One-sidedness of the answer**: the mean resultant length of the
  directions from a scan's k-NN position to the survey positions within
  ``EDGE_RADIUS_M`` (1 with fewer than two). Inside a corridor the survey lies
  on both sides of the answer (near 0); a scan taken in a hole is
  answered at the edge of the surveyed stretch (near 1). A geometric
  feature of the answer: it does not rest on signal-space distances.
  Survey positions on the answer itself do not count.
  Its ROC AUC against the scans in holes, beside the model's coverage
  probability's.
  (The single-scan 95 % circle is widened by it in the package since:
  ``edge_sigma_m``, measured by ``fusion.py`` and ``panel.py``.)
- **The filter** (mean fused / single error, the worst pair, p95, the
  largest error after 60 s, the 95 % ellipse): the default; scans
  weighed by one-sidedness (coverage 1 - side, ``coverage_full`` 0.5);
  two sensor models that ask where the *particle* is: ``EdgeSensor`` (a
  particle more than 3 m from the survey expects the scan 3 m from the
  nearest survey position, on its way there: near where a k-NN answer
  from a hole lands, and continuous at 3 m) and ``BeliefSensor`` (a scan
  trusted as far as the particles lie within 3 m of the survey, once
  their heading is known: the particles' unweighted share, and the
  restart rule reads the previous scan's trust, as the sensor interface
  is called); and told which scans lie in holes (the upper bound).

Table on stdout, JSON in ``benchmarks/results/coverage-ideas.json``.

    python benchmarks/coverage_ideas.py [--data ../shared/datasets/robot]
"""

import argparse
from dataclasses import replace
from itertools import permutations
import json
from pathlib import Path
import sys
import tempfile

import numpy as np
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.atomic import atomic_write
from wifi_place_recognition.core.coverage import (
    COVERED_M, EDGE_RADIUS_M, one_sidedness, PAIRS_PER_STEP)
from wifi_place_recognition.core.filter.fusion import Fusion
from wifi_place_recognition.core.filter.sensor import WifiSensorModel
from wifi_place_recognition.core.filter.trajectory import fuse_offline, score
from wifi_place_recognition.training.coverage import auc

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fusion as fb  # noqa: E402  (the fusion benchmark's protocol)

#: The mean resultant length of the particles' headings from which the
#: heading counts as known (BeliefSensor).
HEADING_KNOWN = 0.9


def nearest_covered(xy, survey_xy, reach=COVERED_M):
    """Return each position moved to within ``reach`` of the survey."""
    out = np.array(xy, np.float64)
    step = max(1, PAIRS_PER_STEP // len(survey_xy))
    for start in range(0, len(out), step):
        block = out[start:start + step]
        d2 = ((block[:, None] - survey_xy[None]) ** 2).sum(axis=2)
        i = d2.argmin(axis=1)
        d = np.sqrt(d2[np.arange(len(i)), i])
        q, far = survey_xy[i], d > reach
        block[far] = q[far] + (block[far] - q[far]) * \
            (reach / d[far])[:, None]
    return out


class SurveySensor(WifiSensorModel):
    """A sensor model that knows the survey's positions (to 0.25 m)."""

    def __init__(self, params, survey_xy):
        super().__init__(params)
        self.survey = np.unique(np.round(survey_xy * 4) / 4, axis=0)


class EdgeSensor(SurveySensor):
    """The scan expected 3 m from the survey position nearest a particle."""

    def disagrees(self, xy, cov, scan):
        expected = nearest_covered(xy[None], self.survey)[0]
        return super().disagrees(expected, cov, scan)

    def likelihood(self, state, scan):
        p, width = self.params, self.width(scan)
        d2 = ((nearest_covered(state[:, :2], self.survey) - scan.xy) ** 2
              ).sum(axis=1)
        return (1 - p.wifi_outlier) * np.exp(-d2 / (2 * width ** 2)) + \
            p.wifi_outlier


class BeliefSensor(SurveySensor):
    """
    A scan trusted as far as the particles lie on the survey.

    Their unweighted share (the sensor sees no weights); the restart rule
    (:meth:`disagrees`, called first) reads the previous scan's trust.
    """

    def __init__(self, params, survey_xy):
        super().__init__(params, survey_xy)
        self.believed = 1.0

    def disagrees(self, xy, cov, scan):
        return self.believed >= 0.5 and super().disagrees(xy, cov, scan)

    def likelihood(self, state, scan):
        heading = abs(np.mean(np.exp(1j * state[:, 2])))
        on = np.all(nearest_covered(state[:, :2], self.survey) ==
                    state[:, :2], axis=1).mean()
        self.believed = trust = on if heading > HEADING_KNOWN else 1.0
        p, width = self.params, self.width(scan)
        d2 = ((state[:, :2] - scan.xy) ** 2).sum(axis=1)
        floor = p.wifi_outlier + (1 - p.wifi_outlier) * (1 - trust)
        return (1 - p.wifi_outlier) * trust * \
            np.exp(-d2 / (2 * width ** 2)) + floor


def survey_positions(model):
    """Return every reference position of a model (m, map frame)."""
    return np.concatenate([model.position.map_xy(c)
                           for c in range(len(model.classes))])


def filters(fitted, single, side, hole, survey_xy):
    """Return {name: (params, scans' coverage, sensor factory)}."""
    weighed = replace(fitted.fusion, coverage_full=0.5)
    return {
        'default': (fitted.fusion, single[2], None),
        'weighed by one-sidedness': (weighed, 1 - np.nan_to_num(side, nan=1),
                                     None),
        'edge sensor': (fitted.fusion, single[2],
                        lambda p: EdgeSensor(p, survey_xy)),
        'belief sensor': (fitted.fusion, single[2],
                          lambda p: BeliefSensor(p, survey_xy)),
        'told the holes': (weighed, np.where(hole, 0.0, 1.0), None)}


def pair(trained, test, seeds):
    """Return the figures of one test run with one training run's models."""
    plain, fitted = (load_model(p) for p in trained[:2])
    single = fb.single_scans(plain, test)
    hole = fb.in_holes(test, trained[2])
    survey_xy = survey_positions(plain)
    side = one_sidedness(single[0], survey_xy)
    ok = np.isfinite(single[0]).all(axis=1) & np.isfinite(test.xy).all(
        axis=1)
    judged = hole[ok].any()
    modelled = judged and np.isfinite(single[2][ok]).all()
    out = {'hole_scans': int(hole[ok].sum()),
           'auc_coverage': auc(single[2][ok], ~hole[ok]) if modelled
           else None,      # None: no hole, or no coverage model
           'auc_one_sidedness': auc(-side[ok], ~hole[ok]) if judged
           else None}
    alone = fb.single_figures(test, single, hole)['mean_m']
    out['filters'] = {}
    for name, (params, coverage, sensor) in filters(
            fitted, single, side, hole, survey_xy).items():
        runs = []
        for seed in seeds:
            xy, yaw, cov = fuse_offline(
                test.odometry, (test.stamps, single[0], single[1], coverage),
                Fusion(params, seed=seed,
                       sensor=sensor(params) if sensor else None))
            s = score(test.stamps, test.xy, xy, test.yaw, yaw, cov,
                      settle_s=fb.SETTLE_S)
            runs.append({'ratio': s['mean_m'] / alone, 'p95_m': s['p95_m'],
                         'max_after_settle_m': s['max_after_settle_m'],
                         'in_95_ellipse': s['in_95_ellipse']})
        out['filters'][name] = runs
    return out


def line(name, figures):
    """Return one table row."""
    def f(value):
        return '-' if value is None else f'{value:.2f}'
    text = (f'{name:28s} {figures["hole_scans"]:4d} '
            f'{f(figures["auc_coverage"]):>5s} '
            f'{f(figures["auc_one_sidedness"]):>5s}  ratio ')
    return text + ' '.join(
        f'{np.mean([r["ratio"] for r in runs]):.3f}'
        for runs in figures['filters'].values())


def summary(results):
    """Return the filters' mean ratio, worst ratio, p95, max after 60 s."""
    out = {}
    for name in next(iter(results.values()))['filters']:
        runs = [r for figures in results.values()
                for r in figures['filters'][name]]
        out[name] = {
            'mean_ratio': float(np.mean([r['ratio'] for r in runs])),
            'worst_ratio': max(r['ratio'] for r in runs),
            'worst_p95_m': max(r['p95_m'] for r in runs),
            'worst_max_after_settle_m': max(r['max_after_settle_m']
                                            for r in runs),
            'ellipse': [min(r['in_95_ellipse'] for r in runs),
                        max(r['in_95_ellipse'] for r in runs)]}
    return out


def main():
    """Run every pair of every building; print the table, write JSON."""
    p = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    p.add_argument('--data', type=Path, default=fb.DEFAULT_DATA)
    p.add_argument('--seeds', default='0',
                   help='filter seeds, comma-separated (default 0)')
    p.add_argument('--out', type=Path,
                   default=fb.RESULTS / 'coverage-ideas.json')
    args = p.parse_args()
    seeds = [int(s) for s in args.seeds.split(',')]
    results = {}
    print(f'{"test <- survey":28s} hole  AUC: P  side  fused / single: '
          f'default, weighed, edge, belief, told')
    with tempfile.TemporaryDirectory() as folder:
        for site, runs in fb.site_runs(args.data, folder):
            for holes in (False, True):
                trained = {r.name: fb.models(r, folder, holes) for r in runs}
                for train, test in permutations(runs, 2):
                    name = (f'{test.name} <- {train.name}, '
                            f'{"holes" if holes else "full"}')
                    results[name] = pair(trained[train.name], test, seeds)
                    print(line(name, results[name]), flush=True)
    total = summary(results)
    for name, s in total.items():
        print(f'{name}: mean {s["mean_ratio"]:.3f}, worst '
              f'{s["worst_ratio"]:.2f}, p95 up to {s["worst_p95_m"]:.1f} m, '
              f'max after 60 s up to {s["worst_max_after_settle_m"]:.1f} m, '
              f'ellipse {s["ellipse"][0]:.2f}-{s["ellipse"][1]:.2f}')
    with atomic_write(args.out, 'w') as f:
        json.dump({'protocol': __doc__.strip(), 'seeds': seeds,
                   'radius_m': EDGE_RADIUS_M, 'pairs': results,
                   'summary': total}, f, indent=1)
    print(f'wrote {args.out}')


if __name__ == '__main__':
    main()
