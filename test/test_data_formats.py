"""Fingerprint data the package did not write: read it, or refuse it clearly."""

import hashlib
import json
import os
from pathlib import Path

from conftest import FAST, python_module, REPO, run
import numpy as np
import pytest
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.evaluation import align
from wifi_place_recognition.core.scan import ScanMapper
from wifi_place_recognition.data.fingerprints import (
    DataError, Fingerprints, parse_fingerprints, read_fingerprints,
    ReaderOptions)
from wifi_place_recognition.data.poses import read_poses

WIFINE = Path(os.environ.get('WIFI_PR_WIFINE',
                             REPO.parent / 'shared' / 'datasets' / 'wifine'))
#: How WiFine is read (its README: floorID, one building, -100, x/y/z).
WIFINE_OPTIONS = dict(floor_column='floorID', building_column=None,
                      not_detected_marker=-100,
                      meta_columns=('num_visible_APs', 'z'))
WIFINE_ARGS = ['--floor-column', 'floorID', '--building-column', 'none',
               '--not-detected-marker', '-100',
               '--meta-columns', 'num_visible_APs,z']


def parse(text, **options):
    return parse_fingerprints(text, ('f.csv', text.encode()),
                              ReaderOptions(**options))


def walk_csv(path, floor, seed, scans=30, n_aps=12, start=0.0):
    """Write one walk in WiFine's format: -100 = not detected, floorID."""
    centres = np.random.default_rng(floor).uniform(-90, -45, n_aps)
    centres[np.random.default_rng(floor + 10).choice(n_aps, n_aps // 2,
                                                     replace=False)] = -100
    rng = np.random.default_rng(seed)
    lines = [','.join([str(i) for i in range(n_aps)] + [
        'num_visible_APs', 'timestamp', 'x', 'y', 'z', 'floorID'])]
    for s in range(scans):
        noisy = np.round(centres + rng.normal(0, 3, n_aps)).clip(-99, -30)
        rssi = np.where(centres > -100, noisy, -100)
        lines.append(','.join([f'{v:.1f}' for v in rssi] + [
            str(int((rssi > -100).sum())), f'{start + 4.5 * s:.3f}',
            f'{10 + s * 0.5:.6f}', f'{2 + floor:.6f}', '1.39', str(floor)]))
    Path(path).write_text('\n'.join(lines) + '\n')
    return path


# 1. metadata columns outside the fixed list ---------------------------------

ISSUE_COLUMNS = ('WAP001,WAP002,SceneID,SampleTimes,ALTITUDE,num_visible_APs,'
                 'Comment,FLOOR,BUILDINGID\n'
                 '-50,100,3,12,4.5,1,ok,0,0\n'
                 '-60,-70,3,7,0,2,moved,1,0\n'
                 '100,-80,8,9,7.5,1,ok,1,0\n')


def test_metadata_columns_outside_the_fixed_list_are_not_aps():
    fp = parse(ISSUE_COLUMNS)
    assert fp.ap_ids == ('WAP001', 'WAP002')
    assert fp.clipped == 0
    [note] = fp.notes
    for shown in ('SceneID (e.g. 3)', 'SampleTimes (e.g. 12)',
                  'ALTITUDE (e.g. 4.5)', 'num_visible_APs (e.g. 1)',
                  "Comment (e.g. 'ok')"):
        assert shown in note
    assert fp.meta['SceneID'].tolist() == [3, 3, 8]
    assert fp.meta['Comment'].tolist() == ['ok', 'moved', 'ok']

    named = parse(ISSUE_COLUMNS, meta_columns=(
        'SceneID', 'SampleTimes', 'ALTITUDE', 'num_*', 'Comment'))
    assert named.ap_ids == fp.ap_ids and named.notes == []
    only = parse(ISSUE_COLUMNS, ap_columns=('WAP00*',))
    assert only.ap_ids == fp.ap_ids
    assert 'left out: SceneID, SampleTimes' in only.notes[0]
    with pytest.raises(DataError, match="no AP columns .none matches 'WAP9'"):
        parse(ISSUE_COLUMNS, ap_columns=('WAP9',))
    with pytest.raises(DataError, match="row 2, column Comment: value 'ok' "
                                        "is not a number"):
        parse(ISSUE_COLUMNS, ap_columns=('WAP*', 'Comment'))


# 2. the not-detected marker ------------------------------------------------

