"""Your own building over ROS: the scanner and recorder nodes, the whole loop."""

import os
import re
import signal
import time

from conftest import (FAST, FIXTURES, process_alive, python_module, run,
                      wait_until)
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import numpy as np
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from ros_helpers import Client, NodeProcess
from sensor_msgs.msg import JointState
from signals import busy_core
from wifi_place_recognition.data.fingerprints import read_fingerprints
from wifi_place_recognition.data.recording import FingerprintLog
from wifi_place_recognition.ros.messages import status_values

RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


# nodes over ROS ----------------------------------------------------------------

def _statuses(diags, name, level=None):
    return [s for d in diags for s in d.status if s.name == f'{name}: scanner'
            and (level is None or s.level == level)]


def test_scanner_node_publishes_fresh_readings_and_reports_errors(
        ros, fake_tools, tmp_path):
    fake_tools('iw', f'cat "{FIXTURES / "iw_scan_dump_old_entries.txt"}"\n')
    scans, diags = [], []
    subs = [ros.create_subscription(JointState, 'wifi/scan', scans.append,
                                    qos_profile_sensor_data),
            ros.create_subscription(DiagnosticArray, '/diagnostics',
                                    diags.append, RELIABLE)]
    env = dict(os.environ)
    good = NodeProcess(tmp_path, python_module(
        'ros.wifi_scanner_node', '--ros-args', '-p', 'interface:=lo', '-p',
        'period:=0.2'), 'scanner_ok', env=env)
    client = Client(ros, 'scanner_ok')
    try:
        assert wait_until(lambda: scans, 20, ros), good.stop()[1]
        # Default max_age: the period + the command's run time (~0.2 s).
        assert scans[0].header.frame_id == 'lo'
        assert list(scans[0].name) == ['02:11:22:33:44:01']
        assert list(scans[0].position) == [-52.0]
        assert wait_until(lambda: _statuses(diags, 'scanner_ok'), 5, ros)
        status = _statuses(diags, 'scanner_ok')[-1]
        assert status.level == DiagnosticStatus.OK
        assert re.search(r'1 APs from iw \(7 older than 0\.\d s dropped\)',
                         status.message), status.message
        assert int(status_values(status)['stale_readings']) >= 7
        assert client.set_param('max_age', 5.0).successful
        assert not client.set_param('max_age', -1.0).successful
        scans.clear()
        assert wait_until(lambda: len(scans) >= 2, 5, ros)
        assert list(scans[-1].name) == [f'02:11:22:33:44:0{i}'
                                        for i in range(1, 5)]
    finally:
        client.close()
        code, log = good.stop()
    assert code == 0 and 'Traceback' not in log, log

    (fake_tools.folder / 'iw').unlink()          # the tool disappears
    bad = NodeProcess(tmp_path, python_module(
        'ros.wifi_scanner_node', '--ros-args', '-p', 'interface:=lo', '-p',
        'period:=0.2', '-p', 'sources:=[iw, nmcli]'), 'scanner_bad', env=env)

    def errors():
        return _statuses(diags, 'scanner_bad', DiagnosticStatus.ERROR)
    try:
        assert wait_until(lambda: len(errors()) >= 3, 20, ros)
    finally:
        code, log = bad.stop()
    assert code == 0 and 'Traceback' not in log, log
    assert 'iw is not installed' in errors()[0].message
    assert 'nmcli is not installed' in errors()[0].message
    for sub in subs:
        ros.destroy_subscription(sub)


def test_scanner_node_stays_responsive_while_iw_hangs(
        ros, fake_tools, tmp_path):
    pids = tmp_path / 'pids'
    fake_tools('iw', f'sleep 1000 & echo $! >> "{pids}"; wait\n')
    diags = []
    sub = ros.create_subscription(DiagnosticArray, '/diagnostics',
                                  diags.append, RELIABLE)
    # period 3 s: the scan command's timeout is 5 periods, 15 s, longer
    # than a parameter request lost while the service is discovered takes
    # to resend
    node = NodeProcess(tmp_path, python_module(
        'ros.wifi_scanner_node', '--ros-args', '-p', 'interface:=lo', '-p',
        'period:=3.0', '-p', 'sources:=[iw]'), 'scanner_hang')
    client = Client(ros, 'scanner_hang')

    def applied_while_hanging():
        # a status published after the new max_age took effect, while the
        # first scan still runs (no result yet): proof from the node's own
        # words, not from a wall-clock bound on a busy machine
        return [s for s in _statuses(diags, 'scanner_hang')
                if status_values(s)['max_age_s'] == '3'
                and s.message == 'no scan yet'
                and float(status_values(s)['scan_running_s']) > 0.0]
    try:
        assert wait_until(lambda: client.params.service_is_ready(), 20, ros)
        # While the first scan hangs: statuses keep coming, parameters work.
        assert wait_until(lambda: pids.exists(), 10, ros)
        assert client.set_param('max_age', 3.0).successful
        assert wait_until(applied_while_hanging, 10, ros), [
            (s.message, status_values(s)) for s in
            _statuses(diags, 'scanner_hang')]
        # The 15 s timeout (5 periods) ends it with the reason.
        assert wait_until(lambda: _statuses(
            diags, 'scanner_hang', DiagnosticStatus.ERROR), 30, ros)
        error = _statuses(diags, 'scanner_hang', DiagnosticStatus.ERROR)[0]
        assert 'took more than 15 s' in error.message
        # Stopped while the next scan hangs: a quick, clean exit.
        assert wait_until(lambda: len(pids.read_text().split()) >= 2, 15,
                          ros)
    finally:
        client.close()
        ros.destroy_subscription(sub)
        t0 = time.monotonic()
        code, log = node.stop()
    assert code == 0 and 'Traceback' not in log, log
    assert time.monotonic() - t0 < 10
    children = [int(p) for p in pids.read_text().split()]
    assert wait_until(lambda: not any(map(process_alive, children)), 5), children


