"""
trusted_recorder over real ROS: a survey kept only while the localiser is.

The test plays the localiser (``amcl_pose``), localization_monitor (its
latched ``~/status``), classifier_node (its latched ``~/current_place``)
and the scanner, one scan a second just after each localiser pose; the
recorder runs in its own process. Phases: the witness agrees (recorded),
says lost (not), cannot tell (recorded: a survey hole), agrees while the
localiser's covariance is large (not), the localiser jumps 10 m while
the witness cannot tell (nothing for ``settle_s`` seconds, nor after
until the witness agrees), agrees (recorded). The CSV must hold exactly
the trusted scans, labelled with the localiser's pose interpolated
between the poses around it (the last, held until the recorder stops:
the pose before it) and the current place.
"""

import csv
import math

from conftest import mac, python_module, wait_until
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from ros_helpers import NodeProcess, RELIABLE
from sensor_msgs.msg import JointState
from rclpy.qos import ReliabilityPolicy
from std_msgs.msg import String
from test_localization_monitor import LATCHED, pose
from wifi_place_recognition.ros.messages import key_value, status_values

T0 = 7000.0
NAME = 'trusted_node'
#: (witness state, localiser sd m, offset m, scans) of each phase; the
#: jump's phase 12 scans (settle_s 10 s, then 2 scans unconfirmed).
PHASES = [('agrees', 0.1, 0.0, 4), ('lost', 0.1, 0.0, 4),
          ('cannot_tell', 0.1, 0.0, 4), ('agrees', 0.5, 0.0, 4),
          ('cannot_tell', 0.1, 10.0, 12), ('agrees', 0.1, 10.0, 4)]
#: The last scan of the first cannot_tell phase is not: its label comes
#: from the pose after it too, of the uncertain phase.
RECORDED = [0, 1, 2, 3, 8, 9, 10, 28, 29, 30, 31]
#: classifier_node's current place: building 0, floor 1.
PLACE = DiagnosticArray(status=[DiagnosticStatus(
    name='classifier_node: current place', values=[
        key_value('building', 0), key_value('floor', 1),
        key_value('frame_id', 'map')])])


class Recorder:
    """A trusted_recorder process and the test's side of its topics."""

    def __init__(self, ros, tmp_path):
        self.ros = ros
        self.output = tmp_path / 'learned.csv'
        # the localiser's poses and the scans read reliably (best effort,
        # the default, may drop one under load): the CSV is checked exactly
        reliable = [a for topic in ('/amcl_pose', '/wifi/scan') for a in
                    ('-p', f'qos_overrides.{topic}.subscription.reliability'
                     f':=reliable')]
        self.proc = NodeProcess(tmp_path, python_module(
            'ros.trusted_recorder', '--ros-args', '-p',
            f'output:={self.output}', *reliable), NAME)
        self.local = ros.create_publisher(PoseWithCovarianceStamped,
                                          'amcl_pose', RELIABLE)
        self.status = ros.create_publisher(
            String, 'localization_monitor/status', LATCHED)
        self.place = ros.create_publisher(
            DiagnosticArray, 'classifier_node/current_place', LATCHED)
        self.scans = ros.create_publisher(JointState, 'wifi/scan', RELIABLE)
        self.progress = []
        self.sub = ros.create_subscription(DiagnosticArray, '/diagnostics',
                                           self._on_diag, RELIABLE)
        assert wait_until(lambda: all(
            p.get_subscription_count() for p in (
                self.local, self.status, self.place, self.scans)), 60,
            ros), self.proc.stop()[1]
        for topic in ('/amcl_pose', '/wifi/scan'):
            assert wait_until(lambda: self.reliability(topic), 10, ros)
            assert self.reliability(topic) == [ReliabilityPolicy.RELIABLE], \
                topic

    def reliability(self, topic):
        """Return the reliability of the recorder's subscriptions."""
        return [i.qos_profile.reliability for i in
                self.ros.get_subscriptions_info_by_topic(topic)
                if i.node_name == NAME]

    def _on_diag(self, msg):
        self.progress += [status_values(s) for s in msg.status
                          if s.name == f'{NAME}: progress']

    def wait_for(self, key, value):
        """Wait until the progress status has ``key`` = ``value``."""
        assert wait_until(lambda: self.progress and
                          self.progress[-1][key] == str(value), 30,
                          self.ros), (key, value, self.progress[-1:])

    def say(self, state):
        self.status.publish(String(data=state))
        self.wait_for('witness', state)

    def step(self, k, sd, offset):
        """Send the localiser's pose at step ``k``, then a scan."""
        self.local.publish(pose(T0 + k, 10.0 + 0.5 * k + offset, 20.0, 0.0,
                                sd=sd))
        wait_until(lambda: False, 0.05, self.ros)
        scan = JointState(name=[mac(i) for i in range(4)],
                          position=[-50.0, -60.0, -70.0, -80.0 - k % 5])
        scan.header.stamp.sec = int(T0 + k)
        scan.header.stamp.nanosec = 100_000_000
        self.scans.publish(scan)
        wait_until(lambda: False, 0.05, self.ros)

    def close(self):
        """Stop the recorder and the test's side: no latched state left."""
        for pub in (self.local, self.status, self.place, self.scans):
            self.ros.destroy_publisher(pub)
        self.ros.destroy_subscription(self.sub)
        code, log = self.proc.stop()
        assert code == 0 and 'Traceback' not in log, log
        return log


