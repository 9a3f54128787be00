"""Training, the numpy forward pass, and the train/evaluate command lines."""

import csv
import json
import math

from conftest import (dataset_file, FAST, python_module, run, surveyed_csv,
                      synthetic_csv)
import numpy as np
import pytest
import torch
from wifi_place_recognition.core.artifact import load_model, save_model
from wifi_place_recognition.data.fingerprints import read_fingerprints
from fuzz import hostile_model_files
from wifi_place_recognition.core.metrics import class_index
from wifi_place_recognition.core.locator import R95
from wifi_place_recognition.core.model import mean_softmax, ScanForward
from wifi_place_recognition.core.recognizer import PlaceRecognizer
from wifi_place_recognition.training.config import TrainConfig
from wifi_place_recognition.training.folds import grouped_folds
from wifi_place_recognition.training.fitting import best_epoch
from wifi_place_recognition.core.evaluation import align
from wifi_place_recognition.core.coverage import one_sidedness
from wifi_place_recognition.core.locator import (calibrated_edge_sigma,
                                                 calibrated_sigma, EDGE_POWER,
                                                 Locator, MIN_SIGMA)
from wifi_place_recognition.core.preprocessing import signal
from wifi_place_recognition.training.selection import (
    _covered, _cross_validate_position, _Split, COVERED_M, cross_validate,
    fit_temperature, usual_mismatch)
from wifi_place_recognition.training.trainer import train

SMALL = dict(sae_layers=(32, 16), classifier_layers=(16,), sae_epochs=3,
             epochs=15, batch_size=32, ensemble=1)


def _torch_proba(nets, model, rssi):
    x = torch.as_tensor(model.scaler.transform(rssi))
    with torch.no_grad():
        return mean_softmax([net(x).numpy() for net in nets])


def test_same_seed_same_model(tmp_path):
    fp = read_fingerprints(synthetic_csv(tmp_path / 'a.csv'))
    a, _, ra = train(fp, TrainConfig(**SMALL), log=lambda s: None)
    b, _, rb = train(fp, TrainConfig(**SMALL), log=lambda s: None)
    assert ra.selection == rb.selection and ra.epochs == rb.epochs
    for la, lb in zip(a.members[0], b.members[0]):
        np.testing.assert_array_equal(la.weight, lb.weight)


def test_training_leaves_torch_global_state_alone(tmp_path):
    fp = read_fingerprints(synthetic_csv(tmp_path / 'a.csv'))
    threads, rng = torch.get_num_threads(), torch.get_rng_state()
    train(fp, TrainConfig(threads=1, **dict(SMALL, epochs=2, folds=0)),
          log=lambda s: None)
    assert torch.get_num_threads() == threads
    assert torch.equal(torch.get_rng_state(), rng)


def test_learns_the_synthetic_building_and_numpy_matches_torch(tmp_path):
    fp = read_fingerprints(synthetic_csv(tmp_path / 'a.csv'))
    # New scans of the same building: none of them was trained on.
    test = read_fingerprints(synthetic_csv(tmp_path / 'b.csv', scans_seed=1))
    seen, new = (np.nan_to_num(f.rssi, nan=100) for f in (fp, test))
    assert not (new[:, None] == seen[None]).all(axis=2).any()
    config = TrainConfig(**dict(SMALL, ensemble=2))
    model, nets, report = train(fp, config, log=lambda s: None)
    building, floor, _, proba = model.predict(test.rssi)
    assert np.mean((building == test.building) & (floor == test.floor)) > 0.9
    assert len(model.members) == len(nets) == 2
    assert report.selection['accuracy_mean'] > 0.9
    assert 1 <= report.epochs <= config.epochs
    assert report.epochs == model.provenance['epochs']
    reference = _torch_proba(nets, model, test.rssi)
    np.testing.assert_allclose(proba, reference, atol=1e-5)
    forward = ScanForward(model)
    np.testing.assert_allclose([forward(*model.sparse(row)) for row in test.rssi],
                               reference, atol=1e-5)


