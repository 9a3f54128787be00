"""
``update_model`` on a small building, from the command line.

A better candidate put in use, a worse one refused, nothing written on a
failure, a rollback; the same for a references-only update (asked for, or
where torch cannot be imported); nothing built with too little new
ground; the next update judged only on scans the model in use did not
learn; and over real DDS, a running classifier_node taking an update by
the printed ``model_path``, and back on the previous model after a
rollback.

The survey leaves a hole (x > 25 m of a 40 m floor) that the recorded
scans cover; while recording, three APs of the survey are gone and three
new ones are heard.
"""

import json
import sys

from conftest import FAST, mac, python_module, run
import numpy as np
import pytest
from ros_helpers import running_node
from wifi_place_recognition.core.artifact import load_model, save_model
from wifi_place_recognition.core.filter.particles import FusionParams
from wifi_place_recognition.core.model_store import ModelStore, StoreError
from wifi_place_recognition.core.tracking import TrackingParams
from wifi_place_recognition.cli import update_model
from wifi_place_recognition.core.references import PROVENANCE, \
    with_references
from wifi_place_recognition.core.scan import normalize_ap_id
from wifi_place_recognition.core.update_check import newest
from wifi_place_recognition.data.files import DataError
from wifi_place_recognition.data.fingerprints import (check_trainable,
                                                      read_fingerprints)
from wifi_place_recognition.data.recording import FingerprintLog
from wifi_place_recognition.ros.messages import status_values

APS = 33                # 0-29 in the survey; 0-2 gone and 30-32 new later
SURVEYED, RECORDED = range(30), range(3, 33)
TRAIN = [*FAST, '--epochs', '20']


def _building(seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 40, (APS, 2)), rng.integers(0, 2, APS)


def _readings(building, xy, floor, aps, rng):
    """Return {AP: dBm} heard at ``xy`` on ``floor`` (path loss)."""
    ap_xy, ap_floor = building
    aps = np.asarray(aps)
    d = np.linalg.norm(ap_xy[aps] - xy, axis=1) + 1.0
    rssi = -30 - 25 * np.log10(d) - 12 * (ap_floor[aps] != floor) + \
        rng.normal(0, 2, len(aps))
    return {mac(i): round(v) for i, v in zip(aps, rssi) if v >= -85}


def _survey(path, building, shuffled=False, per_floor=150):
    """Write the survey (x <= 25 m); ``shuffled``: its labels permuted."""
    rng = np.random.default_rng(1)
    rows = []
    for floor in (0, 1):
        for s in range(per_floor):
            xy = rng.uniform((0, 0), (25, 40))
            rows.append((_readings(building, xy, floor, SURVEYED, rng), xy,
                         floor, s % 4))
    labels = [(xy, floor) for _, xy, floor, _ in rows]
    if shuffled:
        labels = [labels[i] for i in rng.permutation(len(labels))]
    lines = [','.join([mac(i) for i in SURVEYED]
                      + ['X', 'Y', 'FLOOR', 'BUILDINGID', 'PHONEID'])]
    for (heard, _, _, phone), (xy, floor) in zip(rows, labels):
        cells = [str(heard.get(mac(i), 100)) for i in SURVEYED]
        lines.append(','.join(cells + [f'{xy[0]:.2f}', f'{xy[1]:.2f}',
                                       str(floor), '0', str(phone)]))
    path.write_text('\n'.join(lines) + '\n')
    return path


def _recorded(path, building, scans=300, lost=0, later=0):
    """
    Write what trusted_recorder would: the whole floors, 2 h, new APs.

    ``lost``: the first ``lost`` scans get each other's positions (a
    localiser lost then); ``later``: the recording that follows this
    many scans (other places, later times).
    """
    rng = np.random.default_rng(2 + later)
    rows = []
    for k in range(scans):
        xy, floor = rng.uniform(0, 40, 2), k % 2
        rows.append((xy, floor, _readings(building, xy, floor, RECORDED,
                                          rng)))
    labels = [xy for xy, _, _ in rows]
    labels[:lost] = [labels[i] for i in
                     np.random.default_rng(3).permutation(lost)]
    log = FingerprintLog(path, positions=True)
    for k, ((_, floor, heard), xy) in enumerate(zip(rows, labels)):
        log.add(list(heard), list(heard.values()), 0, floor,
                24.0 * (later + k), (xy[0], xy[1], 0.0, 'map'))
    return path


