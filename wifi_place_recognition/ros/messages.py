"""Conversions between ROS messages and plain Python values."""

import math

from diagnostic_msgs.msg import KeyValue
from geometry_msgs.msg import PoseWithCovarianceStamped
from sensor_msgs.msg import JointState
import numpy as np

from ..core.filter import particles

#: Variance (rad^2) of the unknown yaw, and of z, roll and pitch: WiFi
#: gives no orientation, and the floor is given by the frame (the
#: filter's own figure for a heading it does not know).
UNKNOWN_VARIANCE = particles.UNKNOWN_VARIANCE


def seconds(stamp):
    """Return a ``builtin_interfaces/Time`` in seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def stamp_time(stamp, clock):
    """Return a header stamp in seconds; an unset (zero) one: ``clock``'s now."""
    return seconds(stamp) or clock.now().nanoseconds * 1e-9


def key_value(key, value):
    """Return a KeyValue of ``value`` as text."""
    return KeyValue(key=key, value=str(value))


def pose_message(xy, cov, stamp, frame_id, yaw=None):
    """
    Return a PoseWithCovarianceStamped at x, y (and ``yaw``, rad).

    ``cov``: 2x2 over x, y; with ``yaw``, 3x3 over x, y, yaw. A yaw whose
    variance is :data:`UNKNOWN_VARIANCE` is no yaw: without one, the
    orientation is the identity and its variance :data:`UNKNOWN_VARIANCE`.
    """
    pose = PoseWithCovarianceStamped()
    pose.header.stamp = stamp
    pose.header.frame_id = frame_id
    pose.pose.pose.position.x = float(xy[0])
    pose.pose.pose.position.y = float(xy[1])
    cov = np.asarray(cov, float)
    if yaw is not None and cov[2, 2] >= UNKNOWN_VARIANCE:
        yaw = None
    covariance = [0.0] * 36
    for i in (14, 21, 28, 35):  # z, roll, pitch, yaw: unknown
        covariance[i] = UNKNOWN_VARIANCE
    rows = (0, 1) if yaw is None else (0, 1, 5)   # x, y, yaw of the 6x6
    for a, i in enumerate(rows):
        for b, j in enumerate(rows):
            covariance[6 * i + j] = float(cov[a, b])
    if yaw is None:
        pose.pose.pose.orientation.w = 1.0
    else:
        pose.pose.pose.orientation.z = math.sin(yaw / 2)
        pose.pose.pose.orientation.w = math.cos(yaw / 2)
    pose.pose.covariance = covariance
    return pose


#: Largest | |q|^2 - 1 | of an orientation taken as a rotation.
UNIT_TOLERANCE = 0.01


def pose_problem(pose):
    """Return why a geometry_msgs/Pose has no finite x, y, yaw, or None."""
    p, q = pose.position, pose.orientation
    if not (math.isfinite(p.x) and math.isfinite(p.y)):
        return f'x, y = {p.x}, {p.y} is not finite'
    norm = q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w
    if not abs(norm - 1) <= UNIT_TOLERANCE:
        return (f'orientation x, y, z, w = {q.x:g}, {q.y:g}, {q.z:g}, '
                f'{q.w:g} is not a unit quaternion')
    return None


def yaw_of(orientation):
    """Return the yaw (rad) of a quaternion (rotation about z)."""
    q = orientation
    return math.atan2(2 * (q.w * q.z + q.x * q.y),
                      1 - 2 * (q.y * q.y + q.z * q.z))


def yaw_text(pose):
    """Return a PoseWithCovarianceStamped's yaw as text: degrees or unknown."""
    if pose.pose.covariance[35] >= UNKNOWN_VARIANCE:
        return 'yaw unknown'
    return f'yaw {math.degrees(yaw_of(pose.pose.pose.orientation)):.0f} deg'


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
