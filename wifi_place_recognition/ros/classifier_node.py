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
changes the building/floor or whose position jumps. ``~/set_pose``
(``PoseWithCovarianceStamped``, robot_localization's ``set_pose``) starts
the fused pose at a pose known otherwise (a dock, an operator's estimate),
heading included; one that cannot be used is refused, logged and
counted (``set_pose_refused``). While odometry
arrives on ``odom`` (``fusion``), ``~/pose`` is the pose fused with it,
with a yaw, at every scan and in between (:mod:`.odometry_fusion`), and
``initialpose`` carries it: after a change of floor, the filter's first
pose there; instead of the scans' jumps, the filter's fresh starts on its
floor. The node only adapts :class:`.scan_pipeline.ScanPipeline`, which
decides all of this (ROS-free, the benchmarks' too): messages, timers,
QoS and logs are the node's.
Setting ``model_path`` while running loads the file in the on-set
callback (a file that does not load, or a model with a position output
where the running one has none or the other way round, is refused with
the reason, and the running model goes on); the next scan is answered by
the new model (:meth:`.scan_pipeline.ScanPipeline.use_model`: the fused
pose and the current place carry on), and the health status names it.
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

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from ..core.artifact import load_model, ModelFileError
from ..core.pipeline.scan_pipeline import (ScanPipeline, SETTINGS,
                                           swap_problem)
from ..core.recognizer import OK, PlaceRecognizer, WARN
from ..core.resources import default_model_path
from ..core.scan import REJECT_REASONS
from .classifier_parameters import (check_frame, declare, no_position,
                                    RECOGNIZER_SETTINGS, refusal)
from .messages import (key_value as _kv, pose_message, pose_problem,
                       stamp_time, UNKNOWN_VARIANCE, yaw_of, yaw_text)
from .odometry_fusion import OdometryFusion
from .place_changes import CurrentPlace
from .runner import names_the_node, run
from .sequence import PublisherGaps

LEVELS = {OK: DiagnosticStatus.OK, WARN: DiagnosticStatus.WARN}
THROTTLE_S = 5.0
# Sensor-data QoS that keeps only the newest scan waiting.
SCAN_QOS = copy.copy(qos_profile_sensor_data)
SCAN_QOS.depth = 1
#: The parameters :meth:`ScanPipeline.configure` takes.
PIPELINE_SETTINGS = RECOGNIZER_SETTINGS + SETTINGS


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
    Thin ROS adapter around :class:`.scan_pipeline.ScanPipeline`.

    ``make_forward(model)`` may supply another forward pass (a benchmark
    baseline); the default is the recognizer's numpy one.
    """

    @names_the_node
    def __init__(self, make_forward=None, **kwargs):
        super().__init__('classifier_node', **kwargs)
        values = declare(self)
        self.odometry = None    # OdometryFusion, with a position model
        self.set_pose_refused = 0
        self._make_forward = make_forward
        self._candidate = None  # (path, model) validated, to swap to
        self.model_path = values['model_path'] or str(default_model_path())
        self.frame_id = values['frame_id']
        check_frame(self.frame_id)
        model = load_model(self.model_path)
        if model.position is None and (values['publish_initial_pose'] or
                                       values['initial_pose_on_change']):
            raise ValueError(no_position(
                'publish_initial_pose' if values['publish_initial_pose']
                else 'initial_pose_on_change'))
        self.pipeline = ScanPipeline(PlaceRecognizer(
            model, forward=self._forward(model)))
        self.pipeline.configure(**{name: values[name]
                                   for name in PIPELINE_SETTINGS})
        if values['publish_initial_pose']:
            self.pipeline.request_initial_pose()
        self.prob_keys = [f'prob/{n}' for n in model.class_names]
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)

        self.status_name = f'{self.get_name()}: place'
        self._gaps = PublisherGaps()
        self.place_pub = self.create_publisher(
            DiagnosticArray, '~/place',
            QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        self.diag_pub = self.create_publisher(DiagnosticArray,
                                              '/diagnostics', 10)
        self.current_place = CurrentPlace(self)
        self._scan_sub = self.create_subscription(
            JointState, 'wifi/scan', self._on_scan, SCAN_QOS,
            qos_overriding_options=QoSOverridingOptions.with_default_policies())
        self.create_timer(1.0, self._publish_health)
        self.create_service(Trigger, '~/reset', self._on_reset)
        if model.position is not None:
            self.pose_pub = self.create_publisher(
                PoseWithCovarianceStamped, '~/pose', 10)
            self.initial_pose_pub = self.create_publisher(
                PoseWithCovarianceStamped, 'initialpose', 1)
            self.create_service(Trigger, '~/publish_initial_pose',
                                self._on_publish_initial_pose)
            self.odometry = OdometryFusion(self, self.pipeline,
                                           self._publish)
            self.create_subscription(
                PoseWithCovarianceStamped, '~/set_pose', self._on_set_pose,
                QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        self.get_logger().info(self._described(model))

    def _forward(self, model):
        return self._make_forward(model) if self._make_forward else None

    def _described(self, model):
        return (f'model {self.model_path}: {len(model.ap_ids)} APs, '
                f'{len(model.class_names)} classes (trained '
                f'{model.provenance.get("created", "?")})')

    # parameters -----------------------------------------------------------
    def _validate_parameters(self, params):
        self._candidate = None
        for p in params:
            reason = refusal(p.name, p.value,
                             self.pipeline.fusion is not None)
            if reason is None and p.name == 'model_path':
                reason = self._load_candidate(p.value)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _load_candidate(self, value):
        """Load the model file ``value`` names; return why not, or None."""
        path = value or str(default_model_path())
        try:
            model = load_model(path)
        except ModelFileError as exc:
            problem = str(exc)
        else:
            problem = swap_problem(self.pipeline.recognizer.model, model)
        if problem:
            reason = f'model_path refused ({problem}); still running ' \
                     f'{self.model_path}'
            self.get_logger().warn(reason)
            return reason
        self._candidate = (path, model)
        return None

    def _apply_parameters(self, params):
        values = {p.name: p.value for p in params}
        if 'model_path' in values:
            self._swap()
        self.pipeline.configure(**{name: value for name, value in
                                   values.items()
                                   if name in PIPELINE_SETTINGS})
        self.frame_id = values.get('frame_id', self.frame_id)
        if self.odometry is not None:
            self.odometry.apply(values)

    def _swap(self):
        """Answer the next scans with the validated candidate; log it."""
        (path, model), self._candidate = self._candidate, None
        changed = self.pipeline.use_model(model, self._forward(model))
        old, self.model_path = self.model_path, path
        self.prob_keys = [f'prob/{n}' for n in model.class_names]
        self.get_logger().info(
            f'model swapped (was {old}): {self._described(model)}; the '
            f'next scan is answered by it' +
            ''.join(f'; {c}' for c in changed))

    def _on_publish_initial_pose(self, request, response):
        self.pipeline.request_initial_pose()
        recognizer = self.pipeline.recognizer
        response.success = True
        response.message = (
            f'the next confident answer (p >= '
            f'{recognizer.min_confidence:g}, >= '
            f'{recognizer.min_known_aps} known APs) goes to '
            f'{self.initial_pose_pub.topic_name}')
        self.get_logger().info(response.message)
        return response

    def _on_reset(self, request, response):
        cleared = self.pipeline.reset()
        response.message = (f'{" and ".join(cleared)} cleared: the next '
                            f'scan starts afresh' if cleared else
                            'tracking and fusion are off: nothing to reset')
        response.success = True
        self.get_logger().info(response.message)
        return response

    def _on_set_pose(self, msg):
        pose, cov, frame = msg.pose.pose, msg.pose.covariance, \
            msg.header.frame_id
        variances = (cov[0], cov[7], cov[35])
        sd = math.sqrt(max(variances[:2])) if min(variances[:2]) >= 0 \
            else math.nan
        problem = pose_problem(pose)
        if problem is None and not all(math.isfinite(v) and v >= 0
                                       for v in variances):
            problem = (f'x, y, yaw variances {variances[0]}, '
                       f'{variances[1]}, {variances[2]}: expected finite '
                       f'and >= 0')
        if problem is None:
            places = [(int(b), int(f)) for b, f in
                      self.pipeline.recognizer.model.classes
                      if self._frame((b, f)) == frame]
            known = variances[2] < UNKNOWN_VARIANCE
            problem = self.pipeline.set_pose(
                stamp_time(msg.header.stamp, self.get_clock()),
                (pose.position.x, pose.position.y),
                yaw_of(pose.orientation) if known else None, sd,
                math.sqrt(variances[2]) if known else 0.0, places)
        p = pose.position
        what = f'x {p.x:g}, y {p.y:g} in frame {frame!r}'
        if problem:
            self.set_pose_refused += 1
            self.get_logger().warn(f'set_pose refused ({what}): {problem}',
                                   throttle_duration_sec=THROTTLE_S)
            return
        self.get_logger().info(
            f'fused pose set to {what} (sd {sd:.2f} m), {yaw_text(msg)}')

    # scans ----------------------------------------------------------------
    def _on_scan(self, msg, info):
        received_at = time.perf_counter()
        self._process(msg, received_at,
                      self._gaps.missed(self._scan_sub, info))

    def _process(self, msg, received_at, dropped=0):
        stamp = msg.header.stamp
        out = self.pipeline.scan(msg.name, msg.position,
                                 stamp_time(stamp, self.get_clock()),
                                 time.monotonic(), stamp, dropped,
                                 received_at)
        status = DiagnosticStatus(name=self.status_name,
                                  hardware_id=msg.header.frame_id)
        place = out.answer
        if place is None:
            status.level = DiagnosticStatus.ERROR
            status.message = f'scan rejected: {out.rejected.detail}'
            status.values = [_kv('reason', out.rejected.reason)]
            self._publish_answer(status, stamp)
            self.get_logger().warn(status.message,
                                   throttle_duration_sec=THROTTLE_S)
            return
        status.level = LEVELS[place.level]
        status.message = place.message
        status.values = [
            _kv('building', place.building), _kv('floor', place.floor),
            _kv('confidence', f'{place.confidence:.6f}'),
            _kv('scan_building', place.scan_building),
            _kv('scan_floor', place.scan_floor),
            _kv('scan_confidence', f'{place.scan_confidence:.6f}'),
            _kv('known_aps', place.known_aps),
            _kv('unknown_aps', place.unknown_aps),
            _kv('clipped_rssi', place.clipped),
            _kv('latency_ms', f'{out.latency_ms:.3f}'),
        ] + [_kv(k, f'{p:.6f}') for k, p in
             zip(self.prob_keys, place.probabilities)]
        if place.position is not None:
            status.values += self._position_values(place)
        self._publish_answer(status, stamp)
        if out.place_changed:
            self.current_place.publish(place, stamp, self._frame(
                (place.building, place.floor)))
        self._publish(out)

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
                _kv('scan_sigma_m', f'{place.scan_sigma:.3f}'),
                # what localization_monitor decides on: exact, so that a
                # value just past its threshold is not rounded onto it
                _kv('scan_knn_sigma_m', repr(float(place.scan_knn_sigma))),
                _kv('coverage', 'nan' if place.coverage is None else
                    repr(float(place.coverage))),
                _kv('mismatch', f'{place.mismatch:.3f}')]

    def _frame(self, place):
        """Return the frame of ``place`` (building, floor)."""
        return self.frame_id.format(building=place[0], floor=place[1])

    def _publish(self, out):
        """Publish an output's poses (and re-seeds); log its problems."""
        for problem in out.problems:
            self.get_logger().warn(problem, throttle_duration_sec=THROTTLE_S)
        for pose in out.poses:
            msg = pose_message(pose.xy, pose.cov, pose.source,
                               self._frame(pose.place), pose.yaw)
            self.pose_pub.publish(msg)
            if pose.initial:
                self._send_initial(msg, pose)

    def _send_initial(self, msg, pose):
        """Publish ``msg`` on initialpose; log why, where and how."""
        self.initial_pose_pub.publish(msg)
        p = msg.pose.pose.position
        how = (f'fused with odometry, {yaw_text(msg)}' if pose.fused else
               f'sigma {math.sqrt(pose.cov.trace() / 2):.1f} m')
        self.get_logger().info(
            f'initialpose sent ({"; ".join(pose.initial)}): building '
            f'{pose.place[0]}, floor {pose.place[1]}, x {p.x:.2f}, y '
            f'{p.y:.2f} in {msg.header.frame_id} ({how})')

    # health ---------------------------------------------------------------
    def _publish_health(self):
        counts = self.pipeline.counts
        provenance = self.pipeline.recognizer.model.provenance
        selection = provenance.get('selection', {})
        rss, peak = _memory_mib()
        values = [_kv(f'scans_{k}', counts.get(k, 0)) for k in
                  ('received', 'answered', 'rejected', 'dropped')]
        coverage = self.pipeline.recognizer.model.coverage
        values.append(_kv('scans_off_survey', 'n/a' if coverage is None
                          else counts['off_survey']))
        values += [_kv(f'rejected/{r}', counts.get(f'rejected/{r}', 0))
                   for r in REJECT_REASONS + ('internal_error',)]
        values += [
            _kv('last_latency_ms', f'{self.pipeline.last_latency_ms:.3f}'),
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
        fusion = self.pipeline.fusion
        if fusion is not None:
            problem, fusion_counts = fusion.health(time.monotonic())
            values += [_kv(k, v) for k, v in fusion_counts.items()]
            values.append(_kv('set_pose_refused', self.set_pose_refused))
            values.append(_kv('fusion', 'on' if fusion.active else
                              'off' if not fusion.enabled else
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
