"""
``localization_monitor``: is the robot's localiser lost? WiFi as a witness.

Subscribes the localiser's pose (``localizer_topic``, e.g. AMCL's
``amcl_pose``), classifier_node's fused pose (``fused_topic``) and its
answers (``place_topic``: each scan's own position, sigma, coverage
probability and relative mismatch), and feeds them to
:class:`.core.witness.Witness`, which judges whether they agree (see
there). Publishes its state on the
latched ``~/status`` (``std_msgs/String``: ``agrees``, ``disagrees``
(evidence gathering, not yet lost), ``cannot_tell``, ``lost``, or
``waiting`` before the localiser's first pose) and the verdict on the
latched ``~/localization_ok`` (``std_msgs/Bool``: true while the
localiser is not known to be lost: agrees, disagrees or cannot tell;
false when lost or before its first pose), each once per change and
logged; a status on
``/diagnostics`` every second and at once on a change of state; and with
``initial_pose_on_lost`` the fused pose (as classifier_node published it:
its frame, pose and covariance) on ``initialpose`` at start-up and when
the localiser is lost.

Setting ``model_path`` while running loads the file in the on-set
callback (one that does not load is refused with the reason, the running
model goes on); the survey is then the new model's, the judgement carries
on, and the status on ``/diagnostics`` names the model.

A localiser pose that is not finite, has no unit quaternion or no positive
definite x, y, yaw covariance, is in a frame ``frame_id`` cannot make, or
is stamped before the previous one is counted by reason, named in a
throttled warning and left out: never a crash, never a verdict.
"""

from collections import Counter
import math
import re
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.qos import (DurabilityPolicy, QoSProfile, ReliabilityPolicy)
from std_msgs.msg import Bool, String

from ..core.artifact import load_model, ModelFileError
from ..core.resources import default_model_path
from ..core.witness import (AGREES, CANNOT_TELL, DISAGREES, LOST, WAITING,
                            Witness)
from ..core.witness_inputs import coverage_is_valid, mismatch_is_valid
from .classifier_parameters import check_frame
from .messages import key_value as _kv, pose_problem, seconds, yaw_of
from .monitor_parameters import declare, WITNESS_FIELDS, witness_params
from .runner import names_the_node, run

THROTTLE_S = 5.0
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
INPUT_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
#: Why a localiser message was refused (counted under these keys).
BAD_REASONS = ('not_finite', 'not_unit_quaternion', 'covariance',
               'unknown_frame', 'stamp_backwards')
#: Each state's /diagnostics level and message (then ": why").
STATES = {WAITING: (DiagnosticStatus.WARN, 'no localiser pose yet'),
          AGREES: (DiagnosticStatus.OK, 'localiser agrees with WiFi'),
          DISAGREES: (DiagnosticStatus.WARN, 'WiFi disagrees so far'),
          CANNOT_TELL: (DiagnosticStatus.WARN, 'WiFi cannot tell'),
          LOST: (DiagnosticStatus.ERROR, 'localiser lost')}


#: What a ~/place answer says of its scan beside the position and sigma:
#: key, its check, what a valid one is (NaN or missing: none, a model
#: without a coverage model or a usual mismatch, an older node).
SCAN_EXTRAS = (('coverage', coverage_is_valid, 'a probability (0-1 or nan)'),
               ('mismatch', mismatch_is_valid, 'a ratio (>= 0 or nan)'))


def scan_extras(values):
    """
    Return a ~/place answer's (coverage, mismatch), or why one is bad.

    (None, reason) when one does not read as :data:`SCAN_EXTRAS` says.
    """
    out = []
    for key, valid, what in SCAN_EXTRAS:
        text = values.get(key, 'nan')
        try:
            value = float(text)
        except ValueError:
            value = None
        if value is None or not valid(value):
            return None, f'{key} {text!r} is not {what}'
        out.append(value)
    return tuple(out), ''


