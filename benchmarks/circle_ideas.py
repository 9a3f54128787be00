"""
The single-scan 95 % circle where the survey never went: widenings tried.

Not the package's code: ideas for issue 35's single-scan circle (0.90-0.98
on the robot runs with survey holes), scored on the fusion benchmark's
pairs (``benchmarks/fusion.py``: every ordered pair of a building's runs,
the model trained by ``train_model`` on one, the other's scans placed; the
full survey and survey holes; a test scan farther than 3 m from every kept
training scan is "in a hole"). The ideas learn from places cut out of the
survey (:func:`cut_places`: discs of 4-8 m radius round survey scans, the
scans of the centre's class inside, until a third of the survey is cut;
4 cuttings, seeded), each cut scan placed among the rest by the model's
own position search (a survey's folds hold out stretches of time, most of
them passed again: few of their scans lie off the survey):

- **default**: the package's circle (the k-NN sigma widened at the
  survey's edge by ``edge_sigma_m`` times the one-sidedness to the 4th,
  and since round 29 by 4 m where the scan sounds more than 1.4 times as
  unlike its references as the survey's usual: ``core/locator.py``).
- **before round 29**: the same without the mismatch's widening; every
  idea below widens this one.
- **edge from cut places**: that edge widening calibrated on the cut
  scans off the survey instead.
- **coverage widening**: a coverage model (the package's features, a
  logistic regression) fitted on the cut scans, and the circle widened to
  hypot(sigma, e (1 - P(covered))^3), e the least that puts 95 % of the
  cut scans inside (at most 15 m, as the edge widening).
- **coverage widening, prior held out**: the same, the probability's
  prior (the regression's intercept) moved from the cut scans' share
  covered to the share among the model's own held-out scans (its
  coverage report): the share another pass over the survey meets.
- **loud k dB, m m/dB**: the circle widened to hypot(sigma, m max(0, x -
  k)), x the scan's loudness excess: the most by which it hears an AP
  louder than the loudest reading of it among the references its class
  searches (the locator keeps that reading: each AP row's int8 scale;
  APs those references never heard left out: the node counts those as
  unknown). Near an AP that no survey place was near, a scan hears it
  louder than the survey ever did. A grid of k and m; one is chosen on
  each building (the most circles within 0.90-0.98, then the least
  distance outside it, then the least from 0.95) and reported on the
  other (leave-one-building-out).
- **loud k dB, calibrated**: m learned per survey, as ``train_model``
  learns the edge widening: the survey's own folds (its default grouped
  folds), each held-out scan placed among the kept ones (the true class
  searched), m the least that puts 95 % of the held-out scans louder
  than the kept ones by more than k inside (none with fewer than 10).
- **mismatch k x, w m**: the circle widened to hypot(sigma, w) where the
  scan's mismatch over the survey's usual (what the filter reads) is
  above k. A grid of k and w, chosen as the loudness widening is, on
  each building (reported on the other) and on both together (what the
  package ships).

Per pair: the share of the test scans inside their circle (all, in holes,
covered), the cut model's ROC AUC against the scans in holes beside the
model's own, and e; of the scans in holes, the median one-sidedness and
P(covered) of those the circle before round 29 misses and holds (every
idea but the default widens that circle). With ``--panel``, also the
default, the circle before round 29 and every loudness and mismatch
widening on each panel dataset's test file (another day; the model
trained by ``train_model --seed 0``, UJIIndoorLoc the shipped model),
where a widening must not push a circle past 0.98; those chosen are
printed. Table on stdout, JSON in ``benchmarks/results/circle-ideas.json``.

    python benchmarks/circle_ideas.py [--data ../shared/datasets/robot]
                                      [--panel]
"""

import argparse
import json
from pathlib import Path
import sys
import tempfile

import numpy as np
from sklearn.linear_model import LogisticRegression
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.atomic import atomic_write
from wifi_place_recognition.core.coverage import (
    COVERED_M, distance_by_place, features, unheard_share)
from wifi_place_recognition.core.evaluation import align
from wifi_place_recognition.core.locator import (
    calibrated_edge_sigma, EDGE_POWER, least_widening, LEVELS, Locator,
    R95)