def test_folds_hold_out_whole_phones_and_keep_every_class(tmp_path):
    fp = read_fingerprints(synthetic_csv(tmp_path / 'a.csv', phones=6))
    labels = class_index(fp.building, fp.floor)[1]
    folds = grouped_folds(fp, labels, 3, seed=3)
    phones = fp.meta['PHONEID']
    assert folds.grouping == 'device' and len(folds.held_out) == 3
    assert sum(m.sum() for m in folds.held_out) == len(fp)
    for held in folds.held_out:
        assert not set(phones[held]) & set(phones[~held])
        assert set(labels[~held]) == set(labels)


def test_folds_keep_a_class_that_only_one_phone_saw_in_training(tmp_path):
    fp = read_fingerprints(synthetic_csv(tmp_path / 'a.csv', phones=6))
    phones = fp.meta['PHONEID'].copy()
    phones[(fp.building == 1) & (fp.floor == 1)] = 99  # only phone 99
    fp.meta['PHONEID'] = phones
    labels = class_index(fp.building, fp.floor)[1]
    folds = grouped_folds(fp, labels, 3)
    for held in folds.held_out:
        assert set(labels[~held]) == set(labels)
        assert not (phones[held] == 99).any()
    assert len(folds.never_held_out) == 1


def test_time_blocks_without_device_or_walk(tmp_path):
    fp = read_fingerprints(synthetic_csv(tmp_path / 'a.csv'))
    fp.meta.pop('PHONEID')
    labels = class_index(fp.building, fp.floor)[1]
    folds = grouped_folds(fp, labels, 4)
    assert folds.grouping == 'time'
    for held in folds.held_out:  # contiguous blocks of file order
        rows = np.flatnonzero(held)
        assert 0.1 < held.mean() < 0.4
        assert len(np.unique(np.diff(rows) > 1)) <= 2


def test_bad_config_values_are_refused():
    with pytest.raises(ValueError, match='dropout'):
        TrainConfig(dropout=1.5)
    with pytest.raises(ValueError, match='grouping must be one of'):
        TrainConfig(grouping='test-file')
    with pytest.raises(ValueError, match='folds must be'):
        TrainConfig(folds=1)
    # 'none' was accepted and silently grouped by time blocks
    with pytest.raises(ValueError, match='grouping must be one of'):
        TrainConfig(grouping='none')
    for option in ('position_representation', 'position_metric',
                   'position_scope'):
        with pytest.raises(ValueError, match=option):
            TrainConfig(**{option: 'nearest'})
    with pytest.raises(ValueError, match='patience'):
        TrainConfig(patience=0)
    # each of these crashed training (overflow, memory) or wrote NaN
    for values, message in (
            ({'augment_gain': math.inf}, "not {'augment_gain': inf}"),
            ({'augment_noise': math.nan}, "not {'augment_noise': nan}"),
            ({'augment_gain': 1.0}, 'gain and dropout < 1'),
            ({'sae_layers': (10 ** 8,)}, 'layer sizes must be from 1 to'),
            ({'learning_rate': 1e6}, 'learning rate in (0, 1], not 0 and'),
            ({'seed': -1}, 'seed must be from 0 to 4294967295, not -1'),
            ({'seed': 10 ** 20}, 'seed must be from 0')):
        with pytest.raises(ValueError) as err:
            TrainConfig(**values)
        assert message in str(err.value), values


def test_selection_stops_patience_epochs_after_the_best(synthetic):
    fp = read_fingerprints(synthetic[0])
    classes, y = class_index(fp.building, fp.floor)
    config = TrainConfig(sae_layers=(32, 16), classifier_layers=(16,),
                         sae_epochs=1, epochs=30, patience=3, folds=2)
    s = cross_validate(fp, y, len(classes), config, log=lambda *a: None)
    assert len(s['mean_curve']) < 30
    assert len(s['mean_curve']) == s['epochs'] + 3
    assert len(s['curves'][0]) == len(s['mean_curve'])


def test_batch_size_follows_the_number_of_scans():
    config = TrainConfig()
    assert [config.batch_for(n) for n in (100, 697, 1476, 3116, 19937)] == \
        [32, 32, 64, 128, 512]
    assert TrainConfig(batch_size=100).batch_for(19937) == 100


