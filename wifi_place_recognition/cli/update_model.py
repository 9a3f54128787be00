"""
``update_model``: a candidate from the survey plus the recorded scans, checked.

At low priority (``--nice``, torch on ``--threads``), the survey and the
scans the robot recorded (trusted_recorder's CSVs) train a candidate with
the package's trainer; with ``--positions-only``, or where torch cannot be
imported, the candidate is the model in use with those scans as its
position references (:mod:`..core.references`, numpy only). The newest
share of the recorded scans that the model in use did not learn is held
out of the candidate and scores it beside the model in use
(:mod:`..core.update_check`). A candidate not
worse is built again by the same recipe from every recorded scan (the
held-out ones too), kept in the models folder and put in use
(:mod:`..core.model_store`), else refused with its reason (exit 1); either
way the report says what kind of update it was, what was compared, how,
and which APs came and went. With ``--min-new-scans N``, fewer than N
recorded scans off the survey build nothing. ``--rollback`` puts the
previous model back.
"""

import argparse
import math
import os
from pathlib import Path
import resource
import sys
import tempfile
import time

import numpy as np

from ..core.artifact import load_model, save_model
from ..core.atomic import probe_folder
from ..core.model_store import ModelStore, StoreError
from ..core.coverage import COVERED_M
from ..core.evaluation import align, mostly_unknown, rows_without_known_ap
from ..core.pipeline.scan_pipeline import swap_problem
from ..core.references import with_references
from ..core.scan import normalize_ap_id, ScanMapper
from ..core.update_check import (ap_changes, HOLDOUT_SHARE, judged,
                                 MIN_HELD_OUT, newest, off_survey,
                                 position_judges, Tolerance, verdict)
from ..data.columns import distinct_aps, TIME
from ..data.fingerprints import Fingerprints
from ..training.config import TrainConfig
from .common import (add_data_arguments, add_training_arguments,
                     data_options, main_wrapper, read_data, trainer,
                     training_config)

REFUSED = 1
#: The provenance key of the newest recorded scan a model learned (s).
LEARNED_UNTIL = 'recorded_until'
NODES = ('classifier_node', 'localization_monitor')
#: The largest tolerance (accuracy, metres) or AP window (hours) taken,
#: and the largest niceness (the lowest priority there is).
MAX_TOLERANCE, MAX_NICE = 1e6, 19


def build_parser():
    """Return the argument parser."""
    p = argparse.ArgumentParser(
        allow_abbrev=False, prog='update_model',
        description='Train a candidate model from the survey plus the '
                    'recorded scans at low priority (without torch, or with '
                    '--positions-only: the model in use with them as its '
                    'position references), check it against the model in '
                    'use on the newest recorded scans (held out), keep and '
                    'put in use the one not worse; or roll back.')
    p.add_argument('--folder', type=Path, required=True,
                   help='the models folder: every model put in use with its '
                        'report, current (the order they were put in use), '
                        'current.npz (a link to the one in use)')
    p.add_argument('--rollback', action='store_true',
                   help='put the previous model back in use and stop')
    p.add_argument('--survey', nargs='+', metavar='PATH',
                   help='the survey: fingerprint CSV(s) or folder(s)')
    p.add_argument('--recorded', nargs='+', metavar='PATH',
                   help='the scans recorded while the localiser was '
                        'trusted (trusted_recorder\'s CSVs, with times)')
    p.add_argument('--model', type=Path,
                   help='the model in use, for a folder that has none yet '
                        '(kept there first when a candidate is put in use)')
    p.add_argument('--positions-only', action='store_true',
                   help='no training: the model in use with the survey and '
                        'the recorded scans as its position references '
                        '(numpy only; also what happens without torch)')
    p.add_argument('--min-new-scans', type=int, default=0, metavar='N',
                   help=f'build nothing (exit 0) unless at least N recorded '
                        f'scans are new ground: farther than {COVERED_M:g} '
                        f'm from every survey scan of their floor (default: '
                        f'%(default)s, always build)')
    p.add_argument('--holdout', type=float, default=HOLDOUT_SHARE,
                   help='share of the recorded scans held out, the newest '
                        '(default: %(default)s)')
    tolerance = Tolerance()
    p.add_argument('--tolerance-accuracy', type=float,
                   default=tolerance.accuracy,
                   help='building+floor accuracy the candidate may lose '
                        '(default: %(default)s)')
    p.add_argument('--tolerance-position', type=float,
                   default=tolerance.position_m, metavar='METRES',
                   help='mean position error it may add (default: '
                        '%(default)s m)')
    p.add_argument('--ap-window', type=float, default=168.0,
                   metavar='HOURS',
                   help='an AP of the model in use not heard in the last '
                        'HOURS of the recording is silent: left out of the '
                        'candidate (default: %(default)s, a week)')
    p.add_argument('--keep-aps', action='store_true',
                   help='keep silent APs in the candidate (still reported)')
    p.add_argument('--nice', type=int, default=10,
                   help='niceness added to this process (default: '
                        '%(default)s)')
    p.add_argument('--quiet', action='store_true',
                   help='no per-epoch progress lines')
    add_data_arguments(p, training=True)
    add_training_arguments(
        p, 'model and training (as train_model\'s, but torch on one '
        'thread by default)', TrainConfig(threads=1))
    return p


