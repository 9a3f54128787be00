"""
``record_fingerprints``: label the robot's WiFi scans and keep them in a CSV.

Subscribes ``wifi/scan`` and appends every scan to ``output`` (the generic
fingerprint format ``train_model`` reads) with the current ``building`` and
``floor`` parameters as labels. Change them at runtime as the robot moves
(``ros2 param set /record_fingerprints floor 2``); -1 pauses recording.
Progress (scans per building/floor) is logged and published on
``/diagnostics``, with the scans received, those with no usable reading,
the readings left out and the scans lost before they reached the node.

A missing output folder is created (``~`` stands for the home folder); it
must be writable at start-up. A write that fails later (the folder gone,
the disk full) makes the status ERROR and is logged (throttled); the scans
wait in memory and are written by the next write that works (tried with
every scan and every second). Those still waiting
at shutdown go to a new file in the temporary folder (or the home folder),
which the log names.

With ``pose_topic`` (e.g. ``/amcl_pose``), each scan also gets an x, y,
yaw and frame by the labelling rule (:mod:`.core.pose_label`, scan and
pose ``header.stamp``; a zero stamp means the time the node takes the
message): interpolated between the poses just before and after it when
both are within ``max_pose_age`` seconds, else the nearest within it;
scans with neither are counted and skipped. A scan is therefore held
until a pose at or after its stamp arrives, or a stamp more than
``max_pose_age`` past it; those held at shutdown are labelled with the
poses there are, and written. A file of an earlier recorder, without
``YAW``, goes on without it (logged).

With ``odom_topic`` (``nav_msgs/Odometry``), every odometry pose is kept
(stamp, x, y, yaw) for the pose CSV beside the output
(:func:`.data.recording.odometry_path`: ``walk1.csv`` ->
``walk1.odom.csv``), written once a second in one batch, with the same
care as the scans (waiting in memory, a fallback file at shutdown).
Poses that are not finite, not a unit quaternion or earlier than the last
one kept are counted and skipped (``fit_odometry`` needs them in order).

The scan subscription is best effort (it must match the scanner's
sensor-data publisher) with a deep queue: rewriting a large file for a new
AP can take a second, and the scans arriving meanwhile wait instead of
being lost. The pose subscription is best effort and volatile, so it
matches reliable and transient-local publishers (AMCL's) as well as
sensor-data ones; parameters can override its reliability and durability.
The odometry subscription is the same, with a deeper queue.
"""

from collections import Counter
import copy
from pathlib import Path
import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import (DurabilityPolicy, qos_profile_sensor_data,
                       QoSProfile, ReliabilityPolicy)
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import JointState

from ..core.pose_label import blend, HeldScans, Pose
from .kept_files import KeptFiles
from .messages import pose_problem, seconds, stamp_time, yaw_of
from .node_interface import declare
from .qos import QOS_OVERRIDES
from .recorder_parameters import PARAMETERS
from .runner import names_the_node, run
from ..data.recording import (FingerprintLog, frame_problem,
                              odometry_path, PoseLog, RecordingError)
from .sequence import PublisherGaps

PROGRESS_EVERY = 20
THROTTLE_S = 10.0
SCAN_QOS = copy.copy(qos_profile_sensor_data)
SCAN_QOS.depth = 1000
POSE_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.VOLATILE)
ODOM_QOS = copy.copy(POSE_QOS)
ODOM_QOS.depth = 1000


