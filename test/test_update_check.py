"""The update's check and its models folder, in process (no torch)."""

import errno
import json
import os
from types import SimpleNamespace

import numpy as np
import pytest
from wifi_place_recognition.core import model_store
from wifi_place_recognition.core.model_store import ModelStore, StoreError
from wifi_place_recognition.core.update_check import (
    ap_changes, MIN_HELD_OUT, newest, off_survey, position_judges, Tolerance,
    verdict)

IN_USE = {'building_floor_accuracy': 0.90, 'position_mean_error_m': 3.0}


def test_the_newest_share_is_held_out_by_time_not_by_row():
    stamps = np.array([50.0, 10.0, 40.0, 20.0, 30.0, 60.0, 0.0, 70.0, 80.0,
                       90.0])
    assert np.flatnonzero(newest(stamps, 10, 0.2)).tolist() == [8, 9]
    assert np.flatnonzero(newest(stamps, 10, 0.3)).tolist() == [7, 8, 9]
    assert np.flatnonzero(newest(None, 10, 0.2)).tolist() == [8, 9]
    assert newest(None, 3, 0.9).sum() == 2      # one is left to train on


@pytest.mark.parametrize('candidate, ok, why', [
    ({'building_floor_accuracy': 0.95, 'position_mean_error_m': 2.0}, True,
     'not worse'),
    ({'building_floor_accuracy': 0.885, 'position_mean_error_m': 3.2}, True,
     'not worse'),      # within the tolerance
    ({'building_floor_accuracy': 0.85, 'position_mean_error_m': 2.0}, False,
     'building+floor accuracy 0.8500 against 0.9000 (tolerance 0.02)'),
    ({'building_floor_accuracy': 0.95, 'position_mean_error_m': 3.3}, False,
     'mean position error 3.30 m against 3.00 m (tolerance 0.25 m)'),
    ({'building_floor_accuracy': 0.95}, False, 'no position output'),
])
def test_a_candidate_worse_beyond_the_tolerance_is_refused(candidate, ok,
                                                           why):
    accepted, reason = verdict(IN_USE, candidate, Tolerance())
    assert accepted == ok
    assert why in reason
    assert '\n' not in reason


def test_silent_and_new_aps():
    hour = 3600.0
    recorded = ('AA-BB-CC-00-00-01', 'aa:bb:cc:00:00:02', 'aa:bb:cc:00:00:09')
    stamps = np.array([0.0, 1.0, 2.0, 3.0]) * hour
    rssi = np.array([[-50, -60, np.nan],     # 01 and 02 heard at 0 h
                     [-50, np.nan, np.nan],
                     [-50, np.nan, -70],     # 09 new
                     [-50, np.nan, np.nan]])
    model = ('aa:bb:cc:00:00:01', 'aa:bb:cc:00:00:02', 'aa:bb:cc:00:00:03')
    found = ap_changes(model, recorded, rssi, stamps, 2 * hour)
    assert found['silent'] == [{'ap': 'aa:bb:cc:00:00:02', 'last_heard': 0.0},
                               {'ap': 'aa:bb:cc:00:00:03',
                                'last_heard': None}]
    assert found['new'] == ['aa:bb:cc:00:00:09']
    assert found['recorded_span_s'] == 3 * hour
    # a recording shorter than the window judges no AP silent
    short = ap_changes(model, recorded, rssi, stamps, 4 * hour)
    assert short['silent'] == [] and 'spans less' in short['note']
    untimed = ap_changes(model, recorded, rssi, None, hour)
    assert untimed['silent'] == [] and untimed['new'] == found['new']


def _places(building, floor, xy):
    return SimpleNamespace(building=np.array(building),
                           floor=np.array(floor),
                           position=np.array(xy, np.float64))


def test_new_ground_is_off_every_survey_scan_of_its_own_floor():
    survey = _places([0, 0, 0], [0, 0, 1], [[0, 0], [10, 0], [20, 0]])
    recorded = _places(
        [0, 0, 0, 0, 0, 1],
        [0, 0, 0, 1, 2, 0],
        [[2.9, 0], [13.1, 0], [5, 0],   # within 3 m; beyond; 5 m from both
         [10, 0],                       # on a survey scan of floor 0 only
         [0, 0], [0, 0]])               # a floor and a building unsurveyed
    assert off_survey(recorded, survey).tolist() == \
        [False, True, True, True, True, True]
    with pytest.raises(ValueError, match='survey scans have no positions'):
        off_survey(recorded, SimpleNamespace(building=np.array([0]),
                                             floor=np.array([0]),
                                             position=None))