class FloorSimulator:
    """Scans drawn from per-floor AP distributions (a simulated building)."""

    def __init__(self, seed=0, n_aps=40, floors=((0, 0), (0, 1), (1, 0))):
        rng = np.random.default_rng(seed)
        self.rng = rng
        self.floors = floors
        self.macs = [f'02:00:00:00:{i // 256:02x}:{i % 256:02x}'
                     for i in range(n_aps)]
        self.mean = rng.uniform(-95, -45, (len(floors), n_aps))
        self.seen = rng.random((len(floors), n_aps)) < 0.45

    def scan(self, floor_index):
        """Return (names, rssi) of one scan on floor ``floor_index``."""
        seen = self.seen[floor_index] & (self.rng.random(len(self.macs)) >
                                         0.15)
        rssi = self.mean[floor_index] + self.rng.normal(0, 4, len(self.macs))
        return ([m for m, s in zip(self.macs, seen) if s],
                [float(v) for v, s in zip(np.clip(rssi, -100, -30), seen)
                 if s])


class RecorderProgress:
    """record_fingerprints' 1 Hz progress statuses on /diagnostics."""

    def __init__(self, ros, name='record_fingerprints'):
        self.ros, self.name, self.statuses = ros, name, []
        self.sub = ros.create_subscription(
            DiagnosticArray, '/diagnostics', self._on_diagnostics, RELIABLE)

    def _on_diagnostics(self, msg):
        self.statuses += [s for s in msg.status
                          if s.name == f'{self.name}: progress']

    def recorded(self, building, floor):
        """Return the scans of (building, floor) in the file, as last reported."""
        values = status_values(self.statuses[-1]) if self.statuses else {}
        return int(values.get(f'scans/B{building}F{floor}', 0))

    def next(self, timeout=30):
        """Wait for the next progress status."""
        seen = len(self.statuses)
        assert wait_until(lambda: len(self.statuses) > seen, timeout,
                          self.ros), f'no progress status in {timeout} s'

    def record(self, client, scan, building, floor, at_least, timeout=180):
        """
        Publish ``scan()`` results until the file holds ``at_least`` of them.

        Then wait until the count stops moving (no scan still on its way, so
        changing the labels next cannot relabel one); return the count.
        """
        deadline = time.monotonic() + timeout
        while self.recorded(building, floor) < at_least:
            assert time.monotonic() < deadline, (
                f'only {self.recorded(building, floor)} of {at_least} scans '
                f'recorded in {timeout} s')
            for _ in range(10):
                client.publish(client.scan(*scan()))
                wait_until(lambda: False, 0.01, self.ros)
            self.next()
        count = None
        while count != self.recorded(building, floor):
            count = self.recorded(building, floor)
            self.next()
        return count

    def close(self):
        """Unsubscribe."""
        self.ros.destroy_subscription(self.sub)


