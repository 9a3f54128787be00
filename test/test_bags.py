"""
Bags in: a shared robot run written as real bags (MCAP, SQLite3) and read.

The bags are written with the rosbags writer from b24test3's CSVs (scans
on wifi/scan, odometry on odom, AMCL on amcl_pose); read back, they give
the run's scans, odometry and poses, labels by the documented rule (equal
to the CSV's where both poses around a scan are within max_pose_age, the
CSV's rule; else the nearest pose), the same odometry drift, and the same
CSVs from bag_to_csv. Bad bags are refused in one line, nothing written.
"""

import json
import math
import shutil

from bag_helpers import (odometry_message, pose_message, RUN,
                         run_messages, scan_message, write_bag,
                         write_ros1_bag)
from conftest import python_module, run
import numpy as np
import pytest
from wifi_place_recognition.cli.common import DataOptions, read_run
from wifi_place_recognition.core.pose_label import MAX_POSE_AGE
from wifi_place_recognition.data.bags import BagOptions, read_bags
from wifi_place_recognition.data.fingerprints import read_fingerprints
from wifi_place_recognition.data.poses import read_poses

pytestmark = pytest.mark.skipif(not RUN.exists(),
                                reason='robot runs not available')


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    """Return {storage: bag folder} of the whole run b24test3."""
    folder = tmp_path_factory.mktemp('bags')
    messages = run_messages()
    return {s: write_bag(folder / s, messages, s)
            for s in ('mcap', 'sqlite3')}


def _same_scans(fp, csv):
    """Assert the scans of ``fp`` are those of the CSV's ``csv``."""
    assert len(fp) == len(csv)
    assert np.array_equal(fp.meta['TIMESTAMP'].round(6),
                          csv.meta['TIMESTAMP'].round(6))
    index = {ap: j for j, ap in enumerate(csv.ap_ids)}
    heard = [index[ap] for ap in fp.ap_ids]
    assert np.array_equal(fp.rssi, csv.rssi[:, heard], equal_nan=True)
    others = np.setdiff1d(np.arange(len(csv.ap_ids)), heard)
    assert np.isnan(csv.rssi[:, others]).all()


@pytest.mark.parametrize('storage,as_file', [('mcap', False),
                                             ('mcap', True),
                                             ('sqlite3', False)])
def test_a_bag_reads_back_as_the_run_s_csvs(bags, storage, as_file):
    path = bags[storage]
    if as_file:
        path = next(path.glob('*.mcap'))
    fp, odometry, poses = read_bags([path])
    csv = read_fingerprints(RUN / 'scans.csv')
    amcl = read_poses(RUN / 'poses.csv')
    # labels by the rule: between the two AMCL poses around each stamp
    # when both are within max_pose_age, as the CSV's X, Y, YAW (written
    # with 6 decimals); else the nearest pose
    stamps = fp.meta['TIMESTAMP']
    i = np.searchsorted(amcl[:, 0], stamps, 'right') - 1
    j = np.minimum(i + 1, len(amcl) - 1)
    both = (i >= 0) & (stamps - amcl[i, 0] <= MAX_POSE_AGE) & \
        (amcl[j, 0] >= stamps) & (amcl[j, 0] - stamps <= MAX_POSE_AGE)
    theirs = np.isin(csv.meta['TIMESTAMP'].round(6), stamps[both].round(6))
    assert 0.9 * len(csv) < both.sum() == theirs.sum() < len(fp) < len(csv) + 7
    _same_scans(fp.subset(both), csv.subset(theirs))
    assert np.abs(fp.position[both] - csv.position[theirs]).max() < 2e-6
    assert np.abs(fp.meta['YAW'][both] - csv.meta['YAW'][theirs]).max() < 2e-6
    nearest = np.abs(amcl[:, 0] - stamps[~both, None]).argmin(axis=1)
    assert np.abs(fp.position[~both] - amcl[nearest, 1:3]).max() < 1e-9
    assert np.abs(odometry - read_poses(RUN / 'odom.csv')).max() < 2e-6
    assert np.abs(poses[:, :4] - read_poses(RUN / 'poses.csv')).max() < 2e-6
    assert fp.building.tolist() == fp.floor.tolist() == [0] * len(fp)


def test_a_ros1_bag_reads_as_the_same_run(bags, tmp_path):
    messages = run_messages(seconds=120)
    # as the tools read their --data: a .bag is a bag
    ros1 = read_run([write_ros1_bag(tmp_path / 'run.bag', messages)],
                    DataOptions(), 'run')
    ros2 = read_run([write_bag(tmp_path / 'run', messages)], DataOptions(),
                    'run')
    _same_scans(ros1[0], ros2[0])
    assert np.array_equal(ros1[0].position, ros2[0].position)
    assert np.array_equal(ros1[1], ros2[1])
    assert np.array_equal(ros1[2], ros2[2])


