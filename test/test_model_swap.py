"""
A new model while running: classifier_node and localization_monitor.

classifier_node drives surveyed_csv's building with odometry (the fusion
test's square) on model A, then gets model B (the same building surveyed
again, other scans) through ``model_path`` while scans and odometry keep
coming: every scan is answered once, none dropped, the fused pose carries
on (same frame, no restart, no jump) and the health status names B. A file
that does not load, and a model without positions, are refused with the
reason; the running model goes on answering. localization_monitor takes a
new model the same way and names it on ``/diagnostics``. The scan queue is
made deep (a QoS override) so that scans sent faster than the node
answers wait instead of replacing each other: what is measured is the
swap, not the depth-1 queue.
"""

from conftest import FAST, python_module, run, surveyed_csv, wait_until
import numpy as np
import pytest
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from ros_helpers import Client, running_node
from test_fusion_node import Drive, odometry_of, RELIABLE_ODOM, square
from test_localization_monitor import Monitor, truth
from test_place_changes import ORIGIN
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.pipeline.scan_pipeline import ScanPipeline
from wifi_place_recognition.core.recognizer import PlaceRecognizer
from wifi_place_recognition.ros.messages import status_values

DEEP_QUEUE = ('-p', 'qos_overrides./wifi/scan.subscription.depth:=200')


@pytest.fixture(scope='module')
def model_b(tmp_path_factory):
    """Return a second model of surveyed_csv's building (other scans)."""
    folder = tmp_path_factory.mktemp('model_b')
    model = folder / 'b.npz'
    result = run(python_module(
        'cli.train_model', '--data',
        surveyed_csv(folder / 'b.csv', scans_seed=7), '-o', model, *FAST,
        '--epochs', '20'))
    assert result.returncode == 0, result.stderr
    return model


def _path_request(path):
    value = ParameterValue(type=ParameterType.PARAMETER_STRING,
                           string_value=str(path))
    return SetParameters.Request(
        parameters=[Parameter(name='model_path', value=value)])


def _answered_by(answer, names, rssi, recognizers):
    """Return which recognizer gives a scan the position ``answer`` has."""
    values = status_values(answer.status[0])
    xy = [float(values['scan_x']), float(values['scan_y'])]
    found = [name for name, recognizer in recognizers.items() if np.allclose(
        recognizer.classify(names, rssi).scan_position, xy, rtol=0,
        atol=2e-3)]
    assert len(found) == 1, (found, values)
    return found[0]


def _health(client):
    client.health.clear()
    assert wait_until(lambda: client.health, 10, client.node)
    return status_values(client.health[-1])


def test_a_swap_under_load_answers_every_scan_once_and_the_fused_pose_goes_on(
        ros, tmp_path, surveyed_model, model_b):
    with running_node(ros, tmp_path, surveyed_model, 'swap_node',
                      *DEEP_QUEUE, *RELIABLE_ODOM) as (client, proc, _):
        drive = Drive(ros, client, 'swap_node')
        route = square(laps=2)
        odometry = odometry_of(route)
        half = len(route) // 2
        drive.drive(route[:half], odometry[:half])     # converged on A
        assert _health(client)['model_path'] == str(surveyed_model)
        restarts = int(_health(client)['fusion_restarts'])
        recognizers = {name: PlaceRecognizer(load_model(path)) for name, path
                       in (('A', surveyed_model), ('B', model_b))}
        # the second lap without waiting for answers; B midway
        sent, at, future = {}, {}, None
        places = client.places
        for i in range(half, len(route) - 1):
            drive.send_odometry(odometry[i])
            if i % 10 == 9:
                drive.send_odometry(odometry[i + 1])
                t, x, y, _ = route[i]
                msg = client.scan(*drive.building.scan(x, y, 0))
                msg.header.stamp.sec = int(t)
                msg.header.stamp.nanosec = int(round((t % 1) * 1e9))
                client.publish(msg)
                sent[msg.header.stamp.sec] = (msg.name, msg.position)
                at[drive.key(msg.header.stamp)] = route[i]
            if i == half + len(route) // 4:
                future = client.params.call_async(_path_request(model_b))
            wait_until(lambda: False, 0.01, ros)
        assert wait_until(lambda: set(sent) <= set(client.answers) and
                          future.done(), 60, ros), \
            sorted(set(sent) - set(client.answers))
        assert future.result().results[0].successful, future.result()
        counts, values = client.settled_counts()
        # every scan answered once: none lost, none twice
        assert counts['dropped'] == 0 and counts['rejected'] == 0, counts
        assert client.places - places == len(sent), \
            (client.places - places, len(sent))
        assert values['model_path'] == str(model_b)
        assert int(values['fusion_restarts']) == restarts, values
        # A answered every scan until one, B every one from it on
        by = [_answered_by(client.answers[sec], names, rssi, recognizers)
              for sec, (names, rssi) in sorted(sent.items())]
        swap = by.index('B')
        assert 0 < swap and by == ['A'] * swap + ['B'] * (len(by) - swap), by
        # the fused pose carries on: same frame, and at the swap the change
        # of its error no larger than 0.1 m or the scans' own on A
        assert wait_until(lambda: set(at) <= set(drive.poses), 10, ros)
        keys = sorted(at)
        frames = {drive.poses[k].header.frame_id for k in keys}
        assert frames == {'map'}, frames
        error = np.array([[drive.poses[k].pose.pose.position.x,
                           drive.poses[k].pose.pose.position.y] -
                          (at[k][1:3] + ORIGIN) for k in keys])
        steps = np.linalg.norm(np.diff(error, axis=0), axis=1)
        jump = steps[swap - 1]
        assert jump <= max(0.1, steps[:swap - 1].max()), \
            (jump, steps[:swap - 1])
        print(f'error change at the swap {jump:.3f} m; on A: median '
              f'{np.median(steps[:swap - 1]):.3f}, largest '
              f'{steps[:swap - 1].max():.3f} m')
    log = proc.log.read_text()
    assert f'model swapped (was {surveyed_model}): model {model_b}' in log, \
        log