@pytest.fixture(scope='module')
def site(tmp_path_factory):
    """
    Return a folder: survey, poisoned survey, recording, model in use.

    And a recording whose scans not held out have each other's positions.
    """
    folder = tmp_path_factory.mktemp('site')
    building = _building()
    survey = _survey(folder / 'survey.csv', building)
    _survey(folder / 'poisoned.csv', building, shuffled=True)
    _recorded(folder / 'recorded.csv', building)
    _recorded(folder / 'lost.csv', building, lost=240)
    _recorded(folder / 'later.csv', building, later=300)
    result = run(python_module('cli.train_model', '--data', survey, '-o',
                               folder / 'in_use.npz', *TRAIN))
    assert result.returncode == 0, result.stderr
    return folder


def _update(site, models, *args):
    return run(python_module('cli.update_model', '--folder', models, *args,
                             *TRAIN), timeout=600)


def _history(models):
    return (models / 'current').read_text().split()


def _listing(folder):
    return sorted((p.name, p.read_bytes()) for p in folder.iterdir())


def test_update_refuse_fail_and_roll_back(site, tmp_path):
    models = tmp_path / 'models'
    models.mkdir()
    recorded = site / 'recorded.csv'
    # the model in use with the robot's odometry fit
    in_use = load_model(site / 'in_use.npz')
    in_use.fusion = FusionParams(drift_mean=0.01)
    in_use.tracking = TrackingParams(floor_rate=1e-3)
    save_model(in_use, tmp_path / 'in_use.npz')
    # a candidate that fills the hole: kept and put in use
    result = _update(site, models, '--model', tmp_path / 'in_use.npz',
                     '--survey', site / 'survey.csv', '--recorded', recorded,
                     '--ap-window', '1')
    assert result.returncode == 0, result.stderr
    adopted, first = _history(models)
    assert (models / f'{adopted}.npz').read_bytes() == \
        (tmp_path / 'in_use.npz').read_bytes()
    assert (models / 'current.npz').resolve() == models / f'{first}.npz'
    for node in ('classifier_node', 'localization_monitor'):
        assert f'ros2 param set /{node} model_path {models / first}.npz' \
            in result.stdout.splitlines(), result.stdout
    report = json.loads((models / f'{first}.json').read_text())
    assert report['decision'] == 'put in use', report
    assert report['protocol']['held_out_scans'] == 60
    assert report['candidate']['training']['recorded_scans'] == 240
    assert report['protocol']['update'].startswith('full'), report
    beyond, off = _off_survey_bounds(site)
    assert beyond <= report['new_ground']['scans'] <= off, report
    assert report['candidate']['position_mean_error_m'] < \
        report['in_use']['position_mean_error_m'], report
    aps = report['access_points']
    assert [s['ap'] for s in aps['silent']] == [mac(i) for i in range(3)]
    assert aps['new'] == [mac(i).lower() for i in range(30, 33)]
    model = load_model(models / 'current.npz')
    assert {normalize_ap_id(ap) for ap in model.ap_ids} == \
        {normalize_ap_id(mac(i)) for i in RECORDED}
    # retrained on the survey: the robot's odometry fit carried over
    assert model.fusion == in_use.fusion
    assert model.tracking == in_use.tracking
    assert report['candidate']['training']['carried_over'] == \
        ['fusion', 'tracking']
    # built again with the held-out scans once checked
    assert report['put_in_use']['training']['recorded_scans'] == 300
    assert model.provenance['recorded_until'] == 24.0 * 299
    # a candidate from a survey with its labels shuffled, judged on the
    # recording that followed: refused
    before = _history(models)
    result = _update(site, models, '--survey', site / 'poisoned.csv',
                     '--recorded', site / 'later.csv', '--ap-window', '1')
    assert result.returncode == 1, result.stderr
    last = result.stderr.splitlines()[-1]
    assert last.startswith('refused: worse than the model in use on the '
                           'held-out scans: '), result.stderr
    assert _history(models) == before
    refused = sorted(models.glob('*-refused.json'))
    assert len(refused) == 1
    assert json.loads(refused[0].read_text())['decision'] == 'refused'
    # a failure (unreadable recording): one line, nothing written
    before = _listing(models)
    (tmp_path / 'torn.csv').write_text('BUILDINGID,FLOOR,TIMESTAMP\n0,x\n')
    result = _update(site, models, '--survey', site / 'survey.csv',
                     '--recorded', tmp_path / 'torn.csv')
    assert result.returncode == 2, result.stderr
    assert result.stderr.splitlines()[-1].startswith('error: '), \
        result.stderr
    assert _listing(models) == before
    for option, value in (('--tolerance-accuracy', 'nan'),
                          ('--ap-window', '-1'), ('--nice', '-5')):
        result = _update(site, models, '--survey', site / 'survey.csv',
                         '--recorded', recorded, option, value)
        assert result.returncode == 2, result.stderr
        assert result.stderr.splitlines()[-1].startswith(
            f'error: {option} {value}'), result.stderr
    assert _listing(models) == before
    # roll back: the model in use before the update, in use again
    result = run(python_module('cli.update_model', '--folder', models,
                               '--rollback'))
    assert result.returncode == 0, result.stderr
    assert _history(models) == [adopted]
    assert (models / 'current.npz').read_bytes() == \
        (tmp_path / 'in_use.npz').read_bytes()
    assert f'model_path {models / adopted}.npz' in result.stdout
    result = run(python_module('cli.update_model', '--folder', models,
                               '--rollback'))
    assert result.returncode == 2
    assert 'nothing to roll back to' in result.stderr