from wifi_place_recognition.core.preprocessing import signal, signal_dbm
from wifi_place_recognition.data.fingerprints import read_fingerprints
from wifi_place_recognition.training.config import TrainConfig
from wifi_place_recognition.training.coverage import auc, logit
from wifi_place_recognition.training.folds import grouped_folds

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fusion as fb  # noqa: E402  (the fusion benchmark's protocol)

#: Disc radius (m), share of the survey cut, cuttings, the power of
#: 1 - P(covered) that widens the circle.
CUT_RADIUS_M, CUT_SHARE, CUTTINGS, POWER = (4.0, 8.0), 1 / 3, 4, 3


#: Loudness widenings: (margin dB, metres per dB beyond it), and the
#: margin of the one calibrated per survey.
LOUD = tuple((k, m) for k in (0.0, 1.0, 2.0, 3.0, 5.0)
             for m in (0.5, 1.0, 2.0, 4.0))
CALIBRATED_K = 3.0
LOUD_CALIBRATED = f'loud {CALIBRATED_K:g} dB, calibrated'
#: Mismatch widenings: (ratio over the usual, metres added in quadrature).
MISMATCH = tuple((k, w) for k in (1.1, 1.2, 1.3, 1.4, 1.5, 1.6)
                 for w in (2.0, 3.0, 4.0, 5.0, 6.0, 8.0))
BEFORE = 'before round 29'
#: The band a circle should hold, and where a choice aims within it.
BAND, AIM = (0.90, 0.98), 0.95

#: The ideas, in the table's order (the loudness grid in its own table).
ALL = ('default', BEFORE, 'edge from cut places', 'coverage widening',
       'coverage widening, prior held out', LOUD_CALIBRATED)


def loud_name(k, m):
    """Return the name of a loudness widening."""
    return f'loud {k:g} dB, {m:g} m/dB'


def mismatch_name(k, w):
    """Return the name of a mismatch widening."""
    return f'mismatch {k:g} x, {w:g} m'


def before(model, xy, knn, classes):
    """Return each answer's circle sigma without the mismatch's widening."""
    return np.array([model.position.widened(a, k, c)
                     for a, k, c in zip(xy, knn, classes)])


def mismatch_circles(circle, mismatch):
    """Return {idea: sigma}: the mismatch grid, on the circle before."""
    ratio = np.nan_to_num(mismatch, nan=0.0)
    return {mismatch_name(k, w): np.where(ratio > k, np.hypot(circle, w),
                                          circle) for k, w in MISMATCH}


def excess(locator, columns, rssi, c):
    """
    Return how much louder than the survey a scan hears an AP (dB).

    The most by which it hears an AP (``columns``, ``rssi`` dBm) louder
    than the loudest reading of it among the references class c
    searches (LEVELS times the AP row's scale, in dBm); -inf when it
    hears none the references heard.
    """
    g = locator.group[c]
    rows = locator.row_of[g, columns]
    shared = rows >= 0
    if not shared.any():
        return -np.inf
    loudest = signal_dbm(locator.scale[locator.ap_start[g] +
                                       rows[shared]] * LEVELS,
                         locator.representation)
    return float(np.max(np.asarray(rssi, np.float64)[shared] - loudest))


def excesses(locator, rssi, classes):
    """Return the loudness excess of each scan (rows of model columns)."""
    out = []
    for row, c in zip(rssi, classes):
        cols = np.flatnonzero(~np.isnan(row))
        out.append(excess(locator, cols, row[cols], c))
    return np.array(out)


def loud_circles(circle, x, loud_m):
    """Return {idea: sigma}: the grid's and the calibrated widening."""
    out = {loud_name(k, m): np.hypot(circle, m * np.maximum(0.0, x - k))
           for k, m in LOUD}
    out[LOUD_CALIBRATED] = np.hypot(
        circle, loud_m * np.maximum(0.0, x - CALIBRATED_K))
    return out


def survey_classes(model, fp):
    """Return the model's class index of each of a survey's scans."""
    index = {tuple(int(v) for v in c): i for i, c in enumerate(model.classes)}
    return np.array([index[(int(b), int(f))]
                     for b, f in zip(fp.building, fp.floor)])