def test_scans_are_recorded_while_trusted_also_where_wifi_cannot_tell(
        ros, tmp_path):
    r = Recorder(ros, tmp_path)
    r.place.publish(PLACE)
    r.wait_for('place', 'B0F1')
    k = 0
    for state, sd, offset, scans in PHASES:
        r.say(state)
        for _ in range(scans):
            r.step(k, sd, offset)
            k += 1
    r.wait_for('scans_received', k)
    values = r.progress[-1]
    log = r.close()
    with open(r.output) as f:
        rows = list(csv.DictReader(f))
    steps = [round(float(row['TIMESTAMP']) - T0 - 0.1) for row in rows]
    assert steps == RECORDED, (steps, values, log)
    for step, row in zip(steps, rows):
        offset = 10.0 if step >= 16 else 0.0
        # a tenth of the way to the next pose (the last: no next pose)
        ahead = 0.05 if step < k - 1 else 0.0
        assert math.isclose(float(row['X']),
                            10.0 + 0.5 * step + ahead + offset), (step, row)
        assert (row['BUILDINGID'], row['FLOOR'], row['FRAME']) == \
            ('0', '1', 'map'), row
    assert values['skipped/lost'] == '4', values
    assert values['skipped/uncertain'] == '5', values
    assert values['skipped/jumped'] == '10', values
    assert values['skipped/unconfirmed'] == '2', values
    assert values['localizer_jumps'] == '1', values
    assert 'not recording: the WiFi witness says the localiser is lost' \
        in log and 'the localiser jumped 10.50 m in 1.00 s' in log, log


def test_a_stopped_witness_or_place_publisher_stops_recording(ros, tmp_path):
    """
    A latched state outlives its publisher: a dead monitor's ``agrees``.

    Recorded while the witness agrees; its publisher destroyed: nothing
    (``skipped/witness_gone``) until a new one says agrees; the current
    place's publisher destroyed: nothing (``skipped/no_place``).
    """
    r = Recorder(ros, tmp_path)
    r.place.publish(PLACE)
    r.wait_for('place', 'B0F1')
    r.say('agrees')
    k = 0
    for phase in range(4):
        if phase == 1:
            ros.destroy_publisher(r.status)
            r.wait_for('witness', 'gone')
        elif phase == 2:
            r.status = ros.create_publisher(
                String, 'localization_monitor/status', LATCHED)
            r.say('agrees')
        elif phase == 3:
            ros.destroy_publisher(r.place)
            r.wait_for('place', '')
        for _ in range(4):
            r.step(k, 0.1, 0.0)
            k += 1
    r.wait_for('scans_received', k)
    values = r.progress[-1]
    log = r.close()
    with open(r.output) as f:
        steps = [round(float(row['TIMESTAMP']) - T0 - 0.1)
                 for row in csv.DictReader(f)]
    # the last scan of a phase before a stop is labelled by the next
    # phase's first pose, judged with the witness it came with
    assert steps == [0, 1, 2, 3, 8, 9, 10, 11], (steps, values, log)
    assert values['skipped/witness_gone'] == '4', values
    # the last scan waits for a pose after it (judged at the stop)
    assert values['skipped/no_place'] == '3', values
    assert 'the witness stopped' in log, log
