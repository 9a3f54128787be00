"""``replay_run``: a robot run (scans + odometry) through the node, scored."""

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.utilities import remove_ros_args

from ..core.atomic import atomic_write
from ..core.filter.trajectory import (inside_span, odometry_alone, score,
                                      time_span, truth_at)
from ..ros.run_replayer import (arrays, check_spans, ODOMETRY_MARGIN_S,
                                replay_run, RunReplayOptions)
from ..data.bags import is_bag, read_bags
from ..data.poses import COVARIANCE_COLUMNS, POSE_COLUMNS, read_poses
from .common import (add_data_arguments, check_outputs, data_options,
                     json_ready, main_wrapper, option_message,
                     read_pose_input, read_run, topic_name)

#: What each column of the printed table is.
WHO = (('single', 'each scan alone'),
       ('odometry', 'odometry alone from the first true pose in its '
                    'time span'),
       ('fused', 'the node\'s ~/pose'))
ROWS = (('mean_m', 'mean error (m)'), ('median_m', 'median error (m)'),
        ('p95_m', 'p95 error (m)'), ('max_m', 'max error (m)'),
        ('below_2m_from_s', 'below 2 m from (s)'),
        ('max_after_settle_m', 'max error after 30 s (m)'),
        ('yaw_median_deg_after_settle', 'median yaw error (deg)'),
        ('in_95_ellipse', 'in the 95 % ellipse'))


@main_wrapper
def main(argv=None):
    """Replay a run through a running classifier_node; print the scores."""
    p = argparse.ArgumentParser(
        allow_abbrev=False, prog='replay_run',
        description='Publish a robot run\'s scans (wifi/scan) and odometry '
                    '(odom) in stamp order to a running classifier_node and '
                    'score its poses (~/pose) against the truth: each scan '
                    'alone, odometry alone and the fused pose side by '
                    'side.')
    p.add_argument('--data', nargs='+', required=True, metavar='PATH',
                   help='the run\'s scans: a CSV with TIMESTAMP (and X, Y, '
                        'YAW as truth unless --truth is given), or its '
                        'bag(s): scans, odometry, and poses as truth')
    p.add_argument('--odometry', type=Path, metavar='CSV',
                   help='the run\'s odometry: TIMESTAMP, X, Y, YAW, or a '
                        'bag (default: that of the --data bags)')
    p.add_argument('--truth', type=Path, metavar='CSV',
                   help='true poses (TIMESTAMP, X, Y, YAW) or a bag\'s, '
                        'interpolated to the scans (default: the scans\' '
                        'X, Y, YAW)')
    p.add_argument('--speed', type=float, default=10.0,
                   help='times the recorded pace (default: %(default)s)')
    p.add_argument('--wait', type=float, default=15.0,
                   help='seconds to wait for the node to appear')
    p.add_argument('--localizer-topic', metavar='TOPIC',
                   help='also publish the localiser\'s poses with their '
                        'covariance on TOPIC (e.g. amcl_pose), for a '
                        'running localization_monitor: the bag\'s pose '
                        'topic, or --truth (a poses CSV with COV_XX, '
                        'COV_XY, COV_YY, COV_YAWYAW, or a bag)')
    p.add_argument('--place-topic', default='/classifier_node/place')
    p.add_argument('--pose-topic', default='/classifier_node/pose')
    p.add_argument('--json', type=Path, metavar='OUT.json',
                   help='also write the scores')
    p.add_argument('--trajectory', type=Path, metavar='OUT.csv',
                   help='write each scan\'s truth, single-scan, odometry '
                        'and fused pose')
    add_data_arguments(p)
    given = sys.argv[1:] if argv is None else list(argv)
    args = p.parse_args(remove_ros_args(given))
    try:
        options = RunReplayOptions(args.place_topic, args.pose_topic,
                                   args.speed, args.wait)
    except ValueError as exc:
        p.error(option_message(exc))
    check_outputs([('--json', args.json), ('--trajectory', args.trajectory)],
                  [('--data', d) for d in args.data] +
                  [('--odometry', args.odometry), ('--truth', args.truth)])
    data = data_options(args)
    fp, run_odometry, run_poses = read_run(args.data, data, 'run',
                                           role='test')
    if 'TIMESTAMP' not in fp.meta:
        p.error(f'{fp.source} has no TIMESTAMP column')
    odometry = read_pose_input(args.odometry, 'odometry', data, run_odometry)
    odometry_source = args.odometry or fp.source
    truth = truth_at(read_pose_input(args.truth, 'poses', data),
                     fp.meta['TIMESTAMP']) if args.truth else _own_truth(fp)
    if not np.isfinite(truth[0]).all(axis=1).any():
        raise ValueError(f'{args.truth or fp.source}: no true pose within '
                         f'the time span of the scans of {fp.source}')
    send = check_spans(fp.meta['TIMESTAMP'], odometry[:, 0], options.speed,
                       (fp.source, odometry_source))
    sent = int(send.sum())
    localizer = None if args.localizer_topic is None else (
        args.localizer_topic,
        _localizer_poses(args.truth, data, run_poses, fp))
    if sent < len(send):
        print(f'note: {odometry_source}: sending {sent} of {len(send)} '
              f'odometry poses, {len(send) - sent} left out (more than '
              f'{ODOMETRY_MARGIN_S:g} s outside the scans\' time span '
              f'{time_span(fp.meta["TIMESTAMP"])})', file=sys.stderr,
              flush=True)
    rclpy.init(args=given)
    node = rclpy.create_node('run_replayer')
    try:
        for option, topic in (('--place-topic', args.place_topic),
                              ('--pose-topic', args.pose_topic),
                              ('--localizer-topic', args.localizer_topic)):
            if topic is not None:
                topic_name(node, option, topic)
        results = replay_run(node, fp, odometry[send], options,
                             lambda s: print(s, file=sys.stderr, flush=True),
                             localizer)
    except (KeyboardInterrupt, ExternalShutdownException):
        return 130
    except RuntimeError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    scores, table = scored(fp, odometry, truth, results)
    scores['odometry_poses'] = {'total': len(send), 'sent': sent,
                                'left_out': len(send) - sent}
    answered = sum(status is not None for status, _ in results.values())
    print(f'{fp.source}: {answered}/{len(fp)} scans answered, '
          f'{sum(pose is not None for _, pose in results.values())} with a '
          f'pose; odometry {odometry_source}: {sent} of {len(send)} poses '
          f'sent')
    n = scores['scans']
    print(f'scored {n["with_true_pose"]} of {n["total"]} scans '
          f'({n["without_true_pose"]} without a true pose); odometry alone '
          f'{n["with_true_pose"] - n["outside_odometry"]} of them '
          f'({n["outside_odometry"]} outside the odometry\'s time span)')
    print(f'{"":26s}' + ''.join(f'{who:>10s}' for who, _ in WHO))
    for key, name in ROWS:
        cells = [scores[who].get(key) for who, _ in WHO]
        print(f'{name:26s}' + ''.join(
            f'{"-":>10s}' if v is None else f'{v:10.2f}' for v in cells))
    if args.json:
        with atomic_write(args.json, 'w') as f:
            json.dump(json_ready(scores), f, indent=1, allow_nan=False)
    if args.trajectory:
        with atomic_write(args.trajectory, 'w') as f:
            f.write('TIMESTAMP,TRUE_X,TRUE_Y,TRUE_YAW,SCAN_X,SCAN_Y,ODOM_X,'
                    'ODOM_Y,ODOM_YAW,FUSED_X,FUSED_Y,FUSED_YAW\n')
            np.savetxt(f, table, delimiter=',', fmt='%.6f')
    return 0 if answered == len(fp) else 1


