"""Each scan's coverage on ~/place, over real ROS, as the core gives it."""

from dataclasses import replace
from pathlib import Path

from conftest import python_module, run
import numpy as np
import pytest
from ros_helpers import running_node
from wifi_place_recognition.core.evaluation import align, unknown_aps
from wifi_place_recognition.core.coverage import unlike_survey
from wifi_place_recognition.core.locator import MISMATCH_SIGMA_M
from wifi_place_recognition.data.fingerprints import read_fingerprints
from wifi_place_recognition.ros.messages import status_values

RUN = Path(__file__).resolve().parents[2] / 'shared' / 'datasets' / \
    'robot' / 'b24' / 'b24test2' / 'scans.csv'
HOLE = (300, 450)   # scan rows cut out of the survey
#: APs no survey scan heard, and the row (of ``rows`` below, one near
#: the hole) sent again with them.
NEW_APS = tuple(f'fe:ee:ee:ee:00:{k:02x}' for k in range(12))
ROW_HEARD = 4


@pytest.mark.skipif(not RUN.exists(), reason='robot runs not available')
def test_place_carries_each_scans_coverage(ros, tmp_path):
    lines = RUN.read_text().splitlines(True)
    survey = tmp_path / 'survey.csv'
    survey.write_text(lines[0] + ''.join(
        line for i, line in enumerate(lines[1:])
        if not HOLE[0] <= i < HOLE[1]))
    model_path = tmp_path / 'm.npz'
    result = run(python_module('cli.train_model', '--data', survey, '-o',
                               model_path, '--quiet'))
    assert result.returncode == 0, result.stderr
    fp = read_fingerprints(RUN)
    rows = [50, 375, 600, 320, 430]   # covered, in the hole, covered, and
    #                                   two answered at the hole's edges
    with running_node(ros, tmp_path, model_path, 'coverage_node') as (
            client, proc, model):
        proba, xy, sigma, expected, mismatch = model.predict_positions(
            align(model, fp), coverage=True)
        narrow = model.predict_positions(align(model, fp), widened=False)[2]
        got, sigmas, knn, sounds = [], [], [], []
        for row in rows:
            detected = np.flatnonzero(np.isfinite(fp.rssi[row]))
            status = client.resend_until_answered(client.scan(
                [fp.ap_ids[j] for j in detected], fp.rssi[row, detected]),
                30)
            assert status is not None
            values = status_values(status)
            got.append(float(values['coverage']))
            sigmas.append(float(values['scan_sigma_m']))
            knn.append(float(values['scan_knn_sigma_m']))
            sounds.append(float(values['mismatch']))
        # the mismatch over the survey's usual, as offline (the filter's)
        np.testing.assert_allclose(sounds, mismatch[rows], atol=1e-3)
        assert model.position.usual_mismatch > 0
        # exact, not rounded (the monitor's 0.5 rule decides on them)
        np.testing.assert_allclose(got, expected[rows], rtol=1e-6, atol=0)
        assert all(0.0 <= p <= 1.0 for p in got)
        # a scan that also heard APs the survey never did: judged alike
        # offline (the APs the model lacks counted as the node counts them)
        row = rows[ROW_HEARD]
        detected = np.flatnonzero(np.isfinite(fp.rssi[row]))
        status = client.resend_until_answered(client.scan(
            [fp.ap_ids[j] for j in detected] + list(NEW_APS),
            list(fp.rssi[row, detected]) + [-70.0] * len(NEW_APS)), 30)
        louder = replace(fp, ap_ids=fp.ap_ids + NEW_APS, rssi=np.hstack(
            [fp.rssi, np.full((len(fp), len(NEW_APS)), -70.0, np.float32)]))
        heard = model.predict_positions(
            align(model, louder), coverage=True,
            unknown=unknown_aps(model, louder))[3][row]
        assert abs(heard - expected[row]) > 0.1    # the count matters
        assert float(status_values(status)['coverage']) == \
            pytest.approx(heard, rel=1e-6, abs=0)
        # the health counts the answers off the survey (these rows: some
        # in the hole, the others not; the probe), a scan answered twice
        # (sent again before its answer came back) twice
        assert 0 < (expected[rows] < 0.5).sum() < len(rows)
        off = sum(float(status_values(msg.status[0])['coverage']) < 0.5
                  for msg in client.answers.values())
        counts, values = client.settled_counts()
        repeated = counts['answered'] - len(client.answers)
        assert off <= int(values['scans_off_survey']) <= off + repeated, \
            (values['scans_off_survey'], off, repeated)
        # each scan's own sigma, widened where the answer lies at the
        # survey's edge (the survey calibrated by how much)
        assert model.position.edge_sigma > 0
        np.testing.assert_allclose(sigmas, sigma[rows], rtol=1e-3,
                                   atol=2e-3)
        assert (np.array(sigmas[3:]) > narrow[rows[3:]] + 1.0).all()
        # and by MISMATCH_SIGMA_M more where it sounds unlike the survey
        # (the hole's scans)
        edge = np.array([model.position.widened(xy[r], narrow[r],
                                                proba[r].argmax())
                         for r in rows])
        unlike = unlike_survey(mismatch[rows])
        assert 0 < unlike.sum() < len(rows)
        np.testing.assert_allclose(
            sigmas, np.where(unlike, np.hypot(edge, MISMATCH_SIGMA_M), edge),
            rtol=1e-3, atol=2e-3)
        # and the k-NN's, which the localization monitor reads
        np.testing.assert_allclose(knn, narrow[rows], rtol=1e-6, atol=0)
