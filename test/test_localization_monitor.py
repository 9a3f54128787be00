"""
localization_monitor over real ROS: a localiser judged against the WiFi pose.

The test plays the localiser (``amcl_pose``) and classifier_node (its fused
``~/pose``) from this process, on stamps one second apart (the monitor
judges by stamps, so a minute of driving takes a second or two); the
monitor runs in its own process (the shipped model's survey). The robot
drives along x at 0.5 m/s; the fused pose is the truth with 0.5 m and 3
degrees of spread (a kidnap: the scans' own positions on ``~/place``
instead). Checked: the latched ``~/status`` and ``~/localization_ok``,
the status on ``/diagnostics``, ``initialpose`` (at start-up once the
fused pose has stayed sure for 15 s; none from a fused pose built on
scans off the survey, nor while the last minute's scans lie aside of it),
the log, and parameters refused in the parameters' own terms.
"""

import math

from conftest import python_module, wait_until
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
import numpy as np
import pytest
from ros_helpers import Client, NodeProcess, RELIABLE
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Bool, String
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.resources import default_model_path
from wifi_place_recognition.ros.localization_monitor import survey_of
from wifi_place_recognition.ros.messages import (key_value, status_values,
                                                 yaw_of)

T0 = 5000.0
SPEED = 0.5
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: The latched topics read with room for every change (a state may last
#: only a few milliseconds).
EVERY_CHANGE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)
LEVELS = {DiagnosticStatus.OK: 'OK', DiagnosticStatus.WARN: 'WARN',
          DiagnosticStatus.ERROR: 'ERROR'}


def pose(t, x, y, yaw, frame='map', sd=0.1, yaw_sd=0.05):
    """Return a PoseWithCovarianceStamped at stamp ``t`` (s)."""
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = frame
    msg.header.stamp.sec = int(math.floor(t))
    msg.header.stamp.nanosec = int(round((t - math.floor(t)) * 1e9))
    msg.pose.pose.position.x = float(x)
    msg.pose.pose.position.y = float(y)
    msg.pose.pose.orientation.z = math.sin(yaw / 2)
    msg.pose.pose.orientation.w = math.cos(yaw / 2)
    cov = [0.0] * 36
    cov[0] = cov[7] = sd ** 2
    cov[14] = cov[21] = cov[28] = 1e6
    cov[35] = yaw_sd ** 2
    msg.pose.covariance = cov
    return msg


def truth(k):
    """Return the true (x, y, yaw) at step ``k``."""
    return 10.0 + SPEED * k, 20.0, 0.0