def test_the_position_is_judged_where_the_candidate_learned():
    survey = _places([0, 0], [0, 0], [[0, 0], [10, 0]])
    recorded = _places([0], [0], [[40, 0]])
    n = MIN_HELD_OUT + 2
    # near the survey, near the recorded scan, on ground nobody learned
    x = [1.0] * (n - 4) + [2.0, 41.0, 25.0, 60.0]
    held = _places([0] * n, [0] * n, [[v, 0] for v in x])
    assert position_judges(held, [survey, recorded]).tolist() == \
        [True] * (n - 2) + [False, False]
    # too few where it learned: every held-out scan judges
    few = _places([0] * n, [0] * n, [[25.0, 0]] * (n - 3) + [[0, 0]] * 3)
    assert position_judges(few, [survey, recorded]).all()


def _model(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content)
    return path


def _listing(folder):
    return sorted((p.name, p.read_bytes() if p.is_file() else None)
                  for p in folder.iterdir())


def test_install_keeps_every_model_and_rollback_restores_the_previous(
        tmp_path):
    folder = tmp_path / 'models'
    folder.mkdir()
    store = ModelStore(folder)
    assert store.current() is None
    first = store.install(_model(tmp_path, 'a.npz', b'model A'),
                          {'decision': 'adopted'})
    second = store.install(_model(tmp_path, 'b.npz', b'model B'),
                           {'decision': 'put in use'})
    assert store.current() == second
    assert (folder / 'current.npz').read_bytes() == b'model B'
    report = json.loads(second.with_suffix('.json').read_text())
    assert report['decision'] == 'put in use'
    assert report['file'] == second.name
    assert second.name.endswith(report['sha256'][:12] + '.npz')
    assert first.read_bytes() == b'model A'
    now, undone = store.rollback()
    assert (now, undone) == (first, second)
    assert store.current() == first
    assert os.readlink(folder / 'current.npz') == first.name
    assert undone.exists()      # kept
    with pytest.raises(StoreError, match='nothing to roll back to'):
        store.rollback()
    assert store.current() == first
    # a new model after a rollback: the rolled-back one is not its previous
    third = store.install(_model(tmp_path, 'c.npz', b'model C'), {})
    assert store.rollback()[0] == first
    assert third.exists()


@pytest.mark.parametrize('failing', ['.json', 'current'])
def test_a_failed_install_leaves_the_folder_as_it_was(tmp_path, monkeypatch,
                                                      failing):
    folder = tmp_path / 'models'
    folder.mkdir()
    store = ModelStore(folder)
    store.install(_model(tmp_path, 'a.npz', b'model A'), {})
    before = _listing(folder)
    real = model_store.atomic_write

    def disk_full(path, mode='wb'):
        if str(path).endswith(failing):
            raise OSError(errno.ENOSPC, 'No space left on device', str(path))
        return real(path, mode)
    monkeypatch.setattr(model_store, 'atomic_write', disk_full)
    with pytest.raises(OSError, match='No space left'):
        store.install(_model(tmp_path, 'b.npz', b'model B'), {})
    assert _listing(folder) == before


def test_a_report_that_is_not_json_writes_nothing(tmp_path):
    folder = tmp_path / 'models'
    folder.mkdir()
    with pytest.raises(ValueError):
        ModelStore(folder).install(_model(tmp_path, 'a.npz', b'A'),
                                   {'error_m': float('nan')})
    assert list(folder.iterdir()) == []


def test_a_broken_history_is_named(tmp_path):
    (tmp_path / 'current').write_text('20250101T000000000000Z-abc\n')
    with pytest.raises(StoreError, match='lists 20250101T000000000000Z-abc, '
                                         'not in the folder'):
        ModelStore(tmp_path).current()
    with pytest.raises(StoreError, match='not a folder'):
        ModelStore(tmp_path / 'nothing')
