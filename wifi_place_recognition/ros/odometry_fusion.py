"""
classifier_node's odometry input: :class:`.core.filter.fusion.Fusion` on ROS.

Subscribes ``odom`` (``nav_msgs/Odometry``, the pose in the robot's odom
frame; sensor-data QoS with a deep queue) and feeds it, with each answered
scan's position, to the filter in stamp order (a zero stamp means the
time the node takes the message). Fused poses go to ``publish(fused,
stamp, place, relocated)``: one per scan, stamped with the scan's stamp,
and ``pose_rate`` times a second between scans while odometry moves on;
``relocated`` when the filter started afresh on the place it was on (the
scans kept disagreeing with it, or WiFi alone for long). A timer lets a
scan that waited ``odom_timeout`` seconds for odometry through alone.
Odometry faults (:data:`.core.filter.fusion.ODOMETRY_FAULTS`) are counted and
logged (throttled); the health status is WARN while odometry is faulty or
stale. An error inside the filter is counted and logged, never raised.
"""

import copy
from dataclasses import replace
import math
import time

from nav_msgs.msg import Odometry
from rclpy.qos import qos_profile_sensor_data

from ..core.filter.fusion import Fusion, FusionLimits, ODOMETRY_FAULTS
from .messages import pose_problem, stamp_time, yaw_of

ODOM_QOS = copy.copy(qos_profile_sensor_data)
ODOM_QOS.depth = 100
THROTTLE_S = 5.0
#: Seconds after a fault or a scan fused alone during which health is WARN.
WARN_S = 10.0
#: Names of :class:`.core.filter.fusion.Fusion` counts in the health status.
HEALTH_NAMES = {'odometry': 'odometry_received',
                'scans_fused': 'fusion_scans_fused',
                'scans_alone': 'fusion_scans_alone',
                'scans_other_place': 'fusion_scans_other_place',
                'scans_late': 'fusion_scans_late',
                'scans_off_track': 'fusion_scans_off_track',
                'scans_without_position': 'fusion_scans_without_position',
                'restarts': 'fusion_restarts'}
#: Scans kept waiting for odometry at most (more: the oldest forgotten).
MAX_WAITING = 100


