"""The position k-NN: exact neighbours, and its arrays in the model file."""

from dataclasses import replace
import json
import math

from conftest import save_unchecked
import numpy as np
import pytest
from wifi_place_recognition.core.artifact import (_digest, load_model,
                                                  ModelFileError, save_model)
from wifi_place_recognition.core.coverage import UNLIKE_SURVEY_ABOVE
from wifi_place_recognition.core.locator import (calibrated_edge_sigma,
                                                 calibrated_sigma, Locator,
                                                 MAX_EDGE_SIGMA_M,
                                                 MAX_MISMATCH_DB,
                                                 MISMATCH_SIGMA_M, R95)
from wifi_place_recognition.core.preprocessing import signal


def _references(rng, n=300, n_aps=40, n_classes=3):
    rssi = np.where(rng.random((n, n_aps)) < 0.2,
                    rng.uniform(-100, -40, (n, n_aps)), np.nan)
    classes = rng.integers(0, n_classes, n)
    xy = rng.uniform(-7700, -7600, (n, 2)) + [0, 4864900]
    return rssi.astype(np.float32), classes, xy


def _rewrite_header(path, change):
    """Change a model file's header in place (its checksum made anew)."""
    with np.load(path) as f:
        arrays = {k: f[k] for k in f.files}
    header = json.loads(arrays.pop('header').tobytes())
    header.pop('sha256')
    change(header)
    header['sha256'] = _digest(header, arrays)
    arrays['header'] = np.frombuffer(json.dumps(header).encode(), np.uint8)
    np.savez(path, **arrays)


def _stored(locator, c):
    """Return class ``c``'s references as the locator holds them (dense)."""
    g = locator.group[c]
    rows = slice(locator.ap_start[g], locator.ap_start[g + 1])
    out = np.zeros((len(locator.reference_xy(c)),
                    locator.n_aps))
    out[:, locator.ap_column[rows]] = \
        (locator.blocks[g] * locator.scale[rows, None]).T
    return out


@pytest.mark.parametrize('representation, metric, group', [
    ('positive', 'euclidean', None), ('powed', 'sorensen', None),
    ('exponential', 'euclidean', None), ('positive', 'sorensen', None),
    ('positive', 'euclidean', [0, 0, 1]), ('powed', 'sorensen', [1, 0, 1])])
def test_locate_is_distance_weighted_knn_within_the_group(representation,
                                                          metric, group):
    rng = np.random.default_rng(0)
    rssi, classes, xy = _references(rng)
    for c in range(3):                  # class c never detects AP c
        rssi[classes == c, c] = np.nan
    locator = Locator.build(rssi, classes, xy, 3, neighbours=4,
                            sigma=[1.0, 2.0, 3.0],
                            representation=representation, metric=metric,
                            group=group)
    group = np.arange(3) if group is None else np.array(group)
    values = signal(rssi, representation)
    for c in range(3):  # int8 references: within half a step of each row
        stored = _stored(locator, c)
        mine = group[classes] == group[c]
        step = np.abs(values[mine]).max(axis=0) / 127
        assert (np.abs(stored - values[mine]) <=
                step / 2 * 1.001 + 1e-7).all()
    for _ in range(20):
        query = np.where(rng.random(40) < 0.3, rng.uniform(-100, -40, 40),
                         np.nan).astype(np.float32)
        query[:3] = -70.0               # an AP its class never detects
        columns = np.flatnonzero(~np.isnan(query))
        q = signal(query, representation)
        c = int(rng.integers(0, 3))
        mine = np.flatnonzero(group[classes] == group[c])
        refs = _stored(locator, c)
        if metric == 'euclidean':
            distance = np.linalg.norm(refs - q, axis=1)
        else:
            distance = np.abs(refs - q).sum(axis=1) / (refs + q).sum(axis=1)
        nearest = np.argsort(distance)[:4]
        weight = 1 / distance[nearest]
        expected = weight @ xy[mine[nearest]] / weight.sum()
        got, sigma = locator.locate(columns, query[columns], c)
        np.testing.assert_allclose(got, expected, atol=1e-3)
        # sigma: the class's scale times the nearest distance (>= 0.1 m)
        assert sigma == pytest.approx(max((c + 1) * distance.min(), 0.1),
                                      rel=1e-4)


