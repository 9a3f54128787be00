"""
A survey that fills its own holes: one working run recorded, then updated.

For every building and ordered pair of its runs (survey S, working run W):

- **the survey** is S with holes (``benchmarks/fusion.py``'s survey_holes,
  seed 0: a third of S's scans cut in pieces of 15-25 m driven);
  ``train_model`` and ``fit_odometry`` on it make the model in use;
- **the working run** W goes through what the robot runs: its scans
  through the model in use (each scan's position and sigma) and, with its
  odometry, the filter (:func:`core.filter.trajectory.fuse_offline`, seed
  0); the witness (:func:`core.witness_offline.replay`, the node's
  defaults) compares the fused poses with W's ``poses.csv`` (AMCL's own
  output, the localiser); the trusted recorder's rule
  (:class:`core.trusted.TrustGate`, defaults) takes AMCL's poses, the
  witness's state and the place (the model's class of the scan before) in
  stamp order and writes the scans it trusts as trusted_recorder writes
  them (:class:`data.recording.FingerprintLog`); then ``update_model``
  (the documented command, its defaults) builds, checks and keeps or
  refuses a candidate from the survey plus that recording;
- **judged** on S's cut scans (both buildings: single-scan error of the
  model in use before and after the update, and of a perfect recording:
  ``train_model`` on S with holes plus every scan of W at its true
  position; S whole cannot judge its own scans, it was trained on them),
  and where the building has a third run J, on J: single and fused
  errors (seeds 0-2, the model in use's fitted odometry for every model:
  a running node keeps the fit it started with) overall and in the
  former holes (J's scans farther than 3 m from every kept survey scan),
  before, after, with S whole and with the perfect recording; coverage:
  the share of the judged scans within 3 m of a survey scan (the
  recorded scans' labels count after);
- **a lost localiser** injected into W: at a seeded moment (60 s after
  the start to 90 s before the end) AMCL's poses are displaced 5-30 m in
  a random direction and carried on by W's odometry
  (``benchmarks/witness.py``'s displaced localiser) until the witness
  re-seeds (then AMCL's own poses again) or the run ends; the scans
  recorded inside the episode are counted (goal: none), three moments
  per pair (``--seed``); the first one's recording is also updated and judged.

Each recording is updated twice: retrained (``update_model``'s default)
and references only (``--positions-only``, what a robot without torch
does). Where the check refuses a candidate, the figures it would have
given are judged too (``--tolerance-position 1e9``): what the check cost.

Goals (issue 36): after one working run the single-scan error on the cut
scans within 20 % of the full survey's, the fused error on J within 10 %;
zero scans learned while lost. Table on stdout, JSON in
``benchmarks/results/self-update.json``.

    python benchmarks/self_update.py [--data ../shared/datasets/robot]
"""

import argparse
from collections import Counter
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
from wifi_place_recognition.core.coverage import (COVERED_M,
                                                  distance_to_survey)
from wifi_place_recognition.core.evaluation import scan_answers
from wifi_place_recognition.core.filter.trajectory import (fuse_offline,
                                                           score, truth_at)
from wifi_place_recognition.core.filter.fusion import Fusion
from wifi_place_recognition.core.trusted import LocaliserPose, TrustGate
from wifi_place_recognition.core.witness_offline import replay
from wifi_place_recognition.data.recording import FingerprintLog

sys.path.insert(0, str(Path(__file__).resolve().parent))
from fusion import (cli, models, SEEDS, SETTLE_S,  # noqa: E402
                    site_runs, survey_holes)
from witness import (amcl, carried, END_S, START_S,  # noqa: E402
                     survey as survey_xy)

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / 'benchmarks' / 'results'
DEFAULT_DATA = ROOT.parent / 'shared' / 'datasets' / 'robot'
#: Lost-localiser moments per pair (the first is also updated).
LOST_MOMENTS = 3
#: The kinds of update and update_model's options for them.
KINDS = {'retrained': (), 'references_only': ('--positions-only',)}
GOALS = ('single-scan error on the cut scans after <= 1.2 x a perfect '
         'recording\'s (the survey with holes plus every scan of the '
         'working run); fused error on the third run after <= 1.1 x the '
         'survey whole\'s; 0 scans learned while the localiser was lost')


def errors(model, fp, xy):
    """
    Return each scan's error in metres, and the model's answers.

    (xy, sigma, coverage, mismatch), as the node's filter takes them.
    """
    _, out, *answers = scan_answers(model, fp)
    return np.linalg.norm(out - xy, axis=1), (out, *answers)