def test_numpy_matches_torch_on_real_data():
    fp = read_fingerprints(dataset_file('trainingData.csv'))
    test = read_fingerprints(dataset_file('validationData-public.csv'))
    model, nets, _ = train(fp, TrainConfig(sae_epochs=1, epochs=2, folds=0,
                                           ensemble=2), log=lambda s: None)
    proba = model.predict_proba(test.rssi)
    ref = _torch_proba(nets, model, test.rssi)
    assert np.abs(proba - ref).max() <= 1e-5
    assert (proba.argmax(1) == ref.argmax(1)).all()
    # The node's one-scan path (sparse first layer) agrees as well.
    forward = ScanForward(model)
    single = np.stack([forward(*model.sparse(row)) for row in test.rssi])
    assert np.abs(single - ref).max() <= 1e-5
    assert (single.argmax(1) == ref.argmax(1)).all()


def test_shipped_model_reaches_the_paper_level():
    result = run(python_module(
        'cli.evaluate_model', '--json', '--data',
        dataset_file('validationData-public.csv')))
    assert result.returncode == 0, result.stderr
    scores = json.loads(result.stdout)
    assert scores['samples'] == 556
    assert scores['building_floor_accuracy'] >= 0.92


# command lines ---------------------------------------------------------------

def test_train_then_evaluate_on_the_command_line(tmp_path):
    data = synthetic_csv(tmp_path / 'a.csv')
    model = tmp_path / 'out' / 'model.npz'
    (tmp_path / 'out').mkdir()
    result = run(python_module('cli.train_model', '--data', data, '-o', model,
                               '--test', data, *FAST))
    assert result.returncode == 0, result.stderr
    assert 'building floor accuracy' in result.stdout
    assert load_model(model).provenance['config']['epochs'] == 15

    preds = tmp_path / 'pred.csv'
    result = run(python_module('cli.evaluate_model', '--model', model, '--data',
                               data, '--json', '--predictions', preds))
    assert result.returncode == 0, result.stderr
    scores = json.loads(result.stdout)
    assert {'samples', 'building_accuracy', 'floor_accuracy',
            'building_floor_accuracy'} <= set(scores)
    rows = list(csv.DictReader(preds.open()))
    assert len(rows) == scores['samples'] == 240
    assert rows[0].keys() >= {'pred_building', 'pred_floor', 'confidence'}


def test_validation_data_chooses_epochs_and_sigma(tmp_path):
    data = surveyed_csv(tmp_path / 'a.csv')
    validation = surveyed_csv(tmp_path / 'v.csv', scans_seed=2,
                              scans_per_floor=60)
    model = tmp_path / 'm.npz'
    result = run(python_module('cli.train_model', '--data', data,
                               '--validation', validation, '-o', model,
                               *FAST))
    assert result.returncode == 0, result.stderr
    assert f'validation data {validation}: building+floor' in result.stdout
    loaded = load_model(model)
    selection = loaded.provenance['selection']
    assert selection['grouping'] == 'validation'
    assert [f['held_out_scans'] for f in selection['folds']] == [120]
    assert loaded.provenance['validation_data']['scans'] == 120
    assert loaded.provenance['epochs'] == \
        best_epoch(selection['mean_curve']) + 1
    assert loaded.position is not None      # sigma from validation scans
    assert selection['position_mean_error_m'] < 5.0
    # every scan of the validation data right: the probabilities are not
    # sharpened (temperature 1)
    calibration = loaded.provenance['calibration']
    assert calibration['fitted_on'] == f'validation data {validation}'
    assert loaded.temperature == calibration['temperature'] == 1.0
    # a class the training data lacks: exit 2 naming it, nothing written
    other = synthetic_csv(tmp_path / 'other.csv')
    result = run(python_module('cli.train_model', '--data', data,
                               '--validation', other, '-o',
                               tmp_path / 'no.npz', *FAST))
    assert result.returncode == 2
    assert 'building 1 floor 0' in result.stderr and \
        'not in the training data' in result.stderr
    assert 'Traceback' not in result.stderr
    assert not (tmp_path / 'no.npz').exists()


