"""Recording positions: the X, Y, FRAME columns and a pose topic over ROS."""

import math
from pathlib import Path
import time

from conftest import python_module, run, wait_until
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped
import numpy as np
import pytest
from rclpy.qos import (DurabilityPolicy, qos_profile_sensor_data, QoSProfile,
                       ReliabilityPolicy)
from ros_helpers import Client, NodeProcess
from sensor_msgs.msg import JointState
from wifi_place_recognition.data.fingerprints import read_fingerprints
from wifi_place_recognition.data.poses import read_poses
from wifi_place_recognition.data.recording import (FingerprintLog,
                                                   odometry_path, PoseLog,
                                                   RecordingError)
from wifi_place_recognition.ros.messages import status_values

AP1, AP2 = 'aa:bb:cc:00:00:01', 'aa:bb:cc:00:00:02'
#: The QoS of Nav2 AMCL's amcl_pose publisher.
AMCL_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


# the file ---------------------------------------------------------------------

def test_positions_are_columns_that_train_model_reads(tmp_path):
    path = tmp_path / 'rec.csv'
    log = FingerprintLog(path, positions=True)
    assert log.add([AP1], [-50.0], 0, 1, 10.0, (1.5, -2.25, 0.5, 'map')) == \
        (True, 0)
    # A new AP rewrites the file with the wider header: positions stay.
    log.add([AP1, AP2], [-55.0, -70.0], 0, 2, 11.0,
            (3.0, 4.0, -3.1416, 'map_f2'))
    log.add([AP2], [-60.0], 0, 2, 12.0,
            (-7600.125, 4864900.5, 0.0, 'map_f2'))
    assert path.read_text().splitlines()[0] == \
        f'BUILDINGID,FLOOR,TIMESTAMP,X,Y,YAW,FRAME,{AP1},{AP2}'
    fp = read_fingerprints(path)
    assert fp.position_columns == ('X', 'Y')
    np.testing.assert_array_equal(fp.position, [[1.5, -2.25], [3.0, 4.0],
                                                [-7600.125, 4864900.5]])
    assert fp.meta['FRAME'].tolist() == ['map', 'map_f2', 'map_f2']
    assert fp.meta['YAW'].astype(float).tolist() == [0.5, -3.1416, 0.0]
    assert fp.ap_ids == (AP1, AP2)
    np.testing.assert_array_equal(fp.rssi, [[-50, np.nan], [-55, -70],
                                            [np.nan, -60]])
    assert fp.notes == []           # FRAME is known metadata, not a guess
    # A frame that is a number is metadata too, never an AP.
    FingerprintLog(path, positions=True).add([AP1], [-40.0], 0, 1, 13.0,
                                             (0.0, 0.0, 0.0, '-50'))
    fp = read_fingerprints(path)
    assert fp.ap_ids == (AP1, AP2) and fp.notes == []


def test_a_torn_line_is_cut_and_positions_continue(tmp_path):
    path = tmp_path / 'rec.csv'
    FingerprintLog(path, positions=True).add([AP1], [-50.0], 1, 2, 1.0,
                                             (1.0, 2.0, 0.0, 'map'))
    with open(path, 'a') as f:
        f.write('1,2,2.000,3.0')        # killed mid-append
    log = FingerprintLog(path, positions=True)
    assert log.counts == {(1, 2): 1}
    log.add([AP1], [-51.0], 1, 2, 3.0, (5.0, 6.0, 0.0, 'map'))
    fp = read_fingerprints(path)
    np.testing.assert_array_equal(fp.position, [[1.0, 2.0], [5.0, 6.0]])


def test_a_file_keeps_the_way_it_started(tmp_path):
    plain, placed = tmp_path / 'plain.csv', tmp_path / 'placed.csv'
    FingerprintLog(plain).add([AP1], [-50.0], 0, 0, 1.0)
    FingerprintLog(placed, positions=True).add([AP1], [-50.0], 0, 0, 1.0,
                                               (1.0, 2.0, 0.0, 'map'))
    with pytest.raises(RecordingError, match='without positions .*cannot '
                       'add positions half-way'):
        FingerprintLog(plain, positions=True)
    with pytest.raises(RecordingError, match='with positions .*cannot '
                       'continue without them'):
        FingerprintLog(placed)
    # Neither file was touched.
    assert read_fingerprints(plain).position is None
    assert len(read_fingerprints(placed)) == 1


