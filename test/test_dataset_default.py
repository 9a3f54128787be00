"""
The tests find UJIIndoorLoc the same way however pytest is started.

``scripts/test.sh`` and ``python -m pytest`` alike (test/conftest.py):
$WIFI_PR_DATASET, else the shared copy beside the repository.
"""

import os
import sys

from conftest import DEFAULT_DATASET, REPO, run
import pytest

#: A test that reads UJIIndoorLoc through ``dataset_file``.
READS_UJIINDOORLOC = 'test/test_fingerprints.py::test_real_training_file'


def pytest_directly(cwd, **variables):
    """Run that test with ``python -m pytest`` from ``cwd``; return stdout."""
    env = {k: v for k, v in os.environ.items() if k != 'WIFI_PR_DATASET'}
    out = run([sys.executable, '-m', 'pytest', '-q', '-rs', '-p',
               'no:cacheprovider', str(REPO / READS_UJIINDOORLOC)],
              cwd=cwd, env={**env, **variables})
    return out.stdout + out.stderr


def test_python_m_pytest_reads_the_shared_copy_without_the_variable(
        tmp_path):
    if not DEFAULT_DATASET.is_dir():
        pytest.skip(f'{DEFAULT_DATASET} absent')
    for cwd in (REPO, tmp_path):
        out = pytest_directly(cwd)
        assert '1 passed' in out, out[-3000:]


def test_the_variable_still_chooses_the_folder(tmp_path):
    out = pytest_directly(REPO, WIFI_PR_DATASET=str(tmp_path))  # empty
    assert '1 skipped' in out and 'UJIIndoorLoc not available' in out, \
        out[-3000:]