@pytest.mark.parametrize('content, message', [
    ('WAP1,FLOOR\n-50,1\n', 'missing label column(s) BUILDINGID'),
    ('WAP1,FLOOR,BUILDINGID\n-50,x,0\n', "row 2, column FLOOR: value 'x'"),
    ('WAP1,FLOOR,BUILDINGID\n-50,1,0\n-60,1\n', 'row 3 has 2 fields'),
    ('', 'empty file'),
    ('WAP1,FLOOR,BUILDINGID\n-50,1,0\n-60,1,0\n', 'only one building/floor'),
    ('WAP1,FLOOR,BUILDINGID\n-50,1,0\n-60,1,0\n-70,2,0\n',
     'row 4, columns BUILDINGID/FLOOR: building 0, floor 2 has 1 scan(s)'),
    ('WAP1,FLOOR,BUILDINGID\n100,1,0\n100,2,0\n', 'no scan detects any AP'),
    ('WAP1,WAP2,FLOOR,BUILDINGID\n', 'no data rows'),
    ('WAP1,WAP1,FLOOR,BUILDINGID\n-50,-50,1,0\n', "'WAP1' appears twice"),
    ('WAP1\tFLOOR\tBUILDINGID\n-50\t1\t0\n', 'comma-separated'),
])
def test_train_model_bad_csv_exits_2_and_writes_nothing(
        tmp_path, content, message):
    data = tmp_path / 'bad.csv'
    data.write_text(content)
    model = tmp_path / 'model.npz'
    result = run(python_module('cli.train_model', '--data', data, '-o', model,
                               *FAST))
    assert result.returncode == 2
    assert message in result.stderr and 'Traceback' not in result.stderr
    assert list(tmp_path.iterdir()) == [data]


def test_evaluate_model_bad_inputs_exit_2_without_traceback(
        synthetic, tmp_path):
    data, model = synthetic
    files = hostile_model_files(model, tmp_path, tmp_path / 'PWNED')
    for args, message in [
            *[(['--model', path, '--data', data], str(path))
              for path in files.values()],
            (['--model', model, '--data', tmp_path / 'none.csv'],
             'cannot read'),
            (['--model', model], 'no data given')]:
        result = run(python_module('cli.evaluate_model', *args))
        assert result.returncode == 2, args
        assert message in result.stderr
        assert 'Traceback' not in result.stderr
    assert not (tmp_path / 'PWNED').exists()


# position -------------------------------------------------------------------

def test_position_by_neighbours_round_trips_the_model_file(tmp_path):
    fp = read_fingerprints(surveyed_csv(tmp_path / 'a.csv'))
    test = read_fingerprints(surveyed_csv(tmp_path / 'b.csv', scans_seed=1,
                                          scans_per_floor=60))
    config = TrainConfig(sae_layers=(32, 16), classifier_layers=(16,),
                         sae_epochs=3, epochs=20, batch_size=32, ensemble=2,
                         folds=2)
    model, nets, report = train(fp, config, log=lambda s: None)
    save_model(model, tmp_path / 'm.npz')
    loaded = load_model(tmp_path / 'm.npz')
    assert loaded.position.columns == ('X', 'Y')
    assert loaded.position.neighbours == report.selection['neighbours']
    np.testing.assert_array_equal(loaded.position.origin,
                                  fp.position.mean(axis=0))
    proba, xy, sigma = loaded.predict_positions(test.rssi)
    error = np.linalg.norm(xy - test.position, axis=1)
    # scans spread over 40 m x 40 m floors: guessing the middle is ~15 m off
    assert error.mean() < 4.0, error.mean()
    assert report.selection['position_mean_error_m'] < 5.0
    assert 0.85 <= (error <= R95 * sigma).mean() <= 1.0
    recognizer = PlaceRecognizer(loaded)
    for row in range(0, len(test), 7):
        detected = np.flatnonzero(np.isfinite(test.rssi[row]))
        place = recognizer.classify([test.ap_ids[j] for j in detected],
                                    test.rssi[row, detected])
        np.testing.assert_allclose(place.probabilities, proba[row],
                                   atol=1e-5)
        np.testing.assert_allclose(place.position, xy[row], atol=1e-6)
        assert place.position_sigma == pytest.approx(sigma[row])


