"""
Whether the coverage model's probability holds on another day's scans.

``train_model`` learns each model's coverage model from its own survey
(held-out device, walk or time groups) and reports how it separates and
how well calibrated it is on those held-out scans. This benchmark asks
the same of each dataset's test file, recorded on another day: the model
trained by the documented command (``train_model`` with the dataset's
format flags only, ``--seed 0``; UJIIndoorLoc: the shipped model), its
coverage probability of every test scan as the node computes it (the APs
the model lacks counted), against whether a training scan of the scan's
true building/floor lies within 3 m (the label ``train_model`` learns
from). The robot pairs also with the fusion benchmark's survey holes
(``fusion.survey``: pieces of the training run cut out). Per dataset:
the share of test scans covered, the ROC AUC, the reliability table (5
bins) and its expected calibration error (ECE), the share judged off the
survey (below 0.5, or not judged: no AP the model knows) with how many
of those are truly off (precision) and of the truly off how many are
judged so (recall), beside the training's cross-fitted AUC and ECE; and
the ECE and share judged off of the same model with the prior it learned
from the held-out scans (``as_learned``: the share covered among them,
before ``PRIOR_FLOOR``), and with other floors (``floors``); and the
floor leave-one-building-out would choose by the ECE. One seed.

And the scans' mismatch (every dataset, with a coverage model or not):
the survey's usual mismatch on covered ground, which ``train_model``
learns from held-out stretches (``usual_mismatch_db``), against the
median mismatch of the test file's covered scans (another day), their
ratio, the test scans' median ratio off the survey, and the ROC AUC of
each scan's mismatch against the scans off the survey (the filter
widens the scans whose recent mismatch is above the usual).

And what ``survey_gaps`` would list for a run without positions (the
test file in time order, or in file order without stamps), under each
rule for a scan off the survey: the coverage probability below 0.5 (the
tool's), the relative mismatch above 1.4 (``unlike_survey``: the
circle's and the witness's), or either: the true stretches (at least
``MIN_SCANS`` scans off the survey in a row) holding a scan the rule
calls off, the stretches it lists holding no scan truly off, the share
of scans it calls off and of the truly off ones.

    python benchmarks/coverage_check.py
"""

import argparse
import json
from pathlib import Path
import tempfile

import numpy as np
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.atomic import atomic_write
from wifi_place_recognition.core.coverage import (COVERED_M,
                                                  distance_by_place,
                                                  uncovered, unlike_survey)
from wifi_place_recognition.core.evaluation import scan_answers
from wifi_place_recognition.core.gaps import gaps, MIN_SCANS
from wifi_place_recognition.core.resources import default_model_path
from wifi_place_recognition.data.fingerprints import read_fingerprints
from wifi_place_recognition.training.coverage import (auc, logit,
                                                      PRIOR_FLOOR,
                                                      reliability)

from datasets import DATASETS, PANEL, read, ROBOT
from fusion import Run, survey
from runs import command, measured

ROOT = Path(__file__).resolve().parent.parent
NAMES = PANEL + ('ujiindoorloc', 'wifine') + tuple(ROBOT)


#: Other floors of the prior, scored beside the default's.
FLOORS = (0.8, 0.85, 0.95, 0.99)


def at_prior(p, report, floor=None):
    """
    Return ``p`` at another prior.

    The held-out scans' own share covered (``floor`` None), or that
    share but at least ``floor``.
    """
    share = report['covered'] / (report['covered'] + report['not_covered'])
    prior = share if floor is None else max(share, floor)
    z = np.log(p / (1 - p)) - logit(report['prior']) + logit(prior)
    return 1 / (1 + np.exp(-z))


def covered_truth(train, test):
    """Return which test scans lie within COVERED_M of a training scan."""
    return distance_by_place(
        test.position, np.column_stack([test.building, test.floor]),
        train.position,
        np.column_stack([train.building, train.floor])) <= COVERED_M


