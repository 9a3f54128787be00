"""
``wifi_scanner_node``: the robot's WiFi interface as ``wifi/scan`` messages.

Every ``period`` seconds it reads a scan from the first working source of
``sources`` (``iw`` triggers a scan, ``iw_dump`` reads the kernel's cached
results, ``nmcli`` asks NetworkManager; see :mod:`.wifi_sources`) and
publishes a ``sensor_msgs/JointState`` (name = BSSID, position = RSSI dBm,
frame_id = interface). No interface, no permission or a missing tool gives an
ERROR status on ``/diagnostics`` with the reason; it keeps retrying.
"""

import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState

from .runner import names_the_node, run
from ..data.wifi_sources import scan, SOURCES, SourceError, wireless_interfaces

THROTTLE_S = 30.0


class WifiScannerNode(Node):
    """Publish scans of one wireless interface at a fixed period."""

    @names_the_node
    def __init__(self):
        super().__init__('wifi_scanner_node')
        self.interface = self.declare_parameter(
            'interface', '', ParameterDescriptor(
                description='wireless interface; empty: the first one '
                            'found in /sys/class/net',
                read_only=True)).value
        period = self.declare_parameter(
            'period', 2.0, ParameterDescriptor(
                description='seconds between scans', read_only=True,
                floating_point_range=[FloatingPointRange(
                    from_value=0.1, to_value=3600.0)])).value
        self.sources = list(self.declare_parameter(
            'sources', ['iw', 'iw_dump', 'nmcli'], ParameterDescriptor(
                description=f'tried in order; any of {sorted(SOURCES)}',
                read_only=True)).value)
        unknown = [s for s in self.sources if s not in SOURCES]
        if unknown or not self.sources:
            raise ValueError(f'unknown scan sources {unknown}; use any of '
                             f'{sorted(SOURCES)}')
        self.timeout = min(period * 5, 30.0)
        self.pub = self.create_publisher(JointState, 'wifi/scan',
                                         qos_profile_sensor_data)
        self.diag_pub = self.create_publisher(DiagnosticArray,
                                              '/diagnostics', 10)
        self.scans = 0
        self.create_timer(period, self._scan_once)

    def _scan_once(self):
        iface = self.interface or next(iter(wireless_interfaces()), '')
        stamp = self.get_clock().now().to_msg()
        try:
            if not iface:
                raise SourceError('no wireless interface found')
            source, readings = scan(self.sources, iface, self.timeout)
        except SourceError as exc:
            self._status(DiagnosticStatus.ERROR, f'no scan: {exc}', iface)
            self.get_logger().error(f'no scan: {exc}',
                                    throttle_duration_sec=THROTTLE_S)
            return
        if not readings:
            self._status(DiagnosticStatus.WARN, f'{source}: no AP in range',
                         iface)
            return
        msg = JointState(name=[b for b, _ in readings],
                         position=[r for _, r in readings])
        msg.header.stamp = stamp
        msg.header.frame_id = iface
        self.pub.publish(msg)
        self.scans += 1
        self._status(DiagnosticStatus.OK,
                     f'{len(readings)} APs from {source}', iface)

    def _status(self, level, message, iface):
        out = DiagnosticArray()
        out.header.stamp = self.get_clock().now().to_msg()
        out.status = [DiagnosticStatus(
            level=level, name=f'{self.get_name()}: scanner', message=message,
            hardware_id=iface or 'none',
            values=[KeyValue(key='scans_published', value=str(self.scans)),
                    KeyValue(key='sources', value=','.join(self.sources))])]
        self.diag_pub.publish(out)


def main(args=None):
    """Run the scanner until SIGINT/SIGTERM; exit 1 on bad parameters."""
    return run(WifiScannerNode, args)


if __name__ == '__main__':
    sys.exit(main())
