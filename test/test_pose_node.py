"""Position over real ROS: ~/pose, per-floor frames, initialpose service."""

import json

from conftest import FAST, python_module, run, surveyed_csv, wait_until
from geometry_msgs.msg import PoseWithCovarianceStamped
import numpy as np
import pytest
from ros_helpers import RELIABLE, running_node
from std_srvs.srv import Trigger
from wifi_place_recognition.core.locator import R95
from wifi_place_recognition.data.fingerprints import read_fingerprints
from wifi_place_recognition.ros.messages import status_values

FRAME = 'b{building}_floor{floor}'


@pytest.fixture(scope='module')
def located(surveyed_model, tmp_path_factory):
    """Return (model path, test fingerprints) of a model with positions."""
    folder = tmp_path_factory.mktemp('located')
    test = read_fingerprints(surveyed_csv(folder / 'b.csv', scans_seed=1,
                                          scans_per_floor=10))
    return surveyed_model, test


class Poses:
    """Collects ~/pose and initialpose messages."""

    def __init__(self, node, name):
        self.pose, self.initial = [], []
        self.subs = [
            node.create_subscription(PoseWithCovarianceStamped,
                                     f'/{name}/pose', self.pose.append,
                                     RELIABLE),
            node.create_subscription(PoseWithCovarianceStamped,
                                     '/initialpose', self.initial.append,
                                     RELIABLE)]


def _send(client, fp, row):
    detected = np.flatnonzero(np.isfinite(fp.rssi[row]))
    msg = client.scan([fp.ap_ids[j] for j in detected],
                      fp.rssi[row, detected])
    status = client.resend_until_answered(msg, 30)
    assert status is not None
    return msg.header.stamp.sec, status_values(status)


def test_pose_per_answer_in_the_floor_frame_with_the_model_covariance(
        ros, tmp_path, located):
    model, fp = located
    with running_node(ros, tmp_path, model, 'pose_node', '-p',
                      f'frame_id:={FRAME}', '-p', 'tracking:=false') as (
            client, proc, loaded):
        poses = Poses(ros, 'pose_node')
        assert wait_until(lambda: poses.subs[0].get_publisher_count(), 30,
                          ros)
        errors, sigmas = [], []
        for row in range(len(fp)):
            stamp, values = _send(client, fp, row)
            assert wait_until(lambda: any(
                p.header.stamp.sec == stamp for p in poses.pose), 30, ros)
            pose = next(p for p in poses.pose if p.header.stamp.sec == stamp)
            assert pose.header.frame_id == FRAME.format(
                building=values['building'], floor=values['floor'])
            xy = np.array([pose.pose.pose.position.x,
                           pose.pose.pose.position.y])
            np.testing.assert_allclose(
                xy, [float(values['x']), float(values['y'])], atol=1e-3)
            assert pose.pose.pose.position.z == 0.0
            assert pose.pose.pose.orientation.w == 1.0
            cov = np.reshape(pose.pose.covariance, (6, 6))
            sigma = float(values['position_sigma_m'])
            np.testing.assert_allclose(cov[:2, :2], np.eye(2) * sigma ** 2,
                                       rtol=1e-3)  # values carry 3 decimals
            assert cov[5, 5] >= 1e6    # yaw unknown
            errors.append(np.linalg.norm(xy - fp.position[row]))
            sigmas.append(sigma)
        assert np.mean(errors) < 10.0, errors
        assert np.mean(np.array(errors) <= R95 * np.array(sigmas)) >= 0.7
        assert not client.set_param('frame_id', 'map_{room}').successful
        assert poses.initial == []


def test_publish_initial_pose_sends_the_next_confident_answer_once(
        ros, tmp_path, located):
    model, fp = located
    with running_node(ros, tmp_path, model, 'initial_node') as (
            client, proc, loaded):
        poses = Poses(ros, 'initial_node')
        service = ros.create_client(Trigger,
                                    '/initial_node/publish_initial_pose')
        assert service.wait_for_service(timeout_sec=30)
        assert wait_until(lambda: poses.subs[1].get_publisher_count(), 30,
                          ros)
        _send(client, fp, 0)
        assert not wait_until(lambda: poses.initial, 1.0, ros)
        future = service.call_async(Trigger.Request())
        assert wait_until(future.done, 30, ros)
        assert future.result().success
        assert 'initialpose' in future.result().message
        stamp, _ = _send(client, fp, 1)
        assert wait_until(lambda: poses.initial, 30, ros)
        _send(client, fp, 2)
        wait_until(lambda: len(poses.initial) > 1, 1.0, ros)
        assert len(poses.initial) == 1
        assert poses.initial[0].header.stamp.sec == stamp
        assert poses.initial[0].header.frame_id == 'map'


def test_one_floor_survey_makes_a_position_only_model(ros, tmp_path):
    one = surveyed_csv(tmp_path / 'one.csv', floors=(1,))
    model = tmp_path / 'one.npz'
    result = run(python_module('cli.train_model', '--data', one, '-o', model,
                               *FAST))
    assert result.returncode == 0, result.stderr
    assert 'position only (one class)' in result.stdout
    test = surveyed_csv(tmp_path / 'test.csv', floors=(1,), scans_seed=1,
                        scans_per_floor=10)
    result = run(python_module('cli.evaluate_model', '--model', model,
                               '--data', test, '--json'))
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout)
    assert figures['building_floor_accuracy'] == 1.0
    assert figures['position_mean_error_m'] < 10.0
    fp = read_fingerprints(test)
    with running_node(ros, tmp_path, model, 'one_node', '-p',
                      'tracking:=false') as (client, proc, loaded):
        poses = Poses(ros, 'one_node')
        assert wait_until(lambda: poses.subs[0].get_publisher_count(), 30,
                          ros)
        for row in range(3):
            stamp, values = _send(client, fp, row)
            assert (values['building'], values['floor']) == ('0', '1')
            assert float(values['confidence']) == 1.0
            assert wait_until(lambda: any(
                p.header.stamp.sec == stamp for p in poses.pose), 30, ros)