MINUS_100 = ('0,1,2,3,4,5,FLOOR,BUILDINGID\n'
             '-50,-60,-100,-100,-100,-100,0,0\n'
             '-100,-55,-70,-100,-100,-100,0,0\n'
             '-100,-100,-100,-65,-75,-100,1,0\n'
             '-100,-100,-100,-100,-80,-45,1,0\n')


def test_a_bottom_marker_is_detected_with_a_note_or_given():
    fp = parse(MINUS_100)
    assert np.isfinite(fp.rssi).sum(axis=1).tolist() == [2, 2, 2, 2]
    assert any('-100 fills 67% of the cells of the AP columns' in n
               for n in fp.notes)
    assert '2.0 detected per scan on average' in fp.summary()
    given = parse(MINUS_100, not_detected_marker=-100)
    np.testing.assert_array_equal(given.rssi, fp.rssi)
    assert given.notes == []
    as_signal = parse(MINUS_100, not_detected_marker=100)
    assert np.isfinite(as_signal.rssi).all()     # the silent failure


def test_a_rare_bottom_value_stays_a_reading():
    fp = parse('W1,W2,W3,FLOOR,BUILDINGID\n-100,100,100,0,0\n'
               '-60,-100,100,1,0\n')
    assert fp.rssi[0, 0] == -100 and fp.rssi[1, 1] == -100
    assert fp.notes == []


def test_a_zero_marker_is_refused_until_named():
    text = 'A,B,FLOOR,BUILDINGID\n0,-60,0,0\n0,0,1,0\n-70,0,1,0\n'
    with pytest.raises(DataError, match=r'no AP columns: .*'
                                        r'--not-detected-marker'):
        parse(text)
    fp = parse(text, not_detected_marker=0)
    np.testing.assert_array_equal(fp.rssi, [[np.nan, -60], [np.nan, np.nan],
                                            [-70, np.nan]])


# 3. device ids as text, times as ISO dates ----------------------------------

def test_device_names_are_categories_and_iso_times_are_seconds():
    fp = parse('WAP1,WAP2,FLOOR,BUILDINGID,PHONEID,TIMESTAMP\n'
               '-50,-60,0,0,Sony E5823,2017-08-18 11:59:23\n'
               '-55,100,1,0,"Galaxy S6, white",2017-08-18T11:59:28.5\n'
               '100,-70,1,0,Sony E5823,2017-08-18 12:59:23+01:00\n')
    assert fp.meta['PHONEID'].tolist() == ['Sony E5823', 'Galaxy S6, white',
                                           'Sony E5823']
    assert fp.meta['TIMESTAMP'].tolist() == [1503057563.0, 1503057568.5,
                                             1503057563.0]
    numbers = parse('WAP1,FLOOR,BUILDINGID,model,time\n-50,0,0,13,17.5\n'
                    '-60,1,0,2,21\n', device_column='model',
                    time_column='time')
    assert numbers.meta['PHONEID'].tolist() == [13, 2]
    assert numbers.meta['PHONEID'].dtype == np.int64
    assert numbers.meta['TIMESTAMP'].tolist() == [17.5, 21.0]
    with pytest.raises(DataError, match='f.csv: row 3, column TIMESTAMP: '
                                        'value nan is not a finite number'):
        parse('WAP1,FLOOR,BUILDINGID,PHONEID,TIMESTAMP\n-50,0,0,Sony,1.5\n'
              '-60,1,0,Sony,nan\n')


@pytest.mark.parametrize('device, time, message', [
    ('Sony', 'yesterday', "row 3, column TIMESTAMP: value 'yesterday' is "
                          "neither a number nor an ISO date"),
    ('Sony', '2017-13-45 11:00:00', "row 3, column TIMESTAMP: value "
                                    "'2017-13-45 11:00:00'"),
    ('', '2017-08-18 11:59:23', 'row 3, column PHONEID: empty device id'),
])
def test_unreadable_devices_and_times_name_file_row_and_column(
        device, time, message):
    with pytest.raises(DataError) as err:
        parse(f'WAP1,FLOOR,BUILDINGID,PHONEID,TIMESTAMP\n'
              f'-50,0,0,Sony,2017-08-18 11:59:20\n'
              f'-60,1,0,{device},{time}\n')
    assert str(err.value).startswith('f.csv: ')
    assert message in str(err.value)