def test_a_position_needs_a_writable_frame(tmp_path):
    log = FingerprintLog(tmp_path / 'rec.csv', positions=True)
    for frame in ('', 'map,2', 'map\n', 'a"b'):
        with pytest.raises(RecordingError, match='frame_id'):
            log.add([AP1], [-50.0], 0, 0, 1.0, (1.0, 2.0, 0.0, frame))
    with pytest.raises(ValueError, match='position'):
        log.add([AP1], [-50.0], 0, 0, 1.0)
    with pytest.raises(ValueError, match='position'):
        FingerprintLog(tmp_path / 'plain.csv').add([AP1], [-50.0], 0, 0, 1.0,
                                                   (1.0, 2.0, 0.0, 'map'))
    assert not (tmp_path / 'rec.csv').exists()


def test_a_file_without_yaw_goes_on_without_it(tmp_path):
    # As an earlier recorder wrote it: X, Y, FRAME, no YAW.
    path = tmp_path / 'old.csv'
    path.write_text(f'BUILDINGID,FLOOR,TIMESTAMP,X,Y,FRAME,{AP1}\n'
                    f'0,1,1.000,1.000,2.000,map,-50\n')
    log = FingerprintLog(path, positions=True)
    assert not log.yaw and log.counts == {(0, 1): 1}
    log.add([AP1, AP2], [-51.0, -60.0], 0, 1, 2.0, (3.0, 4.0, 1.5, 'map'))
    log.add([AP2], [-61.0], 0, 1, 3.0, (5.0, 6.0, 1.5, 'map'))
    header, *rows = path.read_text().splitlines()
    assert header == f'BUILDINGID,FLOOR,TIMESTAMP,X,Y,FRAME,{AP1},{AP2}'
    assert rows[1:] == ['0,1,2.000,3.000,4.000,map,-51,-60',
                        '0,1,3.000,5.000,6.000,map,100,-61']
    fp = read_fingerprints(path)
    assert fp.ap_ids == (AP1, AP2) and 'YAW' not in fp.meta
    np.testing.assert_array_equal(fp.position, [[1, 2], [3, 4], [5, 6]])
    assert FingerprintLog(tmp_path / 'new.csv', positions=True).yaw


def test_odometry_file_is_named_after_the_output():
    assert odometry_path('/a/walk1.csv') == Path('/a/walk1.odom.csv')
    assert odometry_path('/a/walk1.CSV') == Path('/a/walk1.odom.csv')
    assert odometry_path('walk1') == Path('walk1.odom.csv')
    assert odometry_path('/a/b.c/walk') == Path('/a/b.c/walk.odom.csv')


def test_a_pose_log_writes_what_read_poses_reads_in_batches(tmp_path):
    path = tmp_path / 'walk.odom.csv'
    log = PoseLog(path)
    assert log.add(10.0, 1.0, -2.0, 3.1) is None
    assert log.add(10.1, 1.05, -2.0, -3.1) is None
    assert not path.exists()                # written by flush, in a batch
    assert log.flush() and log.written == 2 and not log.pending
    # refused: what read_poses would refuse; an equal stamp is kept
    assert log.add(math.nan, 0.0, 0.0, 0.0)[0] == 'invalid'
    assert log.add(10.2, math.inf, 0.0, 0.0)[0] == 'invalid'
    kind, why = log.add(10.05, 0.0, 0.0, 0.0)
    assert kind == 'out_of_order' and '10.050000 is earlier than the last ' \
        'recorded, 10.100000' in why
    assert log.add(10.1, 1.1, -2.0, -3.1) is None
    assert log.flush()
    np.testing.assert_allclose(read_poses(path), [
        [10.0, 1.0, -2.0, 3.1], [10.1, 1.05, -2.0, -3.1],
        [10.1, 1.1, -2.0, -3.1]])
    # A kill mid-write: the torn line is cut, the file continues, and a
    # stamp before the last in the file is refused.
    with open(path, 'a') as f:
        f.write('10.200000,1.2')
    log = PoseLog(path)
    assert log.add(10.0, 0.0, 0.0, 0.0)[0] == 'out_of_order'
    log.add(10.3, 1.3, -2.0, -3.0)
    log.flush()
    assert read_poses(path)[:, 0].tolist() == [10.0, 10.1, 10.1, 10.3]
    assert path.read_text().count('TIMESTAMP') == 1


