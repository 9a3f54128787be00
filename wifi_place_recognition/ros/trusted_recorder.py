"""
``trusted_recorder``: a survey recorded while the robot's localiser is trusted.

Subscribes ``wifi/scan``, the localiser's pose (``localizer_topic``,
AMCL's ``amcl_pose``), localization_monitor's latched state
(``status_topic``) and classifier_node's latched current place
(``place_topic``), and appends each scan to ``output`` labelled with the
localiser's pose by the labelling rule (:mod:`.core.pose_label`:
interpolated between the poses around it, else the nearest, within
``max_pose_age``) and the current building and floor, when
:class:`.core.trusted.TrustGate` finds no reason against it (the
localiser sure of its pose and not jumping, the witness saying neither
lost nor disagrees; ``cannot_tell`` does not stop it, except after a
jump: then nothing until the witness agrees). Both latched inputs count
only while their publisher lives: once the witness's is gone (the
monitor stopped or died), its last state is :data:`.core.trusted.GONE`;
once the current place's is, there is no place. A scan is held, with the
witness's state and the place when it arrived, until a pose at or after its stamp
arrives or a stamp more than ``max_pose_age`` past it; those held at
shutdown are judged and labelled with the poses there are. The file is
written as
record_fingerprints writes it (:class:`.data.recording.FingerprintLog`
with positions, :class:`.kept_files.KeptFiles`: nothing lost on a write
fault, continued after a restart). Scans left out are counted by reason
on ``/diagnostics``; the log says when recording stops and starts, and
why. A localiser pose that is not finite, has no unit quaternion, no
usable frame or a negative or NaN variance is counted and left out.
"""

from collections import Counter
from dataclasses import replace
from functools import partial
import math
from pathlib import Path
import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from ..core.trusted import (GONE, LocaliserPose, REASONS, TrustGate,
                            TrustParams)
from ..data.recording import FingerprintLog, frame_problem, RecordingError
from .kept_files import KeptFiles
from .messages import (key_value as _kv, pose_problem, seconds, stamp_time,
                       status_values, yaw_of)
from .node_interface import declare
from .qos import QOS_OVERRIDES
from .record_fingerprints import POSE_QOS, SCAN_QOS
from .runner import names_the_node, run
from .sequence import PublisherGaps
from .trusted_parameters import PARAMETERS, TRUST_FIELDS

THROTTLE_S = 10.0
#: The latched inputs forgotten once their publisher is gone: their
#: subscription (index of ``subs``), the value they take, what it means.
GONE_INPUTS = {'witness': (1, GONE, 'the witness stopped'),
               'place': (2, None, 'no current place')}
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