def test_a_candidate_the_running_nodes_would_refuse_is_not_put_in_use(
        site, synthetic, tmp_path):
    # the model in use has no position output, the candidate has one:
    # classifier_node refuses such a swap, so the update does too
    models = tmp_path / 'models'
    models.mkdir()
    result = _update(site, models, '--model', synthetic[1], '--survey',
                     site / 'survey.csv', '--recorded',
                     site / 'recorded.csv', '--ap-window', '1')
    assert result.returncode == 1, result.stderr
    assert 'restart the node' in result.stderr.splitlines()[-1]
    assert not (models / 'current').exists()


#: update_model where torch cannot be imported, as on a robot with the
#: nodes only.
NO_TORCH = ('import sys; sys.modules["torch"] = None; '
            'from wifi_place_recognition.cli.update_model import main; '
            'sys.exit(main(sys.argv[1:]))')


def _references_only(site, models, *args, torch=True):
    argv = ['--folder', models, '--survey', site / 'survey.csv',
            '--ap-window', '1', *args]
    if torch:
        return run(python_module('cli.update_model', '--positions-only',
                                 *argv))
    return run([sys.executable, '-c', NO_TORCH, *map(str, argv)])


def _report(models, name):
    return json.loads((models / f'{name}.json').read_text())


@pytest.mark.parametrize('torch', [True, False], ids=['asked', 'no-torch'])
def test_a_references_only_update_fills_the_hole(site, tmp_path, torch):
    models = tmp_path / 'models'
    models.mkdir()
    result = _references_only(site, models, '--model', site / 'in_use.npz',
                              '--recorded', site / 'recorded.csv',
                              torch=torch)
    assert result.returncode == 0, result.stderr
    assert 'Traceback' not in result.stderr
    notes = [line for line in result.stderr.splitlines()
             if 'torch' in line]
    if torch:
        assert notes == [], result.stderr
    else:
        assert len(notes) == 1 and notes[0].startswith(
            'note: training needs torch') and notes[0].endswith(
                'updating only the position references (numpy)'), notes
    adopted, first = _history(models)
    report = _report(models, first)
    assert report['decision'] == 'put in use', report
    assert report['protocol']['update'].startswith('references only'), \
        report['protocol']
    assert report['protocol']['held_out_scans'] == 60
    assert report['candidate']['position_mean_error_m'] < \
        report['in_use']['position_mean_error_m'] - 1.0, report
    assert report['candidate']['references']['recorded']['used'] == 240
    assert report['cost']['torch_threads'] is None
    # the APs that came and went are reported, not applied
    aps = report['access_points']
    assert [s['ap'] for s in aps['silent']] == [mac(i) for i in range(3)]
    assert aps['new'] == [mac(i).lower() for i in range(30, 33)]
    assert aps['left_out'] == [] and 'not learned' in aps['not_applied']
    in_use, model = (load_model(site / 'in_use.npz'),
                     load_model(models / 'current.npz'))
    assert model.ap_ids == in_use.ap_ids
    for a, b in zip(in_use.members[0], model.members[0]):
        assert np.array_equal(a.weight, b.weight)
        assert np.array_equal(a.bias, b.bias)
    assert model.provenance[PROVENANCE]['from'] == str(site / 'in_use.npz')
    # checked without the held-out scans, put in use with them
    assert report['put_in_use']['references']['recorded']['used'] == 300
    assert len(model.position.xy) == 300 + 300