def test_a_classifier_only_model_refuses_to_locate(synthetic):
    model = load_model(synthetic[1])
    assert model.position is None
    with pytest.raises(ValueError, match='no position output'):
        model.predict_positions(np.full((1, len(model.ap_ids)), -60.0))


def test_evaluate_model_reports_position_errors_and_draws(tmp_path):
    data = surveyed_csv(tmp_path / 'a.csv')
    test = surveyed_csv(tmp_path / 'b.csv', scans_seed=1, scans_per_floor=40)
    model = tmp_path / 'model.npz'
    result = run(python_module(
        'cli.train_model', '--data', data, '-o', model, *FAST,
        '--epochs', '20', '--folds', '2'))
    assert result.returncode == 0, result.stderr
    preds, plots = tmp_path / 'pred.csv', tmp_path / 'plots'
    result = run(python_module(
        'cli.evaluate_model', '--model', model, '--data', test, '--json',
        '--predictions', preds, '--plot', plots, '--plot-baseline', data))
    assert result.returncode == 0, result.stderr
    scores = json.loads(result.stdout)
    errors = {k: scores[k] for k in (
        'position_mean_error_m', 'position_median_error_m',
        'position_p75_error_m', 'position_p95_error_m',
        'position_penalised_mean_error_m', 'position_in_95_ellipse')}
    assert 0 < errors['position_median_error_m'] <= \
        errors['position_p75_error_m'] <= errors['position_p95_error_m']
    assert errors['position_mean_error_m'] < 8.0, errors
    assert errors['position_penalised_mean_error_m'] >= \
        errors['position_mean_error_m']
    rows = list(csv.DictReader(preds.open()))
    assert len(rows) == 80 and {'x', 'y', 'sigma_m'} <= rows[0].keys()
    assert abs(float(rows[0]['x']) + 7600) < 100  # absolute coordinates
    assert sorted(p.name for p in plots.iterdir()) == [
        'confusion.png', 'error_cdf.png', 'map_B0F0.png', 'map_B0F1.png']
    assert all(p.read_bytes()[:4] == b'\x89PNG' for p in plots.iterdir())


def test_the_temperature_fit_finds_the_one_that_made_the_labels():
    rng = np.random.default_rng(0)
    logits = rng.normal(0, 3, (20000, 4))
    for made in (1.5, 2.5, 6.0):
        proba = mean_softmax([logits / made])
        y = (proba.cumsum(axis=1) < rng.random((len(proba), 1))).sum(axis=1)
        assert fit_temperature(logits, y) == pytest.approx(made, rel=0.05)
    # scans more often right than their probabilities say: never sharpened
    assert fit_temperature(logits, logits.argmax(axis=1)) == 1.0


def test_validation_data_with_errors_fits_the_temperature(tmp_path):
    data = surveyed_csv(tmp_path / 'a.csv')
    validation = surveyed_csv(tmp_path / 'v.csv', scans_seed=2,
                              scans_per_floor=60)
    lines = validation.read_text().splitlines()
    for i in range(1, len(lines), 6):     # a floor label wrong in 1 of 6
        cells = lines[i].split(',')
        cells[-3] = str(1 - int(cells[-3]))
        lines[i] = ','.join(cells)
    validation.write_text('\n'.join(lines) + '\n')
    model = tmp_path / 'm.npz'
    result = run(python_module('cli.train_model', '--data', data,
                               '--validation', validation, '-o', model,
                               *FAST))
    assert result.returncode == 0, result.stderr
    loaded = load_model(model)
    # the ensemble's probabilities of the validation scans fit the
    # temperature the file carries: the best of its neighbours there
    calibration = loaded.provenance['calibration']
    assert loaded.temperature == calibration['temperature'] > 1.0
    assert calibration['nll_after'] < calibration['nll_before']
    fp = read_fingerprints(validation)
    y = class_index(fp.building, fp.floor)[1]
    nll = []
    for factor in (0.9, 1.0, 1.1):
        loaded.temperature = calibration['temperature'] * factor
        proba = loaded.predict_proba(align(loaded, fp))
        nll.append(-np.log(proba[np.arange(len(fp)), y]).mean())
    assert nll[1] == pytest.approx(calibration['nll_after'], rel=1e-4)
    assert nll[1] < min(nll[0], nll[2])


