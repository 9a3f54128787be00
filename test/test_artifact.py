"""The model file: round trip, and refusal of every kind of bad file."""

from dataclasses import asdict
import json
import os
import stat

import numpy as np
import pytest
from wifi_place_recognition.core.artifact import (
    _digest, load_model, ModelFileError, save_model)
from wifi_place_recognition.core.model import ScanForward
from fuzz import hostile_model_files
from wifi_place_recognition.core.resources import default_model_path
from wifi_place_recognition.training.config import TrainConfig


def test_round_trip_keeps_predictions(synthetic, tmp_path):
    _, model_path = synthetic
    model = load_model(model_path)
    save_model(model, tmp_path / 'copy.npz')
    copy = load_model(tmp_path / 'copy.npz')
    x = np.full((3, len(model.ap_ids)), np.nan, np.float32)
    x[:, :5] = -60
    np.testing.assert_array_equal(model.predict_proba(x),
                                  copy.predict_proba(x))
    assert copy.ap_ids == model.ap_ids
    assert copy.provenance['config']['sae_layers'] == [32, 16]


@pytest.mark.parametrize('umask', [0o022, 0o027, 0o077, 0o002], ids=oct)
def test_a_saved_file_has_the_usual_permissions(tmp_path, umask):
    model = load_model(default_model_path())
    previous = os.umask(umask)
    try:
        save_model(model, tmp_path / 'm.npz')
    finally:
        os.umask(previous)
    # like open(): 0o666 less the umask, bit for bit (not mkstemp's 0o600)
    mode = stat.S_IMODE((tmp_path / 'm.npz').stat().st_mode)
    assert oct(mode) == oct(0o666 & ~umask)


def test_shipped_model_loads_with_its_provenance():
    model = load_model(default_model_path())
    assert len(model.ap_ids) == 520 and len(model.classes) == 13
    prov = model.provenance
    assert prov['training_data']['sha256'].startswith('45ca0128')
    assert prov['selection']['grouping'] == 'device'
    # trained by the documented command: the default recipe, its batch
    # size as resolved from the number of scans
    default = asdict(TrainConfig())
    default['batch_size'] = TrainConfig().batch_for(
        prov['training_data']['scans'])
    assert prov['config'] == json.loads(json.dumps(default))
    assert len(model.members) == TrainConfig().ensemble
    assert model.position.columns == ('LONGITUDE', 'LATITUDE')
    assert 4864000 < model.position.origin[1] < 4866000   # UTM, float64
    # what the documented command learns today beside the networks: the
    # edge widening, the coverage section, the survey's usual mismatch
    assert model.position.edge_sigma == 15.0 and model.coverage is not None
    assert model.position.usual_mismatch == pytest.approx(4.93, abs=0.01)
    assert 'usual_mismatch_note' in prov