def test_scans_a_references_only_update_cannot_use_are_named(site,
                                                             tmp_path):
    lines = (site / 'recorded.csv').read_text().splitlines(True)
    assert lines[0].startswith('BUILDINGID,FLOOR,')
    moved = tmp_path / 'moved.csv'      # 20 scans of a floor not surveyed
    moved.write_text(lines[0] + ''.join(
        '0,2,' + line.split(',', 2)[2] if k < 20 else line
        for k, line in enumerate(lines[1:])))
    models = tmp_path / 'models'
    models.mkdir()
    result = _references_only(site, models, '--model', site / 'in_use.npz',
                              '--recorded', moved)
    assert result.returncode == 0, result.stderr
    assert f'note: {moved}: 20 of the 300 scans built from left out of ' \
        f'the position references: 20 of a building/floor the model does ' \
        f'not know (B0F2: 20) (a full update learns new floors and APs)\n' \
        in result.stderr, result.stderr
    assert _report(models, _history(models)[1])['put_in_use']['references'][
        'recorded']['left_out']['unknown_place'] == {'B0F2': 20}


def test_messages_about_a_recorded_scan_name_its_file_and_row(tmp_path):
    building = _building()
    survey = read_fingerprints(str(_survey(tmp_path / 'survey.csv',
                                           building, per_floor=10)))
    path = _recorded(tmp_path / 'recorded.csv', building, scans=10)
    lines = path.read_text().splitlines(True)
    path.write_text(''.join(lines[:5]) + '0,7,' + lines[5].split(',', 2)[2]
                    + ''.join(lines[6:]))     # its 5th scan: floor 7
    recorded = read_fingerprints(str(path))
    fp = update_model.together(survey, recorded, [])
    with pytest.raises(DataError, match=f'^{survey.source} \\+ {path}: '
                                        f'{path}: row 6, columns BUILDINGID'
                                        f'/FLOOR: building 0, floor 7 has 1 '
                                        f'scan'):
        check_trainable(fp)


def test_a_failed_rebuild_puts_the_checked_candidate_in_use(
        site, tmp_path, monkeypatch, capsys):
    built = []

    def rebuild_fails(model, parts, source):
        built.append(sum(len(p) for p in parts))
        if len(built) == 2:
            raise MemoryError
        return with_references(model, parts, source)
    monkeypatch.setattr(update_model, 'with_references', rebuild_fails)
    models = tmp_path / 'models'
    models.mkdir()
    code = update_model.main([
        '--folder', str(models), '--positions-only', '--nice', '0', '--model',
        str(site / 'in_use.npz'), '--survey', str(site / 'survey.csv'),
        '--recorded', str(site / 'recorded.csv'), '--quiet'])
    assert code == 0 and built == [300 + 240, 300 + 300], built
    assert 'note: the rebuild with the held-out scans failed ' \
        '(MemoryError); putting the checked candidate in use' in \
        capsys.readouterr().err
    report = _report(models, _history(models)[-1])
    assert report['decision'] == 'put in use'
    assert 'the checked candidate was put in use' in \
        report['put_in_use']['note']
    assert len(load_model(models / 'current.npz').position.xy) == 300 + 240