def test_named_columns_must_exist():
    text = 'WAP1,FLOOR,BUILDINGID\n-50,0,0\n-60,1,0\n'
    for options, message in [
            (dict(device_column='model'), "no device column 'model'"),
            (dict(time_column='when'), "no time column 'when'"),
            (dict(position_columns=('E', 'N')), "no position column 'E'"),
            (dict(floor_column='BUILDINGID'),
             "'BUILDINGID' cannot be the building and the floor column")]:
        with pytest.raises(DataError, match=message):
            parse(text, **options)


# 4. several files, folders: walks -------------------------------------------

def test_a_folder_is_one_walk_per_file(tmp_path):
    folder = tmp_path / 'train'
    folder.mkdir()
    walk_csv(folder / 'a.csv', 0, seed=1, scans=3)
    walk_csv(folder / 'b.csv', 1, seed=2, scans=4, n_aps=14)
    walk_csv(folder / 'c.csv', 2, seed=3, scans=2)
    (folder / 'notes.txt').write_text('not a walk')
    fp = read_fingerprints(folder, options=ReaderOptions(**WIFINE_OPTIONS))
    assert fp.source == str(folder)
    assert fp.walk.tolist() == ['a.csv'] * 3 + ['b.csv'] * 4 + ['c.csv'] * 2
    assert fp.line.tolist() == [2, 3, 4, 2, 3, 4, 5, 2, 3]
    assert fp.ap_ids == tuple(str(i) for i in range(14))  # the union
    assert np.isnan(fp.rssi[:3, 12:]).all() and np.isnan(fp.rssi[7:, 12:]).all()
    assert (np.isfinite(fp.rssi).sum(axis=1) ==
            fp.meta['num_visible_APs']).all()
    assert fp.building.tolist() == [0] * 9
    assert fp.floor.tolist() == [0] * 3 + [1] * 4 + [2] * 2
    assert fp.meta['TIMESTAMP'][:3].tolist() == [0.0, 4.5, 9.0]
    assert fp.position_columns == ('x', 'y')
    assert fp.position[3].tolist() == [10.0, 3.0]
    digest = hashlib.sha256()
    for name in ('a.csv', 'b.csv', 'c.csv'):
        raw = (folder / name).read_bytes()
        digest.update(name.encode() + b'\0' + len(raw).to_bytes(8, 'big')
                      + raw)
    assert fp.sha256 == digest.hexdigest()
    assert 'from 3 files' in fp.summary()

    sub = fp.subset(fp.floor == 1)
    assert sub.walk.tolist() == ['b.csv'] * 4
    assert sub.position[0].tolist() == [10.0, 3.0]
    assert sub.line.tolist() == [2, 3, 4, 5]
    assert sub.meta['TIMESTAMP'].tolist() == [0.0, 4.5, 9.0, 13.5]

    several = read_fingerprints([folder / 'c.csv', folder / 'a.csv'],
                                options=ReaderOptions(**WIFINE_OPTIONS))
    assert several.walk.tolist() == [str(folder / 'c.csv')] * 2 + \
        [str(folder / 'a.csv')] * 3
    assert several.source == f'{folder / "c.csv"} and 1 more'
    (folder / 'a.csv').rename(folder / 'a2.csv')
    assert read_fingerprints(folder, options=ReaderOptions(
        **WIFINE_OPTIONS)).sha256 != fp.sha256


def test_folder_errors_name_the_file(tmp_path):
    (tmp_path / 'train').mkdir()
    (tmp_path / 'test').mkdir()
    with pytest.raises(DataError, match='no .csv files in this folder '
                                        r'\(it has folders: test, train\)'):
        read_fingerprints(tmp_path)
    options = ReaderOptions(**WIFINE_OPTIONS)
    walk_csv(tmp_path / 'train' / 'a.csv', 0, seed=1, scans=3)
    bad = tmp_path / 'train' / 'b.csv'
    walk_csv(bad, 1, seed=2, scans=3)
    lines = bad.read_text().splitlines()
    lines[3] = lines[3].replace('-100.0', '-200.0', 1)
    bad.write_text('\n'.join(lines) + '\n')
    with pytest.raises(DataError, match=f'{bad}: row 4, column .*: RSSI '
                                        f'-200 dBm'):
        read_fingerprints(tmp_path / 'train', options=options)
    walk_csv(bad, 1, seed=2, scans=3)
    bad.write_text(bad.read_text().replace('timestamp', 'seconds'))
    with pytest.raises(DataError, match=f'{bad}: has no time column, '
                                        f'unlike .*a.csv'):
        read_fingerprints(tmp_path / 'train', options=options)


