"""
Where the survey never went: candidate ideas against the default.

Not the package's code: ideas for issue 35 scored on the fusion
benchmark's protocol (``benchmarks/fusion.py``: every ordered pair of a
building's runs, trained on one by ``train_model`` + ``fit_odometry``,
the other localised; the full survey and survey holes; a test scan
farther than 3 m from every kept training scan is "in a hole"), filter
seeds ``--seeds`` (default 0), the fitted odometry. The filter is round
23's: the scans' mismatch (round 24's widening, ``fusion.py``) is not
given to it, so every idea is measured against the filter it was
proposed for ("the default" here: the default without the mismatch).

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
- **The heading at a start** (the filter starts from a scan with every
  heading, and where the robot drives slowly past poor scans it settles
  on a wrong one): told the true heading whenever it starts (the upper
  bound: the particles' headings set to AMCL's, 0.1 rad spread), and
  the survey's corridor as a heading prior (``AxisPriorFusion``: while
  the particles' heading is not known and the robot drives, a particle
  whose direction of travel lies across the principal axis of the
  survey positions within ``AXIS_RADIUS_M`` of the scan's answer is
  weighed down, in proportion to how line-like they lie); and told
  both the heading at a start and the holes; the heading the scans'
  own track gives (``TrackHeadingFusion``: the odometry of the last
  ``track_s`` seconds turned onto the scans' positions by least squares,
  as the filter's misfit does, gives the map heading; each particle
  weighed by it, a Gaussian of ``TRACK_HEADING_K`` times the fit's root
  mean square residual (at least ``TRACK_HEADING_LEAST_M``) over the
  track's root mean square radius, over the outlier floor), always or
  only while the particles' heading is not known.
- **How soon a hole must be known** (round 23): told the holes
  ``LATE_SCANS`` scans late, entering and leaving (what a detector
  averaged over the last scans could at best do).
- **The loudness as a weight** (round 23): a scan's loudness excess (the
  most by which it hears an AP louder than the loudest reading of it
  among the references its class searches, ``circle_ideas.excess``),
  averaged over the last ``LOUD_SCANS`` scans; the scan counts 1 below
  ``lo`` dB, 0 above ``hi``, linearly between (``coverage_full`` 1), for
  each (lo, hi) of ``LOUD_RAMPS``; a scan that hears no AP the
  references heard counts fully.

Table on stdout, JSON in ``benchmarks/results/coverage-ideas.json``.

    python benchmarks/coverage_ideas.py [--data ../shared/datasets/robot]
"""

import argparse
from dataclasses import replace
from itertools import permutations
import json
import math
from pathlib import Path
import sys
import tempfile

import numpy as np
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.atomic import atomic_write
from wifi_place_recognition.core.coverage import (
    COVERED_M, EDGE_RADIUS_M, one_sidedness, PAIRS_PER_STEP)
from wifi_place_recognition.core.evaluation import align, scan_answers
from wifi_place_recognition.core.filter.angles import wrap
from wifi_place_recognition.core.filter.fusion import Fusion, relative
from wifi_place_recognition.core.filter.particles import UNKNOWN_VARIANCE
from wifi_place_recognition.core.filter.sensor import WifiSensorModel
from wifi_place_recognition.core.filter.track_misfit import (TrackMisfit,
                                                             track_fit)
from wifi_place_recognition.core.filter.trajectory import fuse_offline, score
from wifi_place_recognition.training.coverage import auc

sys.path.insert(0, str(Path(__file__).resolve().parent))
from circle_ideas import excesses  # noqa: E402  (the loudness excess)
import fusion as fb  # noqa: E402  (the fusion benchmark's protocol)