def test_a_bad_model_file_is_refused_and_the_running_model_answers_on(
        ros, tmp_path, surveyed_model, synthetic):
    broken = tmp_path / 'broken.npz'
    broken.write_bytes(b'not a model')
    with running_node(ros, tmp_path, surveyed_model, 'refusing_node') as \
            (client, proc, model):
        refused = {name: client.set_param('model_path', str(path))
                   for name, path in (('broken', broken),
                                      ('missing', tmp_path / 'none.npz'),
                                      ('no positions', synthetic[1]))}
        status = client.send(model.ap_ids[:6], [-60.0] * 6)
        values = _health(client)
    for name, result in refused.items():
        assert not result.successful, name
        assert result.reason.startswith('model_path refused (') and \
            result.reason.endswith(f'); still running {surveyed_model}'), \
            result.reason
    assert str(broken) in refused['broken'].reason
    assert 'cannot read' in refused['missing'].reason
    assert 'no position output' not in refused['no positions'].reason
    assert 'this one has none: restart the node' in \
        refused['no positions'].reason
    assert 'x' in status_values(status), status
    assert values['model_path'] == str(surveyed_model)


def test_the_monitor_takes_a_new_model_and_refuses_a_bad_one(
        ros, tmp_path, surveyed_model, model_b):
    broken = tmp_path / 'broken.npz'
    broken.write_bytes(b'not a model')
    m = Monitor(ros, tmp_path, 'swap_monitor', '-p',
                f'model_path:={surveyed_model}')
    client = Client(ros, 'swap_monitor')
    try:
        for k in range(5):
            m.step(k, local=truth(k))
        m.wait_state('agrees')
        assert m.latest_status()['model_path'] == str(surveyed_model)
        refused = client.set_param('model_path', str(broken))
        assert m.latest_status()['model_path'] == str(surveyed_model)
        assert client.set_param('model_path', str(model_b)).successful
        assert m.latest_status()['model_path'] == str(model_b)
        for k in range(5, 10):          # the judgement carries on
            m.step(k, local=truth(k))
    finally:
        client.close()
    assert not refused.successful
    assert refused.reason.startswith(f'model_path refused ({broken}: ') and \
        refused.reason.endswith(f'); still using {surveyed_model}'), \
        refused.reason
    assert m.states == ['waiting', 'cannot_tell', 'agrees'], m.states
    assert m.verdicts == [False, True], m.verdicts
    log = m.close()
    m.close = lambda: None
    assert f'model swapped (was {surveyed_model}): ' in log and \
        f'surveyed positions from {model_b}' in log, log


def test_the_pipeline_swaps_the_recognizer_and_keeps_the_rest(
        surveyed_model, model_b, synthetic):
    a, b = load_model(surveyed_model), load_model(model_b)
    pipeline = ScanPipeline(PlaceRecognizer(a))
    pipeline.configure(tracking=True, min_confidence=0.7, max_aps=50)
    fusion, tracker = pipeline.fusion, pipeline.recognizer.tracker
    assert pipeline.use_model(b) == []
    new = pipeline.recognizer
    assert new.model is b and pipeline.fusion is fusion
    # the same classes and tracking section: the belief carries on
    assert new.tracker is tracker
    assert (new.min_confidence, new.mapper.max_aps) == (0.7, 50)
    # a model without positions cannot replace one with (and back)
    plain = load_model(synthetic[1])
    with pytest.raises(ValueError, match='this one has none: restart'):
        pipeline.use_model(plain)
    assert pipeline.recognizer is new
    other = ScanPipeline(PlaceRecognizer(plain))
    other.configure(tracking=True)
    with pytest.raises(ValueError, match='has no position output and '
                       'this one has one'):
        other.use_model(a)
