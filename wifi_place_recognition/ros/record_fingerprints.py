"""
``record_fingerprints``: label the robot's WiFi scans and keep them in a CSV.

Subscribes ``wifi/scan`` and appends every scan to ``output`` (the generic
fingerprint format ``train_model`` reads) with the current ``building`` and
``floor`` parameters as labels. Change them at runtime as the robot moves
(``ros2 param set /record_fingerprints floor 2``); -1 pauses recording.
Progress (scans per building/floor) is logged and published on
``/diagnostics``, with the scans received, those with no usable reading,
the readings left out and the scans lost before they reached the node.

The subscription is best effort (it must match the scanner's sensor-data
publisher) with a deep queue: rewriting a large file for a new AP can take
a second, and the scans arriving meanwhile wait instead of being lost.
"""

from collections import Counter
import copy
import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import IntegerRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import JointState

from .runner import names_the_node, run
from ..data.recording import FingerprintLog, RecordingError
from .sequence import PublisherGaps

PROGRESS_EVERY = 20
THROTTLE_S = 10.0
SCAN_QOS = copy.copy(qos_profile_sensor_data)
SCAN_QOS.depth = 1000


def _label(description):
    return ParameterDescriptor(
        description=description + '; -1: pause recording',
        integer_range=[IntegerRange(from_value=-1, to_value=1000, step=1)])


class RecordFingerprintsNode(Node):
    """Append labelled scans to a fingerprint CSV."""

    @names_the_node
    def __init__(self):
        super().__init__('record_fingerprints')
        output = self.declare_parameter(
            'output', '', ParameterDescriptor(
                description='fingerprint CSV to create or continue',
                read_only=True)).value
        if not output:
            raise RecordingError('parameter output (the CSV path) is not '
                                 'set')
        self.declare_parameter('building', -1, _label('building label'))
        self.declare_parameter('floor', -1, _label('floor label'))
        self.log = FingerprintLog(output)
        self.counts = Counter(scans_received=0, scans_paused=0,
                              scans_unusable=0, scans_lost=0,
                              skipped_readings=0)
        self._gaps = PublisherGaps()
        self.diag_pub = self.create_publisher(DiagnosticArray,
                                              '/diagnostics', 10)
        self._scan_sub = self.create_subscription(
            JointState, 'wifi/scan', self._on_scan, SCAN_QOS,
            qos_overriding_options=QoSOverridingOptions.with_default_policies())
        self.create_timer(1.0, self._publish_progress)
        self.get_logger().info(
            f'recording to {output} ({sum(self.log.counts.values())} scans '
            f'already there, {len(self.log.ap_ids)} APs)')

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
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        recorded, skipped = self.log.add(msg.name, msg.position, building,
                                         floor, stamp)
        self.counts['skipped_readings'] += skipped
        if not recorded:
            self.counts['scans_unusable'] += 1
            self.get_logger().warn('scan skipped: no usable reading (RSSI '
                                   'not finite or implausible, or a bad AP '
                                   'name)', throttle_duration_sec=THROTTLE_S)
            return
        n = self.log.counts[(building, floor)]
        if n % PROGRESS_EVERY == 0:
            self.get_logger().info(f'building {building}, floor {floor}: '
                                   f'{n} scans')

    def _publish_progress(self):
        counts = sorted(self.log.counts.items())
        out = DiagnosticArray()
        out.header.stamp = self.get_clock().now().to_msg()
        out.status = [DiagnosticStatus(
            level=DiagnosticStatus.OK, name=f'{self.get_name()}: progress',
            message=', '.join(f'B{b}F{f}: {n}' for (b, f), n in counts)
            or 'no scans yet',
            hardware_id=str(self.log.path),
            values=[KeyValue(key=f'scans/B{b}F{f}', value=str(n))
                    for (b, f), n in counts] +
            [KeyValue(key='aps', value=str(len(self.log.ap_ids)))] +
            [KeyValue(key=k, value=str(n)) for k, n in self.counts.items()])]
        self.diag_pub.publish(out)


def main(args=None):
    """Record until SIGINT/SIGTERM; exit 1 if the file cannot be used."""
    return run(RecordFingerprintsNode, args, (RecordingError, OSError))


if __name__ == '__main__':
    sys.exit(main())