class Monitor:
    """A localization_monitor process and the test's side of its topics."""

    def __init__(self, ros, tmp_path, name, *params):
        self.ros, self.name = ros, name
        self.proc = NodeProcess(tmp_path, python_module(
            'ros.localization_monitor', '--ros-args', *params), name)
        self.verdicts, self.initial, self.status = [], [], []
        self.states, self.diagnostics = [], []   # (level, message, values)
        self.seen_local = False
        self.local = ros.create_publisher(PoseWithCovarianceStamped,
                                          'amcl_pose', RELIABLE)
        self.fused = ros.create_publisher(PoseWithCovarianceStamped,
                                          'classifier_node/pose', RELIABLE)
        self.subs = [
            ros.create_subscription(Bool, f'/{name}/localization_ok',
                                    lambda m: self.verdicts.append(m.data),
                                    LATCHED),
            ros.create_subscription(String, f'/{name}/status',
                                    lambda m: self.states.append(m.data),
                                    EVERY_CHANGE),
            ros.create_subscription(PoseWithCovarianceStamped,
                                    '/initialpose', self.initial.append,
                                    RELIABLE),
            ros.create_subscription(DiagnosticArray, '/diagnostics',
                                    self._on_diag, RELIABLE)]
        assert wait_until(lambda: self.local.get_subscription_count() and
                          self.fused.get_subscription_count() and
                          all(s.get_publisher_count() for s in self.subs) and
                          self.verdicts and self.states, 60, ros), \
            self.proc.stop()[1]

    def _on_diag(self, msg):
        mine = [s for s in msg.status
                if s.name == f'{self.name}: localization']
        self.status += [status_values(s) for s in mine]
        self.diagnostics += [(LEVELS[s.level], s.message, status_values(s))
                             for s in mine]

    def diagnosed_states(self):
        """Return the states seen on /diagnostics, each repeat once."""
        out = []
        for _, _, values in self.diagnostics:
            if out[-1:] != [values['state']]:
                out.append(values['state'])
        return out

    def diagnosis(self, state):
        """Return (level, message, values) of the first status in ``state``."""
        return next(d for d in self.diagnostics if d[2]['state'] == state)

    def wait_state(self, state):
        """Wait until ``~/status`` says ``state``."""
        assert wait_until(lambda: self.states[-1:] == [state], 10,
                          self.ros), self.states

    def spin(self, seconds=0.03):
        wait_until(lambda: False, seconds, self.ros)

    def step(self, k, local=None, fused=None, frame='map', fused_sd=0.5):
        """Send step ``k``: the localiser's pose (if any), then the fused."""
        if local is not None:
            self.send_local(pose(T0 + k, *local, frame=frame))
        rng = np.random.default_rng(k)
        x, y, yaw = fused if fused is not None else truth(k)
        dx, dy = rng.normal(0, 0.3, 2)
        self.fused.publish(pose(T0 + k, x + dx, y + dy, yaw + rng.normal(
            0, math.radians(2)), sd=fused_sd, yaw_sd=math.radians(3)))
        self.spin()

    def send_local(self, msg):
        """Send a localiser pose; the first: wait until the monitor has it."""
        self.local.publish(msg)
        self.spin(0.01)
        if not self.seen_local:     # else a start-up seed may go out
            assert wait_until(lambda: self.verdicts[-1], 10, self.ros)
            self.seen_local = True

    def latest_status(self):
        """Return the newest status values (waits for the next one)."""
        self.status.clear()
        assert wait_until(lambda: self.status, 10, self.ros)
        return self.status[-1]

    def close(self):
        for sub in self.subs:
            self.ros.destroy_subscription(sub)
        self.ros.destroy_publisher(self.local)
        self.ros.destroy_publisher(self.fused)
        code, log = self.proc.stop()
        assert code == 0 and 'Traceback' not in log, log
        return log


@pytest.fixture
def monitor(ros, tmp_path, request):
    """Return a starter of monitors (each closed after the test)."""
    started = []

    def start(name, *params):
        started.append(Monitor(ros, tmp_path, name, *params))
        return started[-1]
    yield start
    for m in started:
        m.close()


def test_a_localiser_that_agrees_is_never_judged_lost(monitor, ros):
    m = monitor('agreeing_monitor', '-p', 'initial_pose_on_lost:=true')
    for k in range(60):
        x, y, yaw = truth(k)
        m.step(k, local=(x + 0.3, y - 0.2, yaw + 0.03))
    m.spin(0.5)
    assert m.verdicts[0] is False           # before the first pose
    assert m.verdicts[1:] == [True], m.verdicts
    # the first pose has nothing to compare with, the next fused pose has
    assert m.states == ['waiting', 'cannot_tell', 'agrees'], m.states
    assert not m.initial
    values = m.latest_status()
    assert values['localization_ok'] == 'true'
    assert float(values['agreement_sigma']) < 3, values
    assert float(values['score']) < 0.5, values
    assert m.diagnostics[-1][:2] == ('OK', 'localiser agrees with WiFi')


