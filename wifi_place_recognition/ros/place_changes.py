"""
``~/current_place``: the confident place, latched, once per change.

:class:`CurrentPlace` publishes the changes of place that
:class:`.pipeline.place_changes.PlaceChanges` decides (a new place
at its second confident answer in a row): one
``diagnostic_msgs/DiagnosticArray`` per change, one status with
``building``, ``floor``, ``frame_id`` and ``confidence``, the header
stamp that of the scan that changed it; latched (reliable, transient
local, depth 1), so a subscriber that starts late gets the current place
at once.
"""

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from .messages import key_value

CURRENT_PLACE_QOS = QoSProfile(depth=1,
                               reliability=ReliabilityPolicy.RELIABLE,
                               durability=DurabilityPolicy.TRANSIENT_LOCAL)


class CurrentPlace:
    """The latched current place of ``node``."""

    def __init__(self, node):
        self._name = f'{node.get_name()}: current place'
        self._logger = node.get_logger()
        self.publisher = node.create_publisher(
            DiagnosticArray, '~/current_place', CURRENT_PLACE_QOS)

    def publish(self, place, stamp, frame):
        """Publish ``place`` (the answer) in ``frame``; log it."""
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
