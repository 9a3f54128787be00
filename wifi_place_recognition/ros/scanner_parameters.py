"""wifi_scanner_node's interface: what it does, its topics, its parameters."""

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import ParameterDescriptor
from sensor_msgs.msg import JointState

from ..data.wifi_sources import SOURCES
from .node_interface import float_range

SUMMARY = """
Publishes the robot's WiFi scans: every `period` seconds it reads a scan
of a wireless interface with the first working source (iw, iw dump, nmcli)
and publishes it on wifi/scan, the input of classifier_node and
record_fingerprints. Scan commands run off the executor; a missing tool or
permission is an ERROR status and it keeps retrying.
"""

#: (role, name, type, what) of every topic the node uses.
TOPICS = (
    ('publishes', 'wifi/scan', JointState,
     'one scan: name = BSSID, position = RSSI dBm, header.frame_id = the '
     'interface; sensor-data QoS (best effort)'),
    ('publishes', '/diagnostics', DiagnosticArray,
     'the scanner status every second (last result, counts)'),
)


#: (name, default, descriptor) of every parameter, in declaration order.
PARAMETERS = (
    ('interface', '', ParameterDescriptor(
        description='wireless interface; empty: the first one found in '
                    '/sys/class/net', read_only=True)),
    ('period', 2.0, ParameterDescriptor(
        description='seconds between scans', read_only=True,
        floating_point_range=float_range(0.1, 3600.0))),
    ('sources', ['iw', 'iw_dump', 'nmcli'], ParameterDescriptor(
        description=f'tried in order; any of {sorted(SOURCES)}',
        read_only=True)),
    ('max_age', 0.0, ParameterDescriptor(
        description='readings of APs last seen longer ago (s) are dropped; '
                    '0: period + the scan command\'s run time',
        floating_point_range=float_range(0.0, 3600.0))),
)
