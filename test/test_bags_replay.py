"""
Bags through the tools that use a model: train, evaluate, replay.

A model trained from a bag of b24test3; evaluate_model gives the same
figures on the bag as on the run's CSV (labelled by the package's rule,
as the bag is); replay_run plays a slice of the
bag into a running classifier_node and scores it against the bag's poses.
"""

import re
import subprocess

from bag_helpers import relabelled, RUN, run_messages, write_bag
from conftest import FAST, python_module, run, wait_until
import pytest
import rclpy
from ros_helpers import NodeProcess

pytestmark = pytest.mark.skipif(not RUN.exists(),
                                reason='robot runs not available')
#: A deep scan queue: at ten times real speed on a busy machine the
#: node's depth-1 queue may drop a scan, and replay_run then exits 1 (not
#: every scan answered), which is not what these tests are about.
DEEP_QUEUE = ('-p', 'qos_overrides./wifi/scan.subscription.depth:=200')


@pytest.fixture(scope='module')
def trained(tmp_path_factory):
    """Return (bag of the whole run, model trained from it)."""
    folder = tmp_path_factory.mktemp('bag_model')
    bag = write_bag(folder / 'run', run_messages(), 'sqlite3')
    model = folder / 'model.npz'
    result = run(python_module('cli.train_model', '--data', bag, '-o',
                               model, *FAST))
    assert result.returncode == 0, result.stderr
    return bag, model


def test_evaluate_model_gives_the_same_figures_on_the_bag(trained,
                                                          tmp_path):
    bag, model = trained
    csv = relabelled(RUN, tmp_path / 'run') / 'scans.csv'
    out = [run(python_module('cli.evaluate_model', '--model', model,
                             '--data', data))
           for data in (csv, bag)]
    assert [o.returncode for o in out] == [0, 0], out[1].stderr
    # the figures, less the first line (the data's name)
    figures = [o.stdout.split('\n', 1)[1] for o in out]
    assert 'position error (m)' in figures[0]
    assert figures[0] == figures[1]


def test_replay_run_plays_a_bag_into_the_node_and_scores_it(trained,
                                                            tmp_path):
    _, model = trained
    bag = write_bag(tmp_path / 'slice', run_messages(seconds=90))
    node = NodeProcess(tmp_path, python_module(
        'ros.classifier_node', '--ros-args', '-p',
        f'model_path:={model}', *DEEP_QUEUE))
    try:
        result = run(python_module('cli.replay_run', '--data', bag,
                                   '--speed', '10', '--wait', '60'),
                     timeout=240)
    finally:
        code, log = node.stop()
    assert result.returncode == 0, result.stderr + log
    assert code == 0, log
    # every scan with a pose around it answered and scored, fused too
    answered = re.search(r'(\d+)/(\d+) scans answered', result.stdout)
    assert answered[1] == answered[2] and int(answered[1]) > 80, \
        result.stdout
    assert f'scored {answered[1]} of {answered[1]} scans' in result.stdout
    fused = re.search(r'mean error \(m\) +[\d.]+ +[\d.]+ +([\d.]+)',
                      result.stdout)
    assert float(fused[1]) < 3.0, result.stdout


def test_replay_run_feeds_the_localiser_to_a_monitor(trained, tmp_path, ros):
    # the bag's amcl_pose on --localizer-topic: localization_monitor
    # judges the replayed run as it would the robot's
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String
    _, model = trained
    bag = write_bag(tmp_path / 'slice', run_messages(seconds=240))
    states = []
    ros.create_subscription(
        String, '/localization_monitor/status',
        lambda msg: states.append(msg.data),
        QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                   durability=DurabilityPolicy.TRANSIENT_LOCAL))
    nodes = [NodeProcess(tmp_path, python_module(
        f'ros.{name}', '--ros-args', '-p', f'model_path:={model}',
        *(DEEP_QUEUE if name == 'classifier_node' else ())), name)
        for name in ('classifier_node', 'localization_monitor')]
    try:
        replay = subprocess.Popen(python_module(
            'cli.replay_run', '--data', bag, '--speed', '10', '--wait',
            '60', '--localizer-topic', 'amcl_pose'),
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        while replay.poll() is None:
            rclpy.spin_once(ros, timeout_sec=0.1)
        out, err = replay.communicate()
        wait_until(lambda: False, 1.0, ros)
    finally:
        logs = [node.stop() for node in nodes]
    assert replay.returncode == 0, err
    assert all(code == 0 for code, _ in logs), logs
    assert 'agrees' in states and 'lost' not in states, states


def test_localizer_topic_needs_poses_with_their_covariance(tmp_path):
    result = run(python_module(
        'cli.replay_run', '--data', RUN / 'scans.csv', '--odometry',
        RUN / 'odom.csv', '--localizer-topic', 'amcl_pose', '--wait', '0'))
    assert result.returncode == 2
    last = result.stderr.strip().splitlines()[-1]    # after the notes
    assert last.startswith('error: --localizer-topic needs') and \
        'COV_XX' in last, result.stderr
    assert 'Traceback' not in result.stderr
