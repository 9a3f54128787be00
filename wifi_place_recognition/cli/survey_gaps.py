"""``survey_gaps``: where a recorded run drove without survey coverage."""

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from ..core.artifact import load_model
from ..core.evaluation import align, unknown_aps
from ..core.coverage import (COVERED_M, OFF_SURVEY_BELOW,
                             distance_by_place, uncovered)
from ..core.gaps import gaps, MIN_SCANS
from ..core.resources import default_model_path
from .common import (add_data_arguments, check_outputs, data_options,
                     json_ready, main_wrapper, read_data)


@main_wrapper
def main(argv=None):
    """List (and draw) a run's stretches off the survey; exit 2 on bad input."""
    p = argparse.ArgumentParser(
        allow_abbrev=False, prog='survey_gaps',
        description='Where to survey next: the stretches of a recorded run '
                    '(record_fingerprints CSV, or any fingerprint CSV in '
                    'time order) that no survey scan of the model covers. '
                    'With positions in the run (X, Y from the robot\'s '
                    'localiser), a scan is off the survey when no survey '
                    'scan of its building/floor lies within --covered-m; '
                    f'without, when the model\'s coverage probability is '
                    f'below {OFF_SURVEY_BELOW:g}.')
    p.add_argument('--model', type=Path, default=None,
                   help=f'model file with a position output (default: the '
                        f'shipped {default_model_path().name})')
    p.add_argument('--data', nargs='+', required=True, metavar='PATH',
                   help='the run: CSV(s) or folder(s) of CSVs')
    p.add_argument('--covered-m', type=float, default=COVERED_M,
                   metavar='M', help='a survey scan this close covers a '
                                     'scan (default: %(default)s m)')
    p.add_argument('--min-scans', type=int, default=MIN_SCANS, metavar='N',
                   help='leave out stretches of fewer scans (default: '
                        '%(default)s)')
    p.add_argument('--plot', metavar='OUT.png', default=None,
                   help='draw the run\'s path over the survey, the '
                        'stretches marked (needs matplotlib)')
    p.add_argument('--json', action='store_true',
                   help='print one JSON object instead of the table')
    add_data_arguments(p)
    args = p.parse_args(argv)
    if not (math.isfinite(args.covered_m) and args.covered_m > 0):
        raise ValueError(f'--covered-m {args.covered_m}: expected a number '
                         f'> 0')
    if args.min_scans < 1:
        raise ValueError(f'--min-scans {args.min_scans}: expected >= 1')
    check_outputs([('--plot', args.plot)], [('--model', args.model)])
    if args.plot:
        _picture_format(args.plot)
    model = load_model(args.model or default_model_path())
    if model.position is None:
        raise ValueError('the model has no position output: train it with '
                         'X, Y (or LONGITUDE, LATITUDE) columns')
    fp = read_data(args.data, data_options(args), 'data', role='test')
    found = off_survey(model, fp, args.covered_m)
    stamps = fp.meta.get('TIMESTAMP')
    order = np.argsort(stamps, kind='stable') if stamps is not None else \
        np.arange(len(fp))
    xy = fp.position[order] if fp.position is not None else None
    t = None if stamps is None else np.asarray(stamps, np.float64)[order]
    stretches = gaps(found['off'][order], t, xy, args.min_scans)
    t0 = t[0] if t is not None and len(t) else 0.0
    result = {'source': fp.source, 'basis': found['basis'],
              'covered_m': args.covered_m, 'scans': len(fp),
              'scans_off_survey': int(found['off'].sum()),
              'scans_without_known_ap': found['strangers'],
              'stretches': [{'start_s': g.start_s - t0,
                             'end_s': g.end_s - t0, 'scans': g.scans,
                             'length_m': g.length_m, 'from_xy': g.start_xy,
                             'to_xy': g.end_xy} for g in stretches]}
    if found['strangers']:
        print(f'note: {found["strangers"]} of {len(fp)} scans share no AP '
              f'with the model (a scan the node would reject): is it this '
              f'building\'s model?', file=sys.stderr)
    if args.plot:
        _plot(args.plot, model, fp.position, found['off'], stretches, order)
    if args.json:
        print(json.dumps(json_ready(result), allow_nan=False))
        return 0
    print(f'{fp.source}: {len(fp)} scans, {result["scans_off_survey"]} off '
          f'the survey ({found["basis"]}); {len(stretches)} stretches of '
          f'at least {args.min_scans} scans')
    if stretches:
        print(f'{"#":>3s} {"start s":>8s} {"end s":>8s} {"scans":>6s} '
              f'{"length m":>9s}  from (x, y) -> to (x, y)')
    for k, g in enumerate(result['stretches'], 1):
        print(f'{k:3d} {g["start_s"]:8.1f} {g["end_s"]:8.1f} '
              f'{g["scans"]:6d} {g["length_m"]:9.1f}  '
              f'({g["from_xy"][0]:.1f}, {g["from_xy"][1]:.1f}) -> '
              f'({g["to_xy"][0]:.1f}, {g["to_xy"][1]:.1f})')
    if args.plot:
        print(f'wrote {args.plot}')
    return 0