class OdometryFusion:
    """Odometry in, fused poses out, for ``node``."""

    def __init__(self, node, params, odom_timeout, pose_rate, publish):
        self._node = node
        self._publish = publish
        self.fusion = Fusion(params, FusionLimits(odom_timeout=odom_timeout))
        self._last_problem = (None, -float('inf'))   # (what, monotonic s)
        self._published_stamp = None
        self._place = None     # of the last pose published
        self._stamps = {}   # float stamp -> the message's, to publish it
        self._odometry_stamp = (None, None)
        self._odometry_arrival = -math.inf   # monotonic s, last good one
        self.counts_internal = 0
        self._timer = None
        self.enabled = True
        self._subscription = node.create_subscription(
            Odometry, 'odom', self._on_odometry, ODOM_QOS)
        self.configure(odom_timeout, pose_rate)

    def configure(self, odom_timeout=None, pose_rate=None):
        """Change the timeout (s) or the between-scan rate (Hz; 0: none)."""
        if odom_timeout is not None:
            self.fusion.limits = replace(self.fusion.limits,
                                         odom_timeout=odom_timeout)
        if pose_rate is not None:
            if self._timer is not None:
                self._node.destroy_timer(self._timer)
            self.pose_rate = pose_rate
            self._timer = self._node.create_timer(
                1.0 / pose_rate if pose_rate else 0.1, self._on_timer)
            if not self.enabled:    # fusion off: no wake-ups
                self._timer.cancel()

    @property
    def active(self):
        """Return True when enabled and odometry has arrived."""
        return self.enabled and self.fusion.odometry_stamp is not None

    def enable(self, enabled):
        """Fuse (True) or ignore odometry and forget the filter (False)."""
        if not enabled:
            self.reset()
        self.enabled = enabled
        if enabled:
            self._timer.reset()
        else:       # no wake-ups while off
            self._timer.cancel()

    def reset(self):
        """Forget the filter and odometry: the next scan starts afresh."""
        self.fusion.reset()
        self._stamps.clear()
        self._place = None

    def scan(self, stamp, xy, place, confident, sigma=None):
        """Feed the answer to one scan; publish the poses it releases."""
        self._guarded('on a scan', self._scan, stamp, xy, place, confident,
                      sigma)

    def _guarded(self, where, step, *args):
        """Run ``step``; an error is counted and logged, never raised."""
        try:
            step(*args)
        except Exception as exc:   # never let the filter stop the node
            self.counts_internal += 1
            self._problem(f'internal error {where}: {exc!r}')

    def _scan(self, stamp, xy, place, confident, sigma):
        seconds = stamp_time(stamp, self._node.get_clock())
        now = time.monotonic()
        timeout = self.fusion.limits.odom_timeout
        stale = now - self._odometry_arrival > timeout
        self._stamps[seconds] = stamp
        released = self.fusion.scan(
            seconds, xy, place, confident,
            now - 2 * timeout if stale else now,  # stale: no waiting
            sigma)
        if released is None:
            del self._stamps[seconds]
            self._problem('a scan without a finite position: not fused')
            return
        self._emit(released)
        if stale:
            self._expire(now)
        if len(self._stamps) > MAX_WAITING:     # never released: forget
            for key in list(self._stamps)[:-MAX_WAITING]:
                del self._stamps[key]

    def _on_odometry(self, msg):
        if self.enabled:
            self._guarded('on odometry', self._odometry, msg)

    def _odometry(self, msg):
        pose = msg.pose.pose
        seconds = stamp_time(msg.header.stamp, self._node.get_clock())
        problem = pose_problem(pose)    # e.g. a zero quaternion: no yaw
        yaw = math.nan if problem else yaw_of(pose.orientation)
        fault, fused = self.fusion.odometry(seconds, pose.position.x,
                                            pose.position.y, yaw)
        if not fault:
            self._odometry_stamp = (seconds, msg.header.stamp)
            self._odometry_arrival = time.monotonic()
        else:
            where = problem or (f'x {pose.position.x:g}, y '
                                f'{pose.position.y:g}')
            self._problem(f'{fault.replace("_", " ")}: odometry message '
                          f'skipped (stamp {msg.header.stamp.sec}.'
                          f'{msg.header.stamp.nanosec:09d}: {where})')
        self._emit(fused)

    def _on_timer(self):
        if self.enabled:
            self._guarded('in the fusion timer', self._tick)

    def _tick(self):
        self._expire(time.monotonic())
        if self.pose_rate and \
                self.fusion.odometry_stamp != self._published_stamp:
            pose = self.fusion.pose()
            if pose is not None:
                self._emit([pose])

    def _expire(self, now):
        """Publish the scans that waited too long, fused alone; say so."""
        fused = self.fusion.expire(now)
        if fused:
            self._problem(f'no odometry covering {len(fused)} scan(s) '
                          f'within {self.fusion.limits.odom_timeout:g} s: '
                          f'fused alone (WiFi only)')
        self._emit(fused)

    def _emit(self, poses):
        for pose in poses:
            stamp = self._stamps.pop(pose.stamp, None)
            if stamp is None:     # between scans: the newest odometry's
                seconds, stamp = self._odometry_stamp
                if seconds != pose.stamp:
                    continue
            self._published_stamp = pose.stamp
            self._publish(pose, stamp, pose.place,
                          pose.restarted and pose.place == self._place)
            self._place = pose.place

    def _problem(self, what):
        self._last_problem = (what, time.monotonic())
        self._node.get_logger().warn(what, throttle_duration_sec=THROTTLE_S)

    def health(self):
        """Return (problem or None, {count name: value}) for diagnostics."""
        counts = self.fusion.counts
        values = {HEALTH_NAMES.get(k, k): counts.get(k, 0) for k in
                  ('odometry', 'odometry_same_stamp') + ODOMETRY_FAULTS +
                  ('scans_fused', 'scans_alone', 'scans_other_place',
                   'scans_late', 'scans_off_track', 'scans_without_position',
                   'restarts')}
        values['fusion_internal_errors'] = self.counts_internal
        what, when = self._last_problem
        now = time.monotonic()
        silent = now - self._odometry_arrival
        if self.enabled and self.fusion.odometry_stamp is not None and \
                silent > self.fusion.limits.odom_timeout:
            return f'no odometry for {silent:.1f} s', values
        return (what if now - when < WARN_S else None), values