def together(survey, recorded, leave_out):
    """
    Return the survey and the recorded scans as one :class:`Fingerprints`.

    The AP columns of both, less ``leave_out`` (identifiers) and those no
    scan heard; each file stays a walk, each scan its row in its file.
    """
    if (survey.position is None) != (recorded.position is None):
        raise ValueError('the survey and the recorded scans must both have '
                         'positions (X, Y) or both have none')
    parts = (survey, recorded)
    gone = {normalize_ap_id(ap) for ap in leave_out}
    ids = distinct_aps(ap for p in parts for ap in p.ap_ids
                       if normalize_ap_id(ap) not in gone)
    mapper = ScanMapper(ids)
    rssi = np.concatenate([mapper.map_rows(p.ap_ids, p.rssi) for p in parts])
    heard = np.isfinite(rssi).any(axis=0)
    walk = np.concatenate([p.walk if p.walk is not None else
                           np.full(len(p), p.source) for p in parts])
    position = None if survey.position is None else \
        np.concatenate([p.position for p in parts])
    line = None if any(p.line is None for p in parts) else \
        np.concatenate([p.line for p in parts])
    return Fingerprints(
        tuple(ap for ap, h in zip(ids, heard) if h), rssi[:, heard],
        np.concatenate([p.building for p in parts]),
        np.concatenate([p.floor for p in parts]), {},
        f'{survey.source} + {recorded.source}',
        sha256=f'{survey.sha256}+{recorded.sha256}', walk=walk,
        position=position, position_columns=survey.position_columns,
        line=line)


def _param_lines(path):
    return [f'ros2 param set /{node} model_path {path}' for node in NODES]


def _rollback(store):
    now, undone = store.rollback()
    print(f'rolled back: {now.name} in use again ({undone.name} kept); '
          f'for the running nodes:')
    print('\n'.join(_param_lines(now)))
    return 0


def _in_use(store, given):
    current = store.current()
    if current is not None and given is not None and \
            os.path.realpath(given) != os.path.realpath(current):
        raise ValueError(f'--model {given}: the folder has its model in use '
                         f'({current}); --model is for a folder without one')
    if current is None and given is None:
        raise ValueError(f'the folder {store.folder} has no model yet: '
                         f'give the model in use with --model')
    return current or given


def _log(args):
    def log(line):
        if not args.quiet:
            print(line, file=sys.stderr, flush=True)
    return log


