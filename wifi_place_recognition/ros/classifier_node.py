"""
``classifier_node``: WiFi scans in, building/floor with probabilities out.

Subscribes ``wifi/scan`` (``sensor_msgs/JointState``: ``name`` = AP id,
``position`` = RSSI dBm) and publishes one ``diagnostic_msgs/DiagnosticArray``
per processed scan on ``~/place`` and ``/diagnostics``, plus a 1 Hz health
status on ``/diagnostics``; the confident place, once per change, on the
latched ``~/current_place``. With a model that has a position output, also
a ``geometry_msgs/PoseWithCovarianceStamped`` on ``~/pose`` per answer;
``initialpose`` gets the next confident one after a ``~/publish_initial_pose``
request and, with ``initial_pose_on_change``, every confident one that
changes the building/floor or whose position jumps (:mod:`.place_changes`).
While odometry arrives on ``odom`` (``fusion``), ``~/pose`` is the pose
fused with it, with a yaw, at every scan and in between
(:mod:`.odometry_fusion`), and ``initialpose`` carries it: after a change
of floor, the filter's first pose there; instead of the scans' jumps, the
filter's fresh starts on its floor.
Inference is a numpy forward pass: torch is never imported. Each scan is
processed in the subscription callback. The subscription keeps one scan
(KEEP_LAST, depth 1): a scan that arrives while another is processed
replaces any still waiting, so the newest is processed next; the gaps in
the publisher's sequence numbers count the replaced ones as dropped
(:class:`.sequence.PublisherGaps`).
"""

import copy
import math
import sys
import time
from collections import Counter

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from ..core.artifact import load_model, ModelFileError
from .classifier_parameters import (check_frame, declare, no_position,
                                    RECOGNIZER_SETTINGS, refusal)
from .messages import (key_value as _kv, pose_message, stamp_time,
                       yaw_text)
from .odometry_fusion import OdometryFusion
from .place_changes import PlaceChanges
from .runner import names_the_node, run
from .sequence import PublisherGaps
from ..core.recognizer import OK, PlaceRecognizer, WARN
from ..core.resources import default_model_path
from ..core.scan import REJECT_REASONS, ScanRejected

LEVELS = {OK: DiagnosticStatus.OK, WARN: DiagnosticStatus.WARN}
THROTTLE_S = 5.0
# Sensor-data QoS that keeps only the newest scan waiting.
SCAN_QOS = copy.copy(qos_profile_sensor_data)
SCAN_QOS.depth = 1


def _memory_mib():
    """
    Return (resident, peak resident) MiB of this process (Linux), or NaN.

    From /proc/self/status: unlike getrusage's ru_maxrss, VmHWM is not
    inherited from the parent through fork and exec.
    """
    found = {}
    try:
        with open('/proc/self/status') as f:
            for line in f:
                key, _, value = line.partition(':')
                if key in ('VmRSS', 'VmHWM'):
                    found[key] = int(value.split()[0]) / 1024
    except OSError:
        pass
    return found.get('VmRSS', math.nan), found.get('VmHWM', math.nan)