def _localizer_poses(truth, data, run_poses, fp):
    """
    Return the localiser's poses with their covariance, (n, 8) rows.

    From ``--truth`` (a poses CSV with the covariance columns, or a bag),
    else the run's bags'; the poses within the scans' span and
    :data:`ODOMETRY_MARGIN_S` of it.
    """
    if truth is not None:
        poses = read_poses(truth, POSE_COLUMNS + COVARIANCE_COLUMNS) \
            if not is_bag(truth) else read_bags([truth], data.bag)[2]
    else:
        poses = run_poses
    if poses is None or poses.shape[1] < 8:
        raise ValueError('--localizer-topic needs the localiser\'s poses '
                         'with their covariance: a bag with its pose '
                         'topic, or --truth poses with COV_XX, COV_XY, '
                         'COV_YY, COV_YAWYAW')
    times = fp.meta['TIMESTAMP']
    keep = (poses[:, 0] >= np.min(times) - ODOMETRY_MARGIN_S) & \
        (poses[:, 0] <= np.max(times) + ODOMETRY_MARGIN_S)
    return poses[keep, :8]


def _own_truth(fp):
    if fp.position is None or 'YAW' not in fp.meta:
        raise ValueError(f'{fp.source}: no X, Y, YAW columns to score '
                         f'against: give --truth')
    return fp.position, fp.meta['YAW']


def scored(fp, odometry, truth, results):
    """Return ({who: scores}, trajectory table) of a replayed run."""
    stamps = fp.meta['TIMESTAMP']
    true_xy, true_yaw = truth
    single, xy, yaw, cov = arrays(results, len(fp))
    posed = np.isfinite(true_xy).all(axis=1)
    inside = posed & inside_span(stamps, odometry[:, 0])
    odo_xy, odo_yaw = odometry_alone(odometry, stamps, true_xy, true_yaw)
    scores = {'single': score(stamps, true_xy, single),
              'odometry': score(stamps, true_xy, odo_xy, true_yaw, odo_yaw),
              'fused': score(stamps, true_xy, xy, true_yaw, yaw, cov),
              'scans': {'total': len(fp), 'with_true_pose': int(posed.sum()),
                        'without_true_pose': int((~posed).sum()),
                        'outside_odometry': int((posed & ~inside).sum())}}
    table = np.column_stack([stamps, true_xy, true_yaw, single, odo_xy,
                             odo_yaw, xy, yaw])
    return scores, table


if __name__ == '__main__':
    sys.exit(main())