class TrustedRecorder(Node):
    """Append the scans a trusted localiser labels to a fingerprint CSV."""

    @names_the_node
    def __init__(self):
        super().__init__('trusted_recorder')
        values = declare(self, PARAMETERS)
        if not values['output']:
            raise RecordingError('parameter output (the CSV path) is not '
                                 'set')
        self.gate = TrustGate(TrustParams(**{k: values[k]
                                             for k in TRUST_FIELDS}))
        self.log = FingerprintLog(Path(values['output']).expanduser(),
                                  positions=True)
        self.counts = Counter(scans_received=0, scans_recorded=0,
                              scans_lost=0, scans_unusable=0,
                              localizer_poses=0, localizer_rejected=0,
                              localizer_jumps=0)
        self.counts.update({f'skipped/{r}': 0 for r in REASONS})
        self.files = KeptFiles(self.get_logger(), self.counts)
        self.files.add(self.log, 'scans', 'write_errors')
        self.why_not = 'not started'   # why the last scan was left out
        self._gaps = PublisherGaps()
        self.add_on_set_parameters_callback(self._validate)
        self.add_post_set_parameters_callback(self._apply)
        # the localiser, witness and place before the scans: the executor
        # takes what waits in that order
        self.subs = [
            self.create_subscription(
                PoseWithCovarianceStamped, values['localizer_topic'],
                self._on_pose, POSE_QOS, qos_overriding_options=(
                    QoSOverridingOptions(policy_kinds=QOS_OVERRIDES))),
            self.create_subscription(
                String, values['status_topic'], self._on_status, LATCHED,
                event_callbacks=SubscriptionEventCallbacks(
                    matched=partial(self._on_matched, 'witness'))),
            self.create_subscription(
                DiagnosticArray, values['place_topic'], self._on_place,
                LATCHED, event_callbacks=SubscriptionEventCallbacks(
                    matched=partial(self._on_matched, 'place')))]
        self.diag_pub = self.create_publisher(DiagnosticArray,
                                              '/diagnostics', 10)
        self._scan_sub = self.create_subscription(
            JointState, 'wifi/scan', self._on_scan, SCAN_QOS,
            qos_overriding_options=(
                QoSOverridingOptions.with_default_policies()))
        self.create_timer(1.0, self._publish_progress)
        localizer, status, place = (s.topic_name for s in self.subs)
        p = self.gate.params
        self.get_logger().info(
            f'recording to {self.log.path} ({sum(self.log.counts.values())} '
            f'scans already there) while {localizer} is sure (max_sd '
            f'{p.max_sd:g} m, no jump for settle_s {p.settle_s:g} s) and '
            f'{status} is not lost; building and floor from {place}')

    # parameters -----------------------------------------------------------
    def _validate(self, params):
        for p in params:
            if p.name in TRUST_FIELDS and not math.isfinite(p.value):
                return SetParametersResult(successful=False,
                                           reason=f'{p.name} must be finite')
        return SetParametersResult(successful=True)

    def _apply(self, params):
        self.gate.params = replace(self.gate.params, **{
            p.name: p.value for p in params if p.name in TRUST_FIELDS})

    # inputs ---------------------------------------------------------------
    def _on_pose(self, msg):
        pose, cov = msg.pose.pose, msg.pose.covariance
        problem = frame_problem(msg.header.frame_id) or pose_problem(pose)
        if problem is None and not (cov[0] >= 0 and cov[7] >= 0):
            problem = f'x, y variances {cov[0]}, {cov[7]}: not >= 0'
        if problem:
            self.counts['localizer_rejected'] += 1
            self.get_logger().warn(f'localiser pose ignored: {problem}',
                                   throttle_duration_sec=THROTTLE_S)
            return
        self.counts['localizer_poses'] += 1
        new = LocaliserPose(stamp_time(msg.header.stamp, self.get_clock()),
                            pose.position.x, pose.position.y,
                            yaw_of(pose.orientation), msg.header.frame_id,
                            LocaliserPose.sd_of(cov[0], cov[7]))
        old = self.gate.pose(new)
        if old is not None:
            self.counts['localizer_jumps'] += 1
            step = math.hypot(new.x - old.x, new.y - old.y)
            self.get_logger().info(
                f'the localiser jumped {step:.2f} m in '
                f'{new.stamp - old.stamp:.2f} s ({old.frame} -> {new.frame}): '
                f'nothing recorded for {self.gate.params.settle_s:g} s, '
                f'then only once WiFi agrees')
        self._release()

    def _on_status(self, msg):
        self.gate.witness = msg.data

    def _on_matched(self, what, info):
        """
        Forget a latched input (``what``) once its publisher is gone.

        The witness's state becomes GONE, the current place None.
        """
        if info.current_count or getattr(self.gate, what) is None:
            return
        sub, value, meaning = GONE_INPUTS[what]
        setattr(self.gate, what, value)
        self.get_logger().warn(
            f'{self.subs[sub].topic_name} has no publisher any more '
            f'({meaning}): not recording until it is back')

    def _on_place(self, msg):
        for status in msg.status:
            values = status_values(status)
            try:
                self.gate.place = (int(values['building']),
                                   int(values['floor']))
            except (KeyError, ValueError):
                self.get_logger().warn(f'current place without a building '
                                       f'and floor: {values}',
                                       throttle_duration_sec=THROTTLE_S)

    def _on_scan(self, msg, info):
        self.counts['scans_lost'] += self._gaps.missed(self._scan_sub, info)
        self.counts['scans_received'] += 1
        self.gate.scan(stamp_time(msg.header.stamp, self.get_clock()), msg)
        self._release()

    def _release(self, everything=False):
        """Judge, label and write the held scans the rule can label now."""
        for _, msg, pose, place, why in self.gate.release(everything):
            self._record(msg, pose, place, why)

    def _record(self, msg, pose, place, why):
        """Record the scan if nothing is against it (``why`` None)."""
        self._follow(why)
        if why is not None:
            self.counts[f'skipped/{why}'] += 1
            return
        if len(msg.name) != len(msg.position):
            self.counts['scans_unusable'] += 1
            return
        recorded, _ = self.log.add(
            msg.name, msg.position, *place, seconds(msg.header.stamp),
            (pose.x, pose.y, pose.yaw, pose.frame))
        self.files.check(self.log)
        self.counts['scans_recorded' if recorded else 'scans_unusable'] += 1

    def _follow(self, why):
        """Log when recording stops (and why) or starts again."""
        if why == self.why_not:
            return
        if why is None:
            self.get_logger().info('recording: the localiser is trusted')
        else:
            self.get_logger().info(f'not recording: {REASONS[why]}')
        self.why_not = why

    # outputs --------------------------------------------------------------
    def _publish_progress(self):
        self.files.flush()
        counts = sorted(self.log.counts.items())
        level, message = DiagnosticStatus.OK, (
            'recording' if self.why_not is None else
            f'not recording: {REASONS.get(self.why_not, self.why_not)}')
        message += '; ' + (', '.join(f'B{b}F{f}: {n}' for (b, f), n in
                                     counts) or 'no scans yet')
        failing = self.files.failing()
        if failing:
            level, message = DiagnosticStatus.ERROR, failing + message
        values = [_kv(f'scans/B{b}F{f}', n) for (b, f), n in counts] + [
            _kv('scans_waiting', len(self.log.pending)),
            _kv('scans_held', len(self.gate.held.held)),
            _kv('witness', self.gate.witness or ''),
            _kv('place', '' if self.gate.place is None else
                f'B{self.gate.place[0]}F{self.gate.place[1]}')] + [
            _kv(k, n) for k, n in self.counts.items()]
        out = DiagnosticArray(status=[DiagnosticStatus(
            level=level, name=f'{self.get_name()}: progress',
            message=message, hardware_id=str(self.log.path), values=values)])
        out.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(out)

    def destroy_node(self):
        """Write the held scans and what waits in memory, then stop."""
        self._release(everything=True)
        self.files.save()
        super().destroy_node()


def main(args=None):
    """Record until SIGINT/SIGTERM; exit 1 if the file cannot be used."""
    return run(TrustedRecorder, args, (RecordingError, OSError))


if __name__ == '__main__':
    # As the executable: --help starts nothing (stop signals are caught
    # only from here, after the imports; the installed executable, earlier)
    from wifi_place_recognition.ros.executables import \
        trusted_recorder as _run
    sys.exit(_run())