def test_locator_in_the_model_file_and_tampered_indices(synthetic,
                                                        tmp_path):
    model = load_model(synthetic[1])
    rng = np.random.default_rng(1)
    inputs, classes, xy = _references(rng, n_aps=len(model.ap_ids),
                                      n_classes=len(model.classes))
    model.position = Locator.build(inputs, classes, xy, len(model.classes),
                                   5, np.ones(len(model.classes)),
                                   representation='powed', metric='sorensen')
    save_model(model, tmp_path / 'm.npz')
    loaded = load_model(tmp_path / 'm.npz').position
    np.testing.assert_array_equal(loaded.origin, model.position.origin)
    assert (loaded.representation, loaded.metric) == ('powed', 'sorensen')
    for name in ('group_start', 'group', 'ap_start', 'ap_column', 'scale', 'codes',
                 'norms', 'xy', 'sigma'):
        np.testing.assert_array_equal(getattr(loaded, name),
                                      getattr(model.position, name))
    # Tampered indices and codes are refused on loading.
    for name, index, value, message in (
            ('ap_column', 1, 0, 'not ascending'),
            ('ap_column', -1, len(model.ap_ids), 'not ascending'),
            ('codes', 0, 300, 'codes must be integers'),
            ('codes', 0, 0.5, 'codes must be integers'),
            ('group_start', 1, 10**6, 'inconsistent index'),
            ('group', 0, len(model.classes), 'one group per class'),
            # beyond int64 once cast: must not pass as a small index
            ('group', 1, 1e30, 'not counts'),
            ('ap_column', -1, 1e30, 'not counts')):
        bad = replace(model.position)
        setattr(bad, name, getattr(bad, name).astype(np.float64))
        getattr(bad, name)[index] = value
        with pytest.raises(ValueError, match=message):
            save_model(replace(model, position=bad), tmp_path / 'bad.npz')
        save_unchecked(replace(model, position=bad), tmp_path / 'bad.npz')
        with pytest.raises(ModelFileError, match=message):
            load_model(tmp_path / 'bad.npz')
    # The circle's widening and the usual mismatch are kept; a file
    # without them (older) has none.
    for name, key, top, kept in (
            ('edge_sigma', 'edge_sigma_m', MAX_EDGE_SIGMA_M, 2.5),
            ('usual_mismatch', 'usual_mismatch_db', MAX_MISMATCH_DB, 3.5)):
        setattr(model.position, name, kept)
        save_model(model, tmp_path / 'm.npz')
        assert getattr(load_model(tmp_path / 'm.npz').position, name) == kept
        _rewrite_header(tmp_path / 'm.npz',
                        lambda h: h['position'].pop(key))
        assert getattr(load_model(tmp_path / 'm.npz').position, name) == 0.0
        for value in (-1.0, top + 1, float('nan'), 'wide', True):
            bad = replace(model.position)
            object.__setattr__(bad, name, value)  # past its own check
            save_unchecked(replace(model, position=bad), tmp_path / 'bad.npz')
            with pytest.raises(ModelFileError,
                               match=f'{key} must be a number'):
                load_model(tmp_path / 'bad.npz')
    with pytest.raises(ValueError, match='usual_mismatch must be in'):
        replace(model.position, usual_mismatch=-2.0)
    bad = replace(model.position)
    bad.metric = 'manhattan'
    save_unchecked(replace(model, position=bad), tmp_path / 'bad.npz')
    with pytest.raises(ModelFileError, match='metric one of'):
        load_model(tmp_path / 'bad.npz')
    bad = replace(model.position)
    bad.ap_column = bad.ap_column[:, None]
    save_unchecked(replace(model, position=bad), tmp_path / 'bad.npz')
    with pytest.raises(ModelFileError, match='wrong shape'):
        load_model(tmp_path / 'bad.npz')