def test_without_validation_data_the_probabilities_stay_as_computed(
        synthetic):
    model = load_model(synthetic[1])
    assert model.temperature == 1.0
    assert model.provenance['calibration']['fitted_on'].startswith(
        'nothing: without validation data')


def test_the_sigma_is_calibrated_on_held_out_scans_the_kept_ones_cover(
        tmp_path):
    fp = read_fingerprints(surveyed_csv(tmp_path / 'a.csv',
                                        scans_per_floor=800))
    classes, y = class_index(fp.building, fp.floor)
    x = fp.position[:, 0] - fp.position[:, 0].min()
    keep = x < 20                           # the left half of each floor
    held = ~keep
    split = _Split(fp, y, keep, fp.rssi[held], y[held], fp.position[held])
    gap = np.linalg.norm(fp.position[held][:, None] - fp.position[keep],
                         axis=2)
    gap[y[held][:, None] != y[keep]] = np.inf     # another floor's scan
    covered = gap.min(axis=1) <= COVERED_M
    assert 30 < covered.sum() < held.sum() - 30
    np.testing.assert_array_equal(_covered(split), covered)
    config = TrainConfig(neighbours=3, position_representation='positive',
                         position_metric='euclidean', position_scope='floor')
    chosen = _cross_validate_position([split], [split.held_y], len(classes),
                                      config, log=lambda line: None)
    assert chosen['sigma_calibration_scans'] == covered.sum()
    locator = Locator.build(fp.rssi[keep], y[keep], fp.position[keep],
                            len(classes), 3)
    placed = [locator.positions(locator.distances(
        np.flatnonzero(~np.isnan(r)), signal(r[~np.isnan(r)], 'positive'),
        c), (3,), c) for r, c in zip(fp.rssi[held], y[held])]
    error = np.linalg.norm(np.array([p[0][0] for p in placed])
                           - fp.position[held], axis=1)
    nearest = np.array([p[1] for p in placed])
    np.testing.assert_allclose(chosen['sigma_m'], calibrated_sigma(
        error[covered], nearest[covered], y[held][covered], len(classes)),
        rtol=1e-6)
    # the uncovered half of the held-out scans is placed much worse
    assert error[~covered].mean() > 2 * error[covered].mean()
    # and calibrates how much an answer at the survey's edge is widened
    assert chosen['edge_calibration_scans'] == (~covered).sum()
    sigma = np.maximum(np.array(chosen['sigma_m'])[y[held]] * nearest,
                       MIN_SIGMA)
    xy = np.array([p[0][0] for p in placed])
    side = np.array([one_sidedness(p[None] - locator.origin,
                                   locator.reference_xy(c))[0]
                     for p, c in zip(xy, y[held])])
    edge = chosen['edge_sigma_m']
    assert 0 < edge == pytest.approx(calibrated_edge_sigma(
        error[~covered], sigma[~covered], side[~covered]), rel=1e-6)
    inside = error <= R95 * np.hypot(sigma, edge * side ** EDGE_POWER)
    # (half a floor unsurveyed: more than 15 m would be needed for 95 %)
    assert (error <= R95 * sigma)[~covered].mean() + 0.05 < \
        inside[~covered].mean()
    assert inside[covered].mean() >= 0.95


def test_the_usual_mismatch_is_the_covered_held_out_scans_median():
    mismatch = np.array([1.0, 2.0, 3.0, 40.0, np.nan] * 10)
    covered = np.array([True, True, True, False, True] * 10)
    # the scans off the survey and those without a mismatch left out
    assert usual_mismatch(mismatch, covered) == (2.0, 30)
    # fewer than 30: not known
    assert usual_mismatch(mismatch[:45], covered[:45]) == (0.0, 27)
    # held-out scans that repeat the kept ones: at least 2 dB
    assert usual_mismatch(mismatch / 10, covered) == (2.0, 30)
