"""fit_tracking over real files: walks written by the recorder's own code."""

from conftest import python_module, run, synthetic_csv
import numpy as np
import pytest
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.data.fingerprints import read_fingerprints
from wifi_place_recognition.data.recording import FingerprintLog

PERIOD = 5.0        # s between scans of a walk
LIFT = 30.0         # s without scans while the floor changes


@pytest.fixture(scope='module')
def scans(synthetic, tmp_path_factory):
    """Return fresh scans of the synthetic building, by (building, floor)."""
    path = synthetic_csv(tmp_path_factory.mktemp('fresh') / 'fresh.csv',
                         scans_seed=7)
    fp = read_fingerprints(path)
    rows = {}
    for i, key in enumerate(zip(fp.building.tolist(), fp.floor.tolist())):
        rows.setdefault(key, []).append(i)
    return fp, {k: iter(v) for k, v in rows.items()}


def record(path, fp, rows, legs, wrong=()):
    """
    Write one walk with the recorder's :class:`FingerprintLog`.

    ``legs``: [((building, floor), scans)], a lift ride between legs;
    ``wrong``: scan numbers whose RSSI comes from another floor of the
    building (what a single scan gets wrong), labelled as the leg's.
    """
    log = FingerprintLog(path)
    t, n = 1.7e9, 0
    for leg, ((b, f), count) in enumerate(legs):
        t += LIFT if leg else 0.0
        for _ in range(count):
            source = (b, 1 - f) if n in wrong else (b, f)
            row = next(rows[source])
            seen = np.flatnonzero(np.isfinite(fp.rssi[row]))
            assert log.add([fp.ap_ids[j] for j in seen],
                           fp.rssi[row, seen], b, f, t)[0]
            t += PERIOD
            n += 1
    return path


def fit(*args):
    """Run fit_tracking in its own process; return CompletedProcess."""
    return run(python_module('cli.fit_tracking', *args))


def test_fits_walks_recorded_by_the_recorder_and_writes_the_model(
        synthetic, scans, tmp_path):
    _, model_path = synthetic
    fp, rows = scans
    walks = tmp_path / 'walks'
    walks.mkdir()
    record(walks / 'a.csv', fp, rows, [((0, 0), 20), ((0, 1), 20)],
           wrong={5, 12, 30})
    record(walks / 'b.csv', fp, rows, [((1, 1), 15), ((1, 0), 15)],
           wrong={4, 20})
    out = tmp_path / 'tracked.npz'
    result = fit('--model', model_path, '--walks', walks, '-o', out)
    assert result.returncode == 0, result.stderr
    assert '2 walks, 70 scans' in result.stdout
    assert '2 floor and 0 building changes' in result.stdout
    assert 'helps here' in result.stdout, result.stdout
    params = load_model(out).tracking
    # 2 floor changes in 68 pairs over 2 x (LIFT + 68 x 5 s / 2) seconds
    hours = (2 * LIFT + 68 * PERIOD) / 3600
    assert params.fit['rates']['hours'] == pytest.approx(hours, abs=1e-3)
    assert params.floor_rate == pytest.approx(2 / (hours * 3600), rel=0.5)
    # no building change seen: half a change over the time walked
    assert params.building_rate == pytest.approx(0.5 / (hours * 3600))
    assert params.fit['tracked_accuracy'] > params.fit['single_accuracy']
    assert params.fit['walks_sha256'] and params.fit['walks'] == str(walks)
    assert load_model(model_path).tracking is None      # -o: left alone
    # without -o the model file itself gets the section
    copy = tmp_path / 'copy.npz'
    copy.write_bytes(model_path.read_bytes())
    assert fit('--model', copy, '--walks', walks).returncode == 0
    assert load_model(copy).tracking == params.__class__(
        **dict(params.to_dict(), fit=load_model(copy).tracking.fit))


def test_bad_walks_are_refused_naming_what_is_wrong(synthetic, scans,
                                                    tmp_path):
    csv_path, model_path = synthetic
    fp, rows = scans
    walk = record(tmp_path / 'walk.csv', fp, rows, [((0, 0), 6)])
    text = walk.read_text().splitlines()
    cases = {
        # no labels
        'unlabelled.csv': '\n'.join(
            [','.join(line.split(',')[2:]) for line in text]),
        # no time
        'untimed.csv': '\n'.join(
            [','.join(c for i, c in enumerate(line.split(',')) if i != 2)
             for line in text]),
        # one scan: nothing to learn a change from
        'one.csv': '\n'.join(text[:2]),
        # a floor the model does not know
        'floor7.csv': '\n'.join(text[:1] + [
            line.replace('0,0,', '0,7,', 1) for line in text[1:]]),
    }
    expected = {'unlabelled.csv': 'FLOOR', 'untimed.csv': 'no TIMESTAMP',
                'one.csv': 'no two scans of a walk are within 600 s',
                'floor7.csv': 'the model does not know'}
    for name, content in cases.items():
        (tmp_path / name).write_text(content + '\n')
        result = fit('--model', model_path, '--walks', tmp_path / name)
        assert result.returncode == 2, (name, result.stdout)
        assert 'error:' in result.stderr and expected[name] in \
            result.stderr, (name, result.stderr)
        assert 'Traceback' not in result.stderr
    walk_path = tmp_path / 'walk.csv'
    for timeout in ('inf', 'nan', '0'):
        result = fit('--model', model_path, '--walks', walk_path,
                     '--timeout', timeout)
        assert result.returncode == 2 and '--timeout must be a finite ' \
            'number > 0' in result.stderr, result.stderr
    # the model's own training data: its probabilities are over-confident
    result = fit('--model', model_path, '--walks', csv_path)
    assert result.returncode == 2
    assert "is the model's training data" in result.stderr
    assert load_model(model_path).tracking is None       # nothing written
    # an output that cannot be written, or is an input: nothing written
    kept = model_path.read_bytes()
    for args, message in ((('--report', tmp_path / 'none' / 'r.json'),
                           'no folder'),
                          (('-o', walk), f'-o {walk} is the input --walks')):
        result = fit('--model', model_path, '--walks', walk, *args)
        assert result.returncode == 2 and message in result.stderr, \
            result.stderr
        assert model_path.read_bytes() == kept
    assert walk.read_text().splitlines() == text
