"""``fit_tracking``: fit a model's tracking parameters on recorded walks."""

import argparse
from dataclasses import replace
import json
import math
import sys
import time
from pathlib import Path

from ..core.artifact import load_model, save_model
from ..core.atomic import atomic_write
from ..core.tracking_fit import FitOptions, fit_tracking, walk_evidence
from ..data.walks import walks
from .common import (add_data_arguments, add_model_arguments,
                     check_outputs, data_options, json_ready, main_wrapper,
                     model_output, read_data)


@main_wrapper
def main(argv=None):
    """Fit, write the model file's tracking section; exit 2 on bad input."""
    p = argparse.ArgumentParser(
        allow_abbrev=False, prog='fit_tracking',
        description='Choose the tracking parameters of a model file on '
                    'labelled walks (record_fingerprints CSVs, or a folder '
                    'of one CSV per walk) and write them into the file\'s '
                    'tracking section, which classifier_node uses with '
                    'tracking:=true.')
    add_model_arguments(p, 'tracking')
    p.add_argument('--walks', nargs='+', required=True, metavar='PATH',
                   help='labelled walks with TIMESTAMP, recorded apart from '
                        'the model\'s training data: CSV(s), or folder(s) '
                        'of one CSV per walk')
    p.add_argument('--timeout', type=float, default=FitOptions.timeout,
                   metavar='S',
                   help='scans further apart are not one walk (the node\'s '
                        'tracking_timeout; default: %(default)s)')
    p.add_argument('--report', type=Path, metavar='OUT.json',
                   help='also write the figures and the grids searched')
    add_data_arguments(p)
    args = p.parse_args(argv)
    if not (math.isfinite(args.timeout) and args.timeout > 0):
        p.error(f'--timeout must be a finite number > 0, not {args.timeout}')
    option, out = model_output(args)
    check_outputs([(option, out), ('--report', args.report)],
                  [('--walks', w) for w in args.walks] +
                  [('--model', args.model)])
    model = load_model(args.model)
    fp = read_data(args.walks, data_options(args), 'walks')
    trained_on = model.provenance.get('training_data', {}).get('sha256')
    if trained_on and trained_on == fp.sha256:
        raise ValueError(f'{fp.source} is the model\'s training data: its '
                         f'probabilities there are over-confident; record '
                         f'other walks to fit tracking on')
    evidence = walk_evidence(model, fp, walks(fp))
    params, report = fit_tracking(evidence, FitOptions(timeout=args.timeout))
    summary = report['summary']
    model.tracking = replace(params, fit=dict(
        summary, walks=fp.source, walks_sha256=fp.sha256,
        created=time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())))
    save_model(model, out)      # first: a model it refuses, no report
    if args.report:
        with atomic_write(args.report, 'w') as f:
            json.dump(json_ready(report), f, indent=1, allow_nan=False)
    rates = summary['rates']
    print(f'{fp.source}: {summary["walks"]} walks, {summary["scans"]} '
          f'scans, {rates["hours"]:g} h, {rates["floor_changes"]} floor and '
          f'{rates["building_changes"]} building changes')
    for key, value in params.to_dict().items():
        if key != 'fit':
            print(f'  {key:20s} {value:.4g}')
    single, tracked = summary['single_accuracy'], summary['tracked_accuracy']
    print(f'building+floor on these walks: single scans {single:.4f}, '
          f'tracked {tracked:.4f}: tracking:=true '
          + ('helps here' if tracked > single else
             'does not help here (keep tracking:=false)'))
    print(f'wrote {out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