def test_empty_classes_and_scans_sharing_no_ap():
    rng = np.random.default_rng(2)
    rssi, classes, xy = _references(rng, n_classes=2)
    rssi[classes == 1] = np.nan         # class 1 detects nothing
    rssi[classes == 0, -1] = np.nan     # and class 0 never the last AP
    locator = Locator.build(rssi, classes, xy, 4, sigma=np.ones(4))
    query = np.full(40, np.nan, np.float32)
    query[:3] = -109.0                  # a positive signal of 1
    columns = np.flatnonzero(~np.isnan(query))
    for c in (2, 3):                    # no reference at all
        got, sigma = locator.locate(columns, query[columns], c)
        assert np.isnan(got).all() and np.isnan(sigma)
    # every reference of class 1 is at the same distance: |query|
    np.testing.assert_allclose(
        locator.distances(columns, signal(query[columns], 'positive'), 1),
        np.sqrt(3.0), rtol=1e-6)
    got, _ = locator.locate(columns, query[columns], 1)
    assert np.isfinite(got).all()
    # a scan sharing no AP with class 0: |query|^2 + |reference|^2
    d = locator.distances(np.array([39]), np.ones(1), 0)
    first = locator.group_start[0]
    np.testing.assert_allclose(
        d ** 2, 1.0 + locator.norms[first:first + len(d)], rtol=1e-5)


def test_sigma_scales_with_the_nearest_distance_calibrated_per_class():
    rng = np.random.default_rng(3)
    nearest = rng.uniform(0.1, 1.0, 3000)
    predicted = rng.integers(0, 3, 3000)
    predicted[:10] = 3                  # too few scans: the overall scale
    errors = nearest * rng.rayleigh(1.0 + predicted)
    scale = calibrated_sigma(errors, nearest, predicted, 5)
    inside = errors <= R95 * scale[predicted] * nearest
    for c in range(3):
        assert inside[predicted == c].mean() == pytest.approx(0.95, abs=0.01)
    overall = np.quantile(errors / nearest, 0.95) / R95
    assert scale[3] == scale[4] == pytest.approx(overall)
    assert scale[0] < scale[1] < scale[2]


def _corridor(edge_sigma):
    """Return a locator of one class: 21 references 1 m apart along x."""
    rng = np.random.default_rng(4)
    rssi = rng.uniform(-90, -40, (21, 10)).astype(np.float32)
    xy = np.column_stack([np.arange(21.0), np.zeros(21)])
    return Locator.build(rssi, np.zeros(21, np.int64), xy, 1, 1,
                         np.ones(1), edge_sigma=edge_sigma)


def test_the_circle_widens_where_the_answer_lies_at_the_survey_edge():
    plain, wide = _corridor(0.0), _corridor(4.0)
    # at 18 m: 4 references within 5 m on one side, 2 on the other
    for answer, edge in ((10, 0.0), (0, 4.0), (20, 4.0), (18, 4.0 / 81)):
        distance = np.full(21, 5.0)
        distance[answer] = 3.0          # k = 1: the answer is reference
        xy, knn = wide.weighted(distance, 1, 0)
        np.testing.assert_allclose(xy, [answer, 0], atol=1e-5)
        assert knn == plain.weighted(distance, 1, 0)[1] == \
            pytest.approx(3.0)
        assert plain.widened(xy, knn, 0) == knn
        assert wide.widened(xy, knn, 0) == pytest.approx(np.hypot(3.0, edge),
                                                         rel=1e-5)
    with pytest.raises(ValueError, match='edge_sigma must be in'):
        _corridor(-0.5)