def test_a_pose_log_keeps_rows_it_cannot_write_and_other_files_alone(
        tmp_path):
    folder = tmp_path / 'survey'
    log = PoseLog(folder / 'walk.odom.csv')
    log.add(1.0, 0.0, 0.0, 0.0)
    log.flush()
    folder.rename(tmp_path / 'moved')
    log.add(2.0, 1.0, 0.0, 0.0)
    log.add(3.0, 2.0, 0.0, 0.0)
    assert not log.flush() and isinstance(log.write_error, OSError)
    assert len(log.pending) == 2 and log.written == 1
    folder.mkdir()                  # back: a new file, with its header
    assert log.flush() and log.write_error is None
    assert read_poses(folder / 'walk.odom.csv')[:, 0].tolist() == [2.0, 3.0]
    log.add(4.0, 3.0, 0.0, 0.0)
    saved = log.save_pending(tmp_path)
    assert saved.name.startswith('walk.odom.unsaved-')
    assert saved.suffix == '.csv' and not log.pending
    assert read_poses(saved).tolist() == [[4.0, 3.0, 0.0, 0.0]]
    # Not a pose file, or no complete header: refused, left as it is.
    for text, problem in (('BUILDINGID,FLOOR\n', 'not a pose recording'),
                          ('TIMESTAMP,X', 'no complete header line'),
                          ('TIMESTAMP,X,Y,YAW\nx,1,2,3\n',
                           "row 2, column TIMESTAMP: 'x'")):
        other = tmp_path / 'other.csv'
        other.write_text(text)
        with pytest.raises(RecordingError, match=problem):
            PoseLog(other)
        assert other.read_text() == text


# the recorder over ROS ---------------------------------------------------------

def _pose(stamp, x, y, frame):
    msg = PoseWithCovarianceStamped()
    msg.header.stamp.sec = int(stamp)
    msg.header.stamp.nanosec = int(round((stamp - int(stamp)) * 1e9))
    msg.header.frame_id = frame
    msg.pose.pose.position.x = x
    msg.pose.pose.position.y = y
    msg.pose.pose.orientation.w = 1.0
    return msg


def _scan(stamp):
    msg = JointState(name=[AP1, AP2], position=[-50.0, -70.0])
    msg.header.stamp.sec = int(stamp)
    msg.header.stamp.nanosec = int(round((stamp - int(stamp)) * 1e9))
    return msg


class Progress:
    """The recorder's progress values on /diagnostics, as last published."""

    def __init__(self, ros, name):
        self.ros, self.name, self.values = ros, name, None
        self.sub = ros.create_subscription(DiagnosticArray, '/diagnostics',
                                           self._on_diagnostics, RELIABLE)

    def _on_diagnostics(self, msg):
        for status in msg.status:
            if status.name == f'{self.name}: progress':
                self.values = status_values(status)

    def count(self, key):
        """Return one counter of the last status (0 before any)."""
        return int((self.values or {}).get(key, 0))

    def deliver(self, publish, key, tries=5):
        """Publish until the recorder's counter ``key`` goes up by one."""
        before = self.count(key)
        for _ in range(tries):
            publish()
            if wait_until(lambda: self.count(key) > before, 3, self.ros):
                assert self.count(key) == before + 1, (key, self.values)
                return
        raise AssertionError(f'{key} did not move from {before}')