def test_topics_with_or_without_slash_labels_and_no_poses(bags):
    fp = read_bags([bags['mcap']], BagOptions('/wifi/scan', '/odom', '',
                                              building=2, floor=3))[0]
    assert fp.position is None and 'YAW' not in fp.meta
    assert len(fp) == 689    # every scan: none left out for want of a pose
    assert set(fp.building) == {2} and set(fp.floor) == {3}


def test_bag_to_csv_writes_the_run_s_csvs(bags, tmp_path):
    out = tmp_path / 'b24test3'
    result = run(python_module('cli.bag_to_csv', bags['sqlite3'], '-o', out))
    assert result.returncode == 0, result.stderr
    for name in ('odom.csv', 'poses.csv'):
        assert (out / name).read_bytes() == (RUN / name).read_bytes()
    exported = read_fingerprints(out / 'scans.csv')
    # the labels of the bag tools (the rule), written with 6 decimals
    fp = read_bags([bags['sqlite3']])[0]
    _same_scans(exported, fp)
    assert np.abs(exported.position - fp.position).max() < 1e-6
    # the scans no pose labels are kept, without X, Y, YAW
    lines = (out / 'scans.csv').read_text().splitlines()
    assert len(lines) - 1 == len((RUN / 'scans.csv').read_text()
                                 .splitlines()) - 1 == 689


def test_fit_odometry_gives_the_same_drift_from_the_bag(bags, tmp_path,
                                                        surveyed_model):
    drift = []
    for data in (['--data', RUN / 'scans.csv', '--odometry',
                  RUN / 'odom.csv'], ['--data', bags['mcap']]):
        report = tmp_path / f'{len(drift)}.json'
        result = run(python_module('cli.fit_odometry', '--model',
                                   surveyed_model, *data, '-o',
                                   tmp_path / 'fitted.npz', '--report',
                                   report))
        assert result.returncode == 0, result.stderr
        drift.append(json.loads(report.read_text()))
    assert drift[1]['drift_deg_per_m'] == pytest.approx(
        drift[0]['drift_deg_per_m'], abs=1e-6)
    # the bag's scans the CSV leaves unlabelled (before its first pose,
    # after its last), the rule labels with the nearest pose within 5 s
    assert 0 < drift[1]['scans'] - drift[0]['scans'] <= 6
    assert drift[1]['windows'] == drift[0]['windows']