@main_wrapper
def main(argv=None):
    """Build, check, keep or refuse a candidate; or roll back."""
    args = build_parser().parse_args(argv)
    try:
        store = ModelStore(args.folder)
        if args.rollback:
            return _rollback(store)
        if not (args.survey and args.recorded):
            raise ValueError('give --survey and --recorded (or --rollback)')
        probe_folder(args.folder / 'current')
        if not 0.0 < args.holdout < 1.0:
            raise ValueError(f'--holdout {args.holdout}: must be between 0 '
                             f'and 1')
        for option in ('tolerance_accuracy', 'tolerance_position',
                       'ap_window'):
            value = getattr(args, option)
            if not (math.isfinite(value) and 0 <= value <= MAX_TOLERANCE):
                raise ValueError(f'--{option.replace("_", "-")} {value}: '
                                 f'must be a number from 0 to '
                                 f'{MAX_TOLERANCE:g}')
        if not 0 <= args.nice <= MAX_NICE:
            raise ValueError(f'--nice {args.nice}: must be from 0 to '
                             f'{MAX_NICE} (only lowering the priority needs '
                             f'no privilege)')
        if args.min_new_scans < 0:
            raise ValueError(f'--min-new-scans {args.min_new_scans}: must '
                             f'be >= 0')
        return _update(args, store)
    except StoreError as exc:
        raise ValueError(str(exc)) from None


