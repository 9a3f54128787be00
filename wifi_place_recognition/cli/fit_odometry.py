"""``fit_odometry``: fit the odometry fusion's drift on a surveyed run."""

import argparse
import json
import sys
import time
from pathlib import Path

from ..core.artifact import load_model, save_model
from ..core.atomic import atomic_write
from ..core.filter.odometry_fit import fit_odometry
from ..core.filter.particles import FusionParams
from .common import (add_data_arguments, add_model_arguments,
                     check_outputs, data_options, json_ready, main_wrapper,
                     model_output, read_pose_input, read_run)


@main_wrapper
def main(argv=None):
    """Fit, write the model file's fusion section; exit 2 on bad input."""
    p = argparse.ArgumentParser(
        allow_abbrev=False, prog='fit_odometry',
        description='Fit the heading drift of the robot\'s odometry on a run '
                    'recorded with its localiser running (scans with X, Y, '
                    'YAW and TIMESTAMP, and the odometry beside them, as '
                    'record_fingerprints writes with pose_topic and '
                    'odom_topic) and write it into the model file\'s fusion '
                    'section, which classifier_node uses when odometry '
                    'flows.')
    add_model_arguments(p, 'fusion')
    p.add_argument('--data', nargs='+', required=True, metavar='PATH',
                   help='the run\'s scans: CSV with TIMESTAMP, X, Y, YAW '
                        '(the survey the model was trained on will do), '
                        'or its bag(s) with scans, odometry and poses')
    p.add_argument('--odometry', type=Path, metavar='CSV',
                   help='the run\'s odometry: TIMESTAMP, X, Y, YAW, or a '
                        'bag (default: that of the --data bags)')
    p.add_argument('--window', type=float, default=3.0, metavar='M',
                   help='metres of travel per stretch (default: '
                        '%(default)s)')
    p.add_argument('--report', type=Path, metavar='OUT.json',
                   help='also write what was measured')
    add_data_arguments(p)
    args = p.parse_args(argv)
    if not args.window > 0:
        p.error('--window must be > 0')
    option, out = model_output(args)
    check_outputs([(option, out), ('--report', args.report)],
                  [('--data', d) for d in args.data] +
                  [('--odometry', args.odometry), ('--model', args.model)])
    model = load_model(args.model)
    if model.position is None:
        raise ValueError(f'{args.model}: the model has no position output; '
                         f'fusion needs one (train with X, Y)')
    options = data_options(args)
    fp, run_odometry, _ = read_run(args.data, options, 'run')
    if fp.position is None or 'YAW' not in fp.meta or \
            'TIMESTAMP' not in fp.meta:
        raise ValueError(f'{fp.source}: fitting needs TIMESTAMP, X, Y and '
                         f'YAW columns (the localiser\'s pose at each scan)')
    odometry = read_pose_input(args.odometry, 'odometry', options,
                               run_odometry)
    odometry_source = str(args.odometry or fp.source)
    params, report = fit_odometry(
        odometry, fp.meta['TIMESTAMP'], fp.position,
        fp.meta['YAW'], model.fusion or FusionParams(),
        args.window, (fp.source, odometry_source))
    report.update(run=fp.source, run_sha256=fp.sha256,
                  odometry=odometry_source,
                  created=time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime()))
    params.fit.update(report)
    model.fusion = params
    save_model(model, out)      # first: a model it refuses, no report
    if args.report:
        with atomic_write(args.report, 'w') as f:
            json.dump(json_ready(report), f, indent=1, allow_nan=False)
    print(f'{fp.source}: {report["scans"]} posed scans inside the '
          f'odometry\'s time span ({report["scans_outside_odometry"]} '
          f'outside), {report["distance_m"]:.1f} m driven in '
          f'{report["windows"]} stretches '
          f'({report["windows_across_odometry_gaps"]} more across an '
          f'odometry gap longer than {report["odometry_gap_limit_s"]:g} s '
          f'left out); odometry distance / true distance '
          f'{report["odometry_distance_ratio"]:.4f}')
    print(f'heading drift {report["drift_deg_per_m"]:+.3f} deg/m '
          f'(+- {report["drift_sd_deg_per_m"]:.3f}; stretches spread '
          f'{report["window_drift_deg_per_m_sd"]:.2f})')
    if args.report:
        print(f'wrote {args.report}')
    print(f'wrote {out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
