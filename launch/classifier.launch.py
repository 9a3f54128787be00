"""Start classifier_node with the package's params file, topics remapped."""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

#: Launch arguments that set the node's parameter of the same name over the
#: params file when given (empty, their default: the file's value).
PARAMETERS = {
    'model_path': 'model file (.npz) of classifier_node; empty: the params '
                  'file\'s (its default: the shipped UJIIndoorLoc model)',
    'tracking': 'true: answer with the place tracked over the scans',
    'frame_id': 'frame of ~/pose and initialpose; may hold {building} and '
                '{floor}, e.g. map_b{building}_f{floor} (one map per floor)',
    'publish_initial_pose': 'true: send the first confident answer on '
                            'initialpose (a global fix at start-up)',
    'initial_pose_on_change': 'true: send initialpose when the building/'
                              'floor changes or the position jumps',
}


def _node(context):
    """Return classifier_node with the parameters given as arguments."""
    given = {name: LaunchConfiguration(name) for name in PARAMETERS
             if context.launch_configurations[name]}
    return [Node(
        package='wifi_place_recognition', executable='classifier_node',
        name='classifier_node',
        parameters=[LaunchConfiguration('params_file')] + (
            [given] if given else []),
        remappings=[('wifi/scan', LaunchConfiguration('scan_topic')),
                    ('odom', LaunchConfiguration('odom_topic')),
                    ('initialpose', LaunchConfiguration('initialpose_topic'))],
        output='screen')]


def generate_launch_description():
    """Return the launch description (needs launch_ros: a full ROS install)."""
    share = get_package_share_directory('wifi_place_recognition')
    return LaunchDescription([
        DeclareLaunchArgument(
            'params_file',
            default_value=os.path.join(share, 'config',
                                       'classifier_node.yaml'),
            description='YAML file with the parameters of classifier_node '
                        '(thresholds: see doc/parameters.md); the default '
                        'is the package\'s file of the defaults'),
        DeclareLaunchArgument(
            'scan_topic', default_value='wifi/scan',
            description='topic of the WiFi scans (sensor_msgs/JointState: '
                        'name = BSSID, position = RSSI dBm), remapped to '
                        'the node\'s wifi/scan'),
        DeclareLaunchArgument(
            'odom_topic', default_value='odom',
            description='topic of the robot\'s odometry (nav_msgs/Odometry), '
                        'remapped to the node\'s odom; fused with the WiFi '
                        'positions while it flows (parameter fusion)'),
        DeclareLaunchArgument(
            'initialpose_topic', default_value='initialpose',
            description='where the node\'s initialpose goes (AMCL\'s '
                        '/initialpose, or the robot\'s namespace)'),
        *[DeclareLaunchArgument(name, default_value='',
                                description=description)
          for name, description in PARAMETERS.items()],
        OpaqueFunction(function=_node),
    ])
