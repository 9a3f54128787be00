"""record_fingerprints' interface: what it does, its topics, its parameters."""

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import IntegerRange, ParameterDescriptor
from sensor_msgs.msg import JointState

from ..core.pose_label import MAX_POSE_AGE
from .node_interface import float_range

SUMMARY = """
Records a survey: appends every scan on wifi/scan to the fingerprint CSV
`output` (created with its missing folders, or continued), labelled with
the current `building` and `floor` parameters; change them as the robot
moves (ros2 param set /record_fingerprints floor 2), -1 pauses. With
`pose_topic`, each scan also gets an x, y, yaw interpolated between the
poses around it in time (the nearest if one side is missing). With
`odom_topic`, the odometry goes to a pose CSV beside it (walk1.csv ->
walk1.odom.csv). train_model reads the scans; fit_odometry
fits the odometry's drift on both.
"""

#: (role, name, type, what) of every topic the node uses; {pose_topic} and
#: {odom_topic} are the parameters' values (subscribed only when set).
TOPICS = (
    ('subscribes', 'wifi/scan', JointState,
     'scans (name = AP id, position = RSSI dBm); sensor-data QoS (best '
     'effort), a deep queue'),
    ('subscribes', '{pose_topic}', PoseWithCovarianceStamped,
     'with pose_topic set: the robot\'s pose that labels each scan (best '
     'effort, volatile: matches AMCL\'s and sensor-data publishers)'),
    ('subscribes', '{odom_topic}', Odometry,
     'with odom_topic set: the robot\'s odometry, every pose recorded '
     'beside the output (best effort, volatile, a deep queue)'),
    ('publishes', '/diagnostics', DiagnosticArray,
     'progress every second: scans per building/floor, skipped and lost '
     'scans, odometry poses received, written and skipped, write errors'),
)


def _label(description):
    return ParameterDescriptor(
        description=description + '; -1: pause recording',
        integer_range=[IntegerRange(from_value=-1, to_value=1000, step=1)])


#: (name, default, descriptor) of every parameter, in declaration order.
PARAMETERS = (
    ('output', '', ParameterDescriptor(
        description='fingerprint CSV to create or continue (required; '
                    'missing folders are created, ~ is the home folder)',
        read_only=True)),
    ('building', -1, _label('building label')),
    ('floor', -1, _label('floor label')),
    ('pose_topic', '', ParameterDescriptor(
        description='geometry_msgs/PoseWithCovarianceStamped topic whose '
                    'x, y, yaw label each scan (e.g. /amcl_pose); empty: '
                    'no positions', read_only=True)),
    ('odom_topic', '', ParameterDescriptor(
        description='nav_msgs/Odometry topic whose every pose (TIMESTAMP, '
                    'X, Y, YAW) is recorded to the CSV beside the output, '
                    'named <output without .csv>.odom.csv (walk1.csv -> '
                    'walk1.odom.csv); empty: no odometry', read_only=True)),
    ('max_pose_age', MAX_POSE_AGE, ParameterDescriptor(
        description='s: the poses before and after a scan label it, '
                    'interpolated, when both are this close to it in time; '
                    'else the nearest one, if it is',
        floating_point_range=float_range(0.0, 3600.0))),
)
