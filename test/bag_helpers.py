"""Write real bags from a shared robot run's CSVs, with the rosbags writer."""

import csv
import math
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores

ROBOT = Path(__file__).resolve().parents[2] / 'shared' / 'datasets' / 'robot'
RUN = ROBOT / 'b24' / 'b24test3'
TYPES = get_typestore(Stores.ROS2_JAZZY)
STORAGE = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}


def read_csv(path, until=None):
    """Return (header, float rows) of a run CSV, stamps up to ``until``."""
    with open(path) as f:
        rows = csv.reader(f)
        header = next(rows)
        out = [[float(v) if v else math.nan for v in row] for row in rows]
    return header, [r for r in out if until is None or r[0] <= until]


def _header(stamp, frame):
    t = TYPES.types
    ns = round(stamp * 1e9)
    return t['std_msgs/msg/Header'](
        stamp=t['builtin_interfaces/msg/Time'](sec=ns // 10**9,
                                               nanosec=ns % 10**9),
        frame_id=frame), ns


def _pose(x, y, yaw):
    t = TYPES.types
    return t['geometry_msgs/msg/Pose'](
        position=t['geometry_msgs/msg/Point'](x=x, y=y, z=0.0),
        orientation=t['geometry_msgs/msg/Quaternion'](
            x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)))


def scan_message(stamp, names, rssi):
    """Return a wifi/scan JointState."""
    header, ns = _header(stamp, 'wifi')
    empty = np.zeros(0, np.float64)
    return TYPES.types['sensor_msgs/msg/JointState'](
        header=header, name=list(names),
        position=np.asarray(rssi, np.float64), velocity=empty,
        effort=empty), ns


def odometry_message(stamp, x, y, yaw):
    """Return an odom Odometry."""
    t = TYPES.types
    header, ns = _header(stamp, 'odom')
    zero = t['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.0)
    return t['nav_msgs/msg/Odometry'](
        header=header, child_frame_id='base_link',
        pose=t['geometry_msgs/msg/PoseWithCovariance'](
            pose=_pose(x, y, yaw), covariance=np.zeros(36)),
        twist=t['geometry_msgs/msg/TwistWithCovariance'](
            twist=t['geometry_msgs/msg/Twist'](linear=zero, angular=zero),
            covariance=np.zeros(36))), ns


def pose_message(stamp, x, y, yaw, cxx, cxy, cyy, cyawyaw):
    """Return an amcl_pose PoseWithCovarianceStamped."""
    t = TYPES.types
    header, ns = _header(stamp, 'map')
    cov = np.zeros(36)
    cov[0], cov[1], cov[6], cov[7], cov[35] = cxx, cxy, cxy, cyy, cyawyaw
    return t['geometry_msgs/msg/PoseWithCovarianceStamped'](
        header=header, pose=t['geometry_msgs/msg/PoseWithCovariance'](
            pose=_pose(x, y, yaw), covariance=cov)), ns


def run_messages(run=RUN, seconds=None):
    """
    Return [(topic, type, message, ns)] of a run, in stamp order.

    ``seconds``: the first seconds of the run only (from its first
    odometry stamp).
    """
    _, odom = read_csv(run / 'odom.csv')
    until = None if seconds is None else odom[0][0] + seconds
    odom = [r for r in odom if until is None or r[0] <= until]
    header, scans = read_csv(run / 'scans.csv', until)
    aps = [j for j, h in enumerate(header) if ':' in h]
    _, poses = read_csv(run / 'poses.csv', until)
    out = []
    for row in scans:
        heard = [j for j in aps if row[j] != 100]
        out.append(('/wifi/scan', 'sensor_msgs/msg/JointState') +
                   scan_message(row[0], [header[j] for j in heard],
                                [row[j] for j in heard]))
    out += [('/odom', 'nav_msgs/msg/Odometry') + odometry_message(*r)
            for r in odom]
    out += [('/amcl_pose', 'geometry_msgs/msg/PoseWithCovarianceStamped') +
            pose_message(*r) for r in poses]
    return sorted(out, key=lambda m: m[3])


def write_bag(path, messages, storage='mcap'):
    """Write ``messages`` (from :func:`run_messages`) as a rosbag2 folder."""
    connections = {}
    with Writer(path, version=9, storage_plugin=STORAGE[storage]) as writer:
        for topic, msgtype, msg, ns in messages:
            if topic not in connections:
                connections[topic] = writer.add_connection(
                    topic, msgtype, typestore=TYPES)
            writer.write(connections[topic], ns,
                         TYPES.serialize_cdr(msg, msgtype))
    return Path(path)


def write_ros1_bag(path, messages):
    """Write ``messages`` as a ROS 1 bag (headers get a ``seq``)."""
    from rosbags.rosbag1 import Writer as Ros1Writer
    ros1 = get_typestore(Stores.ROS1_NOETIC)
    connections = {}
    with Ros1Writer(path) as writer:
        for topic, msgtype, msg, ns in messages:
            if topic not in connections:
                connections[topic] = writer.add_connection(
                    topic, msgtype, typestore=ros1)
            fields = dict(vars(msg), header=ros1.types['std_msgs/msg/Header'](
                seq=0, stamp=msg.header.stamp,
                frame_id=msg.header.frame_id))
            writer.write(connections[topic], ns, ros1.serialize_ros1(
                ros1.types[msgtype](**fields), msgtype))
    return Path(path)


def relabelled(run, folder):
    """
    Return a copy of a run's CSVs in ``folder``, its scans labelled by the rule.

    The shared runs' ``scans.csv`` interpolates between the poses around
    every scan; the package's rule (core.pose_label) does so within
    max_pose_age and takes the nearest pose otherwise, as a bag of the
    run is labelled.
    """
    from wifi_place_recognition.data.bags import pose_labels
    from wifi_place_recognition.data.poses import read_poses
    folder = Path(folder)
    folder.mkdir(parents=True)
    for name in ('odom.csv', 'poses.csv', 'initial_pose.yaml'):
        if (run / name).exists():
            (folder / name).write_bytes((run / name).read_bytes())
    header, *rows = (run / 'scans.csv').read_text().splitlines()
    cells = [row.split(',') for row in rows]
    xy, yaw = pose_labels(read_poses(run / 'poses.csv'),
                          np.array([float(c[0]) for c in cells]))
    names = header.split(',')
    at = [names.index(c) for c in ('X', 'Y', 'YAW')]
    for c, label in zip(cells, np.column_stack([xy, yaw])):
        for j, value in zip(at, label):
            c[j] = '' if np.isnan(value) else f'{value:.6f}'
    (folder / 'scans.csv').write_text(
        '\n'.join([header] + [','.join(c) for c in cells]) + '\n')
    return folder