def kept_locator(model, rssi, y, xy, keep):
    """Return the model's locator rebuilt on the ``keep`` scans only."""
    pos = model.position
    return Locator.build(rssi[keep], y[keep], xy[keep], len(model.classes),
                         pos.neighbours, pos.sigma, pos.columns,
                         pos.representation, pos.metric, pos.group,
                         pos.edge_sigma)


def calibrated_loud_m(model, fp):
    """
    Return (m, scans it learned from): the loudness widening of a survey.

    ``fp`` the survey's scans, placed fold by fold among the kept ones
    as the model places a scan (the true class searched): m the least
    that puts 95 % of those louder than the kept references by more
    than CALIBRATED_K within their circle (0 with fewer than 10).
    """
    pos, rssi, y = model.position, align(model, fp), survey_classes(model, fp)
    config = TrainConfig()
    error, sigma, x = [], [], []
    for held in grouped_folds(fp, y, config.folds, config.grouping,
                              config.seed).held_out:
        locator = kept_locator(model, rssi, y, fp.position, ~held)
        for row, c, truth in zip(rssi[held], y[held], fp.position[held]):
            cols = np.flatnonzero(~np.isnan(row))
            distance = locator.distances(
                cols, signal(row[cols], pos.representation), c)
            at, knn = locator.weighted(distance, pos.neighbours, c)
            error.append(np.linalg.norm(at - truth))
            sigma.append(locator.widened(at, knn, c))
            x.append(excess(locator, cols, row[cols], c))
    error, sigma, x = (np.array(v) for v in (error, sigma, x))
    loud = np.isfinite(error) & (x > CALIBRATED_K)
    if loud.sum() < 10:
        return 0.0, int(loud.sum())
    return least_widening(error[loud], sigma[loud],
                          x[loud] - CALIBRATED_K), int(loud.sum())


def cut_places(xy, y, rng):
    """Return which survey scans one cutting removes (a mask)."""
    ok = np.isfinite(xy).all(axis=1)
    cut = np.zeros(len(xy), bool)
    while cut.sum() < CUT_SHARE * ok.sum():
        i = rng.choice(np.flatnonzero(ok & ~cut))
        near = np.linalg.norm(xy - xy[i], axis=1) < rng.uniform(*CUT_RADIUS_M)
        cut |= ok & near & (y == y[i])
    return cut


def cut_examples(model, survey_csv, seed=0):
    """
    Return the cut scans' (features, covered, error m, k-NN sigma m, side).

    Each placed among the survey's other scans, as the model places a scan.
    """
    fp = read_fingerprints(survey_csv)
    rssi, xy, pos = align(model, fp), fp.position, model.position
    y = survey_classes(model, fp)
    rng = np.random.default_rng(seed)
    x, covered, answers = [], [], []
    for _ in range(CUTTINGS):
        cut = cut_places(xy, y, rng)
        keep = ~cut
        locator = kept_locator(model, rssi, y, xy, keep)
        covered.append(distance_by_place(xy[cut], y[cut], xy[keep],
                                         y[keep]) <= COVERED_M)
        for row, c, truth in zip(rssi[cut], y[cut], xy[cut]):
            cols = np.flatnonzero(~np.isnan(row))
            distance = locator.distances(
                cols, signal(row[cols], pos.representation), c)
            x.append(features(locator, distance, c,
                              unheard_share(locator, cols, c)))
            at, knn = locator.weighted(distance, pos.neighbours, c)
            answers.append((np.linalg.norm(at - truth), knn,
                            locator.one_sidedness(at, c)
                            if np.isfinite(at).all() else np.nan))
    x, answers = np.array(x), np.array(answers)
    ok = np.isfinite(x).all(axis=1) & np.isfinite(answers).all(axis=1)
    return x[ok], np.concatenate(covered)[ok], *answers[ok].T


