"""
The robot benchmarks' ``--data``: the folders they take, and what they refuse.

A folder of building folders, or one building folder; a building with one
run is passed over with a line; nothing to score stops them in one line.
"""

import subprocess
import sys

from bag_helpers import ROBOT
from conftest import REPO
import pytest

pytestmark = pytest.mark.skipif(not (ROBOT / 'b24').exists(),
                                reason='robot runs not available')
RUNS = ('b24test2', 'b24test3')


def building(folder, runs):
    """Make a building folder of links to the shared b24 runs; return it."""
    folder.mkdir(parents=True)
    for name in runs:
        (folder / name).symlink_to(ROBOT / 'b24' / name)
    return folder


def names(found):
    """Return [(building, [run names])] of what site_runs yielded."""
    return [(site, [r.name for r in runs]) for site, runs in found]


def test_a_building_folder_is_taken_as_its_parent_is(
        fusion, tmp_path, monkeypatch):
    one = building(tmp_path / 'data' / 'b24', RUNS)
    (tmp_path / 'data' / 'map').mkdir()         # no runs: not a building
    (tmp_path / 'data' / 'stray.mcap').touch()  # a bag beside buildings
    expected = [('b24', list(RUNS))]
    assert names(fusion.site_runs(tmp_path / 'data', tmp_path)) == expected
    assert names(fusion.site_runs(one, tmp_path)) == expected
    monkeypatch.chdir(one)
    assert names(fusion.site_runs('.', tmp_path)) == expected


def test_a_building_with_one_run_is_passed_over_with_a_line(
        fusion, tmp_path, capsys):
    building(tmp_path / 'data' / 'b24', RUNS)
    building(tmp_path / 'data' / 'lonely', RUNS[:1])
    assert names(fusion.site_runs(tmp_path / 'data', tmp_path)) == \
        [('b24', list(RUNS))]
    assert 'lonely: 1 run(s), passed over' in capsys.readouterr().err


@pytest.mark.parametrize('script', ['fusion.py', 'witness.py'])
def test_nothing_to_score_stops_in_one_line(tmp_path, script):
    building(tmp_path / 'one' / 'b24', RUNS[:1])
    for data, why in ((tmp_path / 'one', 'no building folder with two runs'),
                      (tmp_path / 'none', 'not a folder')):
        out = tmp_path / 'out.json'
        done = subprocess.run(
            [sys.executable, REPO / 'benchmarks' / script, '--data', data,
             '--out', out], capture_output=True, text=True, timeout=300)
        assert done.returncode != 0
        last = done.stderr.strip().splitlines()[-1]
        assert last.startswith(f'error: --data {data}: {why}'), done.stderr
        assert 'Traceback' not in done.stderr and not out.exists()
