"""record_fingerprints' interface: what it does, its topics, its parameters."""

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange,
                                ParameterDescriptor)
from sensor_msgs.msg import JointState

SUMMARY = """
Records a survey: appends every scan on wifi/scan to the fingerprint CSV
`output` (created with its missing folders, or continued), labelled with
the current `building` and `floor` parameters; change them as the robot
moves (ros2 param set /record_fingerprints floor 2), -1 pauses. With
`pose_topic`, each scan also gets the x, y of the nearest pose in time.
train_model reads the file.
"""

#: (role, name, type, what) of every topic the node uses; {pose_topic} is
#: the parameter's value (subscribed only when it is set).
TOPICS = (
    ('subscribes', 'wifi/scan', JointState,
     'scans (name = AP id, position = RSSI dBm); sensor-data QoS (best '
     'effort), a deep queue'),
    ('subscribes', '{pose_topic}', PoseWithCovarianceStamped,
     'with pose_topic set: the robot\'s pose that labels each scan (best '
     'effort, volatile: matches AMCL\'s and sensor-data publishers)'),
    ('publishes', '/diagnostics', DiagnosticArray,
     'progress every second: scans per building/floor, skipped and lost '
     'scans, write errors'),
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
                    'x, y label each scan (e.g. /amcl_pose); empty: no '
                    'positions', read_only=True)),
    ('max_pose_age', 2.0, ParameterDescriptor(
        description='s: the largest time between a scan and the pose that '
                    'labels it', floating_point_range=[FloatingPointRange(
                        from_value=0.0, to_value=3600.0)])),
)