def test_the_whole_loop_in_a_simulated_building(ros, tmp_path):
    sim = FloorSimulator()
    csv_path = tmp_path / 'building.csv'
    progress = RecorderProgress(ros)
    recorder = NodeProcess(tmp_path, python_module(
        'ros.record_fingerprints', '--ros-args', '-p', f'output:={csv_path}'),
        'record_fingerprints')
    client = Client(ros, 'record_fingerprints')
    per_floor = {}
    try:
        assert wait_until(lambda: client.pub.get_subscription_count() and
                          client.params.service_is_ready(), 60, ros), \
            recorder.stop()[1]
        for k, (building, floor) in enumerate(sim.floors):
            assert client.set_param('building', building).successful
            assert client.set_param('floor', floor).successful
            # The robot drives around the floor until 50 scans are recorded.
            per_floor[k] = progress.record(client, lambda: sim.scan(k),
                                           building, floor, 50)
    finally:
        progress.close()
        client.close()
        code, log = recorder.stop()
    assert code == 0 and 'Traceback' not in log, log
    recorded = read_fingerprints(csv_path)
    assert per_floor == {
        k: int(((recorded.building == b) & (recorded.floor == f)).sum())
        for k, (b, f) in enumerate(sim.floors)}, per_floor
    assert len(recorded) == sum(per_floor.values())

    model = tmp_path / 'building.npz'
    # A few hundred scans: many more epochs than the UJIIndoorLoc default.
    trained = run(python_module('cli.train_model', '--data', csv_path, '-o',
                                model, *FAST, '--epochs', '150'))
    assert trained.returncode == 0, trained.stderr

    node = NodeProcess(tmp_path, python_module(
        'ros.classifier_node', '--ros-args', '-p', f'model_path:={model}'),
        'classifier_node')
    client = Client(ros, 'classifier_node')
    try:
        client.wait_ready(node, sim.scan(0))
        right = 0
        for k, (building, floor) in enumerate(sim.floors):
            for _ in range(20):
                values = status_values(client.send(*sim.scan(k)))
                right += (int(values['building']), int(values['floor'])) == \
                    (building, floor)
    finally:
        client.close()
        code, log = node.stop()
    assert code == 0, log
    assert right >= 0.9 * 20 * len(sim.floors), trained.stdout


def test_recorder_keeps_every_scan_at_10_hz_on_a_busy_machine(ros, tmp_path):
    csv_path = tmp_path / 'survey.csv'
    sim = FloorSimulator(seed=2, n_aps=200)
    progress = []
    sub = ros.create_subscription(
        DiagnosticArray, '/diagnostics',
        lambda m: progress.extend(s for s in m.status
                                  if s.name == 'survey: progress'),
        RELIABLE)
    # The scanner's QoS: best effort, depth 5.
    pub = ros.create_publisher(JointState, 'wifi/scan',
                               qos_profile_sensor_data)
    recorder = NodeProcess(tmp_path, python_module(
        'ros.record_fingerprints', '--ros-args', '-p', f'output:={csv_path}',
        '-p', 'building:=0', '-p', 'floor:=1'), 'survey')
    sent = 60
    try:
        with busy_core():
            assert wait_until(lambda: pub.get_subscription_count() and
                              progress, 20, ros), recorder.stop()[1]
            t0 = time.monotonic()
            for i in range(sent):
                pub.publish(client_scan(*sim.scan(0), stamp=i + 1))
                # Scans 20-34 at once: what waits in the queue when the
                # recorder stalls 1.5 s (a slow disk, a long rewrite).
                if not 20 <= i < 35:
                    wait_until(lambda: time.monotonic() > t0 + (i + 1) / 10,
                               1, ros)

            def counted():
                values = status_values(progress[-1])
                return int(values.get('scans/B0F1', 0)) == sent
            wait_until(counted, 20, ros)
    finally:
        ros.destroy_publisher(pub)
        ros.destroy_subscription(sub)
        code, log = recorder.stop()
    assert code == 0 and 'Traceback' not in log, log
    values = status_values(progress[-1])
    assert (values['scans/B0F1'], values['scans_received'],
            values['scans_lost']) == (str(sent), str(sent), '0'), values
    assert FingerprintLog(csv_path).counts[(0, 1)] == sent


def client_scan(names, rssi, stamp):
    """Return a scan message with ``stamp`` seconds."""
    msg = JointState(name=list(names), position=list(rssi))
    msg.header.stamp.sec = stamp
    return msg


def test_killed_recorder_continues_the_same_file(ros, tmp_path):
    csv_path = tmp_path / 'rec.csv'
    sim = FloorSimulator(seed=1)
    counted, totals = [], []
    for attempt in range(2):
        progress = RecorderProgress(ros)
        recorder = NodeProcess(tmp_path, python_module(
            'ros.record_fingerprints', '--ros-args', '-p', f'output:={csv_path}',
            '-p', 'building:=0', '-p', 'floor:=1'), 'record_fingerprints')
        client = Client(ros, 'record_fingerprints')
        before = totals[-1] if totals else 0
        try:
            # The killed process's reader lingers in discovery, and the new
            # reader may not accept our first scans: publish until recorded.
            counted.append(progress.record(client, lambda: sim.scan(1), 0, 1,
                                           before + 25))
        finally:
            recorder.proc.send_signal(signal.SIGKILL)
            recorder.proc.wait()
            progress.close()
            client.close()
        totals.append(len(read_fingerprints(csv_path)))
    # Every scan the recorder reported recorded is in the file after a kill.
    assert totals == counted and totals[1] - totals[0] >= 25, (totals,
                                                               counted)
    assert FingerprintLog(csv_path).counts[(0, 1)] == totals[1]
