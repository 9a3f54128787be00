"""
classifier_node's odometry input: the pipeline's fusion on ROS.

Subscribes ``odom`` (``nav_msgs/Odometry``, the pose in the robot's odom
frame; sensor-data QoS with a deep queue, which ``qos_overrides``
parameters change) and hands each pose to the node's
:class:`.scan_pipeline.ScanPipeline` (a zero stamp means the time the
node takes the message), on the monotonic clock; a timer ticks the
pipeline ``pose_rate`` times a second (the fused pose between scans; a
scan that waited ``odom_timeout`` seconds for odometry goes through
alone), and stops while fusion is off. What the pipeline gives goes to
``publish(outputs)``.
"""

import copy
import math
import time

from nav_msgs.msg import Odometry
from rclpy.qos import qos_profile_sensor_data
from rclpy.qos_overriding_options import QoSOverridingOptions

from .messages import pose_problem, stamp_time, yaw_of
from .qos import QOS_OVERRIDES

ODOM_QOS = copy.copy(qos_profile_sensor_data)
ODOM_QOS.depth = 100


class OdometryFusion:
    """Odometry in and the fusion timer, for ``node``'s ``pipeline``."""

    def __init__(self, node, pipeline, publish):
        self._node = node
        self._pipeline = pipeline
        self._publish = publish
        self._timer = None
        self._subscription = node.create_subscription(
            Odometry, 'odom', self._on_odometry, ODOM_QOS,
            qos_overriding_options=QoSOverridingOptions(
                policy_kinds=QOS_OVERRIDES))
        self.apply({'pose_rate': pipeline.fusion.pose_rate})

    @property
    def fusion(self):
        """Return the filter (:class:`.core.filter.fusion.Fusion`)."""
        return self._pipeline.fusion.fusion

    def apply(self, values):
        """Follow new ``pose_rate`` and ``fusion`` values: the timer."""
        stage = self._pipeline.fusion
        if 'pose_rate' in values:
            if self._timer is not None:
                self._node.destroy_timer(self._timer)
            rate = values['pose_rate']
            self._timer = self._node.create_timer(
                1.0 / rate if rate else 0.1, self._on_timer)
        if stage.enabled and values.get('fusion'):
            self._timer.reset()
        elif not stage.enabled:     # fusion off: no wake-ups
            self._timer.cancel()

    def _on_odometry(self, msg):
        if not self._pipeline.fusion.enabled:
            return
        pose, stamp = msg.pose.pose, msg.header.stamp
        problem = pose_problem(pose)    # e.g. a zero quaternion: no yaw
        x, y = pose.position.x, pose.position.y
        self._publish(self._pipeline.odometry(
            stamp_time(stamp, self._node.get_clock()), x, y,
            math.nan if problem else yaw_of(pose.orientation),
            time.monotonic(), stamp,
            f'stamp {stamp.sec}.{stamp.nanosec:09d}: '
            f'{problem or f"x {x:g}, y {y:g}"}'))

    def _on_timer(self):
        self._publish(self._pipeline.tick(time.monotonic()))