def pair(model, survey_csv, test, kept, calibrated):
    """
    Return the circle figures of one test run with one survey's model.

    ``calibrated``: the survey's :func:`calibrated_loud_m`.
    """
    rssi = align(model, test.fp)
    proba, xy, default, p, mismatch = model.predict_positions(
        rssi, coverage=True)
    loud = excesses(model.position, rssi, proba.argmax(axis=1))
    loud_m, loud_scans = calibrated
    knn = model.predict_positions(rssi, widened=False)[2]
    circle = before(model, xy, knn, proba.argmax(axis=1))
    side = np.array([model.position.one_sidedness(a, c)
                     if np.isfinite(a).all() else np.nan
                     for a, c in zip(xy, proba.argmax(axis=1))])
    error = np.linalg.norm(xy - test.xy, axis=1)
    ok = np.isfinite(error)
    hole = fb.in_holes(test.xy, kept)
    x, covered, c_error, c_knn, c_side = cut_examples(model, survey_csv)
    mean, scale = x.mean(axis=0), np.maximum(x.std(axis=0), 1e-9)
    fit = LogisticRegression().fit((x - mean) / scale, covered)
    c_base = np.hypot(c_knn, model.position.edge_sigma *
                      c_side ** EDGE_POWER)
    report = (model.coverage.report or {}) if model.coverage else {}
    held_out = report.get('covered', 0) / max(report.get(
        'held_out_scans', 0), 1)
    shifts = {'coverage widening': 0.0}
    if 0 < held_out < 1:
        shifts['coverage widening, prior held out'] = \
            logit(held_out) - logit(covered.mean())
    test_x = test_features(model, rssi, proba.argmax(axis=1))
    sigmas = {'default': default, BEFORE: circle}
    cut_off = ~covered
    edge = calibrated_edge_sigma(c_error[cut_off], c_knn[cut_off],
                                 c_side[cut_off])
    sigmas['edge from cut places'] = np.hypot(knn, edge * side ** EDGE_POWER)
    out = {'hole_scans': int((hole & ok).sum()),
           'auc_model': auc(p[ok], ~hole[ok]) if (hole & ok).any() and
           np.isfinite(p[ok]).all() else None,
           'auc_cut': None, 'edge_from_cut_places_m': edge, 'e_m': {},
           'loud_calibrated_m_per_db': loud_m,
           'loud_calibration_scans': loud_scans}
    for name, shift in shifts.items():
        def probability(rows):
            z = fit.decision_function((rows - mean) / scale) + shift
            return 1 / (1 + np.exp(-np.clip(z, -30, 30)))
        e = least_widening(c_error, c_base,
                           (1 - probability(x)) ** POWER)
        wide = np.hypot(circle, e * (1 - probability(test_x)) ** POWER)
        sigmas[name] = np.where(np.isfinite(test_x).all(axis=1), wide,
                                circle)
        out['e_m'][name] = e
        if (hole & ok).any() and not shift:
            out['auc_cut'] = auc(probability(test_x)[ok], ~hole[ok])
    miss = ok & hole & (error > R95 * circle)
    hit = ok & hole & ~miss
    out['default_in_holes'] = {   # what the answers show, missed or not
        f'{key}_median_{what}': float(np.nanmedian(v[rows]))
        if rows.any() and np.isfinite(v[rows]).any() else None
        for what, rows in (('missed', miss), ('inside', hit))
        for key, v in (('one_sidedness', side), ('p_covered', p))}
    sigmas.update(loud_circles(circle, loud, loud_m))
    sigmas.update(mismatch_circles(circle, mismatch))
    out['loudness_excess_db'] = {   # medians, scans with an AP heard
        where: float(np.median(loud[rows & np.isfinite(loud)]))
        if (rows & np.isfinite(loud)).any() else None
        for where, rows in (('in_holes', ok & hole),
                            ('covered', ok & ~hole))}
    out['in_95_circle'] = {}
    for name, sigma in sigmas.items():
        inside = error <= R95 * sigma
        out['in_95_circle'][name] = {
            'all': float(inside[ok].mean()),
            'in_holes': float(inside[ok & hole].mean())
            if (ok & hole).any() else None,
            'covered': float(inside[ok & ~hole].mean())}
    return out


