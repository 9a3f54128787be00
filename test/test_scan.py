"""Scan mapping, RSSI rules, preprocessing and the recognizer, without ROS."""

import numpy as np
import pytest
from wifi_place_recognition.core.artifact import load_model, save_model
from wifi_place_recognition.core.model import mean_softmax
from wifi_place_recognition.core.preprocessing import RssiScaler
from wifi_place_recognition.core.recognizer import OK, PlaceRecognizer, WARN
from wifi_place_recognition.core.scan import (
    normalize_ap_id, ScanMapper, ScanRejected)
from wifi_place_recognition.training.augment import ScanAugmenter
from wifi_place_recognition.training.config import TrainConfig


def test_mean_softmax_averages_the_members_probabilities():
    logits = np.array([[[1.0, 2.0, 3.0]], [[0.0, 0.0, 1000.0]]])  # 2 x 1 scan
    first = np.exp([1.0, 2.0, 3.0]) / np.exp([1.0, 2.0, 3.0]).sum()
    expected = (first + [0.0, 0.0, 1.0]) / 2    # no overflow at 1000
    np.testing.assert_allclose(mean_softmax(logits), [expected])
    np.testing.assert_allclose(mean_softmax(logits).sum(), 1.0)


@pytest.mark.parametrize('given, expected', [
    ('AA:BB:CC:00:11:22', 'aa:bb:cc:00:11:22'),
    ('aa-bb-cc-00-11-22', 'aa:bb:cc:00:11:22'),
    (' AABBCC001122 ', 'aa:bb:cc:00:11:22'),
    ('WAP017', 'wap017'),
])
def test_normalize_ap_id(given, expected):
    assert normalize_ap_id(given) == expected


def test_mapping_keeps_strongest_duplicate_and_counts_unknown():
    mapper = ScanMapper(['WAP001', 'WAP002', 'WAP003'])
    scan = mapper.map(['wap002', 'WAP002', 'other', 'WAP003'],
                      [-80, -60, -50, 5])
    assert scan.columns.tolist() == [1, 2]   # WAP001 not detected
    assert scan.rssi.tolist() == [-60, 0]
    assert (scan.known, scan.unknown, scan.clipped) == (2, 1, 1)


@pytest.mark.parametrize('names, rssi, reason', [
    (['WAP001'], [], 'length_mismatch'),
    ([], [], 'empty'),
    (['WAP001'] * 5, [-50] * 5, 'oversize'),
    (['WAP001'], [np.nan], 'non_finite'),
    (['WAP001'], [np.inf], 'non_finite'),
    (['WAP001'], [-121], 'implausible_rssi'),
    (['WAP001'], [21], 'implausible_rssi'),
    (['nope'], [-50], 'no_known_ap'),
])
def test_rejections(names, rssi, reason):
    with pytest.raises(ScanRejected) as err:
        ScanMapper(['WAP001'], max_aps=4).map(names, rssi)
    assert err.value.reason == reason


@pytest.mark.parametrize('representation', ['dbm', 'powed', 'exponential'])
def test_representations_round_trip_through_the_model_file(
        synthetic, tmp_path, representation):
    model = load_model(synthetic[1])
    rssi = np.full((2, len(model.ap_ids)), np.nan, np.float32)
    rssi[:, :4] = [-40, -70, -100, -115]
    model.scaler = RssiScaler(-110, 'joint', representation).fit(rssi)
    x = model.scaler.fill(rssi)
    if representation != 'dbm':
        assert x[0, 0] > x[0, 1] > x[0, 2] > 0
        assert x[0, 3] == 0 and x[0, 5] == 0   # below floor, undetected
    save_model(model, tmp_path / 'm.npz')
    np.testing.assert_array_equal(load_model(tmp_path / 'm.npz').
                                  predict_proba(rssi),
                                  model.predict_proba(rssi))


def _augmented(augmenter):
    rows, cols, values = augmenter.readings()
    assert (np.diff(rows) >= 0).all()
    out = np.full(augmenter.shape, np.nan, np.float32)
    out[rows, cols] = values
    return out


def test_augment_is_seeded_and_stays_plausible():
    config = TrainConfig(augment_offset=10, augment_gain=0.1,
                         augment_noise=2, augment_dropout=0.2)
    rssi = np.full((50, 30), -70, np.float32)
    rssi[:, 20:] = np.nan
    a = _augmented(ScanAugmenter(rssi, config, seed=1))
    b = _augmented(ScanAugmenter(rssi, config, seed=1))
    np.testing.assert_array_equal(a, b)
    augmenter = ScanAugmenter(rssi, config, seed=1)
    assert not np.array_equal(_augmented(augmenter), _augmented(augmenter),
                              equal_nan=True)
    assert np.isnan(a[:, 20:]).all()
    detected = a[np.isfinite(a)]
    assert detected.max() <= 0 and detected.min() >= -110
    assert 0.1 < np.isnan(a[:, :20]).mean() < 0.3
    assert detected.std() > 3


def test_recognizer_levels(synthetic):
    recognizer = PlaceRecognizer(load_model(synthetic[1]), 0.0, 2)
    ids = recognizer.model.ap_ids
    assert recognizer.classify(ids[:3], [-60] * 3).level == OK
    few = recognizer.classify(ids[:1], [-60])
    assert few.level == WARN and 'only 1 known APs' in few.message
    recognizer.min_confidence = 1.0
    assert recognizer.classify(ids[:3], [-60] * 3).level == WARN


def test_estimators_check_fitted_and_width(synthetic):
    with pytest.raises(ValueError, match='not fitted yet'):
        RssiScaler().transform(np.full((1, 3), -60.0))
    model = load_model(synthetic[1])
    width = len(model.ap_ids)
    with pytest.raises(ValueError, match=rf'shape \(n, {width}\).*got shape '
                                         r'\(1, 1\)'):
        model.predict([[-60.0]])
    scaler = RssiScaler().fit(np.full((4, 3), -60.0))
    with pytest.raises(ValueError, match=r'expected 3 AP columns.*\(1, 2\)'):
        scaler.transform(np.full((1, 2), -60.0))
