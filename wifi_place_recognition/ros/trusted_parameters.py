"""trusted_recorder's interface: what it does, its topics, its parameters."""

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped
from rcl_interfaces.msg import ParameterDescriptor
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from ..core.trusted import TrustParams
from .node_interface import float_range

SUMMARY = """
Surveys while the robot works: appends each scan on wifi/scan to the
fingerprint CSV `output` (as record_fingerprints does: created or
continued, nothing lost on a write fault), labelled with the localiser's
pose (x, y, yaw, frame) and classifier_node's current building and floor,
but only while the localiser is trusted: its pose sure (max_sd), no jump
in the last settle_s seconds, and localization_monitor saying neither
lost nor disagrees (cannot_tell does not stop it: inside a survey hole
WiFi cannot testify; but after a jump, nothing until it says agrees)
and still running (its latched state does not outlive its publisher,
nor does the current place). Every scan left out is counted by reason.
"""

#: (role, name, type, what) of every topic the node uses; {name} is the
#: value of the parameter ``name``.
TOPICS = (
    ('subscribes', 'wifi/scan', JointState,
     'scans (name = AP id, position = RSSI dBm); sensor-data QoS (best '
     'effort), a deep queue'),
    ('subscribes', '{localizer_topic}', PoseWithCovarianceStamped,
     'the localiser\'s pose and covariance (AMCL: amcl_pose); best effort, '
     'volatile: matches AMCL\'s and sensor-data publishers'),
    ('subscribes', '{status_topic}', String,
     'localization_monitor\'s state (agrees, disagrees, cannot_tell, '
     'lost, waiting); '
     'latched'),
    ('subscribes', '{place_topic}', DiagnosticArray,
     'classifier_node\'s current place (building, floor); latched'),
    ('publishes', '/diagnostics', DiagnosticArray,
     'progress every second: scans recorded per building/floor, scans left '
     'out by reason, the localiser\'s jumps, write errors'),
)

_D = TrustParams()


def _number(name, default, high, description):
    return (name, default, ParameterDescriptor(
        description=description, floating_point_range=float_range(0.0,
                                                                  high)))


#: (name, default, descriptor) of every parameter, in declaration order.
PARAMETERS = (
    ('output', '', ParameterDescriptor(
        description='fingerprint CSV with positions to create or continue '
                    '(required; missing folders are created, ~ is the home '
                    'folder)', read_only=True)),
    ('localizer_topic', 'amcl_pose', ParameterDescriptor(
        description='the localiser\'s PoseWithCovarianceStamped topic',
        read_only=True)),
    ('status_topic', 'localization_monitor/status', ParameterDescriptor(
        description='localization_monitor\'s ~/status', read_only=True)),
    ('place_topic', 'classifier_node/current_place', ParameterDescriptor(
        description='classifier_node\'s ~/current_place', read_only=True)),
    _number('max_sd', _D.max_sd, 100.0,
            'm: a localiser pose whose x or y standard deviation is larger '
            'labels no scan'),
    _number('jump_m', _D.jump_m, 1000.0,
            'm: a localiser step longer than this plus what max_speed covers '
            'between the two poses is a jump'),
    _number('max_speed', _D.max_speed, 100.0, 'm/s: the robot\'s top speed'),
    _number('settle_s', _D.settle_s, 3600.0,
            's: after a jump of the localiser, no scan is recorded for this '
            'long, and then only once localization_monitor says agrees '
            '(keep it >= its max_age)'),
    _number('max_pose_age', _D.max_pose_age, 3600.0,
            's: the localiser\'s poses before and after a scan label it, '
            'interpolated, when both are this close to it in time; else the '
            'nearest one, if it is'),
)
#: The parameters of :class:`.core.trusted.TrustParams`.
TRUST_FIELDS = ('max_sd', 'jump_m', 'max_speed', 'settle_s', 'max_pose_age')
