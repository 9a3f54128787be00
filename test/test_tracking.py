"""Tracking over a walk: the filter, its fitting, the model file section."""

import json
import time

import numpy as np
import pytest
from wifi_place_recognition.core.artifact import (
    load_model, ModelFileError, save_model)
from wifi_place_recognition.core.tracking import (
    PlaceTracker, PositionFilter, track_walk, TrackingParams)
from wifi_place_recognition.core.tracking_fit import (
    fit_evidence, fit_motion, fit_rates)
from wifi_place_recognition.data.walks import split_walks

#: Two buildings: building 0 has floors 0-2, building 1 floors 0-1.
CLASSES = np.array([[0, 0], [0, 1], [0, 2], [1, 0], [1, 1]])
#: Like those fitted on WiFine: a floor change every ~8 min, scans every 5 s.
PARAMS = TrackingParams(floor_rate=2e-3, building_rate=1e-5, temperature=1.0,
                        min_interval=5.0)


def scan(index, p=0.9, k=len(CLASSES)):
    """Return class probabilities with ``p`` on ``index``, the rest spread."""
    proba = np.full(k, (1 - p) / (k - 1))
    proba[index] = p
    return proba


def test_prediction_spreads_more_with_time_and_rarely_to_another_building():
    tracker = PlaceTracker(CLASSES, TrackingParams(
        floor_rate=1e-3, building_rate=1e-5, min_interval=0.0))
    start = np.eye(len(CLASSES))[0]
    short, long = tracker.predict(start, 10.0), tracker.predict(start, 600.0)
    assert short.sum() == pytest.approx(1) and long.sum() == pytest.approx(1)
    assert 1 > short[0] > long[0] > 0.4
    # the mass that leaves goes mostly to the other floors of building 0
    assert long[1] == long[2] > 50 * long[3]
    assert long[3] == long[4] > 0
    # every scan counts for at least min_interval seconds
    floor5 = PlaceTracker(CLASSES, TrackingParams(min_interval=5.0))
    np.testing.assert_allclose(floor5.predict(start, 0.0),
                               floor5.predict(start, 5.0))


def test_a_single_floor_building_keeps_its_floor_mass():
    tracker = PlaceTracker([[0, 0], [1, 0]], TrackingParams(
        floor_rate=0.1, building_rate=0.0))
    np.testing.assert_allclose(tracker.predict(np.array([1.0, 0.0]), 100),
                               [1.0, 0.0])


def walk(labels, period=5.0, wrong=(), p=0.9):
    """Return (times, proba) of a walk; ``wrong`` maps scan -> wrong class."""
    proba = np.array([scan(dict(wrong).get(i, c), p)
                      for i, c in enumerate(labels)])
    return np.arange(len(labels)) * period, proba


def test_holds_through_an_isolated_wrong_scan():
    labels = [1] * 30
    times, proba = walk(labels, wrong={15: 2})
    tracks = track_walk(PlaceTracker(CLASSES, PARAMS), times, proba)
    assert proba[15].argmax() == 2
    assert [t.index for t in tracks] == labels
    assert tracks[15].confidence > 0.5


def test_follows_a_real_floor_change_within_two_scans():
    labels = [1] * 30 + [2] * 10
    times, proba = walk(labels)
    tracks = track_walk(PlaceTracker(CLASSES, PARAMS), times, proba)
    switched = [i for i, t in enumerate(tracks) if t.index == 2]
    assert switched[0] <= 31 and switched == list(range(switched[0], 40))
    assert (tracks[-1].building, tracks[-1].floor) == (0, 2)


def test_long_gap_restarts_and_backwards_time_restarts():
    tracker = PlaceTracker(CLASSES, PARAMS, timeout=60.0)
    for i in range(20):
        tracker.update(5.0 * i, scan(0, 0.99))
    track = tracker.update(95.0 + 61, scan(3, 0.6))
    assert track.restarted and track.index == 3
    assert track.confidence == pytest.approx(0.6)     # the scan alone
    assert not tracker.update(160.0, scan(3)).restarted
    assert tracker.update(100.0, scan(4)).restarted  # time went backwards


def test_reset_forgets_the_belief():
    tracker = PlaceTracker(CLASSES)
    for i in range(20):
        tracker.update(5.0 * i, scan(0, 0.99))
    tracker.reset()
    track = tracker.update(100.0, scan(3, 0.6))
    assert track.restarted and track.index == 3