def test_a_displaced_localiser_is_lost_and_reseeded_near_the_truth(
        monitor, ros):
    m = monitor('displaced_monitor', '-p', 'initial_pose_on_lost:=true')
    for k in range(20):
        m.step(k, local=truth(k))
    assert m.verdicts[-1] is True
    lost_at = None
    for k in range(20, 50):         # 15 m off, carried on
        x, y, yaw = truth(k)
        m.step(k, local=(x + 12.0, y + 9.0, yaw))
        if lost_at is None and m.verdicts[-1] is False:
            lost_at = k
    assert lost_at is not None and lost_at - 20 <= 15, m.verdicts
    assert wait_until(lambda: m.initial, 5, ros), 'no initialpose'
    seed = m.initial[0]
    k = seed.header.stamp.sec - T0
    x, y, yaw = truth(k)
    p = seed.pose.pose
    assert math.hypot(p.position.x - x, p.position.y - y) < 2.0
    assert abs(math.degrees(yaw_of(p.orientation) - yaw)) < 15
    assert seed.header.frame_id == 'map'
    cov = np.reshape(seed.pose.covariance, (6, 6))
    assert 0 < cov[0, 0] < 1 and 0 < cov[5, 5] < 0.1
    values = m.latest_status()
    assert values['localization_ok'] == 'false'
    assert float(values['distance_m']) > 10, values
    assert float(values['disagreeing_for_s']) > 0, values
    assert int(values['seeds_sent']) == 1
    assert m.states[-1] == 'lost', m.states
    # the evidence gathered before the alarm: disagrees, not agrees
    assert m.states.index('disagrees') < m.states.index('lost'), m.states
    level, message, _ = m.diagnosis('lost')
    assert level == 'ERROR' and message.startswith('localiser lost: ') and \
        'from the WiFi' in message, message
    # the localiser takes the seed: found again
    for k in range(50, 60):
        m.step(k, local=truth(k))
    assert m.verdicts[-1] is True, m.verdicts


def test_a_frozen_localiser_is_lost(monitor, ros):
    m = monitor('frozen_monitor')
    for k in range(20):
        m.step(k, local=truth(k))
    frozen = truth(20)
    lost_at = None
    for k in range(20, 80):         # the robot drives on at 0.5 m/s
        m.step(k, local=frozen)
        if lost_at is None and m.verdicts[-1] is False:
            lost_at = k
    assert lost_at is not None and lost_at - 20 <= 30, m.verdicts
    assert not m.initial        # initial_pose_on_lost is false by default


def test_a_localiser_on_another_floors_map_is_lost(monitor, ros):
    m = monitor('floor_monitor', '-p', 'frame_id:=map_f{floor}', '-p',
                'initial_pose_on_lost:=true')
    for k in range(10):
        m.send_local(pose(T0 + k, *truth(k), frame='map_f0'))
        m.fused.publish(pose(T0 + k, *truth(k), frame='map_f0', sd=0.5,
                             yaw_sd=0.05))
        m.spin()
    assert m.verdicts[-1] is True
    for k in range(10, 20):         # the lift: WiFi says floor 1
        m.send_local(pose(T0 + k, *truth(k), frame='map_f0'))
        m.fused.publish(pose(T0 + k, *truth(k), frame='map_f1', sd=0.5,
                             yaw_sd=0.05))
        m.spin()
    assert m.verdicts[-1] is False, m.verdicts
    assert wait_until(lambda: m.initial, 5, ros)
    assert {p.header.frame_id for p in m.initial} == {'map_f1'}
    values = m.latest_status()
    assert "frame 'map_f0'" in values['reason'], values
    assert values['wifi_frame'] == 'map_f1'


def test_with_no_localiser_pose_the_sure_fused_pose_seeds_it(monitor, ros):
    m = monitor('startup_monitor', '-p', 'initial_pose_on_lost:=true')
    for k in range(10):             # not sure yet: nothing sent
        m.step(k, fused_sd=3.0)
    m.spin(0.3)
    assert not m.initial
    assert m.latest_status()['localization_ok'] == 'false'
    # sure from 10 s, wide at 17 and 18 s (two: one may be lost on a busy
    # machine), sure again from 19 s: the seed waits startup_sure_s (15 s)
    # of a pose sure without a break
    for k in range(10, 40):
        m.step(k, fused_sd=3.0 if k in (17, 18) else 0.5)
    assert wait_until(lambda: m.initial, 5, ros), 'no initial pose'
    seed = m.initial[0]
    assert seed.header.stamp.sec == T0 + 19 + 15
    x, y, _ = truth(19 + 15)
    p = seed.pose.pose.position
    assert math.hypot(p.x - x, p.y - y) < 2
    assert len(m.initial) == 1          # holdoff: once
    assert m.verdicts == [False]


