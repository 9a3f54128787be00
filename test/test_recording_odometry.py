"""
A survey with the localiser and odometry running, recorded over ROS.

The recorder gets scans, AMCL-like poses and odometry of a drive whose
odometry loses 1.4 degrees per metre; its two files are then read as they
are by ``train_model`` and ``fit_odometry``, which must find that drift.
"""

import math
import re
import time

from conftest import FAST, python_module, run, wait_until
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
import numpy as np
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_helpers import NodeProcess
from sensor_msgs.msg import JointState
from test_recording_poses import Progress
from wifi_place_recognition.data.fingerprints import read_fingerprints
from wifi_place_recognition.data.poses import read_poses

RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
T0 = 1000.0
DRIFT_DEG_PER_M = 1.4
#: AP positions (m) of the simulated building.
APS = {f'aa:bb:cc:00:00:0{i}': xy for i, xy in enumerate(
    [(0, 0), (15, 0), (0, 15), (15, 15), (7, 7)], start=1)}


def drive(seconds=40, rate=5, speed=0.5, turn=0.05, yaw=2.5):
    """
    Return (truth, odometry) rows of stamp, x, y, yaw at ``rate`` Hz.

    The robot drives an arc (its yaw passes pi); the odometry starts at
    0, 0 with another heading and loses DRIFT_DEG_PER_M.
    """
    dt, step = 1.0 / rate, speed / rate
    drift = math.radians(DRIFT_DEG_PER_M)
    truth, odo = [(T0, 2.0, 2.0, yaw)], [(T0, 0.0, 0.0, 0.3)]
    for k in range(1, seconds * rate):
        t, x, y, a = truth[-1]
        _, u, v, b = odo[-1]
        truth.append((T0 + k * dt, x + step * math.cos(a + turn * dt / 2),
                      y + step * math.sin(a + turn * dt / 2), a + turn * dt))
        b2 = b + turn * dt - drift * step
        odo.append((T0 + k * dt, u + step * math.cos((b + b2) / 2),
                    v + step * math.sin((b + b2) / 2), b2))
    return np.array(truth), np.array(odo)


def _stamped(msg, stamp):
    msg.header.stamp.sec = int(stamp)
    msg.header.stamp.nanosec = int(round((stamp - int(stamp)) * 1e9))
    return msg


def _set_pose(pose, x, y, yaw, q=None):
    pose.position.x, pose.position.y = float(x), float(y)
    o = pose.orientation
    o.x, o.y, o.z, o.w = q or (0.0, 0.0, math.sin(yaw / 2),
                               math.cos(yaw / 2))


def amcl_pose(t, x, y, yaw, q=None):
    """Return the localiser's pose at ``t`` (``q``: its quaternion)."""
    msg = _stamped(PoseWithCovarianceStamped(), t)
    msg.header.frame_id = 'map'
    _set_pose(msg.pose.pose, x, y, yaw, q)
    return msg


def odometry(t, x, y, yaw, q=None):
    """Return an odometry message (``q``: its quaternion, if not yaw's)."""
    msg = _stamped(Odometry(), t)
    msg.header.frame_id, msg.child_frame_id = 'odom', 'base_link'
    _set_pose(msg.pose.pose, x, y, yaw, q)
    return msg


def scan(t, x, y):
    """Return the scan heard at x, y (log-distance path loss)."""
    rssi = [round(-40 - 25 * math.log10(max(math.dist((x, y), xy), 1.0)))
            for xy in APS.values()]
    return _stamped(JointState(name=list(APS), position=[float(r) for r in
                                                         rssi]), t)