class RecordFingerprintsNode(Node):
    """Append labelled scans to a fingerprint CSV, odometry beside it."""

    @names_the_node
    def __init__(self):
        super().__init__('record_fingerprints')
        values = declare(self, PARAMETERS)
        output, pose_topic = values['output'], values['pose_topic']
        odom_topic = values['odom_topic']
        if not output:
            raise RecordingError('parameter output (the CSV path) is not '
                                 'set')
        output = Path(output).expanduser()
        self.log = FingerprintLog(output, positions=bool(pose_topic))
        self.counts = Counter(scans_received=0, scans_paused=0,
                              scans_unusable=0, scans_lost=0,
                              skipped_readings=0, write_errors=0)
        self.files = KeptFiles(self.get_logger(), self.counts)
        self.files.add(self.log, 'scans', 'write_errors')
        self._gaps = PublisherGaps()
        self._odometry = None
        if odom_topic:
            self._odometry = PoseLog(odometry_path(output))
            self.counts.update(odometry_received=0, odometry_invalid=0,
                               odometry_out_of_order=0)
            self.files.add(self._odometry, 'odometry poses',
                           'odometry_write_errors')
            self._odom_sub = self.create_subscription(
                Odometry, odom_topic, self._on_odometry, ODOM_QOS,
                qos_overriding_options=QoSOverridingOptions(
                    policy_kinds=QOS_OVERRIDES))
        self._poses = None
        self._frame = None
        if pose_topic:
            self.counts.update(scans_no_fresh_pose=0, poses_received=0,
                               poses_rejected=0)
            self._poses = HeldScans()
            # Created before the scan subscription: the executor then takes
            # the poses that wait before the scans that wait.
            self._pose_sub = self.create_subscription(
                PoseWithCovarianceStamped, pose_topic, self._on_pose,
                POSE_QOS, qos_overriding_options=QoSOverridingOptions(
                    policy_kinds=QOS_OVERRIDES))
        self.diag_pub = self.create_publisher(DiagnosticArray,
                                              '/diagnostics', 10)
        self._scan_sub = self.create_subscription(
            JointState, 'wifi/scan', self._on_scan, SCAN_QOS,
            qos_overriding_options=QoSOverridingOptions.with_default_policies())
        self.create_timer(1.0, self._publish_progress)
        self.get_logger().info(
            f'recording to {self.log.path} ({sum(self.log.counts.values())} scans '
            f'already there, {len(self.log.ap_ids)} APs)' + (
                f', positions from {self._pose_sub.topic_name}'
                if pose_topic else '') + (
                f', odometry from {self._odom_sub.topic_name} to '
                f'{self._odometry.path}' if odom_topic else ''))
        if pose_topic and not self.log.yaw:
            self.get_logger().warn(
                f'{self.log.path} has no YAW column (an earlier recorder): '
                f'its scans go on without the yaw, which fit_odometry '
                f'needs; record to a new file for that')

    def _on_pose(self, msg):
        self.counts['poses_received'] += 1
        pose = msg.pose.pose
        problem = frame_problem(msg.header.frame_id) or pose_problem(pose)
        if problem:
            self.counts['poses_rejected'] += 1
            self.get_logger().warn(f'pose ignored: {problem}',
                                   throttle_duration_sec=THROTTLE_S)
            return
        self._poses.add_pose(Pose(
            stamp_time(msg.header.stamp, self.get_clock()), pose.position.x,
            pose.position.y, yaw_of(pose.orientation), msg.header.frame_id))
        self._release()

    def _on_odometry(self, msg):
        self.counts['odometry_received'] += 1
        pose = msg.pose.pose
        problem = pose_problem(pose)
        refused = ('invalid', problem) if problem else self._odometry.add(
            stamp_time(msg.header.stamp, self.get_clock()), pose.position.x,
            pose.position.y, yaw_of(pose.orientation))
        if refused:
            kind, why = refused
            self.counts[f'odometry_{kind}'] += 1
            self.get_logger().warn(f'odometry pose skipped: {why}',
                                   throttle_duration_sec=THROTTLE_S)

    def _release(self, everything=False):
        """Label and write the held scans the rule can label now."""
        max_age = self.get_parameter('max_pose_age').value
        for t, scan, label in self._poses.release(max_age, everything):
            if label is None:
                self._no_pose(t, max_age)
                continue
            before, after, w = label
            self._write(*scan, (*blend(before, after, w),
                                before.frame))

    def _no_pose(self, t, max_age):
        """Count and log a scan that no pose labels."""
        if self._poses.stamps:
            nearest = min(self._poses.stamps, key=lambda s: abs(s - t))
            why = (f'the nearest pose is {abs(nearest - t):.1f} s '
                   f'{"older" if nearest < t else "newer"} than the scan '
                   f'(max_pose_age {max_age:g} s)')
        else:
            why = f'no pose yet on {self._pose_sub.topic_name}'
        self.counts['scans_no_fresh_pose'] += 1
        self.get_logger().warn(f'scan skipped: {why}',
                               throttle_duration_sec=THROTTLE_S)

    def _on_scan(self, msg, info):
        self.counts['scans_lost'] += self._gaps.missed(self._scan_sub, info)
        self.counts['scans_received'] += 1
        building = self.get_parameter('building').value
        floor = self.get_parameter('floor').value
        if building < 0 or floor < 0:
            self.counts['scans_paused'] += 1
            self.get_logger().warn('not recording: set the building and '
                                   'floor parameters',
                                   throttle_duration_sec=THROTTLE_S)
            return
        if len(msg.name) != len(msg.position):
            self.counts['scans_unusable'] += 1
            self.get_logger().warn('scan skipped: name and position differ '
                                   'in length', throttle_duration_sec=THROTTLE_S)
            return
        if self._poses is None:
            self._write(msg, building, floor)
            return
        self._poses.hold(stamp_time(msg.header.stamp, self.get_clock()),
                         (msg, building, floor),
                         self.get_parameter('max_pose_age').value)
        self._release()

    def _write(self, msg, building, floor, position=None):
        """Record one scan with its labels; log how it went."""
        recorded, skipped = self.log.add(msg.name, msg.position, building,
                                         floor, seconds(msg.header.stamp),
                                         position)
        self.files.check(self.log)
        self.counts['skipped_readings'] += skipped
        if not recorded:
            self.counts['scans_unusable'] += 1
            self.get_logger().warn('scan skipped: no usable reading (RSSI '
                                   'not finite or implausible, or a bad AP '
                                   'name)', throttle_duration_sec=THROTTLE_S)
            return
        if position is not None and position[3] != self._frame:
            self.get_logger().info(f'positions in frame {position[3]}' + (
                f' (was {self._frame})' if self._frame else ''))
            self._frame = position[3]
        n = self.log.counts[(building, floor)]
        if n % PROGRESS_EVERY == 0:
            self.get_logger().info(f'building {building}, floor {floor}: '
                                   f'{n} scans')

    def _publish_progress(self):
        self.files.flush()
        counts = sorted(self.log.counts.items())
        level, message = DiagnosticStatus.OK, ', '.join(
            f'B{b}F{f}: {n}' for (b, f), n in counts) or 'no scans yet'
        if self._odometry is not None:
            message += f'; {self._odometry.written} odometry poses'
        failing = self.files.failing()
        if failing:
            level, message = DiagnosticStatus.ERROR, failing + message
        values = [KeyValue(key=f'scans/B{b}F{f}', value=str(n))
                  for (b, f), n in counts] + [
            KeyValue(key='aps', value=str(len(self.log.ap_ids))),
            KeyValue(key='scans_waiting', value=str(len(self.log.pending)))]
        if self._poses is not None:
            values.append(KeyValue(key='scans_held',
                                   value=str(len(self._poses.held))))
        if self._odometry is not None:
            values += [KeyValue(key='odometry_written',
                                value=str(self._odometry.written)),
                       KeyValue(key='odometry_waiting',
                                value=str(len(self._odometry.pending)))]
        out = DiagnosticArray()
        out.header.stamp = self.get_clock().now().to_msg()
        out.status = [DiagnosticStatus(
            level=level, name=f'{self.get_name()}: progress',
            message=message, hardware_id=str(self.log.path),
            values=values + [KeyValue(key=k, value=str(n))
                             for k, n in self.counts.items()])]
        self.diag_pub.publish(out)

    def destroy_node(self):
        """Write the held scans and what waits in memory, then stop."""
        if self._poses is not None:
            self._release(everything=True)
        self.files.save()
        super().destroy_node()


def main(args=None):
    """Record until SIGINT/SIGTERM; exit 1 if the file cannot be used."""
    return run(RecordFingerprintsNode, args, (RecordingError, OSError))


if __name__ == '__main__':
    # As the executable: --help starts nothing (stop signals are caught
    # only from here, after the imports; the installed executable, earlier)
    from wifi_place_recognition.ros.executables import record_fingerprints as _run
    sys.exit(_run())
