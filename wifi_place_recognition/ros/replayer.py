"""
Publish the rows of a fingerprint CSV as WiFi scans and collect the answers.

A stand-in for a robot's WiFi driver: each row becomes a
``sensor_msgs/JointState`` on ``wifi/scan`` (AP names from the CSV header,
undetected APs left out). The classifier node's answers on its ``~/place``
topic are matched to scans by ``header.stamp``; at the end the number of
answered scans and the accuracy against the CSV labels are summarised.
"""

import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import numpy as np
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from ..core.metrics import accuracies
from .messages import scan_message, status_values


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