def figures(error, mask=None):
    """Return the mean and median of ``error`` (where ``mask``; or None)."""
    e = error if mask is None else error[mask]
    e = e[np.isfinite(e)]
    return {'scans': int(len(e)), 'mean_m': float(e.mean()) if len(e)
            else None, 'median_m': float(np.median(e)) if len(e) else None}


class Survey:
    """S with holes: the model in use; and S whole."""

    def __init__(self, run, folder):
        self.run = run
        self.cut = survey_holes(run.xy)
        _, self.model_path, self.kept_xy, self.csv = models(run, folder,
                                                            holes=True)
        self.model = load_model(self.model_path)
        whole = folder / f'{run.name}-full.npz'
        cli('train_model', '--data', run.folder / 'scans.csv', '-o', whole,
            '--quiet')
        self.full = load_model(whole)
        self.cut_fp = run.fp.subset(self.cut)
        self.cut_xy = run.xy[self.cut]

    def with_run(self, work, folder):
        """Return the model of the survey plus every scan of ``work``."""
        path = folder / f'{self.run.name}-holes-{work.name}.npz'
        cli('train_model', '--data', self.csv, work.folder / 'scans.csv',
            '-o', path, '--quiet')
        return load_model(path)


def working_streams(model, run):
    """
    Return W's scan stream, fused stream (seed 0) and places.

    The scans' k-NN sigma, as the monitor reads it (not widened), their
    coverage probability (the APs the model lacks counted) and relative
    mismatch, which the filter and the monitor read.
    """
    proba, *answers = scan_answers(model, run.fp, widened=False)
    scans = (run.stamps, *answers)
    fxy, fyaw, fcov = fuse_offline(run.odometry, scans,
                                   Fusion(model.fusion, seed=0))
    places = [model.classes[c] for c in proba.argmax(axis=1)]
    return scans, (run.stamps, fxy, fyaw, fcov), places


def record(run, model, localiser, streams, path):
    """
    Run the witness and the recorder's rule over W; write what it trusts.

    Return (counts by reason, the stamps and positions recorded, each
    scan's reason: None or a key of core.trusted.REASONS).
    """
    scans, fused, places = streams
    states = []
    for stamp, _, state in replay(localiser, fused, scans=scans,
                                  survey=survey_xy(model)):
        if not states or states[-1][1] != state:
            states.append((stamp, state))
    t, xy, yaw, cov = localiser
    events = sorted([(float(s), 0, i) for i, s in enumerate(t)] +
                    [(float(s), 1, i) for i, s in enumerate(run.stamps)] +
                    [(float(s), 2, k) for k, (s, _) in enumerate(states)])
    gate, log = TrustGate(), FingerprintLog(path, positions=True)
    counts, recorded, reasons = Counter(), [], [None] * len(run.stamps)

    def keep(released):
        for stamp, i, pose, place, why in released:
            counts[why or 'recorded'] += 1
            reasons[i] = why
            if why is None:
                heard = np.isfinite(run.fp.rssi[i])
                log.add([a for a, h in zip(run.fp.ap_ids, heard) if h],
                        run.fp.rssi[i][heard], *place, stamp,
                        (pose.x, pose.y, pose.yaw, pose.frame))
                recorded.append((stamp, pose.x, pose.y))
    for stamp, kind, i in events:
        if kind == 0:
            gate.pose(LocaliserPose(stamp, *xy[i], yaw[i], 'map',
                                    LocaliserPose.sd_of(cov[i, 0, 0],
                                                        cov[i, 1, 1])))
        elif kind == 1:
            gate.scan(stamp, i)
            gate.place = places[i]
        else:
            gate.witness = states[i][1]
        keep(gate.release())
    keep(gate.release(everything=True))
    recorded = np.array(recorded).reshape(-1, 3)
    return counts, recorded[:, 0], recorded[:, 1:], reasons


def lost_localiser(run, local, rng):
    """Return (t0, displacement m, AMCL's stream displaced from t0 on)."""
    t, xy, yaw, _ = local
    t0 = rng.uniform(t[0] + START_S, t[-1] - END_S)
    at, yaw0 = truth_at(np.column_stack([t, xy, yaw]), [t0])
    distance, angle = rng.uniform(5, 30), rng.uniform(0, 2 * math.pi)
    shift = distance * np.array([math.cos(angle), math.sin(angle)])
    return t0, distance, carried(local, run.odometry, t0, at[0] + shift,
                                 float(yaw0[0]))


