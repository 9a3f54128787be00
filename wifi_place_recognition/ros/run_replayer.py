"""
Replay a robot run (scans + odometry) through classifier_node, in stamp order.

A stand-in for a robot: each scan row becomes a ``sensor_msgs/JointState``
on ``wifi/scan`` and each odometry row a ``nav_msgs/Odometry`` on ``odom``
(frame ``odom``, child ``base_link``), all stamped with their recorded
times and sent in stamp order at ``speed`` times the recorded pace (an
odometry pose before a scan of the same stamp). The node's answers on
``~/place`` (with each scan's own position) and its poses on ``~/pose``
are matched to the scans by ``header.stamp``. :func:`check_spans` refuses,
before anything is sent, streams whose time spans do not overlap or whose
replay would take more than a day (a stamp far off), and leaves out the
odometry more than :data:`ODOMETRY_MARGIN_S` outside the scans' span.
"""

from dataclasses import dataclass
import math
import time

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
import numpy as np
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy

from ..core.filter.trajectory import time_span
from .messages import scan_message, status_values, yaw_of
from .replayer import Replayer, unique_stamps


@dataclass(frozen=True)
class RunReplayOptions:
    """How :func:`replay_run` sends a run (``replay_run``'s options)."""

    place_topic: str = '/classifier_node/place'
    pose_topic: str = '/classifier_node/pose'
    speed: float = 10.0      # times the recorded pace
    wait: float = 15.0       # s for the node to appear
    settle: float = 2.0      # s to wait for the last answers

    def __post_init__(self):
        """Refuse a speed or wait that is not a finite number > 0 (>= 0)."""
        if not (math.isfinite(self.speed) and self.speed > 0):
            raise ValueError(f'speed must be > 0, not {self.speed!r}')
        if not (math.isfinite(self.wait) and self.wait >= 0):
            raise ValueError(f'wait must be a finite number >= 0, not '
                             f'{self.wait!r}')


#: Seconds of odometry sent before the scans' first stamp and after their
#: last (the node's default odom_timeout is 1 s); the rest is left out.
ODOMETRY_MARGIN_S = 10.0
#: The longest replay (s of wall-clock time) :func:`check_spans` accepts.
MAX_REPLAY_S = 86400.0


def check_spans(times, odometry_times, speed, names):
    """
    Return which odometry poses to send; refuse (ValueError) a bad replay.

    ``times``: the scans' stamps, ``odometry_times`` the odometry's;
    ``names``: (scans, odometry) for the message, which gives both time
    spans. Sent (a boolean mask): the poses within
    :data:`ODOMETRY_MARGIN_S` of the scans' time span. Refused: spans that
    do not overlap, no pose to send, or a replay of the scans and the poses
    sent that would take more than :data:`MAX_REPLAY_S` at ``speed`` (a
    stamp far off, which the replay would sleep through).
    """
    spans = f'the scans of {names[0]} span {time_span(times)}, the ' \
        f'odometry {names[1]} {time_span(odometry_times)}'
    low, high = np.min(times), np.max(times)
    if max(low, np.min(odometry_times)) > min(high, np.max(odometry_times)):
        raise ValueError(f'{spans}: they do not overlap (another clock, '
                         f'or another run?)')
    send = (odometry_times >= low - ODOMETRY_MARGIN_S) & \
        (odometry_times <= high + ODOMETRY_MARGIN_S)
    if not send.any():
        raise ValueError(f'{spans}: no odometry pose within '
                         f'{ODOMETRY_MARGIN_S:g} s of the scans (a gap in '
                         f'the odometry across all of them)')
    sent = odometry_times[send]
    seconds = (max(high, np.max(sent)) - min(low, np.min(sent))) / speed
    if seconds > MAX_REPLAY_S:
        raise ValueError(f'{spans}: the replay would take {seconds:.4g} s at '
                         f'speed {speed:g}, more than a day '
                         f'({MAX_REPLAY_S:g} s): a stamp far off? Cut the '
                         f'files to the run or raise --speed')
    return send


def localizer_message(row):
    """
    Return a localiser's PoseWithCovarianceStamped (frame ``map``).

    ``row``: stamp, x, y, yaw, then the x, y, yaw covariance as
    :data:`..data.poses.COVARIANCE_COLUMNS` (xx, xy, yy, yaw-yaw).
    """
    msg = PoseWithCovarianceStamped()
    msg.header = odometry_message(row).header
    msg.header.frame_id = 'map'
    msg.pose.pose = odometry_message(row).pose.pose
    cov = [0.0] * 36
    cov[0], cov[1], cov[6], cov[7], cov[35] = (
        float(row[4]), float(row[5]), float(row[5]), float(row[6]),
        float(row[7]))
    msg.pose.covariance = cov
    return msg