def test_no_seed_from_a_fused_pose_built_on_scans_off_the_survey(
        monitor, ros):
    # issue 35: no localiser pose yet, the fused pose sure, but the scans
    # unlike any surveyed one: nothing sent until most of them testify
    here, m, answers = surveyed_monitor(monitor, ros,
                                        'off_survey_seed_monitor', '-p',
                                        'initial_pose_on_lost:=true')
    for k in range(5):              # the scans first: off the survey
        answers.publish(place_answer(T0 + k, here, 5.0))
        m.spin()
    assert wait_until(lambda: m.status and int(m.status[-1]['scans']) == 5,
                      10, ros), m.status[-1:]
    for k in range(5, 15):
        answers.publish(place_answer(T0 + k, here, 5.0))
        m.spin()
        m.fused.publish(pose(T0 + k, *here, 0.0, sd=0.5, yaw_sd=0.05))
        m.spin()
    m.spin(0.3)
    assert not m.initial
    for k in range(15, 25):         # like the surveyed ones again
        answers.publish(place_answer(T0 + k, here, 1.5))
        m.spin()
        m.fused.publish(pose(T0 + k, *here, 0.0, sd=0.5, yaw_sd=0.05))
        m.spin()
    ros.destroy_publisher(answers)
    assert wait_until(lambda: m.initial, 5, ros), 'no initial pose'
    # the third scan like the surveyed ones (17 s) would do; the fused
    # pose, sure since 5 s (off the survey or not), seeds at 5 + 15 s
    assert m.initial[0].header.stamp.sec == T0 + 20, m.initial[0].header
    assert len(m.initial) == 1


def test_no_seed_while_the_scans_of_the_last_minute_lie_aside(monitor, ros):
    # issue 35: a fused pose dragged by scans off the survey comes back
    # with a narrow covariance; the scans of the last minute still lie
    # aside of it. No localiser pose yet: 50 s of scans 4.5 m aside (the
    # fused pose wide), then on it (sure at once): no seed until the
    # last 60 s of scans lie within sure_sd (2 m) on average, at 83 s
    # (27 of 61 aside: 1.99 m), not at 50 s
    here, m, answers = surveyed_monitor(monitor, ros, 'dragged_monitor',
                                        '-p', 'initial_pose_on_lost:=true')
    for k in range(90):
        aside = np.array([4.5, 0.0]) if k < 50 else np.zeros(2)
        answers.publish(place_answer(T0 + k, here + aside, 1.5))
        m.spin()
        m.fused.publish(pose(T0 + k, *here, 0.0, sd=3.0 if k < 50 else 0.5,
                             yaw_sd=0.05))
        m.spin()
    ros.destroy_publisher(answers)
    assert wait_until(lambda: m.initial, 5, ros), 'no initial pose'
    assert m.initial[0].header.stamp.sec >= T0 + 80, m.initial[0].header
    assert len(m.initial) == 1


def place_answer(t, xy, sigma, knn_sigma=None, coverage=None, mismatch=None):
    """Return a ~/place answer as classifier_node sends it (some keys)."""
    values = [key_value('building', 0), key_value('floor', 0),
              key_value('scan_x', f'{xy[0]:.3f}'),
              key_value('scan_y', f'{xy[1]:.3f}'),
              key_value('scan_sigma_m', f'{sigma:.3f}')]
    if knn_sigma is not None:
        values.append(key_value('scan_knn_sigma_m', f'{knn_sigma:.3f}'))
    if coverage is not None:       # a number, or a string as it is sent
        values.append(key_value('coverage', coverage if isinstance(
            coverage, str) else f'{coverage:.4f}'))
    if mismatch is not None:       # a number, or a string as it is sent
        values.append(key_value('mismatch', mismatch if isinstance(
            mismatch, str) else f'{mismatch:.3f}'))
    msg = DiagnosticArray(status=[DiagnosticStatus(
        name='classifier_node: place', values=values)])
    msg.header.stamp.sec = int(t)
    return msg