def test_bad_evidence_is_refused():
    tracker = PlaceTracker(CLASSES)
    with pytest.raises(ValueError, match='5 finite class probabilities'):
        tracker.update(0.0, np.ones(4) / 4)
    with pytest.raises(ValueError, match='finite'):
        tracker.update(0.0, np.full(5, np.nan))
    with pytest.raises(ValueError, match='position'):
        tracker.update(0.0, scan(0), xy=[1.0, 2.0])


def test_position_filter_is_the_constant_velocity_kalman_filter():
    params = TrackingParams(acceleration_noise=0.3, speed_sd=0.7)
    track = PositionFilter(params)
    rng = np.random.default_rng(3)
    eye, x = np.eye(2), None
    for _ in range(40):
        z, s = rng.normal(0, 10, 2), rng.uniform(1, 5)
        noise = np.array([[s * s, 0.4], [0.4, 1.3 * s * s]])
        if x is None:       # a track starts at rest
            x = np.r_[z, 0.0, 0.0]
            cov = np.diag([0.0, 0.0, 0.49, 0.49])
            cov[:2, :2] = noise
        else:               # textbook matrices: F P F^T + Q, then the gain
            dt = rng.uniform(0.5, 20)
            move = np.eye(4) + dt * np.eye(4, k=2)
            q = params.acceleration_noise * np.block(
                [[dt ** 3 / 3 * eye, dt ** 2 / 2 * eye],
                 [dt ** 2 / 2 * eye, dt * eye]])
            x, cov = move @ x, move @ cov @ move.T + q
            track.predict(dt)
            gain = cov[:, :2] @ np.linalg.inv(cov[:2, :2] + noise)
            x, cov = x + gain @ (z - x[:2]), cov - gain @ cov[:2]
        track.update(z, noise)
        xy, xy_cov = track.xy
        np.testing.assert_allclose(xy, x[:2], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(xy_cov, cov[:2, :2], rtol=1e-9,
                                   atol=1e-9)


def test_position_is_smoothed_and_restarts_on_a_floor_change():
    rng = np.random.default_rng(0)
    sigma = 3.0
    truth = np.array([10.0, 20.0])
    tracker = PlaceTracker(CLASSES, TrackingParams(acceleration_noise=1e-5,
                                                   speed_sd=0.1))
    cov = sigma ** 2 * np.eye(2)
    raw, smooth = [], []
    for i in range(60):
        xy = truth + rng.normal(0, sigma, 2)
        track = tracker.update(5.0 * i, scan(1), xy, cov)
        raw.append(np.linalg.norm(xy - truth))
        smooth.append(np.linalg.norm(track.xy - truth))
    assert np.mean(smooth[20:]) < 0.5 * np.mean(raw[20:])
    assert np.trace(track.cov) < 0.3 * np.trace(cov)
    # no position in a scan: the track is kept, less certain after a gap
    kept = tracker.update(5.0 * 60 + 100, scan(1))
    np.testing.assert_allclose(kept.xy, track.xy, atol=0.5)
    assert np.trace(kept.cov) > 2 * np.trace(track.cov)
    # the tracked floor changes: the position restarts from the new scan
    for i in range(3):
        moved = tracker.update(5.0 * 90 + i, scan(2, 0.99), [50.0, 60.0],
                               cov)
    assert moved.index == 2
    np.testing.assert_allclose(moved.xy, [50.0, 60.0], atol=1e-9)
    assert tracker.update(5.0 * 91, scan(2, 0.99)).xy is not None
    tracker.reset()
    assert tracker.update(5.0 * 92, scan(2, 0.99)).xy is None


def walker(rng, n=300, period=5.0):
    """Return (times, true xy) of a walk of straight legs at ~1.2 m/s."""
    times = np.cumsum(rng.uniform(0.8, 1.2, n) * period)
    heading = np.repeat(rng.uniform(0, 2 * np.pi, n // 20 + 1), 20)[:n]
    speed = 1.2 * np.array([np.cos(heading), np.sin(heading)]).T
    steps = speed * np.diff(np.concatenate([[0.0], times]))[:, None]
    return times, np.cumsum(steps, axis=0)


def measured_walk(rng, sigma=4.0):
    """Return (times, measured xy, their cov, true xy) of a walk."""
    times, truth = walker(rng)
    n = len(times)
    return (times, truth + rng.normal(0, sigma, truth.shape),
            np.tile(sigma ** 2 * np.eye(2), (n, 1, 1)), truth)


def test_position_follows_a_walking_robot_better_than_single_scans():
    rng = np.random.default_rng(1)
    params, grid = fit_motion(TrackingParams(),
                              [measured_walk(rng) for _ in range(3)])
    assert 0.6 < params.speed_sd < 1.2     # 1.2 m/s in random directions
    assert len(grid) == 7 and params.acceleration_noise == min(
        grid, key=lambda g: g['mean_error_m'])['acceleration_noise']
    times, xy, cov, truth = measured_walk(rng)
    tracks = track_walk(PlaceTracker(CLASSES, params), times,
                        np.tile(scan(0), (len(times), 1)), xy, cov)
    errors = np.linalg.norm([t.xy for t in tracks] - truth, axis=1)
    raw = np.linalg.norm(xy - truth, axis=1)
    assert errors[10:].mean() < 0.8 * raw[10:].mean()
    # the covariance is honest: about 95 % inside the 95 % ellipse
    inside = [r @ np.linalg.solve(t.cov, r) < 5.991 for t, r in
              zip(tracks[10:], [t.xy for t in tracks[10:]] - truth[10:])]
    assert 0.85 < np.mean(inside) <= 1.0


def test_fit_rates_recovers_the_rate_of_simulated_walks():
    rng = np.random.default_rng(0)
    rate_f, rate_b = 2e-3, 2e-4
    walks = []
    for _ in range(200):
        times = np.cumsum(rng.uniform(1, 30, 100))
        building = np.zeros(100, int)
        floor = np.zeros(100, int)
        for i in range(1, 100):
            dt = times[i] - times[i - 1]
            building[i] = building[i - 1] ^ (rng.random() <
                                             1 - np.exp(-rate_b * dt))
            floor[i] = (floor[i - 1] + (rng.random() <
                                        1 - np.exp(-rate_f * dt))) % 3
        walks.append((times, building, floor))
    floor_rate, building_rate, summary = fit_rates(walks)
    assert floor_rate == pytest.approx(rate_f, rel=0.15)
    assert building_rate == pytest.approx(rate_b, rel=0.3)
    assert summary['pairs'] == 200 * 99
    # pairs further apart than the timeout are left out
    assert fit_rates(walks, timeout=10.0)[2]['pairs'] < 200 * 40


def test_fit_rates_without_any_change_is_small_but_not_zero():
    floor_rate, building_rate, _ = fit_rates(
        [(np.arange(100) * 10.0, np.zeros(100), np.zeros(100))])
    assert floor_rate == pytest.approx(0.5 / 990)
    assert building_rate == pytest.approx(0.5 / 990)
    # a building change is not also a floor change (floor 2 -> floor 0)
    floor_rate, building_rate, summary = fit_rates(
        [(np.arange(100) * 10.0, np.repeat([0, 1], 50),
          np.repeat([2, 0], 50))])
    assert summary['floor_changes'] == 0
    assert summary['building_changes'] == 1
    assert floor_rate == pytest.approx(0.5 / 980)
    assert building_rate > floor_rate


def test_fit_evidence_tempers_over_confident_correlated_errors():
    """Errors that come in runs of 3 confident scans need a temperature."""
    rng = np.random.default_rng(0)
    walks = []
    for _ in range(30):
        truth = np.repeat(rng.integers(0, 3, 4), 25)
        proba = np.array([scan(t, 0.995) for t in truth])
        for start in rng.choice(95, 6, replace=False):
            wrong = (truth[start] + 1) % 3
            proba[start:start + 3] = scan(wrong, 0.995)
        walks.append((np.arange(100) * 5.0, truth, proba))
    params, grid = fit_evidence(TrackingParams(floor_rate=0.01), CLASSES,
                                walks)
    assert params.temperature > 1.0
    assert len(grid) == 35
    chosen = [g for g in grid if g['temperature'] == params.temperature and
              g['min_interval'] == params.min_interval]
    assert chosen[0]['accuracy'] == max(g['accuracy'] for g in grid)
    assert chosen[0]['accuracy'] > min(g['accuracy'] for g in grid)


def test_split_walks_groups_and_orders_by_time():
    user = np.array([1, 2, 1, 2, 1])
    phone = np.array([7, 7, 7, 7, 8])
    times = np.array([30.0, 10.0, 20.0, 5.0, 0.0])
    walks = split_walks((user, phone), times)
    assert [w.tolist() for w in walks] == [[2, 0], [4], [3, 1]]


def test_params_are_checked_by_name():
    with pytest.raises(ValueError, match='temperature = 0'):
        TrackingParams(temperature=0)
    with pytest.raises(ValueError, match="floor_rate = 'x'"):
        TrackingParams(floor_rate='x')
    with pytest.raises(ValueError, match='building_rate = -1'):
        TrackingParams(building_rate=-1)
    with pytest.raises(ValueError, match='unknown tracking parameter'):
        TrackingParams.from_dict({'floor_rat': 1.0})
    params = TrackingParams(floor_rate=2e-3, fit={'walks': 'x'})
    assert TrackingParams.from_dict(json.loads(json.dumps(
        params.to_dict()))) == params


def test_update_is_cheap():
    tracker = PlaceTracker(np.array([[b, f] for b in range(3)
                                     for f in range(5)]))
    rng = np.random.default_rng(0)
    proba = rng.dirichlet(np.ones(15), 2000)
    cost = []
    for i, p in enumerate(proba):
        start = time.perf_counter()
        tracker.update(5.0 * i, p, rng.normal(0, 1, 2), np.eye(2))
        cost.append(time.perf_counter() - start)
    # the node's whole budget is 0.5 ms at the 99th percentile
    assert np.median(cost) < 2e-4, np.median(cost)


# the model file --------------------------------------------------------------
def test_model_file_stores_tracking_and_old_files_load(synthetic, tmp_path):
    _, model_path = synthetic
    model = load_model(model_path)
    assert model.tracking is None           # written without the section
    model.tracking = TrackingParams(floor_rate=3e-3, temperature=1.5,
                                    fit={'source': 'walks.csv'})
    save_model(model, tmp_path / 'tracked.npz')
    assert load_model(tmp_path / 'tracked.npz').tracking == model.tracking


def test_model_file_with_a_bad_tracking_section_is_refused(synthetic,
                                                           tmp_path):
    from wifi_place_recognition.core.artifact import _digest
    with np.load(synthetic[1], allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    header = json.loads(arrays.pop('header').tobytes())
    header.pop('sha256')
    header['tracking'] = {'floor_rate': -1.0}
    header['sha256'] = _digest(header, arrays)   # a valid checksum
    arrays['header'] = np.frombuffer(json.dumps(header).encode(), np.uint8)
    np.savez(tmp_path / 'bad.npz', **arrays)
    with pytest.raises(ModelFileError,
                       match='tracking section: tracking parameter '
                             'floor_rate = -1.0'):
        load_model(tmp_path / 'bad.npz')


# the recognizer -------------------------------------------------------------
def test_recognizer_answers_tracked_and_keeps_the_scan_answer(synthetic):
    from wifi_place_recognition.core.recognizer import PlaceRecognizer, WARN
    model = load_model(synthetic[1])
    model.tracking = PARAMS
    k = len(model.classes)
    evidence = iter([scan(0, 0.9, k)] * 10 + [scan(1, 0.9, k)]
                    + [scan(0, 0.9, k)] * 3)
    recognizer = PlaceRecognizer(model, forward=lambda columns, inputs: next(evidence))
    recognizer.configure(tracking=True)
    names = model.ap_ids[:5]
    places = [recognizer.classify(names, [-60] * 5, 5.0 * i)
              for i in range(14)]
    wrong = places[10]
    assert (wrong.scan_building, wrong.scan_floor) == tuple(model.classes[1])
    assert (wrong.building, wrong.floor) == tuple(model.classes[0])
    assert 'this scan alone: building %d, floor %d (p=0.90)' % tuple(
        model.classes[1]) in wrong.message
    assert wrong.probabilities.sum() == pytest.approx(1)
    assert wrong.probabilities.argmax() == 0     # the tracked belief
    assert all((p.building, p.floor) == tuple(model.classes[0])
               for p in places)
    # without tracking (or without a time) the answer is the scan's own
    recognizer.configure(tracking=False)
    evidence = iter([scan(1, 0.4, k)])
    alone = recognizer.classify(names, [-60] * 5, 100.0)
    assert (alone.building, alone.floor) == tuple(model.classes[1])
    assert alone.confidence == alone.scan_confidence == 0.4
    assert alone.level == WARN and 'this scan alone' not in alone.message
