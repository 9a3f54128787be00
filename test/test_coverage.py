"""The coverage model: learned from the survey, kept, read by the filter."""

import math
from pathlib import Path

from conftest import dataset_file, save_unchecked
import numpy as np
import pytest
from wifi_place_recognition.core.artifact import (load_model, ModelFileError,
                                                  save_model)
from wifi_place_recognition.core.coverage import (COVERED_M, CoverageModel,
                                                  distance_by_place, FEATURES,
                                                  one_sidedness, uncovered)
from wifi_place_recognition.core.evaluation import align, unknown_aps
from wifi_place_recognition.core.filter.particles import (FusionParams,
                                                          ParticleFilter)
from wifi_place_recognition.core.filter.sensor import (WifiPosition,
                                                       WifiSensorModel)
from wifi_place_recognition.data.fingerprints import read_fingerprints
from wifi_place_recognition.training.coverage import (auc, fit_coverage,
                                                      PRIOR_FLOOR,
                                                      reliability)

ROBOT = Path(__file__).resolve().parents[2] / 'shared' / 'datasets' / \
    'robot' / 'b24'
#: A model with a position output, shipped with the package.
SHIPPED = Path(__file__).resolve().parents[1] / 'models' / \
    'ujiindoorloc.npz'


def _model(**change):
    values = dict(mean=(0.0,) * 4, scale=(1.0,) * 4,
                  coef=(-2.0, 0.0, 0.0, -1.0), intercept=1.0)
    values.update(change)
    return CoverageModel(**values)


def test_the_probability_falls_as_the_answer_looks_unlike_the_survey():
    model = _model()
    near, far = model.probability([[-1.0, 0, 0, 0.0], [2.0, 0, 0, 0.5]])
    assert near > 0.9 and far < 0.1


@pytest.mark.parametrize('change, named', [
    ({'coef': (1.0, float('nan'), 0.0, 0.0)}, 'coef'),
    ({'scale': (1.0, 0.0, 1.0, 1.0)}, 'scale'),
    ({'mean': (0.0,) * 3}, 'mean'),
    ({'intercept': 'x'}, 'intercept'),
    ({'features': ('log_sigma',)}, 'features'),
])
def test_a_bad_coverage_section_is_refused_naming_it(change, named):
    with pytest.raises(ValueError, match=named):
        _model(**change)


def test_the_distance_to_the_survey_counts_only_the_same_place():
    survey = [[0.0, 0.0], [10.0, 0.0], [0.0, 5.0]]
    xy = [[0.0, 1.0], [0.0, 1.0], [np.nan, 0.0], [3.0, 4.0]]
    # class labels: the first scan's class has only the far survey scan
    got = distance_by_place(xy, [1, 0, 0, 2], survey, [0, 1, 0])
    assert np.allclose(got[:2], [math.hypot(10, 1), 1.0])
    assert np.isnan(got[2]) and got[3] == np.inf    # no survey of class 2
    # building and floor rows: the same floor of another building differs
    got = distance_by_place(xy[:2], [[0, 1], [1, 1]], survey,
                            [[1, 1], [0, 1], [1, 1]])
    assert np.allclose(got, [math.hypot(10, 1), 1.0])


def test_one_sidedness_is_near_one_only_at_the_survey_edge():
    corridor = np.column_stack([np.arange(0.0, 30.0, 0.5), np.zeros(60)])
    side = one_sidedness([[15, 0], [15.2, 0], [0, 0], [-3, 0], [29.5, 0],
                          [15, 40], [np.nan, 0]], corridor)
    assert side[0] == pytest.approx(0, abs=1e-9)   # survey on both sides
    assert side[1] < 0.1
    assert side[2] == side[3] == side[4] == pytest.approx(1)  # at an end
    assert side[5] == 1                 # no survey within 5 m
    assert np.isnan(side[6])


