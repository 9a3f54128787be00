"""classifier_node over real ROS 2: node and test client in separate processes."""

import csv
import signal

from conftest import dataset_file, python_module, REPO, run
from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
import pytest
from ros_helpers import Client, NodeProcess, running_node
from fuzz import hostile_model_files
from wifi_place_recognition.core.artifact import load_model, save_model
from wifi_place_recognition.data.fingerprints import read_fingerprints
from wifi_place_recognition.ros.messages import status_values


@pytest.fixture
def running(ros, synthetic, tmp_path, request):
    """
    Start a node on the synthetic model; yield (client, proc, model).

    Tracking is off: these tests check each scan's own answer (tracking:
    test_tracking_node).
    """
    name = f'classifier_{request.node.name[5:25]}'.replace('[', '_')
    with running_node(ros, tmp_path, synthetic[1], name, '-p',
                      'max_aps:=50', '-p', 'tracking:=false') as started:
        yield started


def test_answers_match_the_model_and_carry_the_contract(running, synthetic):
    client, proc, model = running
    assert client.set_param('tracking', False).successful
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
        # In the node (scan taken -> answer published) is a part of the
        # round trip this side measured (publish -> answer received).
        assert 0 < float(values['latency_ms']) <= \
            client.round_trip_ms[client.seq], (values['latency_ms'],
                                               client.round_trip_ms)
        probs = [float(values[f'prob/{n}']) for n in model.class_names]
        np.testing.assert_allclose(probs, proba[0], atol=1e-6)
        assert status.message.startswith(
            f'building {building[0]}, floor {floor[0]} (p=')


def test_the_node_applies_the_temperature_of_its_model_file(
        ros, synthetic, tmp_path):
    model = load_model(synthetic[1])
    fp = read_fingerprints(synthetic[0])
    rows = range(0, len(fp), 29)
    raw = model.predict_proba(fp.rssi[list(rows)])
    model.temperature = 4.0
    save_model(model, tmp_path / 'calibrated.npz')
    with running_node(ros, tmp_path, tmp_path / 'calibrated.npz',
                      'classifier_calibrated', '-p', 'max_aps:=50', '-p',
                      'tracking:=false') as (client, _, loaded):
        for row, p in zip(rows, raw):
            detected = np.flatnonzero(np.isfinite(fp.rssi[row]))
            status = client.send([model.ap_ids[j] for j in detected],
                                 list(fp.rssi[row, detected]))
            values = status_values(status)
            probs = np.array([float(values[f'prob/{n}'])
                              for n in model.class_names])
            expected = p ** (1 / 4.0) / (p ** (1 / 4.0)).sum()
            np.testing.assert_allclose(probs, expected, atol=1e-5)
            assert probs.max() < p.max() - 0.01
            assert status.level == (DiagnosticStatus.OK if probs.max() >= 0.5
                                    else DiagnosticStatus.WARN)


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
    counts, values = client.settled_counts()
    assert counts['rejected'] == len(BAD_SCANS), counts
    assert values['rejected/implausible_rssi'] == '2'
    assert values['rejected/non_finite'] == '2'
    assert counts['answered'] >= 2      # the probe and the good scan
    # a model without a coverage model cannot tell scans off the survey
    assert model.coverage is None and values['scans_off_survey'] == 'n/a'
    selection = model.provenance['selection']
    assert float(values['model_cross_validated_building_floor_accuracy']) \
        == pytest.approx(selection['accuracy_mean'])


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
        'ros.classifier_node', '--ros-args', '-p',
        f'model_path:={synthetic[1]}'), f'shutdown_{sig.name}')
    client = Client(ros, proc.name)
    client.wait_ready(proc, (['AA:BB:CC:00:00:00'], [-60.0]))
    client.close()
    code, log = proc.stop(sig)
    assert code == 0, log
    assert 'Traceback' not in log


