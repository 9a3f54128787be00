"""Tracking over real ROS: a walk through classifier_node, reset, timeout."""

import re
import subprocess
import time

from conftest import python_module, run, wait_until
from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
import pytest
from ros_helpers import RELIABLE, running_node
from std_srvs.srv import Trigger
from wifi_place_recognition.core.artifact import load_model, save_model
from wifi_place_recognition.core.tracking import TrackingParams
from wifi_place_recognition.data.fingerprints import read_fingerprints
from wifi_place_recognition.ros.messages import status_values
from wifi_place_recognition.ros.replayer import unique_stamps

PERIOD = 5     # seconds between the walk's scans (their stamps)
TRACKING_ON = ('-p', 'tracking:=true')    # off by default


@pytest.fixture(scope='module')
def tracked_model(synthetic, tmp_path_factory):
    """Return (model path, {(building, floor): [scan rows]}) with tracking."""
    csv_path, model_path = synthetic
    model = load_model(model_path)
    fp = read_fingerprints(csv_path)
    # The evidence of one scan for floor 1 against floor 0 (the model's
    # typical odds) tempered to 30: one scan cannot overturn the prior odds
    # of ~99 after 5 s, two scans can, however confident the model is.
    c = {tuple(k): i for i, k in enumerate(model.classes.tolist())}
    on_floor_1 = model.predict_proba(fp.rssi[(fp.building == 0) &
                                             (fp.floor == 1)])
    odds = np.median(on_floor_1[:, c[0, 1]] /
                     np.maximum(on_floor_1[:, c[0, 0]], 1e-12))
    model.tracking = TrackingParams(
        floor_rate=2e-3, building_rate=1e-5, min_interval=5.0,
        temperature=max(1.0, float(np.log(odds) / np.log(30))))
    path = tmp_path_factory.mktemp('tracking') / 'tracked.npz'
    save_model(model, path)
    rows = {}
    for i, (b, f) in enumerate(zip(fp.building, fp.floor)):
        rows.setdefault((int(b), int(f)), []).append(i)
    return path, fp, rows


class Walk:
    """Sends scans of given classes ``PERIOD`` s apart (stamps), in order."""

    def __init__(self, client, fp, rows):
        self.client, self.fp, self.rows = client, fp, rows
        self.next = {k: iter(v) for k, v in rows.items()}

    def step(self, place, gap=PERIOD):
        """Send the next scan of class ``place`` ``gap`` s after the last."""
        row = next(self.next[place])
        detected = np.flatnonzero(np.isfinite(self.fp.rssi[row]))
        self.client.seq += gap - 1
        msg = self.client.scan([self.fp.ap_ids[j] for j in detected],
                               self.fp.rssi[row, detected])
        status = self.client.resend_until_answered(msg, 30, every=5)
        assert status is not None, f'scan {self.client.seq} not answered'
        values = status_values(status)
        return ((int(values['building']), int(values['floor'])),
                (int(values['scan_building']), int(values['scan_floor'])),
                values, status)


def test_node_holds_through_a_wrong_scan_and_follows_a_floor_change(
        ros, tmp_path, tracked_model):
    path, fp, rows = tracked_model
    with running_node(ros, tmp_path, path, 'tracking_walk',
                      *TRACKING_ON) as (client, *_):
        walk = Walk(client, fp, rows)
        walk.step((0, 0), gap=700)      # after the probe: a new walk
        answers = [walk.step((0, 0)) for _ in range(8)]
        assert all(a[0] == (0, 0) for a in answers)
        # one scan that alone says another floor: the tracked answer holds
        tracked, alone, values, status = walk.step((0, 1))
        assert alone == (0, 1) and tracked == (0, 0)
        assert 'this scan alone: building 0, floor 1' in status.message
        assert float(values['scan_confidence']) > 0.9
        assert float(values['prob/B0F0']) == float(values['confidence'])
        assert walk.step((0, 0))[0] == (0, 0)
        # a real floor change: followed within two scans, then held
        after = [walk.step((0, 1))[0] for _ in range(6)]
        assert after[1] == (0, 1) and after[1:] == [(0, 1)] * 5, after


def test_tracking_is_off_by_default(ros, tmp_path, tracked_model):
    """On WiFine val/ tracking did not beat single scans (README)."""
    path, fp, rows = tracked_model
    with running_node(ros, tmp_path, path, 'tracking_default') as (
            client, *_):
        walk = Walk(client, fp, rows)
        for _ in range(8):
            walk.step((0, 0))
        tracked, alone, values, _ = walk.step((0, 1))
        assert tracked == alone == (0, 1)
        assert values['confidence'] == values['scan_confidence']


