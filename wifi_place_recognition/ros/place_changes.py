"""
The place changes a navigation stack acts on: a new floor, a jump.

:class:`PlaceChanges` follows a node's answers. It publishes the confident
place on ``~/current_place`` (``diagnostic_msgs/DiagnosticArray``, one
status with ``building``, ``floor``, ``frame_id`` and ``confidence``; the
header stamp is that of the scan that changed it), latched (reliable,
transient local, depth 1): one message per change, and a subscriber that
starts late gets the current place at once. It also says when a localiser
should be re-seeded: at the second confident answer in a row on another
building/floor than the last confident one (a single wrong scan does not
switch maps, whatever the model and its tracking), or at a confident
answer whose position jumped (:func:`.step_sigmas`).
"""

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from ..core.place_switch import PlaceSwitch
from ..core.recognizer import step_sigmas
from .messages import key_value

CURRENT_PLACE_QOS = QoSProfile(depth=1,
                               reliability=ReliabilityPolicy.RELIABLE,
                               durability=DurabilityPolicy.TRANSIENT_LOCAL)


class PlaceChanges:
    """The latched current place of ``node``, and when to re-seed."""

    def __init__(self, node, jump_threshold):
        self.jump_threshold = jump_threshold
        self.place = None             # (building, floor), last confident
        self._switch = PlaceSwitch()  # a new place at its second answer
        self._last_position = None    # ((building, floor), xy, cov)
        self._name = f'{node.get_name()}: current place'
        self._logger = node.get_logger()
        self.publisher = node.create_publisher(
            DiagnosticArray, '~/current_place', CURRENT_PLACE_QOS)

    def follow(self, place, confident, stamp, frame, jumps=True):
        """
        Take one answer; return why to re-seed the localiser (a list).

        ``confident``: the answer is OK (not WARN); ``frame``: its pose's
        frame. A jump is a position more than ``jump_threshold`` standard
        deviations from the previous answer's on the same floor (not a
        reason with ``jumps`` False: the odometry fusion judges those).
        Only a confident answer changes the place or gives reasons, and
        a new place only at its second confident answer in a row.
        """
        key = (place.building, place.floor)
        reasons = []
        if place.position is not None:
            last = self._last_position
            if last is not None and last[0] == key:
                sigmas = step_sigmas(last[1], last[2], place.position)
                if jumps and sigmas > self.jump_threshold:
                    reasons.append(f'position jumped {sigmas:.1f} sigma')
            self._last_position = (key, place.position, place.position_cov)
        switch = self._switch.switches(self.place, key, confident)
        if not confident or (self.place not in (None, key) and not switch):
            return []
        if key != self.place:
            if self.place is not None:
                reasons.insert(0, 'building {}, floor {} before'.format(
                    *self.place))
            self.place = key
            self._publish(place, stamp, frame)
        return reasons

    def _publish(self, place, stamp, frame):
        message = f'building {place.building}, floor {place.floor}'
        out = DiagnosticArray(status=[DiagnosticStatus(
            level=DiagnosticStatus.OK, name=self._name, message=message,
            hardware_id=frame, values=[
                key_value('building', place.building),
                key_value('floor', place.floor),
                key_value('frame_id', frame),
                key_value('confidence', f'{place.confidence:.6f}')])])
        out.header.stamp = stamp
        self.publisher.publish(out)
        self._logger.info(f'current place: {message} ({frame})')