def frame_pattern(template):
    """Return a regex matching the frames ``template`` makes."""
    parts = re.split(r'(\{building\}|\{floor\})', template)
    return re.compile(''.join(r'-?\d+' if p in ('{building}', '{floor}')
                              else re.escape(p) for p in parts) + r'\Z')


def covariance3(covariance):
    """Return the x, y, yaw 3x3 block of a 6x6 row-major covariance."""
    c = np.asarray(covariance, np.float64).reshape(6, 6)
    return c[np.ix_((0, 1, 5), (0, 1, 5))]


def survey_of(model, template):
    """Return {frame: (n, 2) surveyed positions} of a model's classes."""
    out = {}
    locator = model.position
    if locator is None:
        return None
    for c, (building, floor) in enumerate(model.classes):
        frame = template.format(building=building, floor=floor)
        refs = locator.map_xy(c)
        out[frame] = np.concatenate([out[frame], refs]) if frame in out \
            else refs
    return out


class LocalizationMonitor(Node):
    """Judge the localiser's pose against the WiFi witness."""

    @names_the_node
    def __init__(self, **kwargs):
        super().__init__('localization_monitor', **kwargs)
        values = declare(self)
        self.frame_id = values['frame_id']
        check_frame(self.frame_id)
        self.frames = frame_pattern(self.frame_id)
        self.reseed = values['initial_pose_on_lost']
        params = witness_params(values)
        self.model_path = values['model_path'] or str(default_model_path())
        self.model = load_model(self.model_path)
        self.witness = Witness(params, survey_of(self.model, self.frame_id))
        self.counts = Counter(localizer_poses=0, fused_poses=0, scans=0,
                              seeds_sent=0, bad_fused=0, bad_scans=0)
        self.last_fused = None       # the newest fused message
        self._logged = {}            # bad-input reason -> when logged
        self.status_pub = self.create_publisher(String, '~/status', LATCHED)
        self.ok_pub = self.create_publisher(Bool, '~/localization_ok',
                                            LATCHED)
        self.diag_pub = self.create_publisher(DiagnosticArray,
                                              '/diagnostics', 10)
        self.initial_pub = self.create_publisher(
            PoseWithCovarianceStamped, 'initialpose', 1)
        inputs = [
            self.create_subscription(PoseWithCovarianceStamped,
                                     values['localizer_topic'],
                                     self._on_localizer, INPUT_QOS),
            self.create_subscription(PoseWithCovarianceStamped,
                                     values['fused_topic'], self._on_fused,
                                     INPUT_QOS),
            self.create_subscription(DiagnosticArray, values['place_topic'],
                                     self._on_place, INPUT_QOS)]
        self._candidate = None       # (path, model) validated, to use
        self.add_on_set_parameters_callback(self._validate)
        self.add_post_set_parameters_callback(self._apply)
        self._published = None       # the Bool published last
        self._state = None           # the state published last
        self._update()
        self.create_timer(1.0, self._publish_status)
        self._log_start(inputs)

    # parameters -----------------------------------------------------------
    def _validate(self, params):
        values = {p.name: p.value for p in params}
        self._candidate = None
        try:
            witness_params(values, self.witness.params)
            if 'frame_id' in values:
                check_frame(values['frame_id'])
            if 'model_path' in values:
                path = values['model_path'] or str(default_model_path())
                self._candidate = (path, load_model(path))
        except ModelFileError as exc:
            reason = (f'model_path refused ({exc}); still using '
                      f'{self.model_path}')
            self.get_logger().warn(reason)
            return SetParametersResult(successful=False, reason=reason)
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply(self, params):
        values = {p.name: p.value for p in params}
        if any(name in WITNESS_FIELDS for name in values):
            self.witness.params = witness_params(values, self.witness.params)
        if 'frame_id' in values:
            self.frame_id = values['frame_id']
            self.frames = frame_pattern(self.frame_id)
        if 'model_path' in values:
            old = self.model_path
            (self.model_path, self.model), self._candidate = \
                self._candidate, None
        if 'frame_id' in values or 'model_path' in values:
            self.witness.survey = survey_of(self.model, self.frame_id)
        if 'model_path' in values:
            self.get_logger().info(
                f'model swapped (was {old}): {self._where()} from '
                f'{self.model_path}; the judgement carries on')
            self._publish_status()
        self.reseed = values.get('initial_pose_on_lost', self.reseed)

    def _where(self):
        survey = self.witness.survey
        return 'no positions: WiFi cannot tell' if survey is None else \
            f'{sum(map(len, survey.values()))} surveyed positions'

    def _log_start(self, inputs):
        where = self._where()
        p = self.witness.params
        localizer, fused, place = (s.topic_name for s in inputs)
        self.get_logger().info(
            f'model {self.model_path}: {where}; judging {localizer} against '
            f'{fused} and {place} in frame {self.frame_id}: agree_sigmas '
            f'{p.agree_sigmas:g}, alarm {p.alarm:g}, max_scan_sigma '
            f'{p.max_scan_sigma:g} m, initial_pose_on_lost '
            f'{str(self.reseed).lower()}')

    # inputs ---------------------------------------------------------------
    def _on_localizer(self, msg):
        pose = msg.pose.pose
        frame = msg.header.frame_id
        reason, problem = None, pose_problem(pose)
        if problem is not None:
            reason = 'not_unit_quaternion' if 'quaternion' in problem \
                else 'not_finite'
        elif not self.frames.match(frame):
            reason, problem = 'unknown_frame', (
                f'frame {frame!r} is not one of frame_id {self.frame_id!r}')
        else:
            problem = self.witness.localiser(
                seconds(msg.header.stamp), frame,
                (pose.position.x, pose.position.y), yaw_of(pose.orientation),
                covariance3(msg.pose.covariance))
            if problem is not None:
                reason = 'stamp_backwards' if 'before' in problem else \
                    'covariance' if 'covariance' in problem else 'not_finite'
        if reason is not None:
            self.counts[f'bad_localizer/{reason}'] += 1
            now = time.monotonic()      # each reason named, throttled
            if now - self._logged.get(reason, -math.inf) >= THROTTLE_S:
                self._logged[reason] = now
                self.get_logger().warn(
                    f'localiser pose refused ({reason}, '
                    f'{self.counts[f"bad_localizer/{reason}"]} so far): '
                    f'{problem}')
            return
        self.counts['localizer_poses'] += 1
        self._update()

    def _on_fused(self, msg):
        pose = msg.pose.pose
        if pose_problem(pose) is not None:
            self.counts['bad_fused'] += 1
            return
        self.counts['fused_poses'] += 1
        self.last_fused = msg
        judgement = self.witness.fused(
            seconds(msg.header.stamp), msg.header.frame_id,
            (pose.position.x, pose.position.y), yaw_of(pose.orientation),
            covariance3(msg.pose.covariance))
        if judgement is None:
            return
        if judgement.seed and self.reseed:
            self._send_seed(msg, judgement.seed)
            self.witness.seeded(judgement.stamp)
        self._update()

    def _on_place(self, msg):
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            try:
                xy = (float(values['scan_x']), float(values['scan_y']))
                # the k-NN's sigma, which the thresholds were chosen on
                # (a node before round 9 sends only scan_sigma_m, the same)
                sigma = float(values.get('scan_knn_sigma_m',
                                         values['scan_sigma_m']))
                frame = self.frame_id.format(
                    building=int(values['building']),
                    floor=int(values['floor']))
            except (KeyError, ValueError):
                continue        # a rejected scan, or no position
            extras, why = scan_extras(values)
            if extras is None:
                self._refuse_scan(why)
                continue
            self.counts['scans'] += 1
            if self.witness.scan(seconds(msg.header.stamp), frame, xy,
                                 sigma, *extras) is not None:
                self._update()

    def _refuse_scan(self, why):
        self.counts['bad_scans'] += 1
        now = time.monotonic()          # throttled, as the poses' reasons
        if now - self._logged.get('bad_scans', -math.inf) >= THROTTLE_S:
            self._logged['bad_scans'] = now
            self.get_logger().warn(
                f'scan refused ({self.counts["bad_scans"]} so far): {why}')

    # outputs --------------------------------------------------------------
    def _send_seed(self, msg, why):
        self.initial_pub.publish(msg)
        self.counts['seeds_sent'] += 1
        p = msg.pose.pose
        cov = covariance3(msg.pose.covariance)
        yaw = math.degrees(yaw_of(p.orientation))
        self.get_logger().info(
            f'initialpose sent ({why}): x {p.position.x:.2f}, y '
            f'{p.position.y:.2f}, yaw {yaw:.0f} deg in '
            f'{msg.header.frame_id} (sd {math.sqrt(cov[0, 0]):.2f} m, '
            f'{math.degrees(math.sqrt(cov[2, 2])):.1f} deg)')

    def _message(self):
        """Return the state's diagnostics level and message."""
        level, message = STATES[self.witness.state]
        why = self.witness.why
        return level, message if why in ('', message) else f'{message}: {why}'

    def _update(self):
        """Publish the Bool and the state when they changed, at once."""
        ok = bool(self.witness.ok)
        if ok != self._published:
            self._published = ok
            self.ok_pub.publish(Bool(data=ok))
        state = self.witness.state
        if state == self._state:
            return
        first, self._state = self._state is None, state
        self.status_pub.publish(String(data=state))
        self._publish_status()
        if first:
            return
        level, message = self._message()
        if level == DiagnosticStatus.ERROR:     # one severity per call site
            self.get_logger().warn(message)
        else:
            self.get_logger().info(message)

    def _publish_status(self):
        w = self.witness
        last = w.last
        now = last.stamp if last is not None else 0.0
        level, message = self._message()
        local = w.local
        values = [
            _kv('state', w.state),
            _kv('localization_ok', str(bool(w.ok)).lower()),
            _kv('agreement_sigma', f'{last.sigmas:.2f}' if last else 'nan'),
            _kv('distance_m', f'{last.distance_m:.2f}' if last else 'nan'),
            _kv('yaw_difference_deg', f'{last.yaw_deg:.1f}' if last
                else 'nan'),
            _kv('disagreeing_for_s', f'{w.disagreeing_for(now):.1f}'),
            _kv('score', f'{w.score:.3f}'),
            _kv('reason', last.reason if last else ''),
            _kv('localizer_frame', local.frame if local else ''),
            _kv('wifi_frame', self.last_fused.header.frame_id
                if self.last_fused else ''),
            _kv('model_path', self.model_path),
        ] + [_kv(k, self.counts.get(k, 0)) for k in
             ('localizer_poses', 'fused_poses', 'scans', 'seeds_sent',
              'bad_fused', 'bad_scans')] + \
            [_kv(f'bad_localizer/{r}', self.counts.get(f'bad_localizer/{r}',
                                                       0))
             for r in BAD_REASONS]
        out = DiagnosticArray(status=[DiagnosticStatus(
            level=level, name=f'{self.get_name()}: localization',
            message=message, hardware_id=local.frame if local else '',
            values=values)])
        out.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(out)


def main(args=None):
    """Run the node until SIGINT/SIGTERM; exit 1 on a bad start-up."""
    return run(LocalizationMonitor, args, (ModelFileError, ValueError))


if __name__ == '__main__':
    # As the executable: --help starts nothing (stop signals are caught
    # only from here, after the imports; the installed executable, earlier)
    from wifi_place_recognition.ros.executables import \
        localization_monitor as _run
    sys.exit(_run())
