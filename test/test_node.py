"""classifier_node over real ROS 2: node and test client in separate processes."""

import csv
import os
import signal
import subprocess

from conftest import dataset_file, python_module, run, wait_until
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
import numpy as np
import pytest
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from wifi_place_recognition.artifact import load_model
from wifi_place_recognition.fingerprints import read_fingerprints
from wifi_place_recognition.replay_scans import status_values

RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)


class NodeProcess:
    """A classifier_node in its own process, stopped with SIGINT."""

    def __init__(self, tmp_path, argv, name='classifier_node'):
        self.log = tmp_path / f'{name}.log'
        self.proc = subprocess.Popen(
            argv + ['--ros-args', '-r', f'__node:={name}'],
            stdout=subprocess.DEVNULL, stderr=self.log.open('w'),
            env=os.environ.copy())
        self.name = name

    def stop(self, sig=signal.SIGINT):
        """Stop the node; return (exit code, its log)."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            code = self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            code = 'hung'
        return code, self.log.read_text()


class Client:
    """The test's side: publishes scans, collects answers by stamp."""

    def __init__(self, node, node_name='classifier_node'):
        self.node = node
        self.pub = node.create_publisher(JointState, 'wifi/scan', RELIABLE)
        self.answers = {}
        self.health = []
        self.subs = [
            node.create_subscription(DiagnosticArray, f'/{node_name}/place',
                                     self._on_place, RELIABLE),
            node.create_subscription(DiagnosticArray, '/diagnostics',
                                     self._on_diag, RELIABLE)]
        self.params = node.create_client(
            SetParameters, f'/{node_name}/set_parameters')
        self.seq = 0

    def _on_place(self, msg):
        self.answers[msg.header.stamp.sec] = msg

    def _on_diag(self, msg):
        self.health += [s for s in msg.status if s.name.endswith('health')]

    def wait_ready(self, proc, probe, timeout=20):
        """Wait for the node, then send ``probe`` scans until one is answered.

        Discovery is not symmetric: the first scans after this side sees the
        node may not yet be accepted by the node's reader.
        """
        assert wait_until(lambda: self.pub.get_subscription_count() > 0 and
                          self.subs[0].get_publisher_count() > 0 and
                          self.params.service_is_ready(), timeout,
                          self.node), proc.stop()[1]
        for _ in range(50):
            try:
                return self.send(*probe, timeout=0.2)
            except AssertionError:
                pass
        raise AssertionError(proc.stop()[1])

    def send(self, names, rssi, frame_id='wlan0', timeout=5.0):
        """Publish one scan; return the node's DiagnosticStatus for it."""
        self.seq += 1
        msg = JointState(name=list(names), position=[float(v) for v in rssi])
        msg.header.stamp.sec = self.seq
        msg.header.frame_id = frame_id
        self.pub.publish(msg)
        seq = self.seq
        assert wait_until(lambda: seq in self.answers, timeout, self.node)
        return self.answers[seq].status[0]

    def set_param(self, name, value):
        """Set one parameter over the service; return SetParametersResult."""
        kind = {float: ParameterType.PARAMETER_DOUBLE,
                int: ParameterType.PARAMETER_INTEGER,
                str: ParameterType.PARAMETER_STRING}[type(value)]
        field = {float: 'double_value', int: 'integer_value',
                 str: 'string_value'}[type(value)]
        pv = ParameterValue(type=kind, **{field: value})
        future = self.params.call_async(SetParameters.Request(
            parameters=[Parameter(name=name, value=pv)]))
        rclpy.spin_until_future_complete(self.node, future, timeout_sec=5)
        return future.result().results[0]

    def close(self):
        """Destroy the publisher, subscriptions and client."""
        for entity in self.subs:
            self.node.destroy_subscription(entity)
        self.node.destroy_publisher(self.pub)
        self.node.destroy_client(self.params)


