"""The recorder when it cannot write: one line at start-up, nothing lost."""

import os
from pathlib import Path

from conftest import python_module, run, wait_until
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
import pytest
from rclpy.qos import qos_profile_sensor_data
from ros_helpers import NodeProcess, RELIABLE
from sensor_msgs.msg import JointState
from wifi_place_recognition.data.poses import read_poses
from wifi_place_recognition.ros.messages import status_values

AP1, AP2, AP3 = 'aa:bb:cc:00:00:01', 'aa:bb:cc:00:00:02', 'aa:bb:cc:00:00:03'


@pytest.mark.parametrize('where, reason', [
    ('a_file/rec.csv', 'cannot create the folder {folder} ({tmp}/a_file is '
     'not a folder)'),
    ('a_file/sub/rec.csv', 'cannot create the folder {folder} ({tmp}/a_file '
     'is not a folder)'),
    ('/sys/rec.csv', 'cannot write in the folder /sys (')])
def test_an_output_folder_that_cannot_be_written_is_one_error_line(
        tmp_path, where, reason):
    (tmp_path / 'a_file').write_text('')
    output = tmp_path / where
    result = run(python_module('ros.record_fingerprints', '--ros-args',
                               '-p', f'output:={output}'), timeout=30)
    assert result.returncode == 1, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    reason = reason.format(folder=output.parent, tmp=tmp_path)
    assert (f'] [record_fingerprints]: cannot start: output {output}: '
            f'{reason}') in lines[0], result.stderr


def test_missing_output_folders_are_created(ros, tmp_path):
    output = tmp_path / 'walks' / 'new' / 'walk1.csv'
    proc = NodeProcess(tmp_path, python_module(
        'ros.record_fingerprints', '--ros-args', '-p', f'output:={output}',
        '-p', 'building:=0', '-p', 'floor:=1'), 'recorder_new_folder')
    recorder = Recorder(ros, 'recorder_new_folder')
    try:
        assert wait_until(lambda: recorder.status is not None, 30, ros), \
            proc.stop()[1]
        recorder.send(1, [AP1])
    finally:
        recorder.close()
        code, log = proc.stop()
    assert code == 0, log
    assert f'recording to {output} ' in log, log
    assert output.read_text().splitlines()[1].startswith('0,1,1.000,'), log


class Recorder:
    """The test's side: sends scans, follows the progress status."""

    def __init__(self, ros, name):
        self.ros, self.name, self.status = ros, name, None
        self.pub = ros.create_publisher(JointState, 'wifi/scan', RELIABLE)
        self.sub = ros.create_subscription(DiagnosticArray, '/diagnostics',
                                           self._on_diagnostics, RELIABLE)

    def _on_diagnostics(self, msg):
        for status in msg.status:
            if status.name == f'{self.name}: progress':
                self.status = status

    def value(self, key):
        """Return one value of the last status ('' before any)."""
        return status_values(self.status).get(key, '') if self.status else ''

    def send(self, stamp, names):
        """Publish a scan until the recorder counts it (best effort)."""
        before = int(self.value('scans/B0F1') or 0)
        msg = JointState(name=names, position=[-60.0] * len(names))
        msg.header.stamp.sec = stamp
        for _ in range(5):
            self.pub.publish(msg)
            if wait_until(lambda: int(self.value('scans/B0F1') or 0) > before,
                          3, self.ros):
                return
        raise AssertionError(f'scan {stamp} not recorded: {self.status}')

    def wait(self, level, waiting):
        """Wait for a status of ``level`` with ``waiting`` scans in memory."""
        assert wait_until(lambda: self.status is not None and
                          self.status.level == level and
                          self.value('scans_waiting') == str(waiting),
                          10, self.ros), self.status

    def close(self):
        """Destroy the publisher and subscription."""
        self.ros.destroy_publisher(self.pub)
        self.ros.destroy_subscription(self.sub)


def _stamps(path):
    """Return the TIMESTAMPs of a recording; every row as wide as its header."""
    header, *rows = Path(path).read_text().splitlines()
    width = len(header.split(','))
    assert all(len(row.split(',')) == width for row in rows), path
    return [float(row.split(',')[2]) for row in rows]