def test_scans_far_from_a_surveyed_localiser_pose_tell_a_kidnap(
        monitor, ros):
    # the shipped model's survey: the localiser stays on a surveyed spot,
    # the fused pose with it (the filter has not noticed yet); the scans
    # say the robot is 15-30 m away, at another surveyed spot
    refs = survey_of(load_model(default_model_path()), 'map')['map']
    here = refs[0]
    far = refs[np.flatnonzero((np.linalg.norm(refs - here, axis=1) > 15) &
                              (np.linalg.norm(refs - here, axis=1) < 30))[0]]
    m = monitor('kidnap_monitor')
    answers = ros.create_publisher(DiagnosticArray, 'classifier_node/place',
                                   RELIABLE)
    assert wait_until(lambda: answers.get_subscription_count(), 30, ros)
    for k in range(40):
        m.send_local(pose(T0 + k, *here, 0.0))
        m.fused.publish(pose(T0 + k, *here, 0.0, sd=0.5, yaw_sd=0.05))
        answers.publish(place_answer(T0 + k, here if k < 10 else far, 1.5))
        m.spin()
    ros.destroy_publisher(answers)
    assert m.verdicts == [False, True, False], m.verdicts
    values = m.latest_status()
    assert 'from the WiFi scans' in values['reason'], values
    assert int(values['scans']) == 40


def surveyed_spot_away(here):
    """Return the first surveyed spot of the shipped model 20-30 m away."""
    refs = survey_of(load_model(default_model_path()), 'map')['map']
    distance = np.linalg.norm(refs - here, axis=1)
    return refs[np.flatnonzero((distance > 20) & (distance < 30))[0]]


def test_a_wide_scan_testifies_when_its_coverage_says_on_the_survey(
        monitor, ros):
    # as the kidnap above, the scans wider than max_scan_sigma: their
    # coverage probability decides (likely off the survey, they testify
    # nothing; likely on it, they do; not a probability: refused, counted)
    here, m, answers = surveyed_monitor(monitor, ros, 'coverage_monitor')
    far = surveyed_spot_away(here)
    for k in range(30):
        m.send_local(pose(T0 + k, *here, 0.0))
        answers.publish(place_answer(T0 + k, far, 3.5, coverage=0.1))
        m.spin()
    off = 'scan off the survey (sigma 3.5 m, coverage 0.10)'
    assert wait_until(lambda: m.latest_status()['reason'] == off, 30, ros)
    assert m.states[-1] == 'cannot_tell', m.states
    for k in range(30, 90):     # each 5 sigma off: lost in about 30 s
        m.send_local(pose(T0 + k, *here, 0.0))
        answers.publish(place_answer(T0 + k, far, 3.5, coverage=0.9))
        m.spin()
    m.wait_state('lost')
    assert 'from the WiFi scans' in m.latest_status()['reason']
    for k, bad in enumerate(('1.5', 'n/a')):
        answers.publish(place_answer(T0 + 90 + k, far, 3.5, coverage=bad))
    assert wait_until(lambda: m.latest_status()['bad_scans'] == '2', 30,
                      ros)
    ros.destroy_publisher(answers)
    assert m.verdicts == [False, True, False], m.verdicts
    log = m.close()
    m.close = lambda: None
    assert "scan refused (1 so far): coverage '1.5' is not a " \
        'probability' in log, log