def test_the_circle_widens_where_the_scan_sounds_unlike_the_survey():
    plain, wide = _corridor(0.0), _corridor(4.0)
    distance = np.full(21, 5.0)
    distance[0] = 3.0                   # at the corridor's end: side 1
    xy, knn = wide.weighted(distance, 1, 0)
    above = UNLIKE_SURVEY_ABOVE
    for mismatch, extra in ((math.nan, 0.0), (0.5, 0.0), (above, 0.0),
                            (above + 0.01, MISMATCH_SIGMA_M),
                            (5.0, MISMATCH_SIGMA_M)):
        assert plain.widened(xy, knn, 0, mismatch) == pytest.approx(
            np.hypot(3.0, extra), rel=1e-6)
        assert wide.widened(xy, knn, 0, mismatch) == pytest.approx(
            np.hypot(np.hypot(3.0, 4.0), extra), rel=1e-6)


def test_the_edge_sigma_is_the_least_that_holds_95_percent():
    rng = np.random.default_rng(5)
    side = rng.uniform(0, 1, 4000)
    sigma = rng.uniform(0.5, 2.0, 4000)
    # one-sided answers are farther off than their sigma says
    errors = np.hypot(sigma, 6 * side ** 4) * rng.rayleigh(1.0, 4000)
    edge = calibrated_edge_sigma(errors, sigma, side)
    inside = errors <= R95 * np.hypot(sigma, edge * side ** 4)
    assert 0.95 <= inside.mean() < 0.9503
    assert 4.0 < edge < 8.0
    # already inside: nothing to widen
    assert calibrated_edge_sigma(errors / 10, sigma, side) == 0.0
    # no widening holds them (outside with side 0): at most the cap
    assert calibrated_edge_sigma(errors * 10, sigma, side * 0) == \
        MAX_EDGE_SIGMA_M
    assert calibrated_edge_sigma(np.empty(0), np.empty(0),
                                 np.empty(0)) == 0.0


@pytest.mark.parametrize('representation', ['positive', 'powed',
                                            'exponential'])
def test_the_mismatch_is_how_unlike_its_nearest_references_a_scan_sounds(
        representation):
    rng = np.random.default_rng(3)
    # 40 places, each surveyed 5 times (readings 1 dB apart)
    places, _, place_xy = _references(rng, n=40, n_aps=30, n_classes=1)
    places[:, :6] = rng.uniform(-90, -50, (40, 6))   # heard everywhere
    rssi = np.repeat(places, 5, axis=0) + rng.normal(0, 1, (200, 30))
    locator = Locator.build(rssi, np.zeros(200, np.int64),
                            np.repeat(place_xy, 5, axis=0), 1,
                            representation=representation,
                            usual_mismatch=2.0)

    def mismatch(row):
        cols = np.flatnonzero(~np.isnan(row))
        distance = locator.distances(
            cols, signal(row[cols], representation), 0)
        return (locator.mismatch(cols, row[cols], 0, distance),
                locator.relative_mismatch(cols, row[cols], 0, distance))
    one = places[17].astype(np.float64)     # at a surveyed place
    assert mismatch(one)[0] < 2.0           # about the readings' noise
    # every AP 8 dB louder (another device, another day): the same
    assert abs(mismatch(one + 8.0)[0] - mismatch(one)[0]) < 0.5
    # the APs it shares with them at other strengths: several dB
    heard = np.flatnonzero(~np.isnan(one))
    other = one.copy()
    other[heard] = rng.permutation(one[heard])
    got, relative = mismatch(other)
    assert got > 4.0 and relative == pytest.approx(got / 2.0)
    # fewer than two APs shared with the nearest: not known
    lone = np.full(30, np.nan)
    lone[heard[0]] = -60.0
    assert np.isnan(mismatch(lone)[0])
    # no usual mismatch (an older model): the ratio is not known
    locator.usual_mismatch = 0.0
    assert np.isnan(mismatch(other)[1])