# 5. suspicious labels --------------------------------------------------------

def small_class_text():
    rows = [f'{-50 - i % 30},{-70 + i % 20},{f},0' for f in (0, 1)
            for i in range(100)]
    rows[150:153] = ['-55,-60,7,0'] * 3        # a typo'd floor, 3 scans
    return 'WAP1,WAP2,FLOOR,BUILDINGID\n' + '\n'.join(rows) + '\n'


def test_classes_far_smaller_than_the_rest_warned_dropped_or_kept():
    text = small_class_text()
    assert parse(text).notes == []               # no check unless asked
    warned = parse(text, small_classes='warn')
    assert len(warned) == 200
    [note] = warned.notes
    assert 'building 0, floor 7: 3 scan(s), first at row 152' in note
    assert '--small-classes drop' in note
    dropped = parse(text, small_classes='drop')
    assert len(dropped) == 197 and 7 not in dropped.floor
    assert 'left out' in dropped.notes[0]
    kept = parse(text, small_classes='keep')
    assert len(kept) == 200 and 'kept as asked' in kept.notes[0]
    assert parse(text.replace(',7,0', ',1,0'), small_classes='warn').notes \
        == []


# 6. one mapping: offline as in the node ----------------------------------------

def test_offline_mapping_is_the_nodes_mapping(synthetic):
    model = load_model(synthetic[1])
    a, b = model.ap_ids[0], model.ap_ids[1]
    dashed = a.upper().replace(':', '-')
    rssi = np.array([[-40, np.nan, -70], [np.nan, -55, np.nan],
                     [-60, -80, np.nan], [-80, -60, np.nan]], np.float32)
    fp = Fingerprints((dashed, a.lower(), b), rssi, np.zeros(4, np.int64),
                      np.zeros(4, np.int64))
    offline = align(model, fp)
    mapper = ScanMapper(model.ap_ids)
    for row, mapped in zip(fp.rssi, offline):
        seen = np.isfinite(row)                   # what a scan would list
        names = [n for n, s in zip(fp.ap_ids, seen) if s]
        scan = mapper.map(names, row[seen])
        online = np.full(len(model.ap_ids), np.nan, np.float32)
        online[scan.columns] = scan.rssi
        np.testing.assert_array_equal(mapped, online)
    assert offline[:, 0].tolist() == [-40, -55, -60, -60]

    read = parse(f'{dashed},{a.lower()},{b},FLOOR,BUILDINGID\n'
                 f'-40,100,-70,0,0\n100,-55,100,0,0\n-60,-80,100,1,0\n'
                 f'-80,-60,100,1,0\n')
    assert read.ap_ids == (dashed, b)
    assert 'merged, the strongest reading wins' in read.notes[0]
    np.testing.assert_array_equal(align(model, read), offline)


def test_one_dataset_onto_anothers_ap_columns_as_the_node_maps():
    # test data aligned onto training data (validation, baselines): the
    # node's rule, not a name lookup of its own
    train = Fingerprints(('aa:bb:cc:00:00:01', 'WAP002', 'aa:bb:cc:00:00:03'),
                         np.zeros((1, 3), np.float32), np.zeros(1, np.int64),
                         np.zeros(1, np.int64))
    rssi = np.array([[-70, -40, -50, -90], [np.nan, -45, np.nan, -60],
                     [-30, np.nan, -75, np.nan]], np.float32)
    test = Fingerprints(('AA-BB-CC-00-00-03', 'wap002', 'AABBCC000003',
                         'aa:bb:cc:00:00:09'), rssi, np.zeros(3, np.int64),
                        np.zeros(3, np.int64))
    aligned = align(train, test)
    np.testing.assert_array_equal(aligned, [[np.nan, -40, -50],
                                            [np.nan, -45, np.nan],
                                            [np.nan, np.nan, -30]])
    mapper = ScanMapper(train.ap_ids)
    for row, mapped in zip(test.rssi, aligned):
        seen = np.isfinite(row)
        scan = mapper.map([n for n, s in zip(test.ap_ids, seen) if s],
                          row[seen])
        online = np.full(len(train.ap_ids), np.nan, np.float32)
        online[scan.columns] = scan.rssi
        np.testing.assert_array_equal(mapped, online)


# 7. one building, a floor column of its own name -------------------------------