def test_reset_service_timeout_and_switching_tracking_off(
        ros, tmp_path, tracked_model):
    path, fp, rows = tracked_model
    with running_node(ros, tmp_path, path, 'tracking_reset',
                      *TRACKING_ON) as (client, *_):
        walk = Walk(client, fp, rows)
        walk.step((0, 0), gap=700)      # after the probe: a new walk
        for _ in range(8):
            assert walk.step((0, 0))[0] == (0, 0)
        # another building in one scan is held ...
        assert walk.step((1, 1))[0] == (0, 0)
        # ... unless the belief is reset first
        reset = ros.create_client(Trigger, '/tracking_reset/reset')
        assert reset.wait_for_service(timeout_sec=30)
        future = reset.call_async(Trigger.Request())
        assert wait_until(future.done, 30, ros)
        assert future.result().success, future.result().message
        ros.destroy_client(reset)
        for _ in range(5):
            assert walk.step((1, 1))[0] == (1, 1)
        # a gap longer than tracking_timeout restarts the belief
        assert client.set_param('tracking_timeout', 30.0).successful
        assert not client.set_param('tracking_timeout', -1.0).successful
        assert walk.step((0, 0), gap=31)[0] == (0, 0)
        # tracking off: every answer is the scan's own
        assert client.set_param('tracking', False).successful
        for _ in range(3):
            walk.step((0, 0))
        tracked, alone, values, _ = walk.step((0, 1))
        assert tracked == alone == (0, 1)
        assert values['confidence'] == values['scan_confidence']


def test_replayed_stamps_are_distinct_and_never_zero():
    stamps = unique_stamps([0.0, 5.0, 5.0, 1371713733.25, 5.0])
    ns = [s.sec * 10 ** 9 + s.nanosec for s in stamps]
    assert ns == [1000, 5 * 10 ** 9, 5 * 10 ** 9 + 1000,
                  1371713733250000000, 5 * 10 ** 9 + 2000]


def walks_csv(path, fp, scans):
    """Write (time, phone, row of ``fp``, (building, floor)) as a CSV."""
    header = list(fp.ap_ids) + ['BUILDINGID', 'FLOOR', 'PHONEID', 'TIMESTAMP']
    lines = [','.join(header)]
    for t, phone, row, (b, f) in scans:
        cells = ['100' if np.isnan(v) else f'{v:g}' for v in fp.rssi[row]]
        lines.append(','.join(cells + [str(b), str(f), str(phone), f'{t:g}']))
    path.write_text('\n'.join(lines) + '\n')
    return path


def test_replay_scans_shows_each_walk_scan_alone_beside_tracked(
        ros, tmp_path, tracked_model):
    path, fp, rows = tracked_model
    # phone 1 on building 0 floor 0, its 5th scan reads like floor 1;
    # phone 2, 10 s later, on building 1: a fresh walk (the node's belief
    # is reset), else the building change would be held
    wrong = iter(rows[(0, 1)][20:])
    floor_0, building_1 = iter(rows[(0, 0)][20:]), iter(rows[(1, 1)][20:])
    scans = [(100.0 + 5 * i, 1, next(wrong if i == 4 else floor_0), (0, 0))
             for i in range(9)]
    scans += [(150.0 + 5 * i, 2, next(building_1), (1, 1)) for i in range(5)]
    data = walks_csv(tmp_path / 'walks.csv', fp, scans[::-1])
    with running_node(ros, tmp_path, path, 'tracking_walks', *TRACKING_ON):
        replay = run(python_module('cli.replay_scans', '--data', data,
                                   '--place-topic', '/tracking_walks/place',
                                   '--timeout', 20), timeout=300)
    assert replay.returncode == 0, replay.stdout + replay.stderr
    out = replay.stdout
    assert '14/14 scans answered (0 rejected), 2 walks, each in time order' \
        in out
    assert re.search(r'PHONEID=1 +0\.8889 +1\.0000 +\(9 scans\)', out), out
    assert re.search(r'PHONEID=2 +1\.0000 +1\.0000 +\(5 scans\)', out), out
    assert re.search(r'building\+floor +0\.9286 +1\.0000\n', out), out


def test_replay_scans_realtime_sends_each_walk_in_time_order_and_pace(
        ros, tmp_path, tracked_model):
    path, fp, rows = tracked_model
    # two walks (PHONEID 1, 2), rows shuffled in the file; walk 1 has a
    # 1000 s pause that --max-wait shortens
    times = {1: [100.0, 100.5, 101.0, 1101.0, 1101.5], 2: [50.0, 50.5, 51.0]}
    scans = [(t, phone, row) for phone, ts in times.items()
             for t, row in zip(ts, rows[(0, 0)][10:])]
    order = np.random.default_rng(0).permutation(len(scans))
    data = walks_csv(tmp_path / 'walks.csv', fp, [
        scans[i] + ((0, 0),) for i in order])
    with running_node(ros, tmp_path, path, 'tracking_replay',
                      *TRACKING_ON):
        seen = []
        sub = ros.create_subscription(
            DiagnosticArray, '/tracking_replay/place',
            lambda m: seen.append(
                m.header.stamp.sec + m.header.stamp.nanosec * 1e-9),
            RELIABLE)
        start = time.monotonic()
        replay = subprocess.Popen(
            python_module('cli.replay_scans', '--data', data, '--realtime',
                          '2', '--max-wait', '0.5', '--place-topic',
                          '/tracking_replay/place'),
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert wait_until(lambda: replay.poll() is not None, 120, ros)
        elapsed = time.monotonic() - start
        wait_until(lambda: len(seen) >= 8, 5, ros)
        ros.destroy_subscription(sub)
    out, err = replay.communicate()
    assert replay.returncode == 0, out + err
    assert '8/8 scans answered' in out
    # walk by walk, in time order, the recorded times as stamps
    expected = times[1] + times[2]
    assert [round(s, 3) for s in seen if s >= 50] == expected
    # paced: gaps / 2: 0.25 + 0.25 + 0.5 (max wait) + 0.25, none between
    # the walks, 0.25 + 0.25
    assert 1.5 <= elapsed < 60