def test_a_survey_with_odometry_is_what_fit_odometry_reads(ros, tmp_path):
    truth, odo = drive()
    at_scans = truth[::5]                   # one scan a second
    output = tmp_path / 'walk1.csv'
    progress = Progress(ros, 'odom_rec')
    # The subscriptions made reliable: every message must reach the files
    # (best effort, the default, may drop one under load, by design).
    reliable = [a for topic in ('/wifi/scan', '/amcl_pose', '/odom') for a in
                ('-p', f'qos_overrides.{topic}.subscription.reliability:='
                 f'reliable')]
    recorder = NodeProcess(tmp_path, python_module(
        'ros.record_fingerprints', '--ros-args', '-p', f'output:={output}',
        '-p', 'building:=0', '-p', 'floor:=0', '-p', 'pose_topic:=/amcl_pose',
        '-p', 'odom_topic:=/odom', *reliable), 'odom_rec')
    scans = ros.create_publisher(JointState, 'wifi/scan', RELIABLE)
    poses = ros.create_publisher(PoseWithCovarianceStamped, '/amcl_pose',
                                 RELIABLE)
    odom = ros.create_publisher(Odometry, '/odom', RELIABLE)

    def publish(publisher, messages, key, total):
        for msg in messages:
            publisher.publish(msg)
            time.sleep(0.005)
        assert wait_until(lambda: progress.count(key) == total, 30, ros), \
            (key, total, progress.values)
    try:
        assert wait_until(lambda: all(p.get_subscription_count() for p in
                                      (scans, poses, odom)) and
                          progress.values, 60, ros), recorder.stop()[1]
        # One more pose, at the first scan, with no rotation: rejected.
        publish(poses, [amcl_pose(*row) for row in at_scans] + [amcl_pose(
            T0, 5.0, 5.0, 0.0, q=(0.0, 0.0, 0.0, 0.0))],
            'poses_received', len(at_scans) + 1)
        publish(odom, [odometry(*row) for row in odo], 'odometry_received',
                len(odo))
        t = odo[-1, 0]
        faults = [odometry(t + 0.1, math.nan, 0.0, 0.0),
                  odometry(t + 0.2, 1.0, 1.0, 0.0, q=(0.0, 0.0, 0.0, 0.0)),
                  odometry(T0 + 5.0, 1.0, 1.0, 0.0)]    # back in time
        publish(odom, faults, 'odometry_received', len(odo) + 3)
        before = time.time()
        publish(odom, [odometry(0.0, 9.0, 9.0, 1.0)], 'odometry_received',
                len(odo) + 4)                           # zero stamp: now
        after = time.time()
        publish(scans, [scan(t, x, y) for t, x, y, _ in at_scans],
                'scans/B0F0', len(at_scans))
        assert wait_until(lambda: progress.count('odometry_written') ==
                          len(odo) + 1, 10, ros), progress.values
        values = dict(progress.values)
    finally:
        for publisher in (scans, poses, odom):
            ros.destroy_publisher(publisher)
        ros.destroy_subscription(progress.sub)
        code, log = recorder.stop()
    assert code == 0 and 'Traceback' not in log, log
    assert {k: int(values[k]) for k in (
        'odometry_received', 'odometry_written', 'odometry_invalid',
        'odometry_out_of_order', 'odometry_waiting', 'odometry_write_errors',
        'scans_no_fresh_pose', 'poses_rejected')} == {
            'odometry_received': len(odo) + 4,
            'odometry_written': len(odo) + 1, 'odometry_invalid': 2,
            'odometry_out_of_order': 1, 'odometry_waiting': 0,
            'odometry_write_errors': 0, 'scans_no_fresh_pose': 0,
            'poses_rejected': 1}, values
    assert f'odometry from /odom to {tmp_path / "walk1.odom.csv"}' in log
    assert 'odometry pose skipped: x, y = nan, 0.0 is not finite' in log, log
    assert 'pose ignored: orientation x, y, z, w = 0, 0, 0, 0 is not a unit ' \
        'quaternion' in log, log
    # The scans: X, Y and the yaw of each scan's pose, wrapped to [-pi, pi].
    assert output.read_text().startswith(
        'BUILDINGID,FLOOR,TIMESTAMP,X,Y,YAW,FRAME,')
    fp = read_fingerprints(output)
    assert fp.notes == [] and fp.ap_ids == tuple(APS)
    np.testing.assert_allclose(fp.meta['TIMESTAMP'].astype(float),
                               at_scans[:, 0])
    np.testing.assert_allclose(fp.position, at_scans[:, 1:3], atol=5e-4)
    wrapped = np.angle(np.exp(1j * at_scans[:, 3]))
    assert (wrapped < 0).any()              # the drive turned past pi
    np.testing.assert_allclose(fp.meta['YAW'].astype(float), wrapped,
                               atol=5e-5)
    # The odometry: every valid message, in order, the zero stamp as now.
    recorded = read_poses(tmp_path / 'walk1.odom.csv')
    assert len(recorded) == len(odo) + 1
    np.testing.assert_allclose(recorded[:-1, 0], odo[:, 0], atol=1e-6)
    np.testing.assert_allclose(recorded[:-1, 1:3], odo[:, 1:3], atol=5e-5)
    np.testing.assert_allclose(np.angle(np.exp(1j * recorded[:-1, 3])),
                               np.angle(np.exp(1j * odo[:, 3])), atol=1e-6)
    assert before - 1 <= recorded[-1, 0] <= after + 1
    assert recorded[-1, 1:].tolist() == [9.0, 9.0, 1.0]
    # Both files as they are: a model, then the odometry's drift fitted.
    model = tmp_path / 'walk1.npz'
    result = run(python_module('cli.train_model', '--data', output, '-o',
                               model, *FAST))
    assert result.returncode == 0, result.stderr
    result = run(python_module('cli.fit_odometry', '--model', model,
                               '--data', output, '--odometry',
                               tmp_path / 'walk1.odom.csv'))
    assert result.returncode == 0, result.stderr
    drift = float(re.search(r'heading drift ([-+.\d]+) deg/m',
                            result.stdout).group(1))
    assert abs(drift - DRIFT_DEG_PER_M) < 0.02, result.stdout


def test_an_odometry_file_that_is_not_ours_stops_the_start(tmp_path):
    (tmp_path / 'walk1.odom.csv').write_text('BUILDINGID,FLOOR\n0,1\n')
    result = run(python_module(
        'ros.record_fingerprints', '--ros-args', '-p',
        f'output:={tmp_path / "walk1.csv"}', '-p', 'odom_topic:=odom'),
        timeout=30)
    assert result.returncode == 1, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert (f'[record_fingerprints]: cannot start: {tmp_path}/walk1.odom.csv'
            f': not a pose recording (the header must be TIMESTAMP,X,Y,YAW)'
            ) in lines[0], lines[0]
    assert (tmp_path / 'walk1.odom.csv').read_text() == \
        'BUILDINGID,FLOOR\n0,1\n'
