"""A model's position references rebuilt from new scans (core, numpy)."""

from dataclasses import replace

from conftest import surveyed_csv
import numpy as np
import pytest
from wifi_place_recognition.core.artifact import (LOCATOR_ARRAYS, load_model,
                                                  save_model)
from wifi_place_recognition.core.evaluation import align
from wifi_place_recognition.core.model import ScanForward
from wifi_place_recognition.core.references import (PROVENANCE,
                                                    with_references)
from wifi_place_recognition.data.fingerprints import read_fingerprints


@pytest.fixture(scope='module')
def scans(tmp_path_factory):
    """Return (the model's own survey, new scans of the same building)."""
    folder = tmp_path_factory.mktemp('scans')
    return (read_fingerprints(surveyed_csv(folder / 'survey.csv')),
            read_fingerprints(surveyed_csv(folder / 'new.csv',
                                           scans_seed=7)))


def _locator(model):
    return {name: getattr(model.position, name)
            for name in (*LOCATOR_ARRAYS, 'origin')}


def _same_network(a, b, rssi):
    assert a.ap_ids == b.ap_ids and a.temperature == b.temperature
    assert (a.classes == b.classes).all()
    assert a.coverage == b.coverage and a.tracking == b.tracking and \
        a.fusion == b.fusion
    assert np.array_equal(a.predict_proba(rssi), b.predict_proba(rssi))
    one, other = ScanForward(a), ScanForward(b)
    for row in rssi[:20]:
        columns, inputs = a.sparse(row)
        assert np.array_equal(one(columns, inputs), other(columns, inputs))


def test_the_survey_it_was_trained_on_gives_the_same_references(
        surveyed_model, scans):
    model = load_model(surveyed_model)
    survey, _ = scans
    same, parts = with_references(model, [survey], 'in_use.npz')
    for name, value in _locator(model).items():
        assert np.array_equal(getattr(same.position, name), value), name
    assert parts == [{'source': survey.source, 'sha256': survey.sha256,
                      'scans': 400, 'used': 400,
                      'left_out': {'unknown_place': {}, 'no_known_ap': 0}}]


def test_new_scans_change_the_references_and_nothing_else(
        surveyed_model, scans, tmp_path):
    model = load_model(surveyed_model)
    before = _locator(model)
    survey, new = scans
    updated, _ = with_references(model, [survey, new], 'in_use.npz')
    rssi = align(model, new)
    _same_network(model, updated, rssi)
    assert len(updated.position.xy) == 800
    for name in ('neighbours', 'representation', 'metric', 'columns'):
        assert getattr(updated.position, name) == \
            getattr(model.position, name)
    for name in ('sigma', 'group'):
        assert np.array_equal(getattr(updated.position, name),
                              getattr(model.position, name))
    assert not np.array_equal(updated.predict_positions(rssi)[1],
                              model.predict_positions(rssi)[1])
    # the model it came from is untouched
    for name, value in _locator(model).items():
        assert np.array_equal(value, before[name])
    update = updated.provenance[PROVENANCE]
    assert update['from'] == 'in_use.npz' and update['references'] == 800
    assert update['kind'].startswith('references only')
    assert 'created' in update and PROVENANCE not in model.provenance
    # a file like any other
    save_model(updated, tmp_path / 'updated.npz')
    loaded = load_model(tmp_path / 'updated.npz')
    _same_network(model, loaded, rssi)
    assert np.array_equal(loaded.predict_positions(rssi)[1],
                          updated.predict_positions(rssi)[1])


def test_scans_of_an_unknown_place_or_hearing_no_known_ap_are_counted(
        surveyed_model, scans):
    model = load_model(surveyed_model)
    survey, new = scans
    building = new.building.copy()
    building[:5] = 3
    floor = new.floor.copy()
    floor[5:7] = 4
    rssi = new.rssi.copy()
    rssi[10:12] = np.nan
    odd = replace(new, building=building, floor=floor, rssi=rssi,
                  source='odd.csv')
    updated, parts = with_references(model, [survey, odd], 'in_use.npz')
    assert parts[1]['left_out'] == {'unknown_place': {'B0F4': 2, 'B3F0': 5},
                                    'no_known_ap': 2}
    assert parts[1]['used'] == 400 - 9
    assert len(updated.position.xy) == 800 - 9


def test_what_cannot_be_references_is_refused_by_name(surveyed_model,
                                                      synthetic, scans):
    model = load_model(surveyed_model)
    survey, new = scans
    with pytest.raises(ValueError, match='no position output'):
        with_references(load_model(synthetic[1]), [survey], 'm.npz')
    with pytest.raises(ValueError, match='new.csv: no positions'):
        with_references(model, [replace(new, position=None,
                                        source='new.csv')], 'm.npz')
    position = new.position.copy()
    position[3] = np.nan
    with pytest.raises(ValueError, match=r'scan 4 has position \[nan, nan\]'):
        with_references(model, [replace(new, position=position)], 'm.npz')
    with pytest.raises(ValueError, match=r'rssi of shape \(400, 29\)'):
        with_references(model, [replace(new, rssi=new.rssi[:, 1:])], 'm.npz')
    with pytest.raises(ValueError, match='base None'):
        with_references(model, [new], None)
    with pytest.raises(TypeError, match='not str'):
        with_references('m.npz', [new], 'm.npz')
    # every floor the model searches must keep a reference
    floor0 = new.subset(new.floor == 0)
    assert model.position.group[0] != model.position.group[1], \
        'the fixture model searches each floor apart'
    with pytest.raises(ValueError, match='no reference scan for B0F1'):
        with_references(model, [floor0], 'm.npz')
