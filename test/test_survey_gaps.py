"""``survey_gaps`` on a robot run whose survey has known holes."""

import json
from pathlib import Path

import numpy as np
import pytest
from wifi_place_recognition.cli.survey_gaps import main
from wifi_place_recognition.cli.train_model import main as train
from wifi_place_recognition.core.artifact import load_model, save_model
from wifi_place_recognition.core.gaps import gaps

RUN = Path(__file__).resolve().parents[2] / 'shared' / 'datasets' / \
    'robot' / 'b24' / 'b24test2' / 'scans.csv'
#: The survey's holes: scan rows (0-based, time order) cut out of the run.
HOLES = ((150, 250), (450, 560))


def test_gaps_are_the_runs_of_scans_off_the_survey():
    off = np.array([0, 1, 1, 0, 0, 1, 1, 1, 0, 1], bool)
    xy = np.column_stack([np.arange(10.0), np.zeros(10)])
    found = gaps(off, np.arange(10.0) * 2, xy, min_scans=2)
    assert [(g.first, g.last) for g in found] == [(1, 2), (5, 7)]
    assert found[1].length_m == 2.0 and found[1].start_s == 10.0
    assert found[1].scans == 3
    assert gaps(np.zeros(4, bool)) == []


@pytest.fixture(scope='module')
def holed(tmp_path_factory):
    """Return (model with holes, the whole run's CSV)."""
    if not RUN.exists():
        pytest.skip('robot runs not available')
    folder = tmp_path_factory.mktemp('gaps')
    lines = RUN.read_text().splitlines(True)
    cut = set()
    for first, end in HOLES:
        cut.update(range(first, end))
    survey = folder / 'survey.csv'
    survey.write_text(lines[0] + ''.join(
        line for i, line in enumerate(lines[1:]) if i not in cut))
    model = folder / 'm.npz'
    assert train(['--data', str(survey), '-o', str(model), '--quiet']) == 0
    return model, RUN


def test_the_holes_of_the_survey_are_the_stretches_listed(holed, capsys,
                                                          tmp_path):
    model, run = holed
    picture = tmp_path / 'gaps.png'
    assert main(['--model', str(model), '--data', str(run), '--json',
                 '--plot', str(picture)]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result['basis'].startswith('no survey scan within 3')
    stretches = result['stretches']
    assert len(stretches) == len(HOLES)
    t0 = float(run.read_text().splitlines()[1].split(',')[0])
    stamps = [float(line.split(',')[0]) - t0
              for line in run.read_text().splitlines()[1:]]
    for s, (first, end) in zip(stretches, HOLES):
        # inside the cut piece, less the 3 m the kept scans cover at its ends
        assert stamps[first] <= s['start_s'] < s['end_s'] <= stamps[end - 1]
        assert s['end_s'] - s['start_s'] > 0.5 * (stamps[end - 1] -
                                                  stamps[first])
        assert s['length_m'] > 5
    assert picture.stat().st_size > 1000


def test_a_run_without_positions_needs_a_coverage_model(holed, capsys,
                                                        tmp_path):
    model, run = holed
    assert main(['--model', str(model), '--data', str(run),
                 '--position-columns', 'none', '--json']) == 0
    result = json.loads(capsys.readouterr().out, parse_constant=lambda c:
                        pytest.fail(f'{c} is not JSON'))
    assert result['basis'] == 'model coverage probability < 0.5'
    assert all(s['length_m'] is None for s in result['stretches'])
    # a model with positions but no coverage section
    bare = load_model(model)
    bare.coverage = None
    save_model(bare, tmp_path / 'bare.npz')
    assert main(['--model', str(tmp_path / 'bare.npz'), '--data', str(run),
                 '--position-columns', 'none']) == 2
    assert 'no coverage section' in capsys.readouterr().err


def test_a_run_the_model_knows_no_ap_of_is_off_the_survey(holed, capsys,
                                                          tmp_path):
    # the same run with every AP renamed: nothing the model heard
    model, run = holed
    header, *rows = run.read_text().splitlines(True)
    renamed = tmp_path / 'elsewhere.csv'
    renamed.write_text(','.join(
        f'fe:ee:ee:ee:{k // 256:02x}:{k % 256:02x}' if name.count(':') == 5
        else name for k, name in enumerate(header.rstrip('\n').split(',')))
        + '\n' + ''.join(rows))
    assert main(['--model', str(model), '--data', str(renamed),
                 '--position-columns', 'none', '--json']) == 0
    out, err = capsys.readouterr()
    result = json.loads(out)
    assert result['scans_off_survey'] == result['scans'] == len(rows)
    assert [s['scans'] for s in result['stretches']] == [len(rows)]
    # and the user is told why, not only that
    assert result['scans_without_known_ap'] == len(rows)
    assert f'{len(rows)} of {len(rows)} scans share no AP with the model' \
        in err
    assert main(['--model', str(model), '--data', str(run), '--json']) == 0
    assert json.loads(capsys.readouterr().out)[
        'scans_without_known_ap'] == 0


def test_bad_arguments_are_refused_with_one_line(holed, capsys, tmp_path):
    model, run = holed
    assert main(['--model', str(model), '--data', str(run),
                 '--covered-m', '0']) == 2
    assert 'covered-m' in capsys.readouterr().err
    assert main(['--model', str(model), '--data', str(run), '--plot',
                 str(tmp_path / 'no' / 'x.png')]) == 2
    assert 'no folder' in capsys.readouterr().err
    # a name matplotlib cannot write: refused before the work, not after
    assert main(['--model', str(model), '--data', str(run), '--plot',
                 str(tmp_path / 'gaps.txt')]) == 2
    captured = capsys.readouterr()
    assert f'--plot {tmp_path}/gaps.txt: not a picture file name (one of ' \
        in captured.err and not captured.out, captured
    assert not (tmp_path / 'gaps.txt').exists()