def episode(local, displaced, t0, model, streams):
    """
    Return (AMCL lost from t0 until the witness re-seeds, the end).

    AMCL's own poses again from the witness's first re-seed on (the seed
    puts it right); lost to the run's end when none comes.
    """
    scans, fused, _ = streams
    end = next((stamp for stamp, j, _ in replay(
        displaced, fused, scans=scans, survey=survey_xy(model))
        if j is not None and j.seed and stamp >= t0), math.inf)
    keep = displaced[0] < end
    return tuple(np.where(keep.reshape((-1,) + (1,) * (a.ndim - 1)), d, a)
                 for d, a in zip(displaced, local)), end


def update(folder, survey, recorded, kind, *options):
    """Run update_model; return (the model in use after, the report)."""
    folder.mkdir()
    out = subprocess.run(
        [sys.executable, '-m', 'wifi_place_recognition.cli.update_model',
         '--folder', folder, '--survey', survey.csv, '--recorded', recorded,
         '--model', survey.model_path, '--quiet', *KINDS[kind], *options],
        capture_output=True, text=True)
    if out.returncode not in (0, 1):
        return survey.model, {'decision': 'not run', 'reason':
                              out.stderr.strip().splitlines()[-1]}
    report = json.loads(max(folder.glob('*.json'),
                            key=lambda p: p.stat().st_mtime).read_text())
    keep = ('decision', 'reason', 'in_use', 'candidate', 'put_in_use',
            'cost')
    report = {k: v for k, v in report.items() if k in keep}
    report['in_use'].pop('file', None)
    return (load_model(folder / 'current.npz') if out.returncode == 0
            else survey.model), report


def covered(xy, survey_xy):
    """Return the share of positions within COVERED_M of a survey one."""
    ok = np.isfinite(xy).all(axis=1)
    return float((distance_to_survey(xy[ok], survey_xy) <= COVERED_M)
                 .mean())


def judge(survey, after, recorded_xy, third, both):
    """
    Return the cut scans' and the third run's figures.

    ``after``: the model in use after the update; ``both``: the survey
    plus every scan of the working run, by train_model (the reference).
    """
    s = survey
    grown = np.concatenate([s.kept_xy, recorded_xy.reshape(-1, 2)])
    out = {'cut': {
        'before': figures(errors(s.model, s.cut_fp, s.cut_xy)[0]),
        'after': figures(errors(after, s.cut_fp, s.cut_xy)[0]),
        'survey_and_working_run': figures(errors(both, s.cut_fp,
                                                 s.cut_xy)[0]),
        'coverage': {'before': covered(s.cut_xy, s.kept_xy),
                     'after': covered(s.cut_xy, grown)}}}
    if third is None:
        return out
    hole = ~(distance_to_survey(third.xy, s.kept_xy) <= COVERED_M) & \
        np.isfinite(third.xy).all(axis=1)
    j = out['third'] = {'run': third.name, 'hole_scans': int(hole.sum()),
                        'coverage': {'before': covered(third.xy, s.kept_xy),
                                     'after': covered(third.xy, grown),
                                     'full': covered(third.xy, s.run.xy)}}
    for name, model in (('before', s.model), ('after', after),
                        ('full', s.full), ('survey_and_working_run', both)):
        error, single = errors(model, third.fp, third.xy)
        fused = []
        for seed in SEEDS:
            xy, yaw, cov = fuse_offline(
                third.odometry, (third.stamps, *single),
                Fusion(s.model.fusion, seed=seed))
            f = score(third.stamps, third.xy, xy, settle_s=SETTLE_S)
            f['hole_mean_m'] = figures(np.linalg.norm(
                xy - third.xy, axis=1), hole)['mean_m']
            fused.append(f)
        j[name] = {'single': figures(error), 'single_in_holes':
                   figures(error, hole), 'fused_mean_m': [
                       f['mean_m'] for f in fused], 'fused_p95_m': [
                       f['p95_m'] for f in fused],
                   'fused_in_holes_mean_m': [f['hole_mean_m']
                                             for f in fused]}
    return out