@pytest.fixture(scope='module')
def ros():
    rclpy.init()
    node = rclpy.create_node('test_client')
    yield node
    node.destroy_node()
    rclpy.try_shutdown()


@pytest.fixture
def running(ros, synthetic, tmp_path, request):
    """Start a node on the synthetic model; yield (client, proc, model)."""
    _, model_path = synthetic
    name = f'classifier_{request.node.name[5:25]}'.replace('[', '_')
    proc = NodeProcess(tmp_path, python_module(
        'classifier_node', '--ros-args', '-p', f'model_path:={model_path}',
        '-p', 'max_aps:=50'), name)
    client = Client(ros, name)
    model = load_model(model_path)
    client.wait_ready(proc, (model.ap_ids[:6], [-60.0] * 6))
    yield client, proc, model
    client.close()
    code, log = proc.stop()
    assert code == 0 and 'Traceback' not in log, log


def test_answers_match_the_model_and_carry_the_contract(running, synthetic):
    client, proc, model = running
    fp = read_fingerprints(synthetic[0])
    for row in range(0, len(fp), 37):
        detected = np.flatnonzero(np.isfinite(fp.rssi[row]))
        # MACs in another spelling: lower case, '-' separators.
        names = [model.ap_ids[j].lower().replace(':', '-') for j in detected]
        status = client.send(names + ['de:ad:be:ef:00:01'],
                             list(fp.rssi[row, detected]) + [-50.0])
        building, floor, confidence, proba = model.predict(fp.rssi[row:row + 1])
        values = status_values(status)
        expected = DiagnosticStatus.OK if confidence[0] >= 0.5 else \
            DiagnosticStatus.WARN
        assert status.level == expected
        assert status.name == f'{proc.name}: place'
        assert status.hardware_id == 'wlan0'
        assert (int(values['building']), int(values['floor'])) == \
            (building[0], floor[0])
        assert int(values['known_aps']) == len(detected)
        assert int(values['unknown_aps']) == 1
        assert float(values['latency_ms']) >= 0
        probs = [float(values[f'prob/{n}']) for n in model.class_names]
        np.testing.assert_allclose(probs, proba[0], atol=1e-6)
        assert status.message.startswith(
            f'building {building[0]}, floor {floor[0]} (p=')


def test_duplicate_ap_keeps_the_strongest_reading(running):
    client, _, model = running
    ap = model.ap_ids[0]
    strong = client.send([ap, ap.lower(), model.ap_ids[1]], [-90, -40, -60])
    once = client.send([ap, model.ap_ids[1]], [-40, -60])
    assert status_values(strong) | {'latency_ms': 0} == \
        status_values(once) | {'latency_ms': 0}
    assert status_values(strong)['known_aps'] == '2'


BAD_SCANS = [
    ('length_mismatch', ['a', 'b'], [-50.0]),
    ('empty', [], []),
    ('oversize', [f'x{i}' for i in range(51)], [-50.0] * 51),
    ('non_finite', ['AA:BB:CC:00:00:00'], [float('nan')]),
    ('non_finite', ['AA:BB:CC:00:00:00'], [float('-inf')]),
    ('implausible_rssi', ['AA:BB:CC:00:00:00'], [-500.0]),
    ('implausible_rssi', ['AA:BB:CC:00:00:00'], [1e9]),
    ('no_known_ap', ['11:22:33:44:55:66'], [-50.0]),
]


