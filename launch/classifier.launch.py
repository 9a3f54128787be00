"""Start classifier_node with the package's params file, scan and odometry remapped."""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Return the launch description (needs launch_ros: a full ROS install)."""
    share = get_package_share_directory('wifi_place_recognition')
    return LaunchDescription([
        DeclareLaunchArgument(
            'params_file',
            default_value=os.path.join(share, 'config',
                                       'classifier_node.yaml'),
            description='YAML file with the parameters of classifier_node '
                        '(model_path, thresholds: see doc/parameters.md); '
                        'the default is the package\'s file of the defaults'),
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
        Node(package='wifi_place_recognition', executable='classifier_node',
             name='classifier_node',
             parameters=[LaunchConfiguration('params_file')],
             remappings=[('wifi/scan', LaunchConfiguration('scan_topic')),
                         ('odom', LaunchConfiguration('odom_topic'))],
             output='screen'),
    ])