def check(model, p, covered):
    """
    Return the coverage model's figures (dict).

    ``p``: its probability of each test scan; ``covered``: the truth.
    """
    judged = np.isfinite(p)
    table, ece = reliability(p[judged], covered[judged])
    off = uncovered(p)
    truly_off = ~covered
    report = model.coverage.report

    def scored(q):
        return {'ece': reliability(q, covered[judged])[1],
                'judged_off_share': float(
                    (uncovered(q).sum() + (~judged).sum()) / len(p))}
    return {
        'test_scans': len(p), 'judged': int(judged.sum()),
        'covered_share': float(covered.mean()),
        'auc': _finite(auc(p[judged], covered[judged])), 'ece': ece,
        'mean_probability': float(p[judged].mean()),
        'judged_off_share': float(off.mean()),
        'off_precision': float(truly_off[off].mean()) if off.any()
        else None,
        'off_recall': float(off[truly_off].mean()) if truly_off.any()
        else None,
        'reliability': table,
        'cross_fitted_auc': report['auc'], 'cross_fitted_ece': report['ece'],
        'prior': report['prior'],
        'as_learned': scored(at_prior(p[judged], report)),
        'floors': {f'{f:g}': scored(at_prior(p[judged], report, f))
                   for f in FLOORS}}


def mismatch(usual, ratio, covered):
    """
    Return how the test file's scans sound against the usual (dict).

    ``usual``: the model's usual mismatch (dB; 0: none); ``ratio``: each
    test scan's mismatch over it; ``covered``: the truth.
    """
    if not usual:
        return {'usual_mismatch_db': 0.0, 'note': 'not known'}
    known = np.isfinite(ratio)
    on, off = known & covered, known & ~covered
    return {'usual_mismatch_db': usual,
            'covered_median_db': float(np.median(ratio[on]) * usual),
            'covered_over_usual': float(np.median(ratio[on])),
            'off_over_usual': float(np.median(ratio[off])) if off.any()
            else None,
            'auc_off': _finite(auc(ratio[known], ~covered[known]))}


def stretches(covered, rules, stamps=None):
    """
    Return how ``survey_gaps``'s list would meet the truth (dict).

    ``covered``: the truth per test scan; ``rules``: {name: True per scan
    the rule calls off the survey}; ``stamps``: the scans' times (None:
    file order), the order the tool reads them in. ``by_rule``: each
    rule's figures.
    """
    order = np.arange(len(covered)) if stamps is None else \
        np.argsort(np.asarray(stamps, np.float64), kind='stable')
    off = ~np.asarray(covered, bool)[order]
    truth = gaps(off, min_scans=MIN_SCANS)
    out = {'true_stretches': len(truth), 'min_scans': MIN_SCANS,
           'by_rule': {}}
    for name, flags in rules.items():
        flags = np.asarray(flags, bool)[order]
        listed = gaps(flags, min_scans=MIN_SCANS)
        out['by_rule'][name] = {
            'found': sum(bool(flags[g.first:g.last + 1].any())
                         for g in truth),
            'listed': len(listed),
            'listed_none_off': sum(not off[g.first:g.last + 1].any()
                                   for g in listed),
            'called_off_share': float(flags.mean()),
            'recall': float(flags[off].mean()) if off.any() else None}
    return out


def off_survey_rules(model, answers):
    """Return each rule's scans off the survey ({name: bools})."""
    out = {'mismatch': unlike_survey(answers[4])}
    if model.coverage is not None:
        out['coverage'] = uncovered(answers[3])
        out['either'] = out['coverage'] | out['mismatch']
    return out


def leave_one_building_out(results):
    """
    Return, per building, the floor the others' mean ECE would choose.

    Among the prior as learned, :data:`FLOORS` and the default (None
    with no other building); a building: a dataset's name up to its
    first ``-`` (robot pairs and their holes together).
    """
    def ece(r, floor):
        if floor == 'as learned':
            return r['as_learned']['ece']
        return r['ece'] if floor == f'{PRIOR_FLOOR:g}' else \
            r['floors'][floor]['ece']
    scored = {k: r for k, r in results.items() if 'ece' in r}
    options = ['as learned', f'{PRIOR_FLOOR:g}'] + [f'{f:g}' for f in FLOORS]
    chosen = {}
    for building in sorted({k.split('-')[0].split()[0] for k in scored}):
        rest = [r for k, r in scored.items()
                if k.split('-')[0].split()[0] != building]
        chosen[building] = min(options, key=lambda f: np.mean(
            [ece(r, f) for r in rest])) if rest else None
    return chosen


def _finite(value):
    """Return ``value``, None if NaN (JSON has no NaN)."""
    return None if np.isnan(value) else value


def _model(name, train, folder):
    if name == 'ujiindoorloc':
        return load_model(default_model_path()), 'the shipped model'
    path = Path(folder) / f'{name}.npz'
    measured(command('train_model') + [
        '--data', *train, *DATASETS[name]['args'], '-o', path, '--seed', '0',
        '--quiet'])
    return load_model(path), 'train_model --seed 0'


