"""
Publish the rows of a fingerprint CSV as WiFi scans and collect the answers.

A stand-in for a robot's WiFi driver: each row becomes a
``sensor_msgs/JointState`` on ``wifi/scan`` (AP names from the CSV header,
undetected APs left out), stamped with the row's TIMESTAMP when the data
has one (else the current time), so a tracking node sees the recorded time
between scans. Data with a TIMESTAMP is replayed walk after walk (one
device or file), each in time order, the node's tracked belief reset
(its ``~/reset`` service) before each walk; with a real-time factor at the
recorded pace (or a multiple of it). The classifier node's answers on its
``~/place`` topic are matched to scans by ``header.stamp``; at the end the
answers and the scans' own answers (``scan_*`` values) are scored against
the CSV labels, overall and per walk.
"""

from dataclasses import dataclass
import math
import time

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import numpy as np
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from ..core.metrics import accuracies
from ..data.walks import walk_name, walks
from .messages import scan_message, status_values


@dataclass(frozen=True)
class ReplayOptions:
    """How :func:`replay` sends the scans (``replay_scans``' options)."""

    place_topic: str = '/classifier_node/place'
    by_walk: bool = True      # walk after walk (needs TIMESTAMP); else rows
    wait: float = 15.0        # s for the node to appear
    rate: float = 0.0         # scans per second; 0: lockstep
    realtime: float = 0.0     # > 0: each walk at its pace times this
    max_wait: float = 10.0    # s between two scans at most (realtime)
    limit: int = None         # send at most this many scans
    timeout: float = 1.0      # s to wait for an answer
    retries: int = 2          # lockstep: resend an unanswered scan
    progress: int = 100       # log every this many scans

    def __post_init__(self):
        """Refuse values out of range and options that contradict."""
        for name, low, strict in (('wait', 0, False), ('rate', 0, False),
                                  ('realtime', 0, False),
                                  ('max_wait', 0, True),
                                  ('timeout', 0, True)):
            value = getattr(self, name)
            if not (math.isfinite(value) and
                    (value > low if strict else value >= low)):
                raise ValueError(f'{name} must be a finite number '
                                 f'{">" if strict else ">="} {low}, not '
                                 f'{value!r}')
        for name, low in (('limit', 1), ('retries', 0), ('progress', 1)):
            value = getattr(self, name)
            if value is not None and value < low:
                raise ValueError(f'{name} must be at least {low}, not '
                                 f'{value!r}')
        if self.realtime and self.rate:
            raise ValueError('realtime is not with --rate')
        if self.realtime and not self.by_walk:
            raise ValueError('realtime replays walks in time order, not '
                             'with --file-order')


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
        # the node's ~/reset: its ~/place topic's namespace
        self.reset_client = node.create_client(
            Trigger, self.place_topic.rpartition('/')[0] + '/reset')

    def _on_place(self, msg):
        row = self.rows.get((msg.header.stamp.sec, msg.header.stamp.nanosec))
        if row is not None and msg.status:
            self.answers[row] = msg.status[0]

    def ready(self):
        """Return True once the node's subscription and answers are seen."""
        return bool(self.pub.get_subscription_count() and
                    self.node.count_publishers(self.place_topic))

    def wait_for_node(self, timeout):
        """Spin (0.05 s at a time) until :meth:`ready`; False at timeout."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.ready():
                return True
            rclpy.spin_once(self.node, timeout_sec=0.05)
        return False

    def reset(self, timeout):
        """Clear the node's tracked belief; raise RuntimeError if it can't."""
        name = self.reset_client.srv_name
        if not self.reset_client.wait_for_service(timeout_sec=timeout):
            raise RuntimeError(f'the node offers no {name} service')
        future = self.reset_client.call_async(Trigger.Request())
        if not self.spin_until(future.done, time.monotonic() + timeout) \
                or not future.result().success:
            raise RuntimeError(f'{name} did not answer within {timeout} s')

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

    Return (the rows sent: one array per walk, or one in file order;
    {row: status}).
    """
    replayer = Replayer(node, options.place_topic)
    if not replayer.wait_for_node(options.wait):
        raise RuntimeError(f'no classifier node answered within '
                           f'{options.wait} s (is it running, on the same '
                           f'ROS_DOMAIN_ID, publishing '
                           f'{options.place_topic}?)')
    groups = []
    for group in walks(fp) if options.by_walk else [np.arange(len(fp))]:
        if options.limit is not None:
            group = group[:options.limit - sum(map(len, groups))]
        if len(group):
            groups.append(group)
    order = np.concatenate(groups) if groups else np.arange(0)
    times = fp.meta.get('TIMESTAMP')
    stamps = None if times is None else unique_stamps(times[order])
    period = 1.0 / options.rate if options.rate > 0 else 0.0
    next_time, i, n = time.monotonic(), 0, len(order)
    for group in groups:
        if options.by_walk:
            replayer.reset(options.wait)
        for k, row in enumerate(group):
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
                    if replayer.spin_until(
                            lambda: row in replayer.answers,
                            time.monotonic() + options.timeout):
                        break
            if options.realtime and k + 1 < len(group):  # recorded gap
                gap = (times[group[k + 1]] - times[row]) / options.realtime
                replayer.spin_until(lambda: False, sent_at + min(
                    max(gap, 0.0), options.max_wait))
            i += 1
            if i % options.progress == 0 or i == n:
                log(f'{i}/{n} scans sent, {len(replayer.answers)} '
                    f'answered')
    replayer.spin_until(lambda: len(replayer.answers) >= n,
                        time.monotonic() + options.timeout)
    return groups, replayer.answers


