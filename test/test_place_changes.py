"""
Place changes for Nav2 over real ROS: a scripted walk that changes floor.

The latched ``~/current_place`` (one message per change, at once for a
subscriber that starts late) and ``initialpose`` on a floor change and on
a jump of the tracked position; the recognizer's one way to be
reconfigured.
"""

from conftest import mac, python_module, run, wait_until
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped
import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from ros_helpers import RELIABLE, running_node
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.recognizer import PlaceRecognizer, step_sigmas
from wifi_place_recognition.core.scan import ScanRejected
from wifi_place_recognition.ros.messages import status_values

FRAME = 'map_b{building}_f{floor}'
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: surveyed_csv's offset of the positions (metres).
ORIGIN = np.array([-7600.0, 4864900.0])


class Building:
    """surveyed_csv's building (seed 0): scans at chosen places."""

    def __init__(self, n_aps=30, seed=0):
        rng = np.random.default_rng(seed)
        self.ap_xy = rng.uniform(0, 40, (n_aps, 2))
        self.ap_floor = rng.integers(0, 2, n_aps)
        self.noise = np.random.default_rng(5)

    def scan(self, x, y, floor):
        """Return (AP names, RSSI) of a scan at x, y on ``floor``."""
        d = np.linalg.norm(self.ap_xy - [x, y], axis=1) + 1.0
        rssi = -30 - 25 * np.log10(d) - 12 * (self.ap_floor != floor) \
            + self.noise.normal(0, 2, len(d))
        seen = np.flatnonzero(rssi >= -85)
        return [mac(i) for i in seen], np.round(rssi[seen]).tolist()


def listen(ros, name):
    """
    Return (current places, initialposes, subscriptions) of node ``name``.

    Once both topics are matched; keep the subscriptions while listening.
    """
    places, initial = [], []
    subs = [ros.create_subscription(DiagnosticArray,
                                    f'/{name}/current_place', places.append,
                                    LATCHED),
            ros.create_subscription(PoseWithCovarianceStamped,
                                    '/initialpose', initial.append, RELIABLE)]
    assert wait_until(lambda: all(s.get_publisher_count() for s in subs), 30,
                      ros)
    return places, initial, subs


#: A walk on floor 0, the lift to floor 1, a walk there, then carried to
#: the far corner: (x, y, floor), one scan every 5 s.
WALK = ([(10 + i, 10, 0) for i in range(8)] +
        [(18 + i, 10, 1) for i in range(8)] + [(34, 34, 1)] * 3)
CHANGE, JUMP = 8, 16     # the scans where the floor changes, the jump
SWITCH = CHANGE + 1      # the second confident scan of floor 1 switches


def test_a_walk_that_changes_floor_reseeds_nav2_and_latches_the_place(
        ros, tmp_path, surveyed_model):
    building = Building()
    with running_node(ros, tmp_path, surveyed_model, 'nav_node', '-p',
                      'tracking:=true', '-p', 'initial_pose_on_change:=true',
                      '-p', f'frame_id:={FRAME}') as (client, proc, _):
        places, initial, subs = listen(ros, 'nav_node')
        answers = []
        for i, (x, y, floor) in enumerate(WALK):
            client.seq += 700 if i == 0 else 4      # a new walk, then 5 s
            msg = client.scan(*building.scan(x, y, floor))
            status = client.resend_until_answered(msg, 30, every=5)
            assert status is not None, f'scan {i} not answered'
            answers.append((msg.header.stamp.sec, status_values(status)))
            if i == 2:      # the walk is under way: what came before is
                del initial[:]  # the probe's place
                assert wait_until(lambda: places, 10, ros)  # matched late
                del places[:-1]
            if i == JUMP - 1:   # a map switcher that starts late
                late = []
                sub = ros.create_subscription(
                    DiagnosticArray, '/nav_node/current_place', late.append,
                    LATCHED)
                assert wait_until(lambda: late, 10, ros)
                wait_until(lambda: len(late) > 1, 0.5, ros)
                ros.destroy_subscription(sub)
        wait_until(lambda: len(initial) >= 2, 5, ros)
        for sub in subs:
            ros.destroy_subscription(sub)
    tracked = [(int(v['building']), int(v['floor'])) for _, v in answers]
    assert tracked == [(0, 0)] * CHANGE + [(0, 1)] * (len(WALK) - CHANGE)
    # Latched: one message per change; the late one gets the current place.
    assert [status_values(m.status[0])['floor'] for m in places] == \
        ['0', '1'], places
    change = places[-1]
    values = status_values(change.status[0])
    assert (values['building'], values['frame_id']) == ('0', 'map_b0_f1')
    assert change.header.stamp.sec == answers[SWITCH][0]
    assert len(late) == 1 and late[0] == change
    # initialpose: at the floor change and at the jump, the tracked pose.
    assert [p.header.stamp.sec for p in initial] == \
        [answers[SWITCH][0], answers[JUMP][0]], initial
    for pose, i in zip(initial, (SWITCH, JUMP)):
        values = answers[i][1]
        assert pose.header.frame_id == 'map_b0_f1'
        assert pose.pose.pose.position.x == pytest.approx(
            float(values['x']), abs=1e-3)
        assert pose.pose.covariance[0] == pytest.approx(
            float(values['position_sigma_m']) ** 2, rel=1e-2)
    far = np.array([pose.pose.pose.position.x, pose.pose.pose.position.y])
    assert np.linalg.norm(far - ORIGIN - [34, 34]) < 10
    code, log = proc.stop()
    assert 'initialpose sent (building 0, floor 0 before)' in log, log
    assert 'initialpose sent (position jumped ' in log, log


