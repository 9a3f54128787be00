"""
Bring up the WiFi side of a robot beside Nav2, from one params file.

wifi_scanner_node, classifier_node, localization_monitor and
trusted_recorder, each switched by an argument (``scanner``,
``classifier``, ``monitor``: true by default; ``recorder``: false), read
their sections of one params file
(``config/wifi_localization.yaml``). ``model_path`` and ``frame_id`` set
both classifier_node's and localization_monitor's: the model and the
frames are the same for both. Every node gets the same remappings: the
scans, the odometry and ``initialpose``.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

#: Launch arguments that switch a node on or off: {argument: (executable,
#: description)}; each node is named as its executable.
NODES = {
    'scanner': ('wifi_scanner_node',
                'true: start wifi_scanner_node (scans of the robot\'s own '
                'interface); false: the scans come from elsewhere, on '
                'scan_topic'),
    'classifier': ('classifier_node',
                   'true: start classifier_node (the place, the position '
                   'and the fused pose from the scans and the odometry)'),
    'monitor': ('localization_monitor',
                'true: start localization_monitor (is the localiser, e.g. '
                'AMCL, lost? re-seeds it with initial_pose_on_lost)'),
    'recorder': ('trusted_recorder',
                 'true: start trusted_recorder (a survey that fills its '
                 'own holes: each scan labelled by the localiser while it '
                 'is trusted, appended to output)'),
}
#: The switches off by default (the others are on).
OFF = ('recorder',)

#: Launch arguments that set the parameter of that name of each node listed
#: over the params file when given (empty, their default: the file's
#: value): {argument: (nodes, description)}.
PARAMETERS = {
    'model_path': (('classifier_node', 'localization_monitor'),
                   'model file (.npz) of classifier_node and of '
                   'localization_monitor (the same); empty: the params '
                   'file\'s (its default: the shipped UJIIndoorLoc model)'),
    'frame_id': (('classifier_node', 'localization_monitor'),
                 'frame of ~/pose and initialpose, and of the localiser\'s '
                 'poses the monitor takes; may hold {building} and {floor}, '
                 'e.g. map_b{building}_f{floor} (one map per floor)'),
    'tracking': (('classifier_node',),
                 'true: answer with the place tracked over the scans'),
    'publish_initial_pose': (('classifier_node',),
                             'true: send the first confident answer on '
                             'initialpose (a global fix at start-up)'),
    'initial_pose_on_change': (('classifier_node',),
                               'true: send initialpose when the building/'
                               'floor changes or the position jumps'),
    'localizer_topic': (('localization_monitor', 'trusted_recorder'),
                        'the localiser\'s PoseWithCovarianceStamped topic '
                        'the monitor watches and the recorder labels by '
                        '(AMCL: amcl_pose)'),
    'output': (('trusted_recorder',),
               'the fingerprint CSV trusted_recorder appends to (needed '
               'with recorder:=true), e.g. /data/recorded.csv'),
    'initial_pose_on_lost': (('localization_monitor',),
                             'true: the monitor sends the fused pose on '
                             'initialpose at start-up and when the '
                             'localiser is lost'),
    'interface': (('wifi_scanner_node',),
                  'wireless interface the scanner reads; empty: the params '
                  'file\'s (its default: the first one found)'),
}

#: Topics remapped on every node: {argument: (the nodes' name, default,
#: description)}.
REMAPS = {
    'scan_topic': ('wifi/scan', 'wifi/scan',
                   'topic of the WiFi scans (sensor_msgs/JointState: name '
                   '= BSSID, position = RSSI dBm), the scanner\'s and '
                   'classifier_node\'s wifi/scan'),
    'odom_topic': ('odom', 'odom',
                   'topic of the robot\'s odometry (nav_msgs/Odometry), '
                   'classifier_node\'s odom; fused with the WiFi positions '
                   'while it flows'),
    'initialpose_topic': ('initialpose', 'initialpose',
                          'where classifier_node\'s and the monitor\'s '
                          'initialpose go (AMCL\'s /initialpose, or the '
                          'robot\'s namespace)'),
}


def _nodes(context):
    """Return the nodes, each with the parameters given as arguments."""
    remappings = [(topic, LaunchConfiguration(argument))
                  for argument, (topic, _, _) in REMAPS.items()]
    nodes = []
    for switch, (executable, _) in NODES.items():
        given = {name: LaunchConfiguration(name)
                 for name, (owners, _) in PARAMETERS.items()
                 if executable in owners and
                 context.launch_configurations[name]}
        nodes.append(Node(
            package='wifi_place_recognition', executable=executable,
            name=executable, condition=IfCondition(LaunchConfiguration(
                switch)),
            parameters=[LaunchConfiguration('params_file')] + (
                [given] if given else []),
            remappings=remappings, output='screen'))
    return nodes


def generate_launch_description():
    """Return the launch description (needs launch_ros: a full ROS install)."""
    share = get_package_share_directory('wifi_place_recognition')
    return LaunchDescription([
        DeclareLaunchArgument(
            'params_file',
            default_value=os.path.join(share, 'config',
                                       'wifi_localization.yaml'),
            description='YAML file with a section per node (thresholds: '
                        'see doc/parameters.md); the default is the '
                        'package\'s file of the defaults'),
        *[DeclareLaunchArgument(switch, default_value=str(
            switch not in OFF).lower(), description=description)
          for switch, (_, description) in NODES.items()],
        *[DeclareLaunchArgument(argument, default_value=default,
                                description=description)
          for argument, (_, default, description) in REMAPS.items()],
        *[DeclareLaunchArgument(name, default_value='',
                                description=description)
          for name, (_, description) in PARAMETERS.items()],
        OpaqueFunction(function=_nodes),
    ])