def _data(root, name, holes, folder):
    """Return (training files, training scans, test scans)."""
    if not holes:
        files = [str(root / p) for p in DATASETS[name]['train']]
        return files, read(root, name, 'train'), read(root, name, 'test')
    run = Run((root / DATASETS[name]['train'][0]).parent)
    scans = survey(run, folder, holes=True)[0]
    return [str(scans)], read_fingerprints(scans), read(root, name, 'test')


def _cell(value, fmt='.3f'):
    return '-' if value is None else format(value, fmt)


def main():
    """Check every dataset's coverage model; print a table; write JSON."""
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--datasets-root', type=Path,
                   default=ROOT.parent / 'shared' / 'datasets')
    p.add_argument('--datasets', default=','.join(NAMES),
                   help='comma-separated (default: every one)')
    p.add_argument('--out', type=Path, default=ROOT / 'benchmarks' /
                   'results' / 'coverage-check.json')
    args = p.parse_args()
    names = args.datasets.split(',')
    unknown = sorted(set(names) - set(NAMES))
    if unknown:
        p.error(f'unknown datasets {unknown}; choose from {NAMES}')
    results = {}
    print(f'{"dataset":16s} {"scans":>6s} {"covered":>8s} {"AUC":>6s} '
          f'{"ECE":>6s} {"off":>6s} {"prec":>6s} {"recall":>6s} '
          f'{"cv AUC":>7s} {"cv ECE":>7s} {"prior":>6s} | as learned: '
          f'{"ECE":>6s} {"off":>6s}')
    with tempfile.TemporaryDirectory() as folder:
        for name, holes in [(n, False) for n in names] + [
                (n, True) for n in names if n in ROBOT]:
            key = f'{name} holes' if holes else name
            files, train, test = _data(args.datasets_root, name, holes,
                                       folder)
            model, basis = _model(name, files, folder)
            answers = scan_answers(model, test)
            truth = covered_truth(train, test)
            sound = mismatch(model.position.usual_mismatch, answers[4],
                             truth)
            print(f'{key:16s} mismatch: usual '
                  f'{sound["usual_mismatch_db"]:.2f} dB, covered test '
                  f'scans {_cell(sound.get("covered_over_usual"), ".2f")}'
                  f' x, off {_cell(sound.get("off_over_usual"), ".2f")} x,'
                  f' AUC {_cell(sound.get("auc_off"), ".2f")}')
            listed = stretches(truth, off_survey_rules(model, answers),
                               test.meta.get('TIMESTAMP'))
            print(f'{key:16s} survey_gaps without positions: '
                  f'{listed["true_stretches"]} true stretches; ' + '; '.join(
                      f'{k}: {v["found"]} found, {v["listed_none_off"]} of '
                      f'{v["listed"]} listed with none off' for k, v in
                      listed['by_rule'].items()))
            if model.coverage is None:
                results[key] = {'model': basis, 'coverage_model': None,
                                'mismatch': sound, 'stretches': listed}
                print(f'{key:16s} no coverage model')
                continue
            r = results[key] = {'model': basis,
                                **check(model, answers[3], truth),
                                'mismatch': sound, 'stretches': listed}
            print(f'{key:16s} {r["test_scans"]:6d} '
                  f'{r["covered_share"]:8.3f} {_cell(r["auc"]):>6s} '
                  f'{r["ece"]:6.3f} {r["judged_off_share"]:6.3f} '
                  f'{_cell(r["off_precision"]):>6s} '
                  f'{_cell(r["off_recall"]):>6s} '
                  f'{_cell(r["cross_fitted_auc"]):>7s} '
                  f'{_cell(r["cross_fitted_ece"]):>7s} {r["prior"]:6.3f} |'
                  f' {"":11s} {r["as_learned"]["ece"]:6.3f} '
                  f'{r["as_learned"]["judged_off_share"]:6.3f}')
    out = {'protocol': __doc__.strip(), 'covered_m': COVERED_M,
           'prior_floor': PRIOR_FLOOR, 'datasets': results,
           'leave_one_building_out': leave_one_building_out(results)}
    print('the floor leave-one-building-out would choose (mean ECE of the '
          'other buildings):', ', '.join(
              f'{k}: {v}' for k, v in out['leave_one_building_out'].items()))
    with atomic_write(args.out, 'w') as f:
        json.dump(out, f, indent=1, allow_nan=False)
    print(f'wrote {args.out}')


if __name__ == '__main__':
    main()