def test_a_scan_that_sounds_unlike_the_survey_testifies_nothing(
        monitor, ros):
    # sure scans, likely covered, 20-30 m off a surveyed localiser pose:
    # sounding unlike the survey (a survey hole, the scans snapped to its
    # edge) they testify nothing; like it, they tell the kidnap; a
    # mismatch that is not a ratio: refused, counted, named
    here, m, answers = surveyed_monitor(monitor, ros, 'mismatch_monitor')
    far = surveyed_spot_away(here)
    for k in range(30):
        m.send_local(pose(T0 + k, *here, 0.0))
        answers.publish(place_answer(T0 + k, far, 1.5, coverage=0.9,
                                     mismatch=2.0))
        m.spin()
    unlike = 'scan unlike the survey (mismatch 2.00 times its usual)'
    assert wait_until(lambda: m.latest_status()['reason'] == unlike, 30,
                      ros)
    assert m.states[-1] == 'cannot_tell', m.states
    for k in range(30, 60):
        m.send_local(pose(T0 + k, *here, 0.0))
        answers.publish(place_answer(T0 + k, far, 1.5, coverage=0.9,
                                     mismatch=1.0))
        m.spin()
    m.wait_state('lost')
    assert 'from the WiFi scans' in m.latest_status()['reason']
    for k, bad in enumerate(('-1', 'loud')):
        answers.publish(place_answer(T0 + 60 + k, far, 1.5, coverage=0.9,
                                     mismatch=bad))
    assert wait_until(lambda: m.latest_status()['bad_scans'] == '2', 30,
                      ros)
    ros.destroy_publisher(answers)
    assert m.verdicts == [False, True, False], m.verdicts
    assert m.latest_status()['scans'] == '60'
    log = m.close()
    m.close = lambda: None
    assert "scan refused (1 so far): mismatch '-1' is not a ratio " \
        '(>= 0 or nan)' in log, log


def test_bad_localiser_messages_are_counted_named_and_left_out(
        monitor, ros):
    m = monitor('bad_input_monitor')
    for k in range(10):
        m.step(k, local=truth(k))
    x, y, yaw = truth(10)
    bad = {'not_finite': pose(T0 + 10, math.nan, y, yaw),
           'not_unit_quaternion': pose(T0 + 10, x, y, yaw),
           'covariance': pose(T0 + 10, x + 20, y, yaw),
           'unknown_frame': pose(T0 + 10, x + 20, y, yaw, frame='odom'),
           'stamp_backwards': pose(T0 + 2, x + 20, y, yaw)}
    bad['not_unit_quaternion'].pose.pose.orientation.w = 0.0
    bad['covariance'].pose.covariance[0] = -1.0
    for k in range(10, 25):
        for msg in bad.values():        # far off, and garbage
            m.local.publish(msg)
        m.spin(0.01)
        m.send_local(pose(T0 + k + 0.5, *truth(k)))
        m.step(k)
    m.spin(0.5)
    assert m.verdicts[1:] == [True], m.verdicts
    values = m.latest_status()
    for reason in bad:
        assert int(values[f'bad_localizer/{reason}']) >= 10, (reason,
                                                              values)
    # the good ones counted, none of the bad (a burst of six into a
    # depth-10 reader may lose a good one on a busy machine)
    assert 20 <= int(values['localizer_poses']) <= 25, values
    log = m.close()
    m.close = lambda: None
    for text in ('x, y = nan', 'w = 0, 0, 0, 0', "frame 'odom'",
                 'before the previous one', 'not positive definite'):
        assert text in log or text.replace('w = ', '') in log, (text, log)


def test_with_nothing_to_compare_wifi_cannot_tell_at_once(monitor, ros):
    m = monitor('nothing_monitor')
    m.send_local(pose(T0, *truth(0)))   # no fused pose, no scan yet
    for k in range(1, 5):               # then fused poses that agree
        m.step(k, local=truth(k))
    m.wait_state('agrees')
    assert m.states == ['waiting', 'cannot_tell', 'agrees'], m.states
    # the Bool: true = not known to be lost, also when WiFi cannot tell
    assert m.verdicts == [False, True], m.verdicts
    # each state went out on /diagnostics when it began, not at the next
    # once-a-second status (cannot_tell lasted a few milliseconds)
    assert m.diagnosed_states()[-2:] == ['cannot_tell', 'agrees'], \
        m.diagnosed_states()
    level, message, values = m.diagnosis('cannot_tell')
    assert (level, message) == ('WARN', 'WiFi cannot tell: no WiFi pose or '
                                'scan yet')
    assert values['localization_ok'] == 'true', values
    log = m.close()
    m.close = lambda: None
    assert 'WiFi cannot tell: no WiFi pose or scan yet' in log, log
    assert 'localiser agrees with WiFi' in log, log


