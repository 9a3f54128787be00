"""
An echo node: classifier_node's scan in and answer out, with no work between.

A benchmark baseline: named ``classifier_node``, it takes ``wifi/scan`` with
the same QoS and answers each scan on ``~/place`` and ``/diagnostics`` with
a one-status ``DiagnosticArray`` stamped with the scan's stamp, holding its
``latency_ms`` as the node does. What classifier_node costs on top of this
is its own: no model, no recognizer, no odometry.
"""

import copy
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from wifi_place_recognition.ros.runner import run

SCAN_QOS = copy.copy(qos_profile_sensor_data)   # as classifier_node's
SCAN_QOS.depth = 1


class EchoNode(Node):
    """Answer every scan at once."""

    def __init__(self, **kwargs):
        super().__init__('classifier_node', **kwargs)
        self.place_pub = self.create_publisher(
            DiagnosticArray, '~/place',
            QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        self.diag_pub = self.create_publisher(DiagnosticArray,
                                              '/diagnostics', 10)
        self.create_subscription(JointState, 'wifi/scan', self._on_scan,
                                 SCAN_QOS)

    def _on_scan(self, msg):
        received_at = time.perf_counter()
        status = DiagnosticStatus(name='echo', message=f'{len(msg.name)} APs')
        latency_ms = (time.perf_counter() - received_at) * 1e3
        status.values = [KeyValue(key='latency_ms', value=f'{latency_ms:.3f}')]
        out = DiagnosticArray(status=[status])
        out.header.stamp = msg.header.stamp
        self.place_pub.publish(out)
        self.diag_pub.publish(out)


if __name__ == '__main__':
    sys.exit(run(EchoNode))
