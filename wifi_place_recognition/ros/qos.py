"""
The QoS policies of the nodes' inputs that parameters may override.

``qos_overrides.<topic>.subscription.<policy>`` on the pose and odometry
subscriptions. Apart from :mod:`.node_interface`, which the executables
import before they catch stop signals, so must not import rclpy.
"""

from rclpy.qos import QoSPolicyKind

QOS_OVERRIDES = (QoSPolicyKind.HISTORY, QoSPolicyKind.DEPTH,
                 QoSPolicyKind.RELIABILITY, QoSPolicyKind.DURABILITY)