def _update(args, store):
    os.nice(args.nice)
    start = time.monotonic()
    config = training_config(args)
    train = _trainer(args)
    in_use_path = _in_use(store, args.model)
    in_use = load_model(in_use_path)
    data = data_options(args)
    survey = read_data(args.survey, data, 'survey',
                       small_classes=args.small_classes)
    recorded = read_data(args.recorded, data, 'recorded scans',
                         small_classes='keep')
    unknown = rows_without_known_ap(align(in_use, recorded))
    if train is None and mostly_unknown(unknown, len(recorded)):
        raise ValueError(f'--recorded: {unknown} of the {len(recorded)} '
                         f'recorded scans hear no AP the model in use '
                         f'({in_use_path}) knows, and a references-only '
                         f'update keeps its APs: scans of another building,'
                         f' or APs replaced (a full update learns them); '
                         f'nothing built')
    stamps = recorded.meta.get(TIME)
    held = newest(stamps, len(recorded), args.holdout) & \
        _unlearned(in_use, stamps, len(recorded))
    learned = recorded.subset(~held)
    new = _new_ground(args, learned, survey)
    if new is not None and new < args.min_new_scans:
        print(f'not updated: {new} recorded scans off the survey (farther '
              f'than {COVERED_M:g} m from every survey scan of their floor),'
              f' fewer than --min-new-scans {args.min_new_scans}; nothing '
              f'built')
        return 0
    if held.sum() < MIN_HELD_OUT:
        print(f'not updated: {held.sum()} of the {len(recorded)} recorded '
              f'scans to judge a candidate on (the newest, not learned by '
              f'the model in use), fewer than {MIN_HELD_OUT}; nothing '
              f'built: record more')
        return 0
    changes = ap_changes(in_use.ap_ids, recorded.ap_ids, recorded.rssi,
                         stamps, args.ap_window * 3600.0)
    if train is None:
        changes['not_applied'] = 'a references-only update keeps the ' \
            'model\'s APs: new APs not learned, silent APs not left out'
        leave_out = []
    else:
        leave_out = [] if args.keep_aps else \
            [s['ap'] for s in changes['silent']]

    def build(scans):
        if train is None:
            return _referenced(in_use, in_use_path, survey, scans)
        return _trained(args, train, config, survey, scans, leave_out,
                        in_use)
    candidate, kind, built = build(learned)
    test = recorded.subset(held)
    judges = position_judges(test, [survey, learned])
    figures = {'in_use': judged(in_use, test, judges),
               'candidate': judged(candidate, test, judges)}
    tolerance = Tolerance(args.tolerance_accuracy, args.tolerance_position)
    ok, reason = verdict(figures['in_use'], figures['candidate'], tolerance)
    swap = swap_problem(in_use, candidate)
    if ok and swap:     # the running nodes would refuse it
        ok, reason = False, swap
    final = final_built = None
    if ok:      # the same recipe, the held-out scans learned too
        final, final_built = _rebuilt(build, recorded, in_use, candidate,
                                      built)
    _left_out_notes(final_built or built)
    used = resource.getrusage(resource.RUSAGE_SELF)
    report = {
        'decision': 'put in use' if ok else 'refused', 'reason': reason,
        'created': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime()),
        'protocol': {
            'update': kind,
            'held_out': f'the newest {args.holdout:g} of the recorded scans '
                        f'by {"TIMESTAMP" if stamps is not None else "row"}'
                        f', less those the model in use learned (up to its '
                        f'{LEARNED_UNTIL}), not trained on',
            'held_out_scans': int(held.sum()),
            'scores': 'core/evaluation.py on the held-out scans, each model '
                      'mapping their APs as the node does: building and '
                      'floor on all, the position on those within '
                      f'{COVERED_M:g} m of a scan the candidate learned from '
                      f'(all when fewer than {MIN_HELD_OUT})',
            'put_in_use': 'a candidate not worse is built again by the same '
                          'recipe from the survey and every recorded scan, '
                          'the held-out ones too (so the model put in use '
                          'was trained on them; the checked candidate if '
                          'that fails)',
            'tolerance': {'building_floor_accuracy': tolerance.accuracy,
                          'position_mean_error_m': tolerance.position_m}},
        'new_ground': {
            'scans': new, 'min_new_scans': args.min_new_scans,
            'rule': f'recorded scans not held out, farther than '
                    f'{COVERED_M:g} m from every survey scan of their '
                    f'building and floor'},
        'in_use': {'file': str(in_use_path), **figures['in_use']},
        'candidate': {**figures['candidate'], **built},
        'put_in_use': None if final is None else final_built,
        'access_points': {**changes, 'left_out': leave_out},
        'cost': {'seconds': round(time.monotonic() - start, 1),
                 'cpu_seconds': round(used.ru_utime + used.ru_stime, 1),
                 'max_rss_mib': round(used.ru_maxrss / 1024, 1),
                 'nice': os.nice(0),
                 'torch_threads': None if train is None else config.threads}}
    print(f'held out {held.sum()} recorded scans: in use '
          f'{_line(figures["in_use"])}; candidate '
          f'{_line(figures["candidate"])}; APs: {len(changes["silent"])} '
          f'silent, {len(changes["new"])} new'
          f'{" (not applied)" if train is None else ""}'
          f'{"" if new is None else f"; {new} scans off the survey"}',
          file=sys.stderr)
    if not ok:
        path = store.refused(report)
        print(f'refused: {reason} (report {path})', file=sys.stderr)
        return REFUSED
    if store.current() is None:
        store.install(in_use_path, {'decision': 'adopted',
                                    'reason': 'the model in use before the '
                                              'first update',
                                    'source': str(in_use_path)})
    if stamps is not None:     # what the next update must not judge on
        final.provenance[LEARNED_UNTIL] = float(np.max(
            stamps if final is not candidate else stamps[~held]))
    with tempfile.TemporaryDirectory(dir=args.folder,
                                     prefix='.candidate.') as tmp:
        save_model(final, Path(tmp) / 'candidate.npz')
        path = store.install(Path(tmp) / 'candidate.npz', report)
    print(f'put in use: {path} (report {path.with_suffix(".json").name}); '
          f'for the running nodes:')
    print('\n'.join(_param_lines(path)))
    return 0


def _trainer(args):
    """Return the trainer, or None for a references-only update."""
    if args.positions_only:
        return None
    try:
        return trainer()
    except ValueError as exc:   # no torch here
        print(f'note: {exc} to retrain; updating only the position '
              f'references (numpy)', file=sys.stderr, flush=True)
        return None


def _new_ground(args, learned, survey):
    """Return how many recorded scans (trained on) are off the survey."""
    if args.min_new_scans or (learned.position is not None and
                              survey.position is not None):
        try:
            return int(off_survey(learned, survey).sum())
        except ValueError as exc:
            raise ValueError(f'--min-new-scans {args.min_new_scans}: '
                             f'{exc}') from None
    return None


