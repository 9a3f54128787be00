"""
Publish the rows of a fingerprint CSV as WiFi scans and collect the answers.

A stand-in for a robot's WiFi driver: each row becomes a
``sensor_msgs/JointState`` on ``wifi/scan`` (AP names from the CSV header,
undetected APs left out), stamped with the row's TIMESTAMP when the data
has one (else the current time), so a tracking node sees the recorded time
between scans. With a real-time factor the walks are replayed in time order
at their recorded pace (or a multiple of it). The classifier node's answers
on its ``~/place`` topic are matched to scans by ``header.stamp``; at the
end the number of answered scans and the accuracy against the CSV labels
are summarised.
"""

from dataclasses import dataclass
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import numpy as np
import rclpy
from builtin_interfaces.msg import Time
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from ..core.metrics import accuracies
from ..data.walks import walks
from .messages import scan_message, status_values


@dataclass(frozen=True)
class ReplayOptions:
    """How :func:`replay` sends the scans (``replay_scans``' options)."""

    place_topic: str = '/classifier_node/place'
    wait: float = 15.0        # s for the node to appear
    rate: float = 0.0         # scans per second; 0: lockstep
    realtime: float = 0.0     # > 0: each walk at its pace times this
    max_wait: float = 10.0    # s between two scans at most (realtime)
    limit: int = None         # send at most this many scans
    timeout: float = 1.0      # s to wait for an answer
    retries: int = 2          # lockstep: resend an unanswered scan
    progress: int = 100       # log every this many scans

    def __post_init__(self):
        """Refuse options that contradict each other."""
        if self.realtime < 0 or (self.realtime and self.rate):
            raise ValueError('realtime must be >= 0, and not with a rate')


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


def unique_stamps(seconds):
    """
    Return a ``Time`` per recorded time (s), all distinct and non-zero.

    Times are kept to the microsecond. Answers are matched to scans by
    stamp: a time already used (or zero, which means "no stamp") is moved
    on by a microsecond.
    """
    used, stamps = set(), []
    for t in seconds:
        ns = round(float(t) * 1e6) * 1000
        while ns in used or ns == 0:
            ns += 1000
        used.add(ns)
        sec, nanosec = divmod(ns, 10 ** 9)
        stamps.append(Time(sec=sec, nanosec=nanosec))
    return stamps


def replay(node, fp, options, log):
    """
    Publish the rows of ``fp`` as :class:`ReplayOptions` say.

    Return (rows sent, {row: status}).
    """
    replayer = Replayer(node, options.place_topic)
    if not replayer.wait_for_node(options.wait):
        raise RuntimeError(f'no classifier node answered within {options.wait} '
                           f's (is it running, on the same ROS_DOMAIN_ID, '
                           f'publishing {options.place_topic}?)')
    times = fp.meta.get('TIMESTAMP')
    order = np.concatenate(walks(fp)) if options.realtime else \
        np.arange(len(fp))
    n = len(fp) if options.limit is None else min(options.limit, len(fp))
    order = order[:n]
    stamps = None if times is None else unique_stamps(times[order])
    period = 1.0 / options.rate if options.rate > 0 else 0.0
    next_time = time.monotonic()
    for i, row in enumerate(order):
        stamp = node.get_clock().now().to_msg() if stamps is None \
            else stamps[i]
        msg = scan_message(fp.ap_ids, fp.rssi[row], stamp)
        sent_at = time.monotonic()
        replayer.publish(row, msg)
        if period:
            next_time += period
            replayer.spin_until(lambda: False, next_time)
        else:  # lockstep: wait for this answer before the next scan
            for attempt in range(1 + options.retries):
                if attempt:
                    replayer.publish(row, msg)
                if replayer.spin_until(lambda: row in replayer.answers,
                                       time.monotonic() + options.timeout):
                    break
        if options.realtime and i + 1 < n:  # and the recorded gap, capped
            gap = (times[order[i + 1]] - times[row]) / options.realtime
            replayer.spin_until(lambda: False, sent_at + min(
                max(gap, 0.0), options.max_wait))   # (< 0: the next walk)
        if (i + 1) % options.progress == 0 or i + 1 == n:
            log(f'{i + 1}/{n} scans sent, {len(replayer.answers)} '
                f'answered')
    replayer.spin_until(lambda: len(replayer.answers) >= n,
                        time.monotonic() + options.timeout)
    return order, replayer.answers


def summarise(fp, rows, answers):
    """
    Return (summary dict, predictions) for the scans of ``rows`` (sent).

    Predictions are arrays in the order of ``fp.subset(np.sort(rows))``.
    """
    rows = np.sort(rows)
    building = np.full(len(rows), -1)
    floor = np.full(len(rows), -1)
    confidence = np.full(len(rows), np.nan)
    rejected = 0
    for i, row in enumerate(rows):
        status = answers.get(row)
        if status is None:
            continue
        if status.level == DiagnosticStatus.ERROR:
            rejected += 1
            continue
        values = status_values(status)
        building[i] = int(values['building'])
        floor[i] = int(values['floor'])
        confidence[i] = float(values['confidence'])
    ok = building >= 0
    summary = {'sent': len(rows), 'answered': len(answers),
               'rejected': rejected}
    summary.update(accuracies(fp.building[rows][ok], fp.floor[rows][ok],
                              building[ok], floor[ok]))
    return summary, {'building': building, 'floor': floor,
                     'confidence': confidence}