def test_one_building_with_a_floor_column_of_its_own_name():
    text = ('0,1,x,y,floorID\n-50,-100,1.5,2.5,4\n-100,-60,3.5,1.25,5\n'
            '-70,-100,2.5,2.0,4\n')
    with pytest.raises(DataError, match=r'missing label column\(s\) '
                                        r'BUILDINGID, FLOOR .*floorID'):
        parse(text)
    fp = parse(text, floor_column='floorID', building_column=None,
               not_detected_marker=-100)
    assert fp.building.tolist() == [0, 0, 0]
    assert fp.floor.tolist() == [4, 5, 4]
    assert fp.notes == ['f.csv: no building column: building 0 for every '
                        'scan']
    assert fp.position.tolist() == [[1.5, 2.5], [3.5, 1.25], [2.5, 2.0]]


def test_positions_keep_float64_and_a_missing_one_is_refused():
    text = ('WAP1,X,Y,FLOOR,BUILDINGID\n-50,-7541.2643,4864920.7782,0,0\n'
            '-60,-7600.5,4864900.25,1,0\n')
    fp = parse(text)
    assert fp.position_columns == ('X', 'Y')
    assert fp.position.dtype == np.float64
    assert fp.position[0].tolist() == [-7541.2643, 4864920.7782]
    missing = text + '-70,-7590.5,,1,0\n'
    with pytest.raises(DataError, match="f.csv: row 4, column Y: value '' "
                                        "is not a number"):
        parse(missing)
    ignored = parse(missing, position_columns=None)
    assert ignored.position is None and ignored.ap_ids == ('WAP1',)


def test_robot_run_rows_without_a_pose_are_left_out_and_yaw_is_no_ap():
    """A robot run's scans.csv: empty X, Y before the first pose; YAW."""
    text = ('TIMESTAMP,X,Y,YAW,aa:bb:cc:dd:ee:01,aa:bb:cc:dd:ee:02,'
            'BUILDINGID,FLOOR\n'
            '10.5,,,,-60,100,0,0\n'
            '11.5,1.25,-2.5,-2.9,-61,-70,0,0\n'
            '12.5,1.5,-2.25,-3.1,-65,-72,0,0\n'
            '13.5,1.75,-2.0,-1.5,100,-75,0,0\n')
    fp = parse(text)
    assert fp.ap_ids == ('aa:bb:cc:dd:ee:01', 'aa:bb:cc:dd:ee:02')
    assert fp.line.tolist() == [3, 4, 5]
    assert fp.position[:, 0].tolist() == [1.25, 1.5, 1.75]
    assert fp.meta['YAW'].astype(float).tolist() == [-2.9, -3.1, -1.5]
    assert fp.notes == ['f.csv: 1 row(s) with empty X and Y left out '
                        '(rows 2)']
    with pytest.raises(DataError, match="row 3, column Y: value '' is not"):
        parse(text.replace('1.25,-2.5', '1.25,'))
    assert fp.meta['YAW'].dtype == np.float64
    # a position or heading that is no finite number, or not in radians
    for old, new, message in [
            ('1.25,-2.5', 'nan,-2.5', "row 3, column X: value 'nan' is not "
                                      "a finite number"),
            ('1.25,-2.5', '1.25,inf', "row 3, column Y: value 'inf'"),
            ('1.25,-2.5', '1e999,-2.5', "row 3, column X: value '1e999'"),
            ('-2.9,-61', '172,-61', 'row 3, column YAW: value 172 is '
                                    'beyond'),
            ('-2.9,-61', 'abc,-61', "row 3, column YAW: value 'abc' is "
                                    "not a number"),
            ('-2.9,-61', ',-61', "row 3, column YAW: value '' is not")]:
        with pytest.raises(DataError, match=message):
            parse(text.replace(old, new))


def test_a_label_too_large_for_an_integer_is_refused():
    text = 'WAP1,FLOOR,BUILDINGID\n-50,0,0\n-60,1e20,0\n'
    with pytest.raises(DataError, match=r'row 3, column FLOOR: value 1e\+20 '
                                        r'is not an integer in \[0, '):
        parse(text)


def test_a_pose_file_with_a_column_twice_is_refused(tmp_path):
    for header in ('TIMESTAMP,X,Y,YAW,yaw', 'TIMESTAMP,X,X,Y,YAW'):
        path = tmp_path / 'odom.csv'
        path.write_text(header + '\n' + ','.join(['1'] * 5) + '\n')
        with pytest.raises(DataError, match=r'columns \d and \d are both'):
            read_poses(path)
    # other columns may repeat, or have no name (a trailing comma)
    path.write_text('TIMESTAMP,X,Y,YAW,cov,cov,\n1,2,3,0.5,0,0,\n')
    assert read_poses(path).tolist() == [[1, 2, 3, 0.5]]