def off_survey(model, fp, covered_m):
    """
    Return {'off': bool per scan, 'basis': ..., 'strangers': ...}.

    ``basis``: how the scans were judged; ``strangers``: how many share
    no AP with the model. From positions when the run has them (the
    nearest survey scan the scan's building/floor searches, or the
    recognised one's when the model does not know it: its floor's, or
    its building's when the model searches the building); else from the
    coverage probability, read as the node reads it (a scan with no AP
    the model knows is off).
    """
    rssi = align(model, fp)
    strangers = int((~np.isfinite(rssi).any(axis=1) & ~fp.empty_rows).sum())
    proba, _, _, coverage, _ = model.predict_positions(
        rssi, coverage=True, unknown=unknown_aps(model, fp))
    if fp.position is None:
        if model.coverage is None:
            raise ValueError('the run has no positions and the model no '
                             'coverage section (trained before it was '
                             'added, or too few held-out scans): record '
                             'the run with a pose topic, or retrain')
        return {'off': uncovered(coverage),
                'basis': f'model coverage probability < '
                         f'{OFF_SURVEY_BELOW:g}', 'strangers': strangers}
    locator = model.position
    index = {tuple(c): i for i, c in enumerate(model.classes.tolist())}
    label = np.array([index.get((int(b), int(f)), -1) for b, f in
                      zip(fp.building, fp.floor)])
    c = np.where(label >= 0, label, proba.argmax(axis=1))
    searched = np.unique(c)
    survey = [locator.map_xy(k) for k in searched]
    distance = distance_by_place(
        fp.position, c, np.concatenate(survey),
        np.repeat(searched, [len(xy) for xy in survey]))
    return {'off': ~(distance <= covered_m) & np.isfinite(
        fp.position).all(axis=1),
        'basis': f'no survey scan within {covered_m:g} m',
        'strangers': strangers}


def _picture_format(path):
    """Refuse, before any work, a picture file matplotlib cannot write."""
    try:
        from matplotlib.backend_bases import FigureCanvasBase
    except ImportError as exc:
        raise ValueError(f'--plot needs matplotlib ({exc})') from None
    formats = FigureCanvasBase.get_supported_filetypes()
    if Path(path).suffix[1:].lower() not in formats:
        raise ValueError(f'--plot {path}: not a picture file name (one of '
                         f'.{", .".join(sorted(formats))})')


def _plot(path, model, xy, off, stretches, order):
    from .plots import _pyplot, _save
    plt = _pyplot()
    locator = model.position
    fig, ax = plt.subplots(figsize=(7, 6))
    refs = locator.xy.astype(np.float64) + locator.origin
    ax.scatter(refs[:, 0], refs[:, 1], s=4, c='0.75', label='survey scans')
    if xy is not None:
        path_xy = xy[order]
        ax.plot(path_xy[:, 0], path_xy[:, 1], '-', c='tab:blue', lw=0.8,
                label='the run')
        for k, g in enumerate(stretches, 1):
            piece = path_xy[g.first:g.last + 1]
            ax.plot(piece[:, 0], piece[:, 1], '-', c='tab:red', lw=2.5,
                    label='off the survey' if k == 1 else None)
            ax.annotate(str(k), piece[0], fontsize=9, color='tab:red')
    ax.set_aspect('equal')
    ax.set_xlabel('x (m)')
    ax.set_ylabel('y (m)')
    ax.set_title(f'{len(stretches)} stretches off the survey '
                 f'({int(off.sum())} scans)', fontsize=10)
    ax.legend(fontsize=8, loc='best')
    _save(plt, fig, path)


if __name__ == '__main__':
    sys.exit(main())