def test_recorder_labels_scans_with_a_fresh_pose_and_skips_stale_ones(
        ros, tmp_path):
    csv_path = tmp_path / 'survey.csv'
    progress = Progress(ros, 'pose_rec')
    recorder = NodeProcess(tmp_path, python_module(
        'ros.record_fingerprints', '--ros-args', '-p', f'output:={csv_path}',
        '-p', 'building:=0', '-p', 'floor:=1', '-p', 'pose_topic:=/amcl_pose',
        '-p', 'max_pose_age:=2.0'), 'pose_rec')
    client = Client(ros, 'pose_rec')
    # AMCL's QoS, and a best-effort volatile source: both must connect.
    amcl = ros.create_publisher(PoseWithCovarianceStamped, '/amcl_pose',
                                AMCL_QOS)
    other = ros.create_publisher(PoseWithCovarianceStamped, '/amcl_pose',
                                 qos_profile_sensor_data)

    def scan(stamp, labelled):
        before = progress.count('scans/B0F1')
        progress.deliver(lambda: client.pub.publish(_scan(stamp)),
                         'scans_received')
        assert progress.count('scans/B0F1') == before + labelled, \
            (stamp, progress.values)

    def pose(publisher, *args):
        progress.deliver(lambda: publisher.publish(_pose(*args)),
                         'poses_received')
    try:
        assert wait_until(lambda: client.pub.get_subscription_count() and
                          amcl.get_subscription_count() and
                          other.get_subscription_count() and
                          client.params.service_is_ready() and
                          progress.values, 60, ros), recorder.stop()[1]
        # Held until a pose after it, or a stamp max_pose_age later:
        scan(990.0, False)
        scan(993.0, False)      # releases the first: no pose yet
        pose(amcl, 1000.0, 1.5, -2.25, 'map')     # 993.0: 7 s before it
        pose(other, 1010.0, 7.0, 8.0, 'map_b0_f1')
        pose(amcl, 1005.0, 0.0, 0.0, '')            # no frame: rejected
        pose(other, 1012.5, math.nan, 0.0, 'map')   # not finite: rejected
        scan(1000.5, True)      # labelled with the pose of 1000.0
        scan(1005.0, False)     # 5 s from both
        scan(1009.0, True)      # the pose of 1010.0, 1 s newer
        scan(1007.5, False)     # the nearest pose is 2.5 s newer
        assert client.set_param('max_pose_age', 3.0).successful
        assert not client.set_param('max_pose_age', -1.0).successful
        scan(1007.25, True)     # 2.75 s: now fresh enough
        # Zero stamps: the time the recorder takes the message; the scan
        # waits for the pose after it (the poses' clock moved to now
        # first: a stamp a minute past every one before it is taken for a
        # clock gone wrong and labelled at once)
        pose(amcl, time.time() - 1.0, 3.0, 4.0, 'map')
        scan(0.0, False)
        pose(amcl, time.time(), 3.0, 4.0, 'map')
        assert progress.count('scans/B0F1') == 4, progress.values
    finally:
        values = progress.values
        for entity in (amcl, other):
            ros.destroy_publisher(entity)
        ros.destroy_subscription(progress.sub)
        client.close()
        code, log = recorder.stop()
    assert code == 0 and 'Traceback' not in log, log
    assert {k: values[k] for k in (
        'scans_received', 'scans_no_fresh_pose', 'scans/B0F1',
        'poses_received', 'poses_rejected', 'scans_lost')} == {
            'scans_received': '8', 'scans_no_fresh_pose': '4',
            'scans/B0F1': '4', 'poses_received': '6', 'poses_rejected': '2',
            'scans_lost': '0'}, values
    assert 'scan skipped: no pose yet on /amcl_pose' in log, log
    assert 'pose ignored: no frame_id' in log, log
    fp = read_fingerprints(csv_path)
    assert fp.notes == []
    np.testing.assert_array_equal(fp.position, [[1.5, -2.25], [7.0, 8.0],
                                                [7.0, 8.0], [3.0, 4.0]])
    assert fp.meta['FRAME'].tolist() == ['map', 'map_b0_f1', 'map_b0_f1',
                                         'map']
    assert fp.meta['TIMESTAMP'].tolist() == [1000.5, 1009.0, 1007.25, 0.0]