def test_fit_learns_from_held_out_scans_and_reports_its_reliability():
    rng = np.random.default_rng(0)
    covered = rng.random(600) < 0.5
    x = rng.normal(size=(600, len(FEATURES)))
    x[:, 0] += np.where(covered, -1.0, 1.0)     # farther when not covered
    model = fit_coverage(x, covered, np.arange(600) % 4, log=lambda _: None)
    report = model.report
    assert report['auc'] > 0.8
    assert report['covered'] + report['not_covered'] == 600
    assert report['ece'] < 0.1
    assert sum(b['scans'] for b in report['reliability']) == 600
    assert fit_coverage(x[:30], covered[:30], np.arange(30) % 4,
                        log=lambda _: None) is None    # too few to learn


@pytest.mark.parametrize('share', [0.5, 0.97])
def test_the_prior_is_the_held_out_share_but_at_least_the_floor(share):
    # the same separation at two shares covered: the odds of covered are
    # those the examples show when above PRIOR_FLOOR, else PRIOR_FLOOR's
    rng = np.random.default_rng(1)
    covered = rng.random(4000) < share
    x = rng.normal(size=(4000, len(FEATURES)))
    x[:, 0] += np.where(covered, -1.0, 1.0)
    model = fit_coverage(x, covered, np.arange(4000) % 4, log=lambda _: None)
    prior = max(covered.mean(), PRIOR_FLOOR)
    assert model.report['prior'] == pytest.approx(prior, abs=1e-4)
    # where a covered and an uncovered scan are alike likely (feature 0),
    # the log-odds are the prior's
    z = np.zeros((1, len(FEATURES)))
    p = float(model.probability(z)[0])
    assert math.log(p / (1 - p)) == pytest.approx(
        math.log(prior / (1 - prior)), abs=0.2)


def test_auc_and_reliability_are_what_they_say():
    assert auc([0.1, 0.2, 0.8, 0.9], [False, False, True, True]) == 1.0
    assert auc([0.5, 0.5], [False, True]) == 0.5
    table, ece = reliability(np.array([0.1, 0.1, 0.9, 0.9]),
                             np.array([False, False, True, True]))
    assert [b['scans'] for b in table] == [2, 2]
    assert ece == pytest.approx(0.1)


def test_a_scan_off_the_survey_moves_no_particle_and_never_restarts():
    params = FusionParams(particles=200, coverage_full=0.5)
    sensor = WifiSensorModel(params)
    state = np.zeros((3, 4))
    state[:, 0] = (0.0, 5.0, 10.0)
    off = WifiPosition(np.zeros(2), coverage=0.0)
    on = WifiPosition(np.zeros(2), coverage=0.9)
    assert np.allclose(sensor.likelihood(state, off), 1.0)
    assert sensor.likelihood(state, on)[2] < 0.6
    pf = ParticleFilter(params, seed=0)
    pf.start(np.zeros(2))
    far = WifiPosition(np.array([50.0, 0.0]), coverage=0.0)
    assert not any(pf.update(far) for _ in range(3 * params.reset_after))
    # the same scans from covered ground restart it
    far = WifiPosition(np.array([50.0, 0.0]), coverage=0.9)
    assert any(pf.update(far) for _ in range(params.reset_after))


def test_coverage_full_zero_leaves_the_filter_as_it_was():
    params = FusionParams()
    sensor = WifiSensorModel(params)
    state = np.zeros((1000, 4))
    state[:, 0] = np.linspace(0.0, 12.0, 1000)
    before = (1 - params.wifi_outlier) * np.exp(
        -state[:, 0] ** 2 / (2 * params.wifi_sd ** 2)) + params.wifi_outlier
    for coverage in (None, 0.0, 0.7):   # round 5's formula, to the bit
        assert np.array_equal(sensor.likelihood(
            state, WifiPosition(np.zeros(2), coverage=coverage)), before)
    with pytest.raises(ValueError, match='coverage_full'):
        FusionParams(coverage_full=1.5)


