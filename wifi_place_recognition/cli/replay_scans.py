"""``replay_scans``: publish a fingerprint CSV's rows as scans, score the node."""

import argparse
import sys

import numpy as np
import rclpy
from rclpy.executors import ExternalShutdownException

from ..data.predictions import write_predictions
from ..ros.replayer import replay, ReplayOptions, summarise
from .common import (add_data_arguments, add_download_arguments,
                     data_options, main_wrapper, read_data)


@main_wrapper
def main(argv=None):
    """Replay a CSV through a running classifier_node and print accuracy."""
    p = argparse.ArgumentParser(
        allow_abbrev=False, prog='replay_scans',
        description='Publish the rows of a UJIIndoorLoc-format CSV as WiFi '
                    'scans and report how the classifier node answered.')
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
    p.add_argument('--max-wait', type=float, default=10.0, metavar='S',
                   help='--realtime: wait at most S seconds between two '
                        'scans (default: %(default)s)')
    p.add_argument('--limit', type=int, default=None,
                   help='replay at most N rows')
    p.add_argument('--place-topic', default='/classifier_node/place',
                   help='where the node answers (default: %(default)s)')
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
    args, ros_args = p.parse_known_args(argv)
    if args.realtime < 0 or (args.realtime and args.rate):
        p.error('--realtime FACTOR must be > 0, and not with --rate')
    options = ReplayOptions(
        place_topic=args.place_topic, wait=args.wait, rate=args.rate,
        realtime=args.realtime, max_wait=args.max_wait, limit=args.limit,
        timeout=args.timeout, retries=args.retries, progress=args.progress)
    fp = read_data(args.data, data_options(args), 'data', role='test')
    if args.realtime and 'TIMESTAMP' not in fp.meta:
        p.error(f'--realtime: {fp.source} has no TIMESTAMP column')
    rclpy.init(args=ros_args)
    node = rclpy.create_node('scan_replayer')
    try:
        rows, answers = replay(node, fp, options,
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
    summary, predictions = summarise(fp, rows, answers)
    if args.predictions:
        write_predictions(args.predictions, fp.subset(np.sort(rows)),
                          predictions)
    print(f'{fp.source}: {summary["answered"]}/{len(rows)} scans answered '
          f'({summary["rejected"]} rejected)')
    for key in ('building_accuracy', 'floor_accuracy',
                'building_floor_accuracy'):
        print(f'  {key.replace("_", " "):24s} {summary[key]:.4f}')
    return 0 if summary['answered'] == len(rows) else 1


if __name__ == '__main__':
    sys.exit(main())