#: The mean resultant length of the particles' headings from which the
#: heading counts as known (BeliefSensor).
HEADING_KNOWN = 0.9
#: The heading prior: survey positions within this radius of the answer
#: (m), the least number of them, the robot's least travel over the last
#: 2 s (m), the prior's sharpness and its largest share (at a line).
AXIS_RADIUS_M, AXIS_MIN_REFS, AXIS_MOVED_M = 4.0, 5, 0.3
AXIS_KAPPA, AXIS_SHARE = 4.0, 0.8
#: Spread (rad) of the true heading a told start is given.
TOLD_HEADING_SD = 0.1
#: The heading from the scans' track: its width is this many times the
#: fit's residual (at least the least, m) over the track's radius.
TRACK_HEADING_K, TRACK_HEADING_LEAST_M = 1.0, 2.0
#: The holes told this many scans late.
LATE_SCANS = (5, 10)
#: The loudness weight: scans averaged, and (lo, hi) dB of its ramp.
LOUD_SCANS, LOUD_RAMPS = 10, ((2.0, 5.0), (3.0, 6.0), (5.0, 8.0))


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


class HeadingToldFusion(Fusion):
    """The filter told the true heading whenever it starts afresh."""

    def __init__(self, params, seed, stamps, yaw):
        super().__init__(params, seed=seed)
        self.truth = stamps, yaw

    def _apply(self, scan, odometry):
        pose = super()._apply(scan, odometry)
        if pose is not None and pose.restarted:
            stamps, yaw = self.truth
            i = min(np.searchsorted(stamps, scan[0]), len(stamps) - 1)
            state = self.filter.state
            state[:, 2] = wrap(yaw[i] + TOLD_HEADING_SD *
                               self.filter.rng.standard_normal(len(state)))
        return pose


class AxisPriorFusion(Fusion):
    """The survey's corridor direction as a prior on an unknown heading."""

    def __init__(self, params, seed, survey_xy):
        super().__init__(params, seed=seed)
        self.survey = survey_xy

    def axis(self, xy):
        """Return (direction, line-likeness) of the survey near ``xy``."""
        near = self.survey[np.hypot(*(self.survey - xy).T) <= AXIS_RADIUS_M]
        if len(near) < AXIS_MIN_REFS:
            return None
        low, high = np.linalg.eigh(np.cov(near.T))
        if low[1] <= 0:
            return None
        return math.atan2(high[1, 1], high[0, 1]), 1 - low[0] / low[1]

    def _apply(self, scan, odometry):
        f = self.filter
        if odometry and f.started and len(self.odom) > 1 and \
                abs(f.weight @ np.exp(1j * f.state[:, 2])) < HEADING_KNOWN:
            step = relative(self._odometry_at(scan[0] - 2.0)[1:],
                            self._odometry_at(scan[0])[1:])
            axis = self.axis(scan[1]) if \
                math.hypot(*step[:2]) >= AXIS_MOVED_M else None
            if axis:
                across = f.state[:, 2] + math.atan2(step[1], step[0]) - \
                    axis[0]
                share = AXIS_SHARE * axis[1]
                f.weight = f.weight * (1 - share + share * np.exp(
                    AXIS_KAPPA * (np.cos(2 * across) - 1)))
                f.weight /= f.weight.sum()
        return super()._apply(scan, odometry)


class TrackHeadingSensor(WifiSensorModel):
    """The default sensor, and a heading to weigh the next update by."""

    heading = None      # (map heading, its width), used once

    def likelihood(self, state, scan):
        """Return the default likelihood times the heading's, if any."""
        out = super().likelihood(state, scan)
        if self.heading is not None:
            (mean, width), self.heading = self.heading, None
            turn = wrap(state[:, 2] - mean)
            floor = self.params.wifi_outlier
            out = out * ((1 - floor) * np.exp(-turn ** 2 / (2 * width ** 2))
                         + floor)
        return out