def test_recorder_interpolates_between_poses_and_writes_held_scans(
        ros, tmp_path):
    csv_path = tmp_path / 'survey.csv'
    progress = Progress(ros, 'interp_rec')
    recorder = NodeProcess(tmp_path, python_module(
        'ros.record_fingerprints', '--ros-args', '-p', f'output:={csv_path}',
        '-p', 'building:=0', '-p', 'floor:=1', '-p', 'pose_topic:=/amcl_pose'),
        'interp_rec')
    client = Client(ros, 'interp_rec')
    amcl = ros.create_publisher(PoseWithCovarianceStamped, '/amcl_pose',
                                AMCL_QOS)
    try:
        assert wait_until(lambda: client.pub.get_subscription_count() and
                          amcl.get_subscription_count() and
                          progress.values, 60, ros), recorder.stop()[1]
        progress.deliver(lambda: amcl.publish(_pose(2000.0, 0.0, 0.0, 'map')),
                         'poses_received')
        # a scan before the next pose waits for it, then is interpolated
        progress.deliver(lambda: client.pub.publish(_scan(2000.5)),
                         'scans_received')
        assert progress.count('scans_held') == 1, progress.values
        progress.deliver(lambda: amcl.publish(_pose(2002.0, 2.0, 4.0, 'map')),
                         'poses_received')
        assert progress.count('scans/B0F1') == 1, progress.values
        # the robot stands still (no pose after): held until the stop
        progress.deliver(lambda: client.pub.publish(_scan(2003.0)),
                         'scans_received')
        assert progress.count('scans_held') == 1, progress.values
    finally:
        ros.destroy_publisher(amcl)
        ros.destroy_subscription(progress.sub)
        client.close()
        code, log = recorder.stop()
    assert code == 0 and 'Traceback' not in log, log
    fp = read_fingerprints(csv_path)
    # interpolated a quarter of the way; then the nearest, 1 s older
    np.testing.assert_array_equal(fp.position, [[0.5, 1.0], [2.0, 4.0]])
    assert fp.meta['TIMESTAMP'].tolist() == [2000.5, 2003.0]


@pytest.mark.parametrize('positions, pose_topic, problem', [
    (False, '/amcl_pose', 'recorded without positions'),
    (True, None, 'recorded with positions')])
def test_a_file_is_continued_only_the_way_it_started(tmp_path, positions,
                                                     pose_topic, problem):
    path = tmp_path / 'rec.csv'
    FingerprintLog(path, positions).add(
        [AP1], [-50.0], 0, 0, 1.0,
        (1.0, 2.0, 0.0, 'map') if positions else None)
    before = path.read_bytes()
    result = run(python_module(
        'ros.record_fingerprints', '--ros-args', '-p', f'output:={path}',
        *(['-p', f'pose_topic:={pose_topic}'] if pose_topic else [])),
        timeout=30)
    assert result.returncode == 1, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert '[record_fingerprints]: cannot start: ' in lines[0]
    assert f'{path}: {problem}' in lines[0], lines[0]
    assert path.read_bytes() == before


def test_qos_overrides_receive_amcls_last_pose(ros, tmp_path):
    amcl = ros.create_publisher(PoseWithCovarianceStamped, '/amcl_pose',
                                AMCL_QOS)
    amcl.publish(_pose(1000.0, 1.0, 2.0, 'map'))   # before the recorder
    progress = Progress(ros, 'latched_rec')
    prefix = 'qos_overrides./amcl_pose.subscription'
    recorder = NodeProcess(tmp_path, python_module(
        'ros.record_fingerprints', '--ros-args', '-p',
        f'output:={tmp_path / "rec.csv"}', '-p', 'pose_topic:=/amcl_pose',
        '-p', f'{prefix}.reliability:=reliable',
        '-p', f'{prefix}.durability:=transient_local'), 'latched_rec')
    try:
        assert wait_until(lambda: progress.count('poses_received') == 1, 30,
                          ros), progress.values
    finally:
        ros.destroy_publisher(amcl)
        ros.destroy_subscription(progress.sub)
        code, log = recorder.stop()
    assert code == 0 and 'Traceback' not in log, log