def test_the_next_update_judges_only_what_the_model_in_use_did_not_learn(
        site, tmp_path):
    # the recording grows after an update that learned all of it so far
    lines = (site / 'recorded.csv').read_text().splitlines(True)
    (tmp_path / 'first.csv').write_text(''.join(lines[:276]))
    models = tmp_path / 'models'
    models.mkdir()
    first = _references_only(site, models, '--model', site / 'in_use.npz',
                             '--recorded', tmp_path / 'first.csv')
    assert first.returncode == 0, first.stderr
    model = load_model(models / 'current.npz')
    assert model.provenance['recorded_until'] == 24.0 * 274
    grown = _references_only(site, models, '--recorded',
                             site / 'recorded.csv')
    assert grown.returncode == 0, grown.stderr
    report = _report(models, _history(models)[-1])
    # of the newest 60, the 25 it had not learned
    assert report['protocol']['held_out_scans'] == 25, report['protocol']
    assert model.provenance['recorded_until'] < 24.0 * 275
    assert load_model(models / 'current.npz').provenance[
        'recorded_until'] == 24.0 * 299
    # nothing recorded since: nothing to judge on, nothing built
    before = _listing(models)
    again = _references_only(site, models, '--recorded',
                             site / 'recorded.csv')
    assert again.returncode == 0, again.stderr
    assert again.stdout.startswith('not updated: 0 of the 300 recorded '
                                   'scans to judge a candidate on'), \
        again.stdout
    assert _listing(models) == before


def test_a_worse_references_only_candidate_is_refused(site, tmp_path):
    # recorded while the localiser was lost: the positions of the scans
    # trained on are each other's; the newest (held out) are right
    models = tmp_path / 'models'
    models.mkdir()
    result = _references_only(site, models, '--model', site / 'in_use.npz',
                              '--recorded', site / 'lost.csv')
    assert result.returncode == 1, result.stderr
    assert result.stderr.splitlines()[-1].startswith(
        'refused: worse than the model in use on the held-out scans: '
        'mean position error'), result.stderr
    assert not (models / 'current').exists()
    refused, = models.glob('*-refused.json')
    report = json.loads(refused.read_text())
    assert report['protocol']['update'].startswith('references only')
    assert report['candidate']['position_mean_error_m'] > \
        report['in_use']['position_mean_error_m'] + 5.0, report


def _off_survey_bounds(site):
    """Return the recorded scans trained on beyond 28 m and beyond 25 m."""
    recorded = read_fingerprints(site / 'recorded.csv')
    x = recorded.position[~newest(recorded.meta['TIMESTAMP'],
                                  len(recorded)), 0]
    return int((x > 25.0 + 3.0).sum()), int((x > 25.0).sum())


def test_too_little_new_ground_builds_nothing(site, tmp_path):
    models = tmp_path / 'models'
    models.mkdir()
    args = ('--model', site / 'in_use.npz', '--recorded',
            site / 'recorded.csv')
    result = _references_only(site, models, *args, '--min-new-scans',
                              '1000')
    assert result.returncode == 0, result.stderr
    line, = result.stdout.splitlines()
    assert line.startswith('not updated: ') and line.endswith(
        'fewer than --min-new-scans 1000; nothing built'), line
    found = int(line.split()[2])
    beyond, off = _off_survey_bounds(site)
    assert beyond <= found <= off, (beyond, found, off)
    assert list(models.iterdir()) == []
    result = _references_only(site, models, *args, '--min-new-scans',
                              str(found + 1))
    assert result.returncode == 0 and list(models.iterdir()) == []
    assert f'not updated: {found} recorded scans' in result.stdout
    # just enough: built, the count in its report
    result = _references_only(site, models, *args, '--min-new-scans',
                              str(found))
    assert result.returncode == 0, result.stderr
    report = _report(models, _history(models)[-1])
    assert report['new_ground']['scans'] == found
    assert report['new_ground']['min_new_scans'] == found
    result = _references_only(site, models, '--recorded',
                              site / 'recorded.csv', '--min-new-scans', '-1')
    assert result.returncode == 2
    assert result.stderr.splitlines()[-1].startswith(
        'error: --min-new-scans -1'), result.stderr


