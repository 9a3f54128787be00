"""Test-side ROS helpers: a node in its own process, and a scan client."""

import contextlib
import os
import signal
import subprocess
import time

from conftest import python_module, wait_until
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.ros.messages import status_values

RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
SCAN_COUNTS = ('received', 'answered', 'rejected', 'dropped')


class NodeProcess:
    """A classifier_node in its own process, stopped with SIGINT."""

    def __init__(self, tmp_path, argv, name='classifier_node', env=None):
        self.log = tmp_path / f'{name}.log'
        self.proc = subprocess.Popen(
            argv + ['--ros-args', '-r', f'__node:={name}'],
            stdout=subprocess.DEVNULL, stderr=self.log.open('w'),
            env=env or os.environ.copy())
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
    """
    The test's side: publishes scans, collects answers by stamp.

    It counts what it sent (``sent``) and every answer message it got
    (``places``), and keeps the client-measured round trip of each scan
    sent with :meth:`send` (``round_trip_ms``, by stamp).
    """

    def __init__(self, node, node_name='classifier_node'):
        self.node = node
        self.node_name = node_name
        self.pub = node.create_publisher(JointState, 'wifi/scan', RELIABLE)
        self.answers = {}
        self.arrived = {}
        self.round_trip_ms = {}
        self.sent = 0
        self.places = 0
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
        self.places += 1
        self.arrived.setdefault(msg.header.stamp.sec, time.monotonic())
        self.answers[msg.header.stamp.sec] = msg

    def _on_diag(self, msg):
        self.health += [s for s in msg.status
                        if s.name == f'{self.node_name}: health']

    def wait_ready(self, proc, probe, timeout=60):
        """
        Wait for the node, then send ``probe`` scans until one is answered.

        Discovery is not symmetric: the first scans after this side sees the
        node may not yet be accepted by the node's reader.
        """
        assert wait_until(lambda: self.pub.get_subscription_count() > 0 and
                          self.subs[0].get_publisher_count() > 0 and
                          self.params.service_is_ready(), timeout,
                          self.node), proc.stop()[1]
        status = self.resend_until_answered(self.scan(*probe), timeout)
        assert status is not None, proc.stop()[1]
        return status

    def resend_until_answered(self, msg, timeout, every=0.5):
        """
        Publish ``msg`` every ``every`` s until answered; return the status.

        For best-effort delivery (the node's scan QoS), which may lose a scan
        after discovery or in a burst. Returns None after ``timeout`` s.
        """
        deadline = time.monotonic() + timeout
        stamp = msg.header.stamp.sec
        while time.monotonic() < deadline:
            self.publish(msg)
            if wait_until(lambda: stamp in self.answers, every, self.node):
                return self.answers[stamp].status[0]
        return None

    def publish(self, msg):
        """Publish one scan message and count it in ``sent``."""
        self.pub.publish(msg)
        self.sent += 1

    def scan(self, names, rssi, frame_id='wlan0'):
        """Return the next scan message, stamped with a new sequence number."""
        self.seq += 1
        msg = JointState(name=list(names), position=[float(v) for v in rssi])
        msg.header.stamp.sec = self.seq
        msg.header.frame_id = frame_id
        return msg

    def send(self, names, rssi, frame_id='wlan0', timeout=30.0):
        """Publish one scan; return the node's DiagnosticStatus for it."""
        msg = self.scan(names, rssi, frame_id)
        seq = self.seq
        sent_at = time.monotonic()
        self.publish(msg)
        assert wait_until(lambda: seq in self.answers, timeout, self.node), \
            f'scan {seq} was not answered within {timeout} s'
        self.round_trip_ms[seq] = (self.arrived[seq] - sent_at) * 1e3
        return self.answers[seq].status[0]

    def settled_counts(self, timeout=120):
        """
        Wait until two health reports in a row agree; return (counts, values).

        The scan counts are then checked against this side: the node cannot
        receive more than was sent, every received scan is answered,
        rejected or dropped, and every answer this side got was counted as
        answered or rejected (only once settled: an earlier report may miss
        answers that were still on their way).
        """
        last = None
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.health.clear()
            assert wait_until(lambda: self.health, 30, self.node), \
                f'no health status from {self.node_name} within 30 s'
            values = status_values(self.health[-1])
            counts = {k: int(values[f'scans_{k}']) for k in SCAN_COUNTS}
            if counts == last:
                break
            last = counts
        else:
            raise AssertionError(f'counts still moving after {timeout} s: '
                                 f'{last}')
        assert counts['received'] <= self.sent, (counts, self.sent)
        assert counts['received'] == (counts['answered'] + counts['rejected']
                                      + counts['dropped']), counts
        assert counts['answered'] + counts['rejected'] >= self.places, \
            (counts, self.places)
        return counts, values

    def set_param(self, name, value):
        """Set one parameter over the service; return SetParametersResult."""
        kind = {float: ParameterType.PARAMETER_DOUBLE,
                int: ParameterType.PARAMETER_INTEGER,
                str: ParameterType.PARAMETER_STRING,
                bool: ParameterType.PARAMETER_BOOL}[type(value)]
        field = {float: 'double_value', int: 'integer_value',
                 str: 'string_value', bool: 'bool_value'}[type(value)]
        pv = ParameterValue(type=kind, **{field: value})
        # resent if no reply: a request sent as the service is discovered
        # can go unanswered (its reply path not yet matched); setting the
        # same value twice is harmless, so a lost one costs 5 s, not more
        for _ in range(9):
            future = self.params.call_async(SetParameters.Request(
                parameters=[Parameter(name=name, value=pv)]))
            rclpy.spin_until_future_complete(self.node, future,
                                             timeout_sec=5)
            if future.done():
                return future.result().results[0]
            self.params.remove_pending_request(future)
        raise AssertionError(f'no reply to setting {name} in 9 tries of '
                             f'5 s')

    def close(self):
        """Destroy the publisher, subscriptions and client."""
        for entity in self.subs:
            self.node.destroy_subscription(entity)
        self.node.destroy_publisher(self.pub)
        self.node.destroy_client(self.params)


@contextlib.contextmanager
def running_node(ros, tmp_path, model_path, name, *ros_args):
    """
    Run a classifier_node on ``model_path``; yield (client, proc, model).

    On exit the node must stop cleanly (exit 0, no traceback).
    """
    proc = NodeProcess(tmp_path, python_module(
        'ros.classifier_node', '--ros-args', '-p', f'model_path:={model_path}',
        *ros_args), name)
    try:
        client = Client(ros, name)
        model = load_model(model_path)
        client.wait_ready(proc, (model.ap_ids[:6], [-60.0] * 6))
        yield client, proc, model
        client.close()
    finally:    # a failed test stops its node too
        code, log = proc.stop()
    assert code == 0 and 'Traceback' not in log, log