def test_a_folder_that_disappears_loses_no_scan_and_the_node_runs_on(
        ros, tmp_path):
    survey = tmp_path / 'survey'
    survey.mkdir()
    tmp = tmp_path / 'tmp'
    tmp.mkdir()
    recorder = NodeProcess(tmp_path, python_module(
        'ros.record_fingerprints', '--ros-args', '-p',
        f'output:={survey / "rec.csv"}', '-p', 'building:=0', '-p',
        'floor:=1'), 'lost_folder', env=dict(os.environ, TMPDIR=str(tmp)))
    side = Recorder(ros, 'lost_folder')
    try:
        assert wait_until(lambda: side.pub.get_subscription_count() and
                          side.status, 30, ros), recorder.stop()[1]
        for stamp in (1, 2, 3):
            side.send(stamp, [AP1])
        assert _stamps(survey / 'rec.csv') == [1, 2, 3]
        # The folder is moved away: scans wait in memory, status ERROR.
        survey.rename(tmp_path / 'survey.moved')
        for stamp, names in ((4, [AP1]), (5, [AP1, AP2]), (6, [AP2])):
            side.send(stamp, names)
        side.wait(DiagnosticStatus.ERROR, 3)
        assert 'cannot write: ' in side.status.message
        assert side.value('write_errors') == '1'
        # It comes back: the waiting scans are written (a new AP on the way).
        survey.mkdir()
        side.wait(DiagnosticStatus.OK, 0)
        assert _stamps(survey / 'rec.csv') == [4, 5, 6]
        assert (survey / 'rec.csv').read_text().startswith(
            f'BUILDINGID,FLOOR,TIMESTAMP,{AP1},{AP2}\n')
        # A file where the folder was, until shutdown.
        survey.rename(tmp_path / 'survey.second')
        survey.write_text('')
        for stamp, names in ((7, [AP3]), (8, [AP1])):
            side.send(stamp, names)
        side.wait(DiagnosticStatus.ERROR, 2)
        assert side.value('write_errors') == '2'
        assert recorder.proc.poll() is None
    finally:
        side.close()
        code, log = recorder.stop()
    assert code == 0 and 'Traceback' not in log, log
    assert log.count('cannot write ') >= 2, log
    assert 'works again' in log, log
    saved, = tmp.glob('rec.unsaved-*.csv')
    assert f'the 2 scans not in it are saved in {saved}' in log, log
    assert _stamps(saved) == [7, 8]
    assert _stamps(tmp_path / 'survey.moved' / 'rec.csv') == [1, 2, 3]
    assert _stamps(tmp_path / 'survey.second' / 'rec.csv') == [4, 5, 6]


def _odometry(stamp):
    msg = Odometry()
    msg.header.stamp.sec = stamp
    msg.pose.pose.position.x = float(stamp)
    msg.pose.pose.orientation.w = 1.0
    return msg


def test_odometry_that_cannot_be_written_waits_and_none_is_lost(
        ros, tmp_path):
    survey = tmp_path / 'survey'
    survey.mkdir()
    tmp = tmp_path / 'tmp'
    tmp.mkdir()
    recorder = NodeProcess(tmp_path, python_module(
        'ros.record_fingerprints', '--ros-args', '-p',
        f'output:={survey / "walk.csv"}', '-p', 'odom_topic:=odom'),
        'lost_odometry', env=dict(os.environ, TMPDIR=str(tmp)))
    side = Recorder(ros, 'lost_odometry')
    odom = ros.create_publisher(Odometry, 'odom', qos_profile_sensor_data)

    def send(*stamps):
        for stamp in stamps:
            before = int(side.value('odometry_received') or 0)
            for _ in range(5):
                odom.publish(_odometry(stamp))
                if wait_until(lambda: int(side.value('odometry_received') or
                                          0) > before, 3, ros):
                    break
            else:
                raise AssertionError(f'odometry {stamp} not received')

    def wait(level, waiting):
        assert wait_until(lambda: side.status is not None and
                          side.status.level == level and
                          side.value('odometry_waiting') == str(waiting),
                          10, ros), side.status
    try:
        assert wait_until(lambda: odom.get_subscription_count() and
                          side.status, 30, ros), recorder.stop()[1]
        send(1, 2, 3)
        wait(DiagnosticStatus.OK, 0)
        assert side.value('odometry_written') == '3'
        # The folder is moved away: the poses wait in memory, status ERROR.
        survey.rename(tmp_path / 'survey.moved')
        send(4, 5, 6)
        wait(DiagnosticStatus.ERROR, 3)
        assert 'cannot write walk.odom.csv: ' in side.status.message
        assert side.value('odometry_write_errors') == '1'
        # It comes back: the waiting poses are written to a new file.
        survey.mkdir()
        wait(DiagnosticStatus.OK, 0)
        assert side.value('odometry_written') == '6'
        # A file where the folder was, until shutdown.
        survey.rename(tmp_path / 'survey.second')
        survey.write_text('')
        send(7, 8)
        wait(DiagnosticStatus.ERROR, 2)
        assert side.value('odometry_write_errors') == '2'
        assert recorder.proc.poll() is None
    finally:
        ros.destroy_publisher(odom)
        side.close()
        code, log = recorder.stop()
    assert code == 0 and 'Traceback' not in log, log
    assert 'works again: the odometry poses kept in memory' in log, log
    saved, = tmp.glob('walk.odom.unsaved-*.csv')
    assert f'the 2 odometry poses not in it are saved in {saved}' in log, log

    def stamps(path):
        return read_poses(path)[:, 0].tolist()
    assert stamps(tmp_path / 'survey.moved' / 'walk.odom.csv') == [1, 2, 3]
    assert stamps(tmp_path / 'survey.second' / 'walk.odom.csv') == [4, 5, 6]
    assert stamps(saved) == [7, 8]
    assert read_poses(saved)[:, 1].tolist() == [7.0, 8.0]
