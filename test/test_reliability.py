"""Hostile and faulty input: torn writes, fuzzed scans, a flood of scans."""

import signal
import subprocess
import sys
import time

from conftest import (FAST, python_module, synthetic_csv, TEST_DIR,
                      wait_until)
import numpy as np
import pytest
from ros_helpers import running_node
from wifi_place_recognition.core.artifact import load_model
from fuzz import fuzz_scans
from wifi_place_recognition.ros.messages import status_values

SAVE_LOOP = (f'import sys; sys.path.insert(0, {str(TEST_DIR)!r}); '
             'from fuzz import rewrite_forever; rewrite_forever(sys.argv[1])')


def test_sigkill_while_saving_never_tears_the_model_file(tmp_path):
    path = tmp_path / 'model.npz'
    rng = np.random.default_rng(0)
    survived = 0
    for attempt in range(12):
        proc = subprocess.Popen([sys.executable, '-c', SAVE_LOOP, str(path)],
                                stdout=subprocess.PIPE, text=True)
        proc.stdout.readline()          # one complete write exists
        time.sleep(rng.uniform(0.0, 0.3))
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        model = load_model(path)        # never a torn file
        assert model.provenance['write'] >= 1
        survived += 1
    assert survived == 12


def test_sigkill_of_train_model_keeps_the_previous_artifact(tmp_path):
    data = synthetic_csv(tmp_path / 'a.csv')
    path = tmp_path / 'model.npz'
    argv = python_module('cli.train_model', '--data', data, '-o', path, *FAST)
    assert subprocess.run(argv, capture_output=True).returncode == 0
    before = path.read_bytes()
    for delay in (0.5, 1.5, 2.5):
        proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        time.sleep(delay)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        load_model(path)
        assert path.read_bytes() in (before, path.read_bytes())


@pytest.fixture
def fuzz_node(ros, synthetic, tmp_path):
    """Start a node on the synthetic model with the default max_aps."""
    with running_node(ros, tmp_path, synthetic[1], 'fuzzed_node') as started:
        yield started


def _settled_counts(client):
    """Wait until the health counts stop moving; return them."""
    last = None
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        client.health.clear()
        wait_until(lambda: len(client.health) >= 1, 3, client.node)
        values = status_values(client.health[-1])
        counts = {k: int(values[f'scans_{k}']) for k in
                  ('received', 'answered', 'rejected', 'dropped')}
        if counts == last:
            return counts, values
        last = counts
    raise AssertionError(f'counts never settled: {last}')


def test_fuzzed_scans_never_kill_the_node(fuzz_node):
    client, proc, model = fuzz_node
    sent = 0
    for msg in fuzz_scans(model.ap_ids, 10_000, seed=1):
        client.pub.publish(msg)
        sent += 1
        if sent % 200 == 0:
            wait_until(lambda: False, 0.01, client.node)
    assert proc.proc.poll() is None, proc.stop()[1]
    counts, values = _settled_counts(client)
    assert counts['received'] == (counts['answered'] + counts['rejected'] +
                                  counts['dropped'])
    assert counts['received'] > 1000, counts
    assert counts['rejected'] > 100 and counts['answered'] > 10, counts
    assert values['rejected/internal_error'] == '0'
    ids = model.ap_ids[:5]
    expected = model.predict(np.where(
        np.isin(np.array(model.ap_ids), ids), -55.0, np.nan)[None, :])
    status = client.send(ids, [-55.0] * 5)
    assert status_values(status)['building'] == str(expected[0][0])
    assert status_values(status)['floor'] == str(expected[1][0])


def test_a_flood_keeps_memory_bounded_and_answers_the_newest(fuzz_node):
    client, proc, model = fuzz_node
    _, before = _settled_counts(client)
    names = list(model.ap_ids[:8])
    t0 = time.monotonic()
    while time.monotonic() - t0 < 5.0:
        for _ in range(100):
            client.pub.publish(client.scan(names, [-60.0] * 8))
        wait_until(lambda: False, 0.001, client.node)
    last = client.seq
    assert wait_until(lambda: last in client.answers, 5, client.node)
    counts, after = _settled_counts(client)
    assert counts['dropped'] > 0
    assert counts['received'] == (counts['answered'] + counts['rejected'] +
                                  counts['dropped'])
    growth = float(after['peak_rss_mib']) - float(before['rss_mib'])
    assert growth < 100, (before['rss_mib'], after['peak_rss_mib'])