def odometry_message(row):
    """Return a nav_msgs/Odometry of a (stamp, x, y, yaw) row."""
    msg = Odometry()
    sec = math.floor(row[0])
    msg.header.stamp = Time(sec=int(sec),
                            nanosec=min(int(round((row[0] - sec) * 1e9)),
                                        999_999_999))
    msg.header.frame_id = 'odom'
    msg.child_frame_id = 'base_link'
    msg.pose.pose.position.x = float(row[1])
    msg.pose.pose.position.y = float(row[2])
    msg.pose.pose.orientation.z = math.sin(row[3] / 2)
    msg.pose.pose.orientation.w = math.cos(row[3] / 2)
    return msg


class RunReplayer(Replayer):
    """A :class:`.replayer.Replayer` that also sends odometry, gets poses."""

    def __init__(self, node, options, localizer_topic=None):
        super().__init__(node, options.place_topic)
        reliable = QoSProfile(depth=1000,
                              reliability=ReliabilityPolicy.RELIABLE)
        self.odom_pub = node.create_publisher(Odometry, 'odom', reliable)
        self.localizer_pub = None if localizer_topic is None else \
            node.create_publisher(PoseWithCovarianceStamped,
                                  localizer_topic, reliable)
        self.poses = {}      # (sec, nanosec) -> PoseWithCovarianceStamped
        node.create_subscription(PoseWithCovarianceStamped,
                                 options.pose_topic, self._on_pose, reliable)

    def _on_pose(self, msg):
        self.poses[(msg.header.stamp.sec, msg.header.stamp.nanosec)] = msg

    def ready(self):
        """Return True once the node takes scans and odometry and answers."""
        return bool(self.odom_pub.get_subscription_count()) and \
            super().ready()


def replay_run(node, fp, odometry, options, log, localizer=None):
    """
    Send the scans of ``fp`` and the ``odometry`` rows, in stamp order.

    ``localizer``: (topic, rows of :func:`localizer_message`): the
    localiser's poses, sent too (for a localization_monitor). Return
    {scan row: (place status or None, pose message or None)}.
    """
    topic, poses = localizer if localizer is not None else (None, ())
    replayer = RunReplayer(node, options, topic)
    if not replayer.wait_for_node(options.wait):
        raise RuntimeError(f'no classifier node took odom and answered on '
                           f'{options.place_topic} within {options.wait} s '
                           f'(is it running, with a model with positions, '
                           f'on the same ROS_DOMAIN_ID?)')
    replayer.reset(options.wait)
    times = fp.meta['TIMESTAMP']
    order = np.argsort(times, kind='stable')
    stamps = dict(zip(order, unique_stamps(times[order])))
    events = sorted([(float(t), 0, k) for k, t in enumerate(odometry[:, 0])] +
                    [(float(times[r]), 1, r) for r in order] +
                    [(float(row[0]), 2, k) for k, row in enumerate(poses)])
    start, t0 = time.monotonic(), events[0][0] if events else 0.0
    for n, (t, kind, k) in enumerate(events):
        replayer.spin_until(lambda: False,
                            start + (t - t0) / options.speed)
        if kind == 1:
            replayer.publish(k, scan_message(fp.ap_ids, fp.rssi[k],
                                             stamps[k]))
        elif kind == 2:
            replayer.localizer_pub.publish(localizer_message(poses[k]))
        else:
            replayer.odom_pub.publish(odometry_message(odometry[k]))
        if (n + 1) % 2000 == 0:
            log(f'{n + 1}/{len(events)} messages sent, '
                f'{len(replayer.answers)} scans answered')
    replayer.spin_until(
        lambda: len(replayer.answers) >= len(order),
        time.monotonic() + options.settle)
    rclpy.spin_once(node, timeout_sec=0.2)
    return {row: (replayer.answers.get(row), replayer.poses.get(
        (stamps[row].sec, stamps[row].nanosec))) for row in order}


def arrays(results, n):
    """
    Return the scans' own and the node's poses as arrays over ``n`` rows.

    (single xy (n, 2), pose xy (n, 2), pose yaw (n,), pose cov (n, 3, 3)),
    NaN where a scan got no answer or no pose.
    """
    single = np.full((n, 2), np.nan)
    xy, yaw = np.full((n, 2), np.nan), np.full(n, np.nan)
    cov = np.full((n, 3, 3), np.nan)
    for row, (status, pose) in results.items():
        values = status_values(status) if status is not None else {}
        if 'scan_x' in values:
            single[row] = float(values['scan_x']), float(values['scan_y'])
        if pose is not None:
            p = pose.pose
            xy[row] = p.pose.position.x, p.pose.position.y
            yaw[row] = yaw_of(p.pose.orientation)
            c = np.asarray(p.covariance).reshape(6, 6)
            cov[row] = c[np.ix_((0, 1, 5), (0, 1, 5))]
    return single, xy, yaw, cov