class TrackHeadingFusion(Fusion):
    """The heading the scans' track gives weighs the particles."""

    def __init__(self, params, seed, while_unknown):
        super().__init__(params, seed=seed, sensor=TrackHeadingSensor(params))
        self.while_unknown = while_unknown
        self.track = TrackMisfit(params.track_s)    # its own, up to the scan

    def heading(self, stamp, xy):
        """Return (map heading, width) from the scans' track, or None."""
        at = self._odometry_at(stamp)
        if self.track.add(stamp, xy, at[1:3]) is None:
            return None
        _, scans, odo = np.array(self.track.track).T
        turn, left = track_fit(scans, odo)
        residual = max(math.sqrt((np.abs(left) ** 2).mean()),
                       TRACK_HEADING_LEAST_M)
        radius = math.sqrt((np.abs(odo - odo.mean()) ** 2).mean())
        return (at[3] + math.atan2(turn.imag, turn.real),
                min(TRACK_HEADING_K * residual / radius, math.pi))

    def _apply(self, scan, odometry):
        f = self.filter
        if not (odometry and f.started and scan[2] == self.place):
            self.track.clear()
        else:
            heading = self.heading(scan[0], scan[1])
            if heading is not None and not (
                    self.while_unknown and
                    f.estimate().cov[2, 2] < UNKNOWN_VARIANCE):
                f.sensor.heading = heading
        pose = super()._apply(scan, odometry)
        f.sensor.heading = None
        if pose is not None and pose.restarted:
            self.track.clear()
        return pose

    def _replay(self):
        self.filter.sensor.heading = None   # not the replayed scans'
        super()._replay()


def late(hole, scans):
    """Return a mask: the holes as known ``scans`` scans after each."""
    out = np.zeros_like(hole)
    out[scans:] = hole[:max(len(hole) - scans, 0)]
    return out


def recent_mean(values, scans):
    """
    Return each value averaged with those before it (``scans`` in all).

    Values that are not finite are left out; NaN where none is left.
    """
    out = np.full(len(values), np.nan)
    for i in range(len(values)):
        window = values[max(0, i - scans + 1):i + 1]
        window = window[np.isfinite(window)]
        if len(window):
            out[i] = window.mean()
    return out


def loudness(model, test, proba):
    """Return each test scan's loudness excess (dB; -inf: no AP shared)."""
    return excesses(model.position, align(model, test.fp),
                    proba.argmax(axis=1))


def survey_positions(model):
    """Return every reference position of a model (m, map frame)."""
    return np.concatenate([model.position.map_xy(c)
                           for c in range(len(model.classes))])


def filters(fitted, single, side, hole, survey_xy, test, loud):
    """Return {name: (params, scans' coverage, fusion factory)}."""
    weighed = replace(fitted.fusion, coverage_full=0.5)
    loud = np.nan_to_num(recent_mean(loud, LOUD_SCANS), nan=-np.inf)

    def sensor(kind):
        return lambda p, seed: Fusion(p, seed=seed,
                                      sensor=kind(p, survey_xy))
    return {
        'default': (fitted.fusion, single[2], None),
        'weighed by one-sidedness': (weighed, 1 - np.nan_to_num(side, nan=1),
                                     None),
        'edge sensor': (fitted.fusion, single[2], sensor(EdgeSensor)),
        'belief sensor': (fitted.fusion, single[2], sensor(BeliefSensor)),
        'told the holes': (weighed, np.where(hole, 0.0, 1.0), None),
        'survey axis as heading prior': (
            fitted.fusion, single[2],
            lambda p, seed: AxisPriorFusion(p, seed, survey_xy)),
        'told the heading at a start': (
            fitted.fusion, single[2],
            lambda p, seed: HeadingToldFusion(p, seed, test.stamps,
                                              test.yaw)),
        'heading from the track': (
            fitted.fusion, single[2],
            lambda p, seed: TrackHeadingFusion(p, seed, False)),
        'heading from the track while unknown': (
            fitted.fusion, single[2],
            lambda p, seed: TrackHeadingFusion(p, seed, True)),
        'told both': (
            weighed, np.where(hole, 0.0, 1.0),
            lambda p, seed: HeadingToldFusion(p, seed, test.stamps,
                                              test.yaw)),
        **{f'told the holes {k} scans late': (
            weighed, np.where(late(hole, k), 0.0, 1.0), None)
           for k in LATE_SCANS},
        **{f'weighed by loudness, {lo:g}-{hi:g} dB': (
            replace(fitted.fusion, coverage_full=1.0),
            np.clip((hi - loud) / (hi - lo), 0.0, 1.0), None)
           for lo, hi in LOUD_RAMPS}}