def _unlearned(in_use, stamps, n):
    """
    Return which recorded scans the model in use did not learn (a mask).

    Those newer than its :data:`LEARNED_UNTIL` (an update put it in use);
    all without it, or without the scans' times.
    """
    until = in_use.provenance.get(LEARNED_UNTIL)
    if until is None or stamps is None:
        return np.ones(n, bool)
    return np.asarray(stamps, np.float64) > float(until)


def _rebuilt(build, recorded, in_use, candidate, built):
    """
    Return (the model to put in use, how it was built).

    ``build`` (the candidate's recipe) on every recorded scan; the checked
    candidate itself when that fails or the running nodes would refuse
    the result (said in how it was built).
    """
    try:
        final, _, final_built = build(recorded)
        problem = swap_problem(in_use, final)
    except (ValueError, RuntimeError, MemoryError) as exc:
        problem = str(exc) or type(exc).__name__
    if problem is None:
        return final, final_built
    print(f'note: the rebuild with the held-out scans failed ({problem}); '
          f'putting the checked candidate in use', file=sys.stderr)
    return candidate, dict(built, note=f'the rebuild with the held-out '
                           f'scans failed ({problem}): the checked '
                           f'candidate was put in use')


def _trained(args, train, config, survey, learned, leave_out, in_use):
    """
    Return (candidate, its kind, its training) trained anew.

    The model in use's odometry fit (``fusion``: the robot's, not the
    survey's) is carried over, and its tracking section, if it has one,
    when the candidate has the same building/floor classes.
    """
    fp = together(survey, learned, leave_out)
    print(fp.summary(), file=sys.stderr, flush=True)
    candidate, _, training = train(fp, config, _log(args))
    candidate.fusion = in_use.fusion
    same = np.array_equal(candidate.classes, in_use.classes) and \
        in_use.tracking is not None
    if same:
        candidate.tracking = in_use.tracking
    return candidate, 'full: network and position references trained ' \
        'anew (training/trainer.py)', {'training': {
            'survey': survey.source, 'survey_scans': len(survey),
            'recorded': learned.source,
            'recorded_scans': len(fp) - len(survey),
            'aps': len(candidate.ap_ids), 'epochs': training.epochs,
            'seconds': round(training.seconds, 1),
            'carried_over': (['fusion'] if in_use.fusion is not None
                             else []) + (['tracking'] if same else [])}}


def _referenced(in_use, path, survey, learned):
    """Return (candidate, its kind, its references): references only."""
    start = time.monotonic()
    candidate, parts = with_references(in_use, [survey, learned], str(path))
    return candidate, 'references only: the model in use\'s network and ' \
        'APs kept, its position references the survey plus the recorded ' \
        'scans (core/references.py)', {'references': {
            'from': str(path), 'survey': parts[0], 'recorded': parts[1],
            'aps': len(candidate.ap_ids),
            'seconds': round(time.monotonic() - start, 1)}}


def _left_out_notes(built):
    """Print a note per part of a references update with scans left out."""
    references = built.get('references')
    for part in () if references is None else \
            (references['survey'], references['recorded']):
        places = part['left_out']['unknown_place']
        silent = part['left_out']['no_known_ap']
        named = ', '.join(f'{k}: {n}' for k, n in places.items())
        why = ([f'{sum(places.values())} of a building/floor the model does '
                f'not know ({named})'] if places else []) + \
            ([f'{silent} hearing none of the model\'s APs'] if silent else [])
        if why:
            print(f'note: {part["source"]}: {part["scans"] - part["used"]} of '
                  f'the {part["scans"]} scans built from left out of the '
                  f'position references: {"; ".join(why)} (a full update '
                  f'learns new floors and APs)', file=sys.stderr)


def _line(figures):
    text = f'building+floor {figures["building_floor_accuracy"]:.4f}'
    if 'position_mean_error_m' in figures:
        text += f', position {figures["position_mean_error_m"]:.2f} m'
    return text


if __name__ == '__main__':
    sys.exit(main())