def test_bad_scans_are_rejected_counted_and_survived(running):
    client, _, model = running
    for reason, names, rssi in BAD_SCANS:
        status = client.send(names, rssi)
        assert status.level == DiagnosticStatus.ERROR, reason
        assert status_values(status)['reason'] == reason
    good = client.send(model.ap_ids[:6], [-60.0] * 6)
    assert good.level != DiagnosticStatus.ERROR

    def counted():
        if not client.health:
            return None
        values = status_values(client.health[-1])
        return values if values['scans_rejected'] == str(len(BAD_SCANS)) \
            else None
    client.health.clear()
    values = wait_until(counted, 5, client.node)
    assert values, client.health[-1:] and status_values(client.health[-1])
    assert values['rejected/implausible_rssi'] == '2'
    assert values['rejected/non_finite'] == '2'
    counts = {k: int(values[f'scans_{k}'])
              for k in ('received', 'answered', 'rejected', 'dropped')}
    assert counts['received'] == \
        counts['answered'] + counts['rejected'] + counts['dropped']
    assert counts['answered'] >= 2      # the probe and the good scan


def test_thresholds_change_at_runtime_and_bad_values_are_refused(running):
    client, _, model = running
    names, rssi = model.ap_ids[:6], [-60.0] * 6
    assert client.set_param('min_known_aps', 7).successful
    warn = client.send(names, rssi)
    assert warn.level == DiagnosticStatus.WARN
    assert 'only 6 known APs' in warn.message
    assert client.set_param('min_known_aps', 1).successful
    assert client.set_param('min_confidence', 0.0).successful
    assert client.send(names, rssi).level == DiagnosticStatus.OK
    assert client.set_param('min_confidence', 1.0).successful
    assert client.send(names, rssi).level == DiagnosticStatus.WARN
    for name, value in [('min_confidence', 1.5), ('min_known_aps', -1),
                        ('min_confidence', 'high'),
                        ('model_path', '/tmp/other.npz')]:
        result = client.set_param(name, value)
        assert not result.successful and result.reason, (name, value)
    assert client.set_param('min_confidence', 0.0).successful
    assert client.send(names, rssi).level == DiagnosticStatus.OK


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_clean_shutdown(ros, synthetic, tmp_path, sig):
    proc = NodeProcess(tmp_path, python_module(
        'classifier_node', '--ros-args', '-p',
        f'model_path:={synthetic[1]}'), f'shutdown_{sig.name}')
    client = Client(ros, proc.name)
    client.wait_ready(proc, (['AA:BB:CC:00:00:00'], [-60.0]))
    client.close()
    code, log = proc.stop(sig)
    assert code == 0, log
    assert 'Traceback' not in log


@pytest.mark.parametrize('content', [None, b'', b'\x80\x04garbage'])
def test_bad_model_path_is_one_clear_error(tmp_path, content):
    path = tmp_path / 'model.npz'
    if content is not None:
        path.write_bytes(content)
    result = run(python_module('classifier_node', '--ros-args', '-p',
                               f'model_path:={path}'), timeout=30)
    assert result.returncode == 1
    assert 'cannot load model' in result.stderr and str(path) in result.stderr
    assert 'Traceback' not in result.stderr


def test_closed_loop_matches_evaluate_model(tmp_path):
    data = dataset_file('validationData-public.csv')
    proc = NodeProcess(tmp_path, python_module('classifier_node'),
                       'classifier_node')
    try:
        replay = run(python_module('replay_scans', '--data', data,
                                   '--predictions', tmp_path / 'ros.csv'),
                     timeout=300)
    finally:
        code, log = proc.stop()
    assert replay.returncode == 0, replay.stderr + log
    assert '556/556 scans answered' in replay.stdout
    offline = run(python_module('evaluate_model', '--data', data,
                                '--predictions', tmp_path / 'offline.csv'))
    assert offline.returncode == 0, offline.stderr
    ros_rows = list(csv.reader((tmp_path / 'ros.csv').open()))
    offline_rows = list(csv.reader((tmp_path / 'offline.csv').open()))
    # Labels equal; confidences to float32 rounding (batch of 1 vs 556).
    assert [r[:5] for r in ros_rows] == [r[:5] for r in offline_rows]
    np.testing.assert_allclose([float(r[5]) for r in ros_rows[1:]],
                               [float(r[5]) for r in offline_rows[1:]],
                               atol=1e-5)
    assert code == 0, log
