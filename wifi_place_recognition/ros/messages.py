"""Conversions between ROS messages and plain Python values."""

from diagnostic_msgs.msg import KeyValue
from geometry_msgs.msg import PoseWithCovarianceStamped
from sensor_msgs.msg import JointState
import numpy as np

#: Variance (rad^2) of the unknown yaw, and of z, roll and pitch: WiFi
#: gives no orientation, and the floor is given by the frame.
UNKNOWN_VARIANCE = 1e6


def seconds(stamp):
    """Return a ``builtin_interfaces/Time`` in seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def stamp_time(stamp, clock):
    """Return a header stamp in seconds; an unset (zero) one: ``clock``'s now."""
    return seconds(stamp) or clock.now().nanoseconds * 1e-9


def key_value(key, value):
    """Return a KeyValue of ``value`` as text."""
    return KeyValue(key=key, value=str(value))


def pose_message(xy, cov, stamp, frame_id):
    """Return a PoseWithCovarianceStamped at x, y with their 2x2 ``cov``."""
    pose = PoseWithCovarianceStamped()
    pose.header.stamp = stamp
    pose.header.frame_id = frame_id
    pose.pose.pose.position.x = float(xy[0])
    pose.pose.pose.position.y = float(xy[1])
    pose.pose.pose.orientation.w = 1.0
    covariance = [0.0] * 36
    (covariance[0], covariance[1]), (covariance[6], covariance[7]) = \
        np.asarray(cov, float).tolist()
    for i in (14, 21, 28, 35):  # z, roll, pitch, yaw: unknown
        covariance[i] = UNKNOWN_VARIANCE
    pose.pose.covariance = covariance
    return pose


def status_values(status):
    """Return a DiagnosticStatus's key/values as a dict."""
    return {kv.key: kv.value for kv in status.values}


def scan_message(ap_ids, rssi, stamp, frame_id='replay'):
    """Return a JointState scan of the detected (non-NaN) APs of one row."""
    detected = np.flatnonzero(np.isfinite(rssi))
    msg = JointState(name=[ap_ids[j] for j in detected],
                     position=rssi[detected].astype(float).tolist())
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    return msg
