"""
``replay_scans``: publish the rows of a fingerprint CSV as WiFi scans.

A stand-in for a robot's WiFi driver: each row becomes a
``sensor_msgs/JointState`` on ``wifi/scan`` (AP names from the CSV header,
undetected APs left out). The classifier node's answers on its ``~/place``
topic are matched to scans by ``header.stamp``; at the end the number of
answered scans and the accuracy against the CSV labels are printed.
"""

import argparse
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import numpy as np
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from .cli import add_download_arguments, data_path, main_wrapper
from .evaluate_model import write_predictions
from .fingerprints import read_fingerprints
from .metrics import accuracies


def status_values(status):
    """Return a DiagnosticStatus's key/values as a dict."""
    return {kv.key: kv.value for kv in status.values}


def scan_message(ap_ids, rssi, stamp, frame_id='replay'):
    """Return a JointState scan of the detected (non-NaN) APs of one row."""
    detected = np.flatnonzero(np.isfinite(rssi))
    msg = JointState(name=[ap_ids[j] for j in detected],
                     position=rssi[detected].astype(float).tolist())
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    return msg


class Replayer:
    """Publish scans and collect the answers, keyed by row."""

    def __init__(self, node, place_topic):
        self.node = node
        self.pub = node.create_publisher(
            JointState, 'wifi/scan',
            QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
        self.place_topic = node.resolve_topic_name(place_topic)
        node.create_subscription(
            DiagnosticArray, self.place_topic, self._on_place,
            QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
        self.rows = {}        # (sec, nanosec) -> row
        self.answers = {}     # row -> DiagnosticStatus

    def _on_place(self, msg):
        row = self.rows.get((msg.header.stamp.sec, msg.header.stamp.nanosec))
        if row is not None and msg.status:
            self.answers[row] = msg.status[0]

    def wait_for_node(self, timeout):
        """Spin until the node's subscription and answer topic are seen."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.pub.get_subscription_count() and \
                    self.node.count_publishers(self.place_topic):
                return True
            rclpy.spin_once(self.node, timeout_sec=0.05)
        return False

    def publish(self, row, msg):
        """Publish one scan for ``row``."""
        stamp = msg.header.stamp
        self.rows[(stamp.sec, stamp.nanosec)] = row
        self.pub.publish(msg)

    def spin_until(self, done, deadline):
        """Spin until ``done()`` or the monotonic ``deadline``."""
        while not done() and time.monotonic() < deadline:
            rclpy.spin_once(self.node, timeout_sec=0.01)
        return done()


def replay(node, fp, args, log):
    """Publish every row of ``fp``; return {row: DiagnosticStatus}."""
    replayer = Replayer(node, args.place_topic)
    if not replayer.wait_for_node(args.wait):
        raise RuntimeError(f'no classifier node answered within {args.wait} '
                           f's (is it running, on the same ROS_DOMAIN_ID, '
                           f'publishing {args.place_topic}?)')
    n = len(fp) if args.limit is None else min(args.limit, len(fp))
    period = 1.0 / args.rate if args.rate > 0 else 0.0
    next_time = time.monotonic()
    for row in range(n):
        stamp = node.get_clock().now().to_msg()
        msg = scan_message(fp.ap_ids, fp.rssi[row], stamp)
        replayer.publish(row, msg)
        if period:
            next_time += period
            replayer.spin_until(lambda: False, next_time)
        else:  # lockstep: wait for this answer before the next scan
            for attempt in range(1 + args.retries):
                if attempt:
                    replayer.publish(row, msg)
                if replayer.spin_until(lambda: row in replayer.answers,
                                       time.monotonic() + args.timeout):
                    break
        if (row + 1) % args.progress == 0 or row + 1 == n:
            log(f'{row + 1}/{n} scans sent, {len(replayer.answers)} '
                f'answered')
    replayer.spin_until(lambda: len(replayer.answers) >= n,
                        time.monotonic() + args.timeout)
    return n, replayer.answers


def summarise(fp, n, answers):
    """Return (summary dict, predictions) for the answered scans."""
    building = np.full(n, -1)
    floor = np.full(n, -1)
    confidence = np.full(n, np.nan)
    rejected = 0
    for row, status in answers.items():
        values = status_values(status)
        if status.level == DiagnosticStatus.ERROR:
            rejected += 1
            continue
        building[row] = int(values['building'])
        floor[row] = int(values['floor'])
        confidence[row] = float(values['confidence'])
    ok = building >= 0
    summary = {'sent': n, 'answered': len(answers), 'rejected': rejected}
    summary.update(accuracies(fp.building[:n][ok], fp.floor[:n][ok],
                              building[ok], floor[ok]))
    return summary, (building, floor, confidence)


@main_wrapper
def main(argv=None):
    """Replay a CSV through a running classifier_node and print accuracy."""
    p = argparse.ArgumentParser(
        prog='replay_scans',
        description='Publish the rows of a UJIIndoorLoc-format CSV as WiFi '
                    'scans and report how the classifier node answered.')
    p.add_argument('--data', help='labelled CSV, or the UCI zip')
    p.add_argument('--rate', type=float, default=0.0,
                   help='scans per second; 0 (default): send each scan '
                        'when the previous one is answered')
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
    args, ros_args = p.parse_known_args(argv)
    fp = read_fingerprints(data_path(args.data, args, 'data'), role='test')
    rclpy.init(args=ros_args)
    node = rclpy.create_node('scan_replayer')
    try:
        n, answers = replay(node, fp, args,
                            lambda s: print(s, file=sys.stderr, flush=True))
    except (KeyboardInterrupt, ExternalShutdownException):
        return 130
    except RuntimeError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    summary, predictions = summarise(fp, n, answers)
    if args.predictions:
        write_predictions(args.predictions, fp, predictions)
    print(f'{fp.source}: {summary["answered"]}/{n} scans answered '
          f'({summary["rejected"]} rejected)')
    for key in ('building_accuracy', 'floor_accuracy',
                'building_floor_accuracy'):
        print(f'  {key.replace("_", " "):24s} {summary[key]:.4f}')
    return 0 if summary['answered'] == n else 1


if __name__ == '__main__':
    sys.exit(main())