def pair(trained, test, seeds):
    """Return the figures of one test run with one training run's models."""
    plain, fitted = (load_model(p) for p in trained[:2])
    proba, *single = scan_answers(plain, test.fp)   # single: as fb's
    hole = fb.in_holes(test.xy, trained[2])
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
    for name, (params, coverage, fusion) in filters(
            fitted, single, side, hole, survey_xy, test,
            loudness(plain, test, proba)).items():
        runs = []
        for seed in seeds:
            xy, yaw, cov = fuse_offline(
                test.odometry, (test.stamps, single[0], single[1], coverage),
                fusion(params, seed) if fusion else
                Fusion(params, seed=seed))
            s = score(test.stamps, test.xy, xy, test.yaw, yaw, cov,
                      settle_s=fb.SETTLE_S)
            runs.append({'ratio': s['mean_m'] / alone, 'p95_m': s['p95_m'],
                         'max_after_settle_m': s['max_after_settle_m'],
                         'in_95_ellipse': s['in_95_ellipse'],
                         'yaw_median_deg': s[
                             'yaw_median_deg_after_settle']})
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
    """
    Return each filter's figures over every pair and per building.

    Mean and worst fused / single, the worst p95, largest error after 60
    s and yaw median, the range of the 95 % ellipse.
    """
    def figures(runs):
        return {
            'mean_ratio': float(np.mean([r['ratio'] for r in runs])),
            'worst_ratio': max(r['ratio'] for r in runs),
            'worst_p95_m': max(r['p95_m'] for r in runs),
            'worst_max_after_settle_m': max(r['max_after_settle_m']
                                            for r in runs),
            'ellipse': [min(r['in_95_ellipse'] for r in runs),
                        max(r['in_95_ellipse'] for r in runs)],
            'worst_yaw_median_deg': max(r['yaw_median_deg'] for r in runs)}
    buildings = sorted({name.split('test')[0] for name in results})
    out = {}
    for name in next(iter(results.values()))['filters']:
        out[name] = figures([r for f in results.values()
                             for r in f['filters'][name]])
        out[name]['by_building'] = {b: figures(
            [r for pair, f in results.items() if pair.startswith(b)
             for r in f['filters'][name]]) for b in buildings}
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
          f'default, weighed, edge, belief, told, axis, heading, track, '
          f'track while unknown, both, told {LATE_SCANS[0]} and '
          f'{LATE_SCANS[1]} scans late, loudness ' + ', '.join(
              f'{lo:g}-{hi:g} dB' for lo, hi in LOUD_RAMPS))
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
        for where, f in (('all', s), *s['by_building'].items()):
            print(f'{name} ({where}): mean {f["mean_ratio"]:.3f}, worst '
                  f'{f["worst_ratio"]:.2f}, p95 up to {f["worst_p95_m"]:.1f} '
                  f'm, max after 60 s up to '
                  f'{f["worst_max_after_settle_m"]:.1f} m, ellipse '
                  f'{f["ellipse"][0]:.2f}-{f["ellipse"][1]:.2f}, yaw median '
                  f'up to {f["worst_yaw_median_deg"]:.1f} deg')
    with atomic_write(args.out, 'w') as f:
        json.dump({'protocol': __doc__.strip(), 'seeds': seeds,
                   'radius_m': EDGE_RADIUS_M, 'pairs': results,
                   'summary': total}, f, indent=1)
    print(f'wrote {args.out}')


if __name__ == '__main__':
    main()
