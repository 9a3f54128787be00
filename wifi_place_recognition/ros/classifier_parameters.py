"""classifier_node's interface: its topics, and its parameters' checks."""

import math

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import IntegerRange, ParameterDescriptor
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from ..core.tracking import DEFAULT_TIMEOUT
from . import node_interface
from .node_interface import float_range


def _integers(low, high):
    return [IntegerRange(from_value=low, to_value=high, step=1)]


SUMMARY = """
Tells which building and floor the robot is on, and where, from WiFi scans:
each scan on wifi/scan is answered on ~/place with the building, floor and
class probabilities (and x, y with a model trained with positions),
single-scan or tracked over the scans (tracking). The model file comes
from train_model; the default is the shipped UJIIndoorLoc model.
"""

#: (role, name, type, what) of every topic and service the node offers.
TOPICS = (
    ('subscribes', 'wifi/scan', JointState,
     'one WiFi scan: name = AP id (BSSID), position = RSSI dBm; sensor-data '
     'QoS (best effort), the newest scan waits'),
    ('publishes', '~/place', DiagnosticArray,
     'the answer to each scan: building, floor, confidence, probabilities '
     '(and x, y, position_sigma_m); reliable'),
    ('publishes', '/diagnostics', DiagnosticArray,
     'every answer, and a health status every second'),
    ('publishes', '~/current_place', DiagnosticArray,
     'the confident place, once per change; latched (transient local)'),
    ('subscribes', 'odom', Odometry,
     'the robot\'s odometry (pose in its odom frame); while it flows, each '
     'answer\'s position is fused with it (fusion); sensor-data QoS'),
    ('subscribes', '~/set_pose', PoseWithCovarianceStamped,
     'a model with positions: a known start (a dock, an operator\'s '
     'estimate) in the frame of a place; the fused pose starts there, '
     'heading included; reliable'),
    ('publishes', '~/pose', PoseWithCovarianceStamped,
     'a model with positions: the position of each answer, in frame_id; '
     'with odometry, the fused pose with yaw, at every scan and '
     'pose_rate times a second between scans'),
    ('publishes', 'initialpose', PoseWithCovarianceStamped,
     'a model with positions: a confident answer to seed a localiser '
     '(see publish_initial_pose, initial_pose_on_change)'),
    ('service', '~/reset', Trigger,
     'forget the tracked belief and the fused pose: the next scan starts '
     'afresh'),
    ('service', '~/publish_initial_pose', Trigger,
     'a model with positions: send the next confident answer on '
     'initialpose'),
)

#: (name, default, descriptor) of every parameter, in declaration order.
PARAMETERS = (
    ('model_path', '', ParameterDescriptor(
        description='model file from train_model; empty: the shipped '
                    'UJIIndoorLoc model; set while running, the next scan '
                    'is answered by it (a file that does not load is '
                    'refused, the running model goes on)')),
    ('min_confidence', 0.5, ParameterDescriptor(
        description='below this top-class probability the status is WARN',
        floating_point_range=float_range(0.0, 1.0))),
    ('min_known_aps', 3, ParameterDescriptor(
        description='with fewer APs known to the model the status is WARN',
        integer_range=_integers(0, 10000))),
    ('max_aps', 4096, ParameterDescriptor(
        description='scans listing more APs are rejected',
        integer_range=_integers(1, 1000000))),
    ('tracking', False, ParameterDescriptor(
        description='answer with the building/floor tracked over the scans '
                    '(false: each scan alone)')),
    ('tracking_timeout', DEFAULT_TIMEOUT, ParameterDescriptor(
        description='seconds between scans (header.stamp) after which the '
                    'tracked belief restarts',
        floating_point_range=float_range(1.0, 1e6))),
    ('frame_id', 'map', ParameterDescriptor(
        description='frame of ~/pose and initialpose; may contain '
                    '{building} and {floor} (one map per floor)')),
    ('publish_initial_pose', False, ParameterDescriptor(
        description='at start-up, send the first confident answer on '
                    'initialpose (as the service does)', read_only=True)),
    ('initial_pose_on_change', False, ParameterDescriptor(
        description='send every confident answer that changes the '
                    'building/floor, or whose position jumps, on '
                    'initialpose (with odometry fused: the filter\'s first '
                    'pose on the new floor, or when it starts afresh)')),
    ('jump_threshold', 5.0, ParameterDescriptor(
        description='a jump: the tracked position moved more than this many '
                    'standard deviations of the previous answer\'s '
                    '(Mahalanobis distance)',
        floating_point_range=float_range(1.0, 100.0))),
    ('fusion', True, ParameterDescriptor(
        description='while odometry arrives on odom, fuse it with the WiFi '
                    'positions (a particle filter over x, y, yaw; a model '
                    'with positions); false: each answer\'s own position')),
    ('odom_timeout', 1.0, ParameterDescriptor(
        description='seconds a scan waits for odometry covering its stamp; '
                    'then it is fused alone (WiFi only, WARN)',
        floating_point_range=float_range(0.05, 60.0))),
    ('pose_rate', 10.0, ParameterDescriptor(
        description='fused poses per second on ~/pose between scans (0: at '
                    'scans only)',
        floating_point_range=float_range(0.0, 100.0))),
)
#: Parameters that :meth:`PlaceRecognizer.configure` takes, by name.
RECOGNIZER_SETTINGS = ('min_confidence', 'min_known_aps', 'max_aps',
                       'tracking', 'tracking_timeout')
#: Parameters that need a model with a position output when set.
NEED_POSITION = ('publish_initial_pose', 'initial_pose_on_change')


def declare(node):
    """Declare every parameter on ``node``; return {name: value}."""
    return node_interface.declare(node, PARAMETERS)


def no_position(name):
    """Return why ``name`` cannot be set for a model without positions."""
    return (f'{name}: the model has no position output (trained without '
            f'X, Y)')


def check_frame(template):
    """Raise ValueError unless ``template`` formats with building, floor."""
    try:
        frame = template.format(building=0, floor=0)
    except (KeyError, IndexError, ValueError) as exc:
        raise ValueError(f'frame_id {template!r}: only {{building}} and '
                         f'{{floor}} may be substituted ({exc!r})') from None
    if not frame:
        raise ValueError('frame_id must not be empty')


def refusal(name, value, has_position):
    """Return why ``value`` is refused for parameter ``name``, or None."""
    if name in ('min_confidence', 'tracking_timeout', 'jump_threshold',
                'odom_timeout', 'pose_rate') and not math.isfinite(value):
        return f'{name} must be finite'
    if name in NEED_POSITION and value and not has_position:
        return no_position(name)
    if name == 'frame_id':
        try:
            check_frame(value)
        except ValueError as exc:
            return str(exc)
    return None