def one_pair(folder, survey, work, third, seed):
    """Return the figures of survey S, working run W (and judged run J)."""
    local = amcl(work.folder)
    streams = working_streams(survey.model, work)
    tag = f'{survey.run.name}-{work.name}'
    learned_csv = folder / f'{tag}-learned.csv'
    counts, stamps, xy, reasons = record(work, survey.model, local,
                                         streams, learned_csv)
    both = survey.with_run(work, folder)
    hole = ~(distance_to_survey(work.xy, survey.kept_xy) <= COVERED_M) & \
        np.isfinite(work.xy).all(axis=1)
    learned = np.isin(work.stamps, stamps)
    out = {'survey': survey.run.name, 'working': work.name,
           'recording': dict(counts), 'working_hole_scans': {
               'scans': int(hole.sum()),
               'recorded': int((hole & learned).sum()),
               'not_recorded_because': dict(Counter(
                   reasons[i] for i in np.flatnonzero(hole & ~learned)))},
           'updates': {}, 'lost': []}
    for kind in KINDS:
        after, report = update(folder / f'{tag}-{kind}', survey,
                               learned_csv, kind)
        out['updates'][kind] = u = {
            'update': report, **judge(survey, after, xy, third, both)}
        if report['decision'] == 'refused':     # what the check cost
            after, _ = update(folder / f'{tag}-{kind}-anyway', survey,
                              learned_csv, kind, '--tolerance-position',
                              '1e9')
            u['had_it_been_put_in_use'] = judge(survey, after, xy, third,
                                                both)
    rng = np.random.default_rng(seed)
    for k in range(LOST_MOMENTS):
        t0, distance, displaced = lost_localiser(work, local, rng)
        lost, end = episode(local, displaced, t0, survey.model, streams)
        path = folder / f'{tag}-lost{k}.csv'
        counts, stamps, xy, _ = record(work, survey.model, lost, streams,
                                       path)
        e = {'t0_s': t0 - local[0][0], 'displaced_m': distance,
             'episode_s': min(end, local[0][-1]) - t0,
             're_seeded': math.isfinite(end),
             'learned_inside': int(((stamps >= t0) & (stamps < end)).sum()),
             'recording': dict(counts)}
        if k == 0:
            after, e['update'] = update(folder / f'{tag}-lost-models',
                                        survey, path, 'retrained')
            e.update(judge(survey, after, xy, third, both))
        out['lost'].append(e)
    return out


def rows(r):
    """Return the table rows of one pair, an update kind a row."""
    out = []
    for kind, u in r['updates'].items():
        c, third = u['cut'], u.get('third')
        fused = '' if third is None else ' '.join(
            f'{np.mean(third[k]["fused_mean_m"]):.2f}'
            for k in ('before', 'after', 'full'))
        holes = r['working_hole_scans']
        out.append(
            f'{r["survey"]:>9} {r["working"]:>9} {kind[:9]:>9} '
            f'{r["recording"].get("recorded", 0):4d} '
            f'{holes["recorded"]:3d}/{holes["scans"]:<3d} '
            f'{u["update"]["decision"][:7]:>7} '
            f'{c["before"]["mean_m"]:5.2f} {c["after"]["mean_m"]:5.2f} '
            f'{c["survey_and_working_run"]["mean_m"]:5.2f} '
            f'{c["coverage"]["before"]:4.2f}>{c["coverage"]["after"]:4.2f} '
            f'{fused:>14}  ' + ' '.join(str(e['learned_inside'])
                                        for e in r['lost']))
    return out


def main():
    """Run every pair of every building; print the table, write JSON."""
    p = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    p.add_argument('--data', type=Path, default=DEFAULT_DATA)
    p.add_argument('--out', type=Path, default=RESULTS / 'self-update.json')
    p.add_argument('--seed', type=int, default=2000,
                   help='the lost moments of pair k are drawn with seed '
                        'SEED + k (default: %(default)s)')
    args = p.parse_args()
    results = {'protocol': __doc__.strip(), 'goals': GOALS, 'pairs': []}
    print('   survey   working    update rec. holes decided  cut: before '
          'after  S+W  coverage third fused b/a/f  learned while lost')
    with tempfile.TemporaryDirectory() as tmp:
        for site, runs in site_runs(args.data, tmp):
            folder = Path(tmp) / site
            folder.mkdir()
            surveys = {}
            for k, (s, w) in enumerate(permutations(runs, 2)):
                if s.name not in surveys:
                    surveys[s.name] = Survey(s, folder)
                third = next((r for r in runs if r not in (s, w)), None)
                r = one_pair(folder, surveys[s.name], w, third,
                             args.seed + k)
                r['building'] = site
                results['pairs'].append(r)
                print('\n'.join(rows(r)), flush=True)
    with atomic_write(args.out, 'w') as f:
        json.dump(results, f, indent=1, allow_nan=False)
        f.write('\n')


if __name__ == '__main__':
    main()