def surveyed_monitor(monitor, ros, name, *params):
    """Return a surveyed spot, a monitor and a ~/place publisher to it."""
    here = survey_of(load_model(default_model_path()), 'map')['map'][0]
    m = monitor(name, *params)
    answers = ros.create_publisher(DiagnosticArray, 'classifier_node/place',
                                   RELIABLE)
    assert wait_until(lambda: answers.get_subscription_count(), 30, ros)
    return here, m, answers


def test_a_wide_fused_pose_and_scans_off_the_survey_cannot_tell(
        monitor, ros):
    here, m, answers = surveyed_monitor(monitor, ros, 'wide_monitor')
    for k in range(10):     # the filter 11 m wide, the scans unlike any
        m.send_local(pose(T0 + k, *here, 0.0))
        m.fused.publish(pose(T0 + k, *here, 0.0, sd=11.0, yaw_sd=0.05))
        answers.publish(place_answer(T0 + k, here, 5.0))
        m.spin()
    m.wait_state('cannot_tell')
    m.latest_status()               # the status after the last judgement
    level, message, values = m.diagnostics[-1]
    assert level == 'WARN' and message.startswith('WiFi cannot tell: ')
    assert 'fused pose too wide (11.0 m)' in message or \
        'scan off the survey (sigma 5.0 m)' in message, message
    assert values['localization_ok'] == 'true'
    for k in range(10, 15):     # a scan like the surveyed ones testifies
        m.send_local(pose(T0 + k, *here, 0.0))
        answers.publish(place_answer(T0 + k, here, 1.5))
        m.spin()
    m.wait_state('agrees')
    ros.destroy_publisher(answers)
    assert m.states == ['waiting', 'cannot_tell', 'agrees'], m.states
    assert m.verdicts == [False, True], m.verdicts


def test_parameters_are_refused_in_their_own_terms(monitor, ros):
    m = monitor('param_monitor')
    client = Client(ros, 'param_monitor')
    try:
        refused = [client.set_param('alarm', value).reason
                   for value in (0, 0.0, 5.0)]
        yaw = client.set_param('yaw_floor_deg', 0.0)
        assert client.set_param('alarm', 20.0).successful
        assert client.set_param('sure_s', 0.0).successful   # 0: off
    finally:
        client.close()
    # an integer for a double: rclpy refuses the type
    assert refused[0].startswith('Wrong parameter type'), refused
    assert refused[1] == 'alarm = 0.0: expected a number > 0'
    # the rule named with what the user sets, not a field of the core
    assert refused[2].startswith('alarm = 5.0 must be above 10: one '
                                 'judgement adds at most 10'), refused
    assert 'agree_sigmas' in refused[2] and 'max_step' not in refused[2]
    assert not yaw.successful and \
        yaw.reason == 'yaw_floor_deg = 0.0: expected a number > 0', yaw
    log = m.close()
    m.close = lambda: None
    assert 'model ' in log and 'surveyed positions; judging /amcl_pose ' \
        'against /classifier_node/pose and /classifier_node/place in frame ' \
        'map: agree_sigmas 3, alarm 60, max_scan_sigma 3 m, ' \
        'initial_pose_on_lost false' in log, log


def test_the_monitor_reads_the_scans_k_nn_sigma_not_the_widened_one(
        monitor, ros):
    # an answer at the survey's edge: its 95 % circle widened to 6 m, its
    # k-NN sigma 1 m (what the thresholds were chosen on): it testifies
    here, m, answers = surveyed_monitor(monitor, ros, 'knn_monitor')
    for k in range(10):
        m.send_local(pose(T0 + k, *here, 0.0))
        answers.publish(place_answer(T0 + k, here, 6.0, knn_sigma=1.0))
        m.spin()
    m.wait_state('agrees')
    ros.destroy_publisher(answers)