def test_lines_ending_in_lf_cr_lf_or_a_bare_cr_read_alike(tmp_path):
    scans = ('WAP001,WAP002,LONGITUDE,LATITUDE,FLOOR,BUILDINGID\n'
             '-60,100,1.5,2.5,0,0\n-70,-80,3.5,4.5,1,0\n')
    poses = 'TIMESTAMP,X,Y,YAW\n0,0,0,0\n1,0.5,0,0.1\n'
    read = {}
    for name, end in (('lf', '\n'), ('crlf', '\r\n'), ('cr', '\r')):
        (tmp_path / f'{name}.csv').write_bytes(
            scans.replace('\n', end).encode())
        (tmp_path / f'{name}-odom.csv').write_bytes(
            poses.replace('\n', end).encode())
        fp = read_fingerprints(tmp_path / f'{name}.csv')
        read[name] = (fp.ap_ids, np.nan_to_num(fp.rssi).tolist(),
                      fp.position.tolist(), fp.floor.tolist(),
                      read_poses(tmp_path / f'{name}-odom.csv').tolist())
    assert read['crlf'] == read['lf'] and read['cr'] == read['lf']


# the real WiFine folders and the command line ----------------------------------

def wifine(split):
    if not (WIFINE / split).is_dir():
        pytest.skip('WiFine not available: set WIFI_PR_WIFINE')
    return WIFINE / split


def test_real_wifine_train_folder():
    fp = read_fingerprints(wifine('train'), options=ReaderOptions(
        floor_column='floorID', building_column=None))   # notes say the rest
    notes = ' '.join(fp.notes)
    assert '-100 fills 88% of the cells' in notes
    assert 'num_visible_APs (e.g. 42)' in notes and 'z (e.g. ' in notes
    with_options = read_fingerprints(wifine('train'), options=ReaderOptions(
        **WIFINE_OPTIONS))
    assert with_options.notes == [f'{WIFINE / "train"}: no building column: '
                                  f'building 0 for every scan']
    for fp in (fp, with_options):
        assert fp.rssi.shape == (19448, 436)
        assert len(np.unique(fp.walk)) == 120
        assert set(fp.floor) == {0, 1, 2} and set(fp.building) == {0}
        assert (np.isfinite(fp.rssi).sum(axis=1) ==
                fp.meta['num_visible_APs']).all()
        assert fp.position_columns == ('x', 'y')
        assert fp.meta['TIMESTAMP'].dtype == np.float64


def test_train_and_evaluate_walk_folders_on_the_command_line(tmp_path):
    for split, seed in (('train', 0), ('test', 100)):
        (tmp_path / split).mkdir()
        for floor in (0, 1, 2):
            for k in (0, 1):
                walk_csv(tmp_path / split / f'walk_{floor}_{k}.csv', floor,
                         seed=seed + 2 * floor + k, start=1000.0 * k)
    model = tmp_path / 'model.npz'
    result = run(python_module(
        'cli.train_model', '--data', tmp_path / 'train', '-o', model,
        '--test', tmp_path / 'test', *WIFINE_ARGS, *FAST))
    assert result.returncode == 0, result.stderr
    assert f'{tmp_path / "train"}: 180 scans from 6 files, 12 APs, 6.0 ' \
        f'detected per scan on average, 3 building/floor classes' \
        in result.stderr
    assert 'note: ' in result.stderr and 'building 0 for every scan' \
        in result.stderr
    assert load_model(model).provenance['selection']['grouping'] == 'walk'

    result = run(python_module(
        'cli.evaluate_model', '--model', model, '--data',
        *sorted((tmp_path / 'test').iterdir())[:4], *WIFINE_ARGS, '--json'))
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)['samples'] == 120

    bad = tmp_path / 'test' / 'walk_0_0.csv'
    bad.write_text(bad.read_text().replace(',4.500,', ',soon,', 1))
    result = run(python_module('cli.evaluate_model', '--model', model,
                               '--data', tmp_path / 'test', *WIFINE_ARGS))
    assert result.returncode == 2
    assert f"{bad}: row 3, column timestamp: value 'soon' is not a number" \
        in result.stderr
    assert 'Traceback' not in result.stderr
