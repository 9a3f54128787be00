"""Conversions between ROS messages and plain Python values."""

from sensor_msgs.msg import JointState
import numpy as np


def seconds(stamp):
    """Return a ``builtin_interfaces/Time`` in seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def stamp_time(stamp, clock):
    """Return a header stamp in seconds; an unset (zero) one: ``clock``'s now."""
    return seconds(stamp) or clock.now().nanoseconds * 1e-9


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