def test_features(model, rssi, classes):
    """Return the coverage features of each test scan (NaN: unplaced)."""
    pos = model.position
    out = []
    for row, c in zip(rssi, classes):
        cols = np.flatnonzero(~np.isnan(row))
        distance = pos.distances(cols, signal(row[cols], pos.representation),
                                 c)
        out.append(features(pos, distance, c, unheard_share(pos, cols, c)))
    return np.array(out)


def panel(root, folder, shown):
    """
    Return the default and loudness circles on each panel dataset.

    Every widening in the JSON; ``shown`` printed.
    """
    from coverage_check import _data, _model
    from datasets import PANEL
    out = {}
    for name in PANEL + ('ujiindoorloc', 'wifine'):
        files, train, test = _data(root, name, False, folder)
        model, basis = _model(name, files, folder)
        rssi = align(model, test)
        proba, xy, default, _, mismatch = model.predict_positions(
            rssi, coverage=True)
        circle = before(model, xy, model.predict_positions(
            rssi, widened=False)[2], proba.argmax(axis=1))
        error = np.linalg.norm(xy - test.position, axis=1)
        ok = np.isfinite(error)
        loud_m, loud_scans = calibrated_loud_m(model, train)
        sigmas = {'default': default, BEFORE: circle, **loud_circles(
            circle, excesses(model.position, rssi, proba.argmax(axis=1)),
            loud_m), **mismatch_circles(circle, mismatch)}
        out[name] = {'model': basis, 'scans': int(ok.sum()),
                     'loud_calibrated_m_per_db': loud_m,
                     'loud_calibration_scans': loud_scans,
                     'in_95_circle': {
                         k: float((error <= R95 * v)[ok].mean())
                         for k, v in sigmas.items()}}
        print(f'{name:14s} ' + ' '.join(
            f'{out[name]["in_95_circle"][n]:.3f}' for n in shown)
            + f' (calibrated: {loud_m:.2f} m/dB from {loud_scans} scans)',
            flush=True)
    return out


def summary(results):
    """
    Return each idea's circles per building: range, within 0.90-0.98.

    Over the pairs the idea was scored on (the prior held out needs the
    model's own coverage report).
    """
    names = {n: None for f in results.values() for n in f['in_95_circle']}
    out = {}
    for name in names:
        out[name] = {}
        for b in sorted({pair.split('test')[0] for pair in results}):
            share = np.array([f['in_95_circle'][name]['all']
                              for pair, f in results.items()
                              if pair.startswith(b) and
                              name in f['in_95_circle']])
            out[name][b] = {
                'min': float(share.min()), 'max': float(share.max()),
                'within_0.90_0.98': int(((share >= 0.9) &
                                         (share <= 0.98)).sum()),
                'runs': len(share),
                'mean_distance_from_0.95': float(np.abs(share - AIM)
                                                 .mean()),
                'distance_outside_band': float(np.sum(np.maximum(
                    BAND[0] - share, 0) + np.maximum(share - BAND[1], 0)))}
    return out


def choice(figures, names, pooled=False):
    """
    Return {building: the widening of ``names`` chosen on it}.

    ``figures``: :func:`summary`'s. On each building: the most circles
    within the band, then the least distance outside it, then the least
    mean distance from AIM; the first of ``names`` wins a tie. With
    ``pooled``, also 'all': chosen on every building together.
    """
    def key(n, buildings):
        f = [figures[n][b] for b in buildings]
        runs = sum(v['runs'] for v in f)
        return (-sum(v['within_0.90_0.98'] for v in f),
                round(sum(v['distance_outside_band'] for v in f), 9),
                round(sum(v['mean_distance_from_0.95'] * v['runs']
                          for v in f) / runs, 9))
    buildings = list(figures[names[0]])
    out = {b: min(names, key=lambda n: key(n, [b])) for b in buildings}
    if pooled:
        out['all'] = min(names, key=lambda n: key(n, buildings))
    return out


def loud_table(results):
    """Print every pair's circle under each loudness widening."""
    print('in the circle, loud k dB, m m/dB: ' + ' '.join(
        f'{k:g},{m:g}' for k, m in LOUD))
    for name, f in results.items():
        print(f'{name:28s} ' + ' '.join(
            f'{f["in_95_circle"][loud_name(k, m)]["all"]:.3f}'
            for k, m in LOUD), flush=True)