def test_a_rejected_scan_gives_no_pose_and_changes_nothing(
        ros, tmp_path, surveyed_model):
    building = Building()
    with running_node(ros, tmp_path, surveyed_model, 'jump_node', '-p',
                      'initial_pose_on_change:=true', '-p',
                      'publish_initial_pose:=true') as (client, *_):
        poses = []
        sub = ros.create_subscription(PoseWithCovarianceStamped,
                                      '/jump_node/pose', poses.append,
                                      RELIABLE)
        assert wait_until(lambda: sub.get_publisher_count(), 30, ros)
        assert client.set_param('jump_threshold', 8.0).successful
        for bad in (0.5, 1000.0, float('nan')):
            result = client.set_param('jump_threshold', bad)
            assert not result.successful and result.reason, bad
        names, rssi = building.scan(10, 10, 0)
        status = client.send(names, rssi[:-1])      # one RSSI missing
        assert status.message.startswith('scan rejected: ')
        assert client.send(names, rssi).message.startswith('building ')
        assert wait_until(lambda: any(p.header.stamp.sec == client.seq
                                      for p in poses), 10, ros)
        assert client.seq - 1 not in [p.header.stamp.sec for p in poses]
        ros.destroy_subscription(sub)


def test_reseeding_needs_a_model_with_positions(synthetic):
    result = run(python_module(
        'ros.classifier_node', '--ros-args', '-p',
        f'model_path:={synthetic[1]}', '-p', 'initial_pose_on_change:=true'),
        timeout=30)
    assert result.returncode == 1, result.stderr
    assert 'cannot start: initial_pose_on_change: the model has no ' \
        'position output' in result.stderr, result.stderr


def test_the_recognizer_is_reconfigured_by_one_method(surveyed_model):
    recognizer = PlaceRecognizer(load_model(surveyed_model))
    names = [mac(i) for i in range(6)]
    recognizer.configure(max_aps=5, min_known_aps=7, min_confidence=0.0)
    with pytest.raises(ScanRejected):
        recognizer.classify(names, [-60.0] * 6)
    recognizer.configure(max_aps=6)
    assert 'only 6 known APs (< 7)' in recognizer.classify(
        names, [-60.0] * 6).message
    recognizer.configure(tracking_timeout=30.0, tracking=True)
    assert recognizer.tracker.timeout == 30.0
    recognizer.configure(tracking_timeout=20.0)     # the running tracker too
    assert recognizer.tracker.timeout == 20.0
    first = recognizer.classify(names, [-60.0] * 6, 100.0)
    assert first.probabilities is not None
    recognizer.configure(tracking=False)
    assert recognizer.tracker is None


def test_step_sigmas_is_the_mahalanobis_distance():
    cov = np.array([[4.0, 0.0], [0.0, 1.0]])
    assert step_sigmas([1.0, 1.0], cov, [7.0, 1.0]) == pytest.approx(3.0)
    assert step_sigmas([1.0, 1.0], cov, [1.0, 4.0]) == pytest.approx(3.0)