BAD_START = [
    ('classifier_node', ['-p', 'min_confidence:=2.0'], 'classifier_node',
     "min_confidence out of range"),
    ('classifier_node', ['-p', 'min_known_aps:=abc'], 'classifier_node',
     "'min_known_aps' to 'abc' of type 'STRING'"),
    ('classifier_node', ['--params-file', 'PARAMS'], 'classifier_node',
     'min_confidence out of range'),
    ('classifier_node', ['-r', '__node:=robot_cls', '-p', 'max_aps:=0'],
     'robot_cls', 'max_aps out of range'),
    ('wifi_scanner_node', ['-p', 'period:=0.0'], 'wifi_scanner_node',
     'period out of range'),
    ('wifi_scanner_node', ['-p', 'sources:=[iw, wext]'], 'wifi_scanner_node',
     "unknown scan sources ['wext']"),
    ('record_fingerprints', ['-p', 'floor:=-2'], 'record_fingerprints',
     'floor out of range'),
    ('classifier_node', ['-p'], 'classifier_node', "trailing -p flag"),
    ('wifi_scanner_node', ['-p'], 'wifi_scanner_node', "trailing -p flag"),
    ('record_fingerprints', ['-r', 'foo'], 'record_fingerprints',
     "remap rule: '-r foo'"),
    ('classifier_node', ['--params-file', 'MISSING'], 'classifier_node',
     "params file: '--params-file MISSING'"),
    ('classifier_node', ['--no-such-option'], 'classifier_node',
     "unknown ROS arguments ['--no-such-option']"),
]


@pytest.mark.parametrize('module, args, logger, reason', BAD_START)
def test_a_bad_start_up_parameter_is_one_error_line(tmp_path, module, args,
                                                    logger, reason):
    params = tmp_path / 'params.yaml'
    params.write_text('classifier_node:\n  ros__parameters:\n'
                      '    min_confidence: 1.5\n')
    files = {'PARAMS': str(params), 'MISSING': str(tmp_path / 'missing')}
    args = [files.get(a, a) for a in args]
    reason = reason.replace('MISSING', files['MISSING'])
    if module == 'record_fingerprints':
        args += ['-p', f'output:={tmp_path / "rec.csv"}']
    result = run(python_module(f'ros.{module}', '--ros-args', *args),
                 timeout=30)
    assert result.returncode == 1, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert f'] [{logger}]: cannot start: ' in lines[0], result.stderr
    assert reason in lines[0], result.stderr
    assert '.c:' not in lines[0], result.stderr     # no rcl source lines


def test_bad_and_hostile_model_files_are_one_clear_error(synthetic, tmp_path):
    marker = tmp_path / 'PWNED'
    files = hostile_model_files(synthetic[1], tmp_path, marker)
    files['missing'] = tmp_path / 'missing.npz'
    for kind, path in files.items():
        result = run(python_module('ros.classifier_node', '--ros-args', '-p',
                                   f'model_path:={path}'), timeout=30)
        assert result.returncode == 1, kind
        assert 'cannot start' in result.stderr, kind
        assert str(path) in result.stderr, kind
        assert 'Traceback' not in result.stderr, kind
    assert not marker.exists()


def test_params_file_is_read(ros, tmp_path):
    params = tmp_path / 'params.yaml'
    params.write_text((REPO / 'config' / 'classifier_node.yaml').read_text()
                      .replace('min_known_aps: 3', 'min_known_aps: 500'))
    proc = NodeProcess(tmp_path, python_module(
        'ros.classifier_node', '--ros-args', '--params-file', params),
        'classifier_node')
    client = Client(ros, proc.name)
    try:
        status = client.wait_ready(proc, (['WAP001'], [-60.0]))
    finally:
        client.close()
        code, log = proc.stop()
    assert 'only 1 known APs (< 500)' in status.message, log
    assert code == 0


def test_closed_loop_matches_evaluate_model(tmp_path):
    data = dataset_file('validationData-public.csv')
    # single-scan answers, as evaluate_model's (tracking: test_tracking_node)
    proc = NodeProcess(tmp_path, python_module(
        'ros.classifier_node', '--ros-args', '-p', 'tracking:=false'),
        'classifier_node')
    try:
        # Lockstep: a long wait per scan costs nothing while answers come.
        replay = run(python_module('cli.replay_scans', '--data', data,
                                   '--predictions', tmp_path / 'ros.csv',
                                   '--wait', 120, '--timeout', 20),
                     timeout=600)
    finally:
        code, log = proc.stop()
    assert replay.returncode == 0, replay.stderr + log
    assert '556/556 scans answered' in replay.stdout
    offline = run(python_module('cli.evaluate_model', '--data', data,
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