def _header_and_arrays(path):
    with np.load(path, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    return json.loads(arrays['header'].tobytes()), arrays


def _write_npz(path, header, arrays):
    arrays = dict(arrays)
    arrays['header'] = np.frombuffer(json.dumps(header).encode(), np.uint8)
    np.savez(path, **arrays)
    return path


def test_missing_file():
    with pytest.raises(ModelFileError, match='cannot read'):
        load_model('/nonexistent/model.npz')


def test_tampered_header_fails_the_checksum(synthetic, tmp_path):
    header, arrays = _header_and_arrays(synthetic[1])
    header['ap_ids'][0] = 'evil'
    path = _write_npz(tmp_path / 't.npz', header, arrays)
    with pytest.raises(ModelFileError, match='checksum mismatch'):
        load_model(path)


def test_an_npz_that_is_not_a_model(tmp_path):
    np.savez(tmp_path / 'plain.npz', x=np.zeros(3))
    with pytest.raises(ModelFileError, match='no header'):
        load_model(tmp_path / 'plain.npz')


def test_every_hostile_file_is_refused_and_runs_nothing(synthetic, tmp_path):
    marker = tmp_path / 'PWNED'
    files = hostile_model_files(synthetic[1], tmp_path, marker)
    assert len(files) == 12
    for kind, path in files.items():
        with pytest.raises(ModelFileError) as err:
            load_model(path)
        assert str(err.value).startswith(str(path)), kind
    assert not marker.exists()


def test_a_header_nested_near_the_recursion_limit_is_refused(synthetic,
                                                             tmp_path):
    # just under the parser's limit, hashing the header hit it instead
    header, arrays = _header_and_arrays(synthetic[1])
    arrays.pop('header')
    for depth in range(940, 1000, 4):
        text = json.dumps(header)[:-1] + ', "deep": ' + '[' * depth + \
            ']' * depth + '}'
        path = tmp_path / f'deep{depth}.npz'
        np.savez(path, header=np.frombuffer(text.encode(), np.uint8),
                 **arrays)
        with pytest.raises(ModelFileError):
            load_model(path)


def test_a_model_that_would_not_load_is_never_written(synthetic, tmp_path):
    model = load_model(synthetic[1])
    path = tmp_path / 'm.npz'
    save_model(model, path)
    before = path.read_bytes()
    model.members[0][0].weight[0, 0] = np.nan    # a training that diverged
    with pytest.raises(ValueError, match=f'so {path} was not written: layer '
                       f'member0.layer0.weight has values that are not '
                       f'finite'):
        save_model(model, path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ['m.npz']


def test_failed_write_keeps_the_previous_file(synthetic, tmp_path,
                                              monkeypatch):
    model = load_model(synthetic[1])
    path = tmp_path / 'm.npz'
    save_model(model, path)
    before = path.read_bytes()

    def disk_full(f, **arrays):
        f.write(b'PK partial')
        raise OSError(28, 'No space left on device')
    monkeypatch.setattr(np, 'savez_compressed', disk_full)
    with pytest.raises(OSError, match=f'No space left on device: .{path}'):
        save_model(model, path)     # named after the file, not its temporary
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ['m.npz']


@pytest.mark.parametrize('where', ['no folder', 'a folder'])
def test_an_unwritable_path_is_named_and_nothing_is_left(synthetic, tmp_path,
                                                         where):
    model = load_model(synthetic[1])
    (tmp_path / 'sub').mkdir()
    path = tmp_path / 'sub' / 'missing' / 'm.npz' if where == 'no folder' \
        else tmp_path / 'sub'       # the temporary file goes beside it
    with pytest.raises(OSError) as err:
        save_model(model, path)
    assert err.value.filename == str(path)
    assert sorted(p.name for p in tmp_path.rglob('*')) == ['sub']


def test_a_rewrite_keeps_a_link_and_the_file_permissions(synthetic,
                                                         tmp_path):
    model = load_model(synthetic[1])
    target = tmp_path / 'v3.npz'
    save_model(model, target)
    target.chmod(0o600)
    link = tmp_path / 'current.npz'
    link.symlink_to(target.name)
    model.provenance['note'] = 'rewritten through the link'
    save_model(model, link)
    assert link.is_symlink() and os.readlink(link) == target.name
    assert load_model(target).provenance['note'] == \
        'rewritten through the link'
    assert stat.S_IMODE(target.stat().st_mode) == 0o600


def test_a_model_file_carries_its_temperature(synthetic, tmp_path):
    model = load_model(synthetic[1])
    x = np.full((4, len(model.ap_ids)), np.nan, np.float32)
    x[:, :6] = [-55, -60, -70, -80, -65, -75]
    x[1, :3] = np.nan
    x[2, 6:9], x[3, :6] = -50, -90
    model.temperature = 1.0
    raw = model.predict_proba(x)
    model.temperature = 3.0
    save_model(model, tmp_path / 'hot.npz')
    copy = load_model(tmp_path / 'hot.npz')
    assert copy.temperature == 3.0
    proba = copy.predict_proba(x)
    expected = raw ** (1 / 3.0)
    np.testing.assert_allclose(proba, expected / expected.sum(
        axis=1, keepdims=True), rtol=1e-5)
    assert (proba.argmax(axis=1) == raw.argmax(axis=1)).all()
    assert (proba.max(axis=1) < raw.max(axis=1) - 1e-3).all()
    forward = ScanForward(copy)
    for row, p in zip(x, proba):
        np.testing.assert_allclose(forward(*copy.sparse(row)), p, atol=1e-5)


def test_a_schema_3_file_loads_uncalibrated(synthetic, tmp_path):
    header, arrays = _header_and_arrays(synthetic[1])
    header.pop('sha256')
    header['schema_version'] = 3
    del header['calibration']
    header['sha256'] = _digest(header, {k: v for k, v in arrays.items()
                                        if k != 'header'})
    model = load_model(_write_npz(tmp_path / 'old.npz', header, arrays))
    assert model.temperature == 1.0


@pytest.mark.parametrize('value', [0, -1.0, 1e9, float('nan'), 'hot', None,
                                   True])
def test_a_bad_temperature_is_refused(synthetic, tmp_path, value):
    header, arrays = _header_and_arrays(synthetic[1])
    header.pop('sha256')
    header['calibration']['temperature'] = value
    header['sha256'] = _digest(header, {k: v for k, v in arrays.items()
                                        if k != 'header'})
    with pytest.raises(ModelFileError, match='calibration: temperature'):
        load_model(_write_npz(tmp_path / 'bad.npz', header, arrays))