@pytest.mark.skipif(not ROBOT.exists(), reason='robot runs not available')
def test_train_model_learns_coverage_from_a_robot_run(tmp_path):
    from wifi_place_recognition.cli.train_model import main
    scans = ROBOT / 'b24test2' / 'scans.csv'
    lines = scans.read_text().splitlines(True)
    # a survey with a hole: the middle fifth of the run cut out
    n = len(lines) - 1
    cut = range(1 + 2 * n // 5, 1 + 3 * n // 5)
    survey = tmp_path / 'survey.csv'
    survey.write_text(''.join(line for i, line in enumerate(lines)
                              if i not in cut))
    path = tmp_path / 'm.npz'
    assert main(['--data', str(survey), '-o', str(path), '--quiet']) == 0
    model = load_model(path)
    report = model.coverage.report
    assert report['auc'] > 0.5 and 0 <= report['ece'] < 0.5
    save_model(model, tmp_path / 'again.npz')
    assert load_model(tmp_path / 'again.npz').coverage == model.coverage
    # the cut scans far from every kept one look less covered than the rest
    run = read_fingerprints(ROBOT / 'b24test3' / 'scans.csv')
    probability = model.predict_positions(align(model, run),
                                          coverage=True)[3]
    assert np.isfinite(probability).all()
    assert ((0 <= probability) & (probability <= 1)).all()
    held = read_fingerprints(scans)
    p_held = model.predict_positions(align(model, held), coverage=True)[3]
    middle = np.zeros(len(p_held), bool)
    middle[2 * n // 5 + 20:3 * n // 5 - 20] = True  # inside the hole
    assert p_held[middle].mean() < p_held[~middle].mean()


def test_the_shipped_models_coverage_holds_on_another_days_scans():
    # UJIIndoorLoc's public validation half, four months after the survey:
    # covered when a training scan of its building/floor lies within 3 m
    train = read_fingerprints(dataset_file('trainingData.csv'))
    test = read_fingerprints(dataset_file('validationData-public.csv'),
                             role='test')
    model = load_model(SHIPPED)
    p = model.predict_positions(align(model, test), coverage=True,
                                unknown=unknown_aps(model, test))[3]
    covered = distance_by_place(
        test.position, np.column_stack([test.building, test.floor]),
        train.position,
        np.column_stack([train.building, train.floor])) <= COVERED_M
    assert auc(p, covered) > 0.7                     # 0.744 measured
    assert reliability(p, covered)[1] < 0.08         # ECE 0.058
    assert uncovered(p).mean() < 0.05                # 0.5 % judged off


@pytest.mark.parametrize('section, named', [
    ('not a dict', 'coverage must be an object'),
    ({'mean': [0] * 4}, 'missing'),
    (dict(_model().to_dict(), extra=1), 'unknown coverage key'),
    (dict(_model().to_dict(), intercept=10 ** 400), 'intercept'),
])
def test_a_bad_coverage_section_in_a_file_is_refused_in_one_line(
        section, named, tmp_path):
    import json
    import zipfile
    from wifi_place_recognition.core.artifact import _digest
    path = tmp_path / 'm.npz'
    model = load_model(SHIPPED) if SHIPPED.exists() else None
    if model is None:
        pytest.skip('no model with a position output')
    save_model(model, path)
    with np.load(path) as f:
        arrays = {k: f[k] for k in f.files}
    header = json.loads(arrays.pop('header').tobytes())
    header.pop('sha256')
    header['coverage'] = section
    header['sha256'] = _digest(header, arrays)
    arrays['header'] = np.frombuffer(json.dumps(header).encode(), np.uint8)
    np.savez(path, **arrays)
    assert zipfile.is_zipfile(path)
    with pytest.raises(ModelFileError, match=named):
        load_model(path)


def test_a_coverage_section_without_a_position_output_is_refused(
        synthetic, tmp_path):
    model = load_model(synthetic[1])
    model.coverage = _model()
    with pytest.raises(ValueError, match='coverage section needs a '
                                         'position output'):
        save_model(model, tmp_path / 'm.npz')
    save_unchecked(model, tmp_path / 'm.npz')
    with pytest.raises(ModelFileError, match='coverage section needs a '
                                             'position output'):
        load_model(tmp_path / 'm.npz')