def test_a_recording_of_another_building_is_refused(site, tmp_path):
    lines = (site / 'recorded.csv').read_text().splitlines(True)
    foreign = tmp_path / 'foreign.csv'     # the same scans, other APs
    foreign.write_text(lines[0].replace('aa:bb:cc:', 'de:ad:be:') +
                       ''.join(lines[1:]))
    models = tmp_path / 'models'
    models.mkdir()
    result = _references_only(site, models, '--model', site / 'in_use.npz',
                              '--recorded', foreign)
    assert result.returncode == 2, result.stderr
    assert result.stderr.splitlines()[-1] == (
        f'error: --recorded: {len(lines) - 1} of the {len(lines) - 1} '
        f'recorded scans hear no AP the model in use ({site}/in_use.npz) '
        f'knows, and a references-only update keeps its APs: scans of '
        f'another building, or APs replaced (a full update learns them); '
        f'nothing built'), result.stderr
    assert list(models.iterdir()) == []
    for option, value in (('--nice', '99999999999'), ('--ap-window', '1e308'),
                          ('--tolerance-position', 'inf')):
        result = _references_only(site, models, '--model',
                                  site / 'in_use.npz', '--recorded',
                                  site / 'recorded.csv', option, value)
        assert result.returncode == 2, result.stderr
        assert result.stderr.splitlines()[-1].startswith(
            f'error: {option} '), result.stderr
        assert 'Traceback' not in result.stderr
    assert list(models.iterdir()) == []


def test_a_history_naming_a_file_outside_the_folder_is_refused(tmp_path):
    models = tmp_path / 'models'
    models.mkdir()
    (tmp_path / 'elsewhere.npz').write_bytes(b'not looked at')
    for name in ('../elsewhere', str(tmp_path / 'elsewhere')):
        (models / 'current').write_text(f'{name}\n')
        with pytest.raises(StoreError, match=f'lists {name}, not a file '
                           f'name of the folder'):
            ModelStore(models).current()


def _param_path(stdout):
    """Return the model path of the printed ``ros2 param set`` lines."""
    paths = {line.split()[-1] for line in stdout.splitlines()
             if line.startswith('ros2 param set /')}
    assert len(paths) == 1, stdout
    return paths.pop()


def test_an_update_and_its_rollback_reach_a_running_node(ros, site,
                                                         tmp_path):
    # a scan in the survey's hole, heard as the recording hears it
    building, rng = _building(), np.random.default_rng(9)
    heard = _readings(building, np.array([35.0, 20.0]), 0, RECORDED, rng)
    names, rssi = list(heard), [float(v) for v in heard.values()]
    models = tmp_path / 'models'
    models.mkdir()

    def where(client):
        values = status_values(client.send(names, rssi))
        return float(values['scan_x']), float(values['scan_y'])
    with running_node(ros, tmp_path, site / 'in_use.npz',
                      'updated_node') as (client, _, _):
        before = where(client)
        put = _references_only(site, models, '--model', site / 'in_use.npz',
                               '--recorded', site / 'recorded.csv')
        assert put.returncode == 0, put.stderr
        assert client.set_param('model_path',
                                _param_path(put.stdout)).successful
        updated = where(client)
        back = run(python_module('cli.update_model', '--folder', models,
                                 '--rollback'))
        assert back.returncode == 0, back.stderr
        assert _param_path(back.stdout) == \
            str(models / f'{_history(models)[-1]}.npz')
        assert client.set_param('model_path',
                                _param_path(back.stdout)).successful
        rolled_back = where(client)
    # off by the hole's width before, found after, as before once undone
    assert before[0] < 26.0, before
    assert np.hypot(updated[0] - 35.0, updated[1] - 20.0) < 5.0, updated
    assert rolled_back == before