class ClassifierNode(Node):
    """
    Thin ROS adapter around :class:`PlaceRecognizer`.

    ``make_forward(model)`` may supply another forward pass (a benchmark
    baseline); the default is the recognizer's numpy one.
    """

    @names_the_node
    def __init__(self, make_forward=None, **kwargs):
        super().__init__('classifier_node', **kwargs)
        values = declare(self)
        self.odometry = None    # OdometryFusion, with a position model
        model_path = values['model_path'] or str(default_model_path())
        self.frame_id = values['frame_id']
        check_frame(self.frame_id)
        self._send_initial_pose = values['publish_initial_pose']
        self.reseed_on_change = values['initial_pose_on_change']
        jump_threshold = values['jump_threshold']

        self.model_path = model_path
        model = load_model(model_path)
        self.recognizer = PlaceRecognizer(
            model, forward=make_forward(model) if make_forward else None)
        self.recognizer.configure(**{
            name: self.get_parameter(name).value
            for name in RECOGNIZER_SETTINGS})
        self.prob_keys = [f'prob/{n}' for n in
                          self.recognizer.model.class_names]
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)

        self.status_name = f'{self.get_name()}: place'
        self.counts = Counter(received=0, answered=0, rejected=0, dropped=0)
        self._gaps = PublisherGaps()
        self.last_latency_ms = math.nan
        self.place_pub = self.create_publisher(
            DiagnosticArray, '~/place',
            QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        self.diag_pub = self.create_publisher(DiagnosticArray,
                                              '/diagnostics', 10)
        self.changes = PlaceChanges(self, jump_threshold)
        self._scan_sub = self.create_subscription(
            JointState, 'wifi/scan', self._on_scan, SCAN_QOS,
            qos_overriding_options=QoSOverridingOptions.with_default_policies())
        self.create_timer(1.0, self._publish_health)
        self.create_service(Trigger, '~/reset', self._on_reset)
        self.pose_pub = self.initial_pose_pub = None
        self._initial_pending = None    # (stamp s, reasons, place): fused
        if model.position is not None:
            self.pose_pub = self.create_publisher(
                PoseWithCovarianceStamped, '~/pose', 10)
            self.initial_pose_pub = self.create_publisher(
                PoseWithCovarianceStamped, 'initialpose', 1)
            self.create_service(Trigger, '~/publish_initial_pose',
                                self._on_publish_initial_pose)
            self.odometry = OdometryFusion(
                self, model.fusion, values['odom_timeout'],
                values['pose_rate'], self._publish_fused)
            self.odometry.enable(values['fusion'])
        elif self._send_initial_pose or self.reseed_on_change:
            raise ValueError(no_position('publish_initial_pose' if
                                         self._send_initial_pose else
                                         'initial_pose_on_change'))
        provenance = self.recognizer.model.provenance
        self.get_logger().info(
            f'model {model_path}: {len(self.recognizer.model.ap_ids)} APs, '
            f'{len(self.prob_keys)} classes (trained '
            f'{provenance.get("created", "?")})')

    # parameters -----------------------------------------------------------
    def _validate_parameters(self, params):
        for p in params:
            reason = refusal(p.name, p.value,
                             self.recognizer.model.position is not None)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _apply_parameters(self, params):
        values = {p.name: p.value for p in params}
        self.recognizer.configure(**{
            name: value for name, value in values.items()
            if name in RECOGNIZER_SETTINGS})
        self.frame_id = values.get('frame_id', self.frame_id)
        self.reseed_on_change = values.get('initial_pose_on_change',
                                           self.reseed_on_change)
        self.changes.jump_threshold = values.get(
            'jump_threshold', self.changes.jump_threshold)
        if self.odometry is not None:
            self.odometry.configure(values.get('odom_timeout'),
                                    values.get('pose_rate'))
            if 'fusion' in values:
                self.odometry.enable(values['fusion'])

    def _on_publish_initial_pose(self, request, response):
        self._send_initial_pose = True
        response.success = True
        response.message = (
            f'the next confident answer (p >= '
            f'{self.recognizer.min_confidence:g}, >= '
            f'{self.recognizer.min_known_aps} known APs) goes to '
            f'{self.initial_pose_pub.topic_name}')
        self.get_logger().info(response.message)
        return response

    def _on_reset(self, request, response):
        tracker = self.recognizer.tracker
        cleared = []
        if tracker is not None:
            tracker.reset()
            cleared.append('tracked belief')
        if self.odometry is not None and self.odometry.enabled:
            self.odometry.reset()
            cleared.append('fused pose')
        response.message = (f'{" and ".join(cleared)} cleared: the next '
                            f'scan starts afresh' if cleared else
                            'tracking and fusion are off: nothing to reset')
        response.success = True
        self.get_logger().info(response.message)
        return response

    # scans ----------------------------------------------------------------
    def _on_scan(self, msg, info):
        received_at = time.perf_counter()
        replaced = self._gaps.missed(self._scan_sub, info)
        self.counts['received'] += 1 + replaced
        self.counts['dropped'] += replaced
        self._process(msg, received_at)

    def _process(self, msg, received_at):
        stamp = msg.header.stamp
        status = DiagnosticStatus(name=self.status_name,
                                  hardware_id=msg.header.frame_id)
        try:
            place = self.recognizer.classify(
                msg.name, msg.position, stamp_time(stamp, self.get_clock()))
        except ScanRejected as exc:
            self._reject(status, exc.reason, str(exc), stamp)
            return
        except Exception as exc:  # never let one scan stop the node
            self._reject(status, 'internal_error', repr(exc), stamp)
            return
        status.level = LEVELS[place.level]
        status.message = place.message
        latency_ms = (time.perf_counter() - received_at) * 1e3
        status.values = [
            _kv('building', place.building), _kv('floor', place.floor),
            _kv('confidence', f'{place.confidence:.6f}'),
            _kv('scan_building', place.scan_building),
            _kv('scan_floor', place.scan_floor),
            _kv('scan_confidence', f'{place.scan_confidence:.6f}'),
            _kv('known_aps', place.known_aps),
            _kv('unknown_aps', place.unknown_aps),
            _kv('clipped_rssi', place.clipped),
            _kv('latency_ms', f'{latency_ms:.3f}'),
        ] + [_kv(k, f'{p:.6f}') for k, p in
             zip(self.prob_keys, place.probabilities)]
        if place.position is not None:
            status.values += self._position_values(place)
        self.last_latency_ms = latency_ms
        self.counts['answered'] += 1
        self._publish_answer(status, stamp)
        confident = status.level == DiagnosticStatus.OK
        fusing = self.odometry is not None and self.odometry.active
        key = (place.building, place.floor)
        reasons = self.changes.follow(place, confident, stamp,
                                      self._frame(key), jumps=not fusing)
        if place.position is None:
            return
        reasons = reasons if self.reseed_on_change else []
        if not fusing:
            self._forget_pending()
        if confident and self._send_initial_pose:
            self._send_initial_pose = False
            reasons = reasons + ['requested']
        if fusing:
            self._fuse(place, key, stamp, confident, reasons)
        else:
            self._publish_pose(place, key, stamp, reasons)

    def _publish_answer(self, status, stamp):
        out = DiagnosticArray(status=[status])
        out.header.stamp = stamp
        self.place_pub.publish(out)
        self.diag_pub.publish(out)

    @staticmethod
    def _position_values(place):
        return [_kv('x', f'{place.position[0]:.3f}'),
                _kv('y', f'{place.position[1]:.3f}'),
                _kv('position_sigma_m', f'{place.position_sigma:.3f}'),
                _kv('scan_x', f'{place.scan_position[0]:.3f}'),
                _kv('scan_y', f'{place.scan_position[1]:.3f}'),
                _kv('scan_sigma_m', f'{place.scan_sigma:.3f}')]

    def _frame(self, place):
        """Return the frame of ``place`` (building, floor)."""
        return self.frame_id.format(building=place[0], floor=place[1])

    def _fuse(self, place, key, stamp, confident, reasons):
        """
        Feed the scan's own position to the filter; initialpose waits.

        The filter follows the answer's place (the tracked one with
        tracking), as ``~/place`` and ``~/current_place`` do. A re-seed
        waits for the first fused pose from this scan on in that place:
        after a change of floor, the filter's start there (at the second
        confident answer in a row), never the old floor's pose.
        """
        if reasons:
            self._initial_pending = (stamp_time(stamp, self.get_clock()),
                                     reasons, key)
        self.odometry.scan(stamp, place.scan_position, key, confident,
                           place.scan_sigma)

    def _forget_pending(self):
        """Fusion stopped before a re-seed went out: a request waits on."""
        if self._initial_pending is not None:
            if 'requested' in self._initial_pending[1]:
                self._send_initial_pose = True
            self._initial_pending = None

    def _publish_fused(self, fused, stamp, place, relocated):
        """
        Publish a fused pose; on initialpose too when a re-seed is due.

        Due: the pending one (:meth:`_fuse`), or, with
        ``initial_pose_on_change``, a ``relocated`` filter (it started
        afresh on the floor it was on: the scans kept disagreeing with it,
        as when the robot is carried away, or it ran on WiFi alone for
        long), which with fusion stands for the scans' own jumps.
        """
        pose = pose_message(fused.xy, fused.cov, stamp, self._frame(place),
                            fused.yaw)
        self.pose_pub.publish(pose)
        waiting, reasons = self._initial_pending, None
        if waiting is not None and fused.stamp >= waiting[0] and \
                place == waiting[2]:
            self._initial_pending, reasons = None, waiting[1]
        elif relocated and self.reseed_on_change:
            reasons = ['the fused pose started afresh']
        if reasons:
            self._send_initial(pose, reasons, place,
                               f'fused with odometry, {yaw_text(pose)}')

    def _publish_pose(self, place, key, stamp, reasons):
        pose = pose_message(place.position, place.position_cov, stamp,
                            self._frame(key))
        self.pose_pub.publish(pose)
        if reasons:
            self._send_initial(pose, reasons, key,
                               f'sigma {place.position_sigma:.1f} m')

    def _send_initial(self, pose, reasons, place, how):
        """Publish ``pose`` on initialpose; log why, where and ``how``."""
        self.initial_pose_pub.publish(pose)
        p = pose.pose.pose.position
        self.get_logger().info(
            f'initialpose sent ({"; ".join(reasons)}): building {place[0]}, '
            f'floor {place[1]}, x {p.x:.2f}, y {p.y:.2f} in '
            f'{pose.header.frame_id} ({how})')

    def _reject(self, status, reason, detail, stamp):
        self.counts['rejected'] += 1
        self.counts[f'rejected/{reason}'] += 1
        status.level = DiagnosticStatus.ERROR
        status.message = f'scan rejected: {detail}'
        status.values = [_kv('reason', reason)]
        self._publish_answer(status, stamp)
        self.get_logger().warn(f'scan rejected: {detail}',
                               throttle_duration_sec=THROTTLE_S)

    # health ---------------------------------------------------------------
    def _publish_health(self):
        counts = self.counts
        provenance = self.recognizer.model.provenance
        selection = provenance.get('selection', {})
        rss, peak = _memory_mib()
        values = [_kv(f'scans_{k}', counts.get(k, 0)) for k in
                  ('received', 'answered', 'rejected', 'dropped')]
        values += [_kv(f'rejected/{r}', counts.get(f'rejected/{r}', 0))
                   for r in REJECT_REASONS + ('internal_error',)]
        values += [
            _kv('last_latency_ms', f'{self.last_latency_ms:.3f}'),
            _kv('rss_mib', f'{rss:.1f}'),
            _kv('peak_rss_mib', f'{peak:.1f}'),
            _kv('model_path', self.model_path),
            _kv('model_created', provenance.get('created', '')),
            _kv('model_training_data_sha256',
                provenance.get('training_data', {}).get('sha256', '')),
            _kv('model_cross_validated_building_floor_accuracy',
                selection.get('accuracy_mean', '')),
        ]
        level = DiagnosticStatus.OK
        message = (f'{counts["answered"]} scans answered, '
                   f'{counts["rejected"]} rejected, '
                   f'{counts["dropped"]} dropped')
        if self.odometry is not None:
            problem, fusion_counts = self.odometry.health()
            values += [_kv(k, v) for k, v in fusion_counts.items()]
            values.append(_kv('fusion', 'on' if self.odometry.active else
                              'off' if not self.odometry.enabled else
                              'waiting for odometry'))
            if problem:
                level = DiagnosticStatus.WARN
                message += f'; odometry: {problem}'
        status = DiagnosticStatus(
            level=level, name=f'{self.get_name()}: health', message=message,
            hardware_id=self.model_path, values=values)
        out = DiagnosticArray(status=[status])
        out.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(out)


def main(args=None):
    """Run the node until SIGINT/SIGTERM; exit 1 on a bad start-up."""
    return run(ClassifierNode, args, (ModelFileError, ValueError))


if __name__ == '__main__':
    # As the executable: --help starts nothing (stop signals are caught
    # only from here, after the imports; the installed executable, earlier)
    from wifi_place_recognition.ros.executables import classifier_node as _run
    sys.exit(_run())