def main():
    """Run every pair of every building; print the table, write JSON."""
    p = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    p.add_argument('--data', type=Path, default=fb.DEFAULT_DATA)
    p.add_argument('--out', type=Path,
                   default=fb.RESULTS / 'circle-ideas.json')
    p.add_argument('--panel', action='store_true',
                   help='also score the loudness widenings on the panel')
    p.add_argument('--datasets-root', type=Path,
                   default=fb.ROOT.parent / 'shared' / 'datasets')
    args = p.parse_args()
    results, names = {}, None
    with tempfile.TemporaryDirectory() as folder:
        for site, runs in fb.site_runs(args.data, folder):
            for holes in (False, True):
                for train in runs:
                    scans, kept = fb.survey(train, folder, holes)
                    path = Path(folder) / \
                        f'{train.name}{"-holes" if holes else ""}.npz'
                    fb.cli('train_model', '--data', scans, '-o', path,
                           '--quiet')
                    model = load_model(path)
                    kept = kept[np.isfinite(kept).all(axis=1)]
                    calibrated = calibrated_loud_m(model,
                                                   read_fingerprints(scans))
                    for test in runs:
                        if test is train:
                            continue
                        name = (f'{test.name} <- {train.name}, '
                                f'{"holes" if holes else "full"}')
                        f = results[name] = pair(model, scans, test, kept,
                                                 calibrated)
                        if names is None:
                            names = [n for n in ALL
                                     if n in f['in_95_circle']]
                            print(f'{"test <- survey":28s} hole AUC: '
                                  f'model  cut | in the circle: '
                                  + ', '.join(names))
                        print(f'{name:28s} {f["hole_scans"]:4d} '
                              + ' '.join(
                                  '    -' if v is None else f'{v:5.2f}'
                                  for v in (f['auc_model'], f['auc_cut']))
                              + ' | ' + ' '.join(
                                  f'{f["in_95_circle"][n]["all"]:.3f}'
                                  if n in f['in_95_circle'] else '    -'
                                  for n in names), flush=True)
    loud_table(results)
    out = {'protocol': __doc__.split('\n\n')[1].replace('\n', ' '),
           'pairs': results, 'summary': summary(results)}
    out['loud_chosen_on'] = chosen = choice(
        out['summary'], [BEFORE, *(loud_name(k, m) for k, m in LOUD)])
    out['mismatch_chosen_on'] = by_mismatch = choice(
        out['summary'], [BEFORE, *(mismatch_name(k, w) for k, w in
                                   MISMATCH)], pooled=True)
    shown = ['default', BEFORE, LOUD_CALIBRATED,
             *sorted(set(chosen.values()) | set(by_mismatch.values()))]
    if args.panel:
        print('panel: in the circle: ' + ', '.join(shown))
        with tempfile.TemporaryDirectory() as folder:
            out['panel'] = panel(args.datasets_root, folder, shown)
    for name in ALL + tuple(n for n in shown if n not in ALL):
        print(f'{name}: ' + '; '.join(
            f'{b} {v["min"]:.3f}-{v["max"]:.3f}, within 0.90-0.98 '
            f'{v["within_0.90_0.98"]} of {v["runs"]}' for b, v in
            out['summary'][name].items()))
    for b, name in [*chosen.items(), *by_mismatch.items()]:
        print(f'chosen on {b}: {name}; on the others: ' + '; '.join(
            f'{o} within 0.90-0.98 {v["within_0.90_0.98"]} of {v["runs"]} '
            f'({BEFORE} {out["summary"][BEFORE][o]["within_0.90_0.98"]}),'
            f' outside by {v["distance_outside_band"]:.3f} ({BEFORE} '
            f'{out["summary"][BEFORE][o]["distance_outside_band"]:.3f})'
            for o, v in out['summary'][name].items() if o != b))
    with atomic_write(args.out, 'w') as f:
        json.dump(out, f, indent=1)
    print(f'wrote {args.out}')


if __name__ == '__main__':
    main()