def summarise(fp, groups, answers):
    """
    Score the answers to the scans sent (``groups`` as :func:`replay`'s).

    Return (summary, per-walk list, predictions). Both score the node's
    answers (``answer_*``: tracked when the node tracks) and each scan's
    own (``scan_*``); positions too when the answers and the data have
    them. Predictions (the answers) are arrays in the order of
    ``fp.subset(np.sort(rows sent))``.
    """
    rows = np.sort(np.concatenate(groups)) if groups else np.arange(0)
    got = {key: np.full(len(fp), np.nan) for key in
           ('building', 'floor', 'confidence', 'scan_building',
            'scan_floor', 'x', 'y', 'scan_x', 'scan_y')}
    rejected = 0
    for row in rows:
        status = answers.get(row)
        if status is None:
            continue
        if status.level == DiagnosticStatus.ERROR:
            rejected += 1
            continue
        values = status_values(status)
        for key, column in got.items():
            if key in values:
                column[row] = float(values[key])
    summary = dict(_scores(fp, rows, got), sent=len(rows),
                   answered=sum(r in answers for r in rows),
                   rejected=rejected)
    per_walk = [dict(_scores(fp, g, got), walk=walk_name(fp, g) if
                     len(groups) > 1 else 'all scans') for g in groups]
    predictions = {'building': np.nan_to_num(got['building'][rows],
                                             nan=-1).astype(int),
                   'floor': np.nan_to_num(got['floor'][rows],
                                          nan=-1).astype(int),
                   'confidence': got['confidence'][rows]}
    return summary, per_walk, predictions


def _scores(fp, rows, got):
    """Return the answers' and the scans' own figures over ``rows``."""
    rows = rows[np.isfinite(got['building'][rows])]
    out = {'scans': len(rows)}
    if not len(rows):
        return out
    for who, prefix in (('answer', ''), ('scan', 'scan_')):
        scores = accuracies(fp.building[rows], fp.floor[rows],
                            got[f'{prefix}building'][rows],
                            got[f'{prefix}floor'][rows])
        del scores['samples']
        out.update({f'{who}_{k}': v for k, v in scores.items()})
        xy = np.stack([got[f'{prefix}x'][rows], got[f'{prefix}y'][rows]], 1)
        if fp.position is not None and np.isfinite(xy).all():
            out[f'{who}_position_mean_error_m'] = float(np.linalg.norm(
                xy - fp.position[rows], axis=1).mean())
    return out
