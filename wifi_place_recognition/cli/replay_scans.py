"""``replay_scans``: publish a fingerprint CSV's rows as scans, score the node."""

import argparse
from dataclasses import replace
import sys

import numpy as np
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.utilities import remove_ros_args

from ..data.predictions import write_predictions
from ..ros.replayer import replay, ReplayOptions, summarise
from .common import (add_data_arguments, add_download_arguments,
                     check_outputs, data_options, main_wrapper,
                     option_message, read_data, topic_name)


@main_wrapper
def main(argv=None):
    """Replay a CSV through a running classifier_node and print accuracy."""
    p = argparse.ArgumentParser(
        allow_abbrev=False, prog='replay_scans',
        description='Publish the rows of a UJIIndoorLoc-format CSV as WiFi '
                    'scans (walk after walk, each in time order, when it '
                    'has a TIMESTAMP) and report how the classifier node '
                    'answered, beside each scan\'s own answer.')
    p.add_argument('--data', nargs='+', metavar='PATH',
                   help='labelled CSV(s) or folder(s) of CSVs, or the UCI '
                        'zip')
    p.add_argument('--rate', type=float, default=0.0,
                   help='scans per second; 0 (default): send each scan '
                        'when the previous one is answered')
    p.add_argument('--realtime', type=float, default=0.0, metavar='FACTOR',
                   help='replay each walk in TIMESTAMP order at its '
                        'recorded pace times FACTOR (1: real time, 10: ten '
                        'times faster; each scan is also answered before '
                        'the next); needs a TIMESTAMP column')
    p.add_argument('--file-order', action='store_true',
                   help='send the rows in file order (default with a '
                        'TIMESTAMP: walk after walk, in time order, the '
                        'node\'s tracking reset before each walk)')
    p.add_argument('--max-wait', type=float, default=10.0, metavar='S',
                   help='--realtime: wait at most S seconds between two '
                        'scans (default: %(default)s)')
    p.add_argument('--limit', type=int, default=None,
                   help='replay at most N rows')
    p.add_argument('--place-topic', default='/classifier_node/place',
                   help='where the node answers (default: %(default)s; '
                        'its reset service is beside it)')
    p.add_argument('--timeout', type=float, default=1.0,
                   help='seconds to wait for an answer (default: 1)')
    p.add_argument('--retries', type=int, default=2,
                   help='lockstep mode: resend an unanswered scan up to N '
                        'times (the first scans after discovery can be '
                        'lost; default: 2)')
    p.add_argument('--wait', type=float, default=15.0,
                   help='seconds to wait for the node to appear')
    p.add_argument('--progress', type=int, default=100,
                   help='print progress every N scans')
    p.add_argument('--predictions', metavar='OUT.csv',
                   help='write the answers in evaluate_model\'s format')
    add_download_arguments(p)
    add_data_arguments(p)
    given = sys.argv[1:] if argv is None else list(argv)
    args = p.parse_args(remove_ros_args(given))
    try:    # checked before the data is read; by_walk needs its stamps
        options = ReplayOptions(
            place_topic=args.place_topic, wait=args.wait, rate=args.rate,
            by_walk=not args.file_order, realtime=args.realtime,
            max_wait=args.max_wait, limit=args.limit, timeout=args.timeout,
            retries=args.retries, progress=args.progress)
    except ValueError as exc:
        p.error(option_message(exc))
    check_outputs([('--predictions', args.predictions)],
                  [('--data', d) for d in args.data or ()])
    fp = read_data(args.data, data_options(args), 'data', role='test')
    timed = 'TIMESTAMP' in fp.meta
    if args.realtime and not timed:
        p.error(f'--realtime: {fp.source} has no TIMESTAMP column')
    options = replace(options, by_walk=timed and not args.file_order)
    rclpy.init(args=given)
    node = rclpy.create_node('scan_replayer')
    try:
        topic_name(node, '--place-topic', args.place_topic)
        groups, answers = replay(node, fp, options,
                                 lambda s: print(s, file=sys.stderr,
                                                 flush=True))
    except (KeyboardInterrupt, ExternalShutdownException):
        return 130
    except RuntimeError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    summary, per_walk, predictions = summarise(fp, groups, answers)
    if args.predictions:
        write_predictions(args.predictions, fp.subset(np.sort(
            np.concatenate(groups))), predictions)
    report(fp, options, summary, per_walk)
    return 0 if summary['answered'] == summary['sent'] else 1


def report(fp, options, summary, per_walk):
    """Print the answers' accuracy beside the scans' own, walk by walk."""
    order = f'{len(per_walk)} walks, each in time order' if \
        options.by_walk else 'file order'
    print(f'{fp.source}: {summary["answered"]}/{summary["sent"]} scans '
          f'answered ({summary["rejected"]} rejected), {order}')
    print(f'{"":28s} {"scan alone":>10s} {"answer":>10s}  (the node\'s '
          f'answer: tracked with tracking:=true)')
    if len(per_walk) > 1:
        print('building+floor, per walk')
        for walk in per_walk:
            if walk['scans']:
                print(f'  {walk["walk"][:26]:26s} '
                      f'{walk["scan_building_floor_accuracy"]:10.4f} '
                      f'{walk["answer_building_floor_accuracy"]:10.4f}  '
                      f'({walk["scans"]} scans)')
    for key, name in (('building_accuracy', 'building'),
                      ('floor_accuracy', 'floor'),
                      ('building_floor_accuracy', 'building+floor'),
                      ('position_mean_error_m', 'position mean error (m)')):
        if f'answer_{key}' in summary:
            print(f'{name:28s} {summary[f"scan_{key}"]:10.4f} '
                  f'{summary[f"answer_{key}"]:10.4f}')


if __name__ == '__main__':
    sys.exit(main())