def _refused(args, tmp_path, message):
    """Run bag_to_csv and train_model: exit 2, one line, nothing written."""
    out = tmp_path / 'out'
    for argv in (python_module('cli.bag_to_csv', *args, '-o', out),
                 python_module('cli.train_model', '--data', *args, '-o',
                               tmp_path / 'm.npz')):
        result = run(argv)
        assert result.returncode == 2, result.stderr
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith('error: '), lines
        assert message in lines[0], lines[0]
        assert not list(tmp_path.glob('out/*')) and \
            not (tmp_path / 'm.npz').exists()


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_a_truncated_bag_is_refused_in_one_line(bags, tmp_path, storage):
    bag = shutil.copytree(bags[storage], tmp_path / 'cut')
    data = next(f for f in bag.iterdir() if f.name != 'metadata.yaml')
    data.write_bytes(data.read_bytes()[:data.stat().st_size // 2])
    _refused([bag], tmp_path, 'truncated or corrupt')
    # a good bag before it: nothing of it written either
    _refused([bags[storage], bag], tmp_path, 'truncated or corrupt')


def _bag(tmp_path, messages, storage='mcap'):
    return write_bag(tmp_path / 'bag', messages, storage)


def test_bad_bags_are_refused_in_one_line(tmp_path):
    first = run_messages(seconds=30)
    scans = [m for m in first if m[0] == '/wifi/scan']
    odometry = [m for m in first if m[0] == '/odom']
    other = [('/wifi/scan', 'nav_msgs/msg/Odometry') + m[2:]
             for m in odometry]
    # recorded after the fifth scan, stamped a second before the first
    early = scan_message(scans[0][2].header.stamp.sec - 1,
                         ['aa:bb:cc:dd:ee:ff'], [-60.0])[0]
    backwards = scans[:5] + [('/wifi/scan', scans[0][1], early,
                              scans[4][3] + 1)]
    for name, messages, message in (
            ('wrong type', other, 'topic /wifi/scan is nav_msgs/msg/'
                                  'Odometry, not sensor_msgs/msg/JointState'),
            ('no scans', odometry, 'no topic /wifi/scan'),
            ('empty', [], 'no topic /wifi/scan'),
            ('backwards', backwards, 'time going backwards')):
        bag = _bag(tmp_path / name.replace(' ', '_'), messages)
        _refused([bag], tmp_path, message)


def test_bag_options_out_of_range_are_refused_before_reading(tmp_path):
    bag = _bag(tmp_path, run_messages(seconds=10))
    (tmp_path / 'file').write_text('not a folder')
    for args, message in (
            (('--bag-floor', str(10 ** 10)), 'labels are from 0 to'),
            (('--bag-building', '-1'), 'labels are from 0 to'),
            (('-o', tmp_path / 'file'), f'-o {tmp_path}/file: is a file')):
        argv = ['-o', tmp_path / 'out', *args] if args[0] != '-o' else \
            list(args)
        result = run(python_module('cli.bag_to_csv', bag, *argv))
        assert result.returncode == 2 and result.stderr.startswith(
            'error: ') and message in result.stderr, result.stderr
    assert not (tmp_path / 'out').exists()
    assert (tmp_path / 'file').read_text() == 'not a folder'


def _stamp(message):
    stamp = message[2].header.stamp
    return stamp.sec + stamp.nanosec * 1e-9


def test_what_the_csvs_cannot_hold_is_left_out_and_counted(tmp_path):
    messages = run_messages(seconds=30)
    at = {topic: [i for i, m in enumerate(messages) if m[0] == topic]
          for topic in ('/wifi/scan', '/odom', '/amcl_pose')}
    i = at['/odom'][3]
    messages[i] = messages[i][:2] + odometry_message(
        _stamp(messages[i]), math.nan, 0.0, 0.0)
    i = at['/amcl_pose'][1]
    messages[i] = messages[i][:2] + pose_message(
        _stamp(messages[i]), 1.0, 2.0, 0.0, math.inf, 0.0, 0.1, 0.1)
    i = at['/wifi/scan'][2]
    scan = messages[i][2]
    messages[i] = messages[i][:2] + scan_message(
        _stamp(messages[i]), list(scan.name) + ['a"b', 'c\rd'],
        list(scan.position) + [-50.0, -50.0])
    out = tmp_path / 'out'
    result = run(python_module('cli.bag_to_csv', _bag(tmp_path, messages),
                               '-o', out))
    assert result.returncode == 0, result.stderr
    for topic in ('/odom', '/amcl_pose'):
        assert f'1 message(s) on {topic} with a pose or covariance that is ' \
            f'not finite left out' in result.stderr, result.stderr
    assert '0 scan(s) with no usable reading and 2 reading(s)' in \
        result.stderr, result.stderr
    fp = read_fingerprints(out / 'scans.csv')     # every file reads back
    assert len(fp) == len(at['/wifi/scan'])
    assert not any('"' in ap or '\r' in ap for ap in fp.ap_ids)
    assert len(read_poses(out / 'odom.csv')) == len(at['/odom']) - 1
    assert len(read_poses(out / 'poses.csv')) == len(at['/amcl_pose']) - 1
    # a bag without odometry into that folder: its odom.csv would stay
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    no_odometry = [m for m in messages if m[0] != '/odom']
    result = run(python_module('cli.bag_to_csv', _bag(
        tmp_path / 'second', no_odometry), '-o', out))
    assert result.returncode == 2 and result.stderr.startswith(
        f'error: {out} holds odom.csv, which this export would leave '), \
        result.stderr
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_a_missing_odometry_topic_is_named_by_the_tool_that_needs_it(
        tmp_path, surveyed_model):
    only_scans = [m for m in run_messages(seconds=60) if m[0] != '/odom']
    bag = _bag(tmp_path, only_scans)
    result = run(python_module('cli.fit_odometry', '--model', surveyed_model,
                               '--data', bag, '-o', tmp_path / 'x.npz'))
    assert result.returncode == 2
    assert result.stderr.strip().splitlines()[-1].startswith(
        'error: no --odometry given (the run is not a bag with odometry)')


def test_scan_matrix_refuses_columns_that_miss_an_ap():
    from wifi_place_recognition.data.bags import Recording, scan_matrix
    recording = Recording('r', [(1.0, ['aa:bb:cc:dd:ee:01',
                                       'aa:bb:cc:dd:ee:02'], [-50.0, -60.0])])
    ap_ids, rssi = scan_matrix(recording, ('aa:bb:cc:dd:ee:02',
                                           'aa:bb:cc:dd:ee:01',
                                           'aa:bb:cc:dd:ee:03'))
    assert rssi[0, :2].tolist() == [-60.0, -50.0] and np.isnan(rssi[0, 2])
    with pytest.raises(ValueError, match='aa:bb:cc:dd:ee:01 is not among'):
        scan_matrix(recording, ('aa:bb:cc:dd:ee:02',))
