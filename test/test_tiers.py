"""The test tiers: every test is marked from what it uses (conftest.py)."""

import os
import sys

from conftest import REPO, run
import pytest

PLUGIN = '''
def pytest_collection_finish(session):
    for item in session.items:
        names = {m.name for m in item.iter_markers()}
        print('TIERS', item.nodeid, ','.join(sorted(names)), sep='\\t')
'''

#: A test of each kind -> the tiers it has (through its own code, a
#: fixture, a helper), and a tier it must not have.
EXPECTED = {
    'test_scan.py::test_mean_softmax_averages_the_members_probabilities':
        ({'unit'}, 'ros'),
    'test_node.py::test_duplicate_ap_keeps_the_strongest_reading':
        ({'ros'}, 'unit'),
    'test_tiers.py::test_every_test_has_a_tier':
        ({'system'}, 'unit'),               # its fixture runs pytest
    'test_fingerprints.py::test_real_training_file': ({'dataset'}, 'unit'),
    'test_shutdown.py::test_stop_signals_at_random_moments_end_every_node_'
    'cleanly': ({'ros', 'stress', 'system'}, 'unit'),  # a helper's processes
    'test_reliability.py::test_fuzzed_scans_never_kill_the_node':
        ({'ros', 'stress'}, 'unit'),        # fuzzed messages via a helper
    'test_reliability.py::test_sigkill_while_saving_never_tears_the_model_'
    'file': ({'system'}, 'unit'),
    'test_flake8.py::test_flake8': ({'linter'}, 'unit'),
    'test_help.py::test_an_offline_tool_answers_help_and_starts_nothing['
    'train_model--h]': ({'system'}, 'unit'),
    'test_help.py::test_a_running_node_declares_the_tables_parameters_and_'
    'topics[classifier_node]': ({'ros', 'system'}, 'unit'),
}


@pytest.fixture(scope='module')
def collected(tmp_path_factory):
    """Return {test id: its markers} of a collection of the whole suite."""
    folder = tmp_path_factory.mktemp('plugin')
    (folder / 'tiers_plugin.py').write_text(PLUGIN)
    env = dict(os.environ, PYTHONPATH=str(folder))
    out = run([sys.executable, '-m', 'pytest', '--collect-only', '-q',
               '-p', 'no:cacheprovider', '-p', 'tiers_plugin', 'test'],
              cwd=REPO, env=env)
    assert out.returncode == 0, out.stdout + out.stderr
    rows = [line.split('\t') for line in out.stdout.splitlines()
            if line.startswith('TIERS\t')]
    return {test.partition('/')[2]: set(markers.split(','))
            for _, test, markers in rows}


@pytest.mark.parametrize('test', sorted(EXPECTED))
def test_each_kind_of_test_gets_its_tiers(collected, test):
    has, lacks = EXPECTED[test]
    assert has <= collected[test], collected[test]
    assert lacks not in collected[test], collected[test]


def test_every_test_has_a_tier(collected):
    tiers = {'unit', 'ros', 'dataset', 'system', 'stress', 'linter'}
    assert not [t for t, markers in collected.items() if not markers & tiers]
    assert sum('unit' in m for m in collected.values()) > 50
