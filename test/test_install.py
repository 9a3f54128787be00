"""The two install layouts: colcon (what ``ros2 run`` execs) and ``pip install``."""

import os
from pathlib import Path
import shutil
import sys
import sysconfig

from conftest import REPO, run
import pytest
from ros_helpers import Client, NodeProcess

PROBE = (['WAP001', 'WAP002', 'WAP003', 'WAP004'], [-60.0, -70.0, -80.0, -50.0])


def _answer_from_installed(ros, tmp_path, executable, prefix, site):
    """Start an installed node with only the install on the path; probe it."""
    env = dict(os.environ, AMENT_PREFIX_PATH=str(prefix),
               PYTHONPATH=os.pathsep.join(
                   [str(site), os.environ.get('PYTHONPATH', '')]))
    proc = NodeProcess(tmp_path, [str(executable)], 'installed_node', env=env)
    client = Client(ros, 'installed_node')
    try:
        status = client.wait_ready(proc, PROBE)
    finally:
        client.close()
        code, log = proc.stop()
    assert code == 0, log
    # The shipped model was found in the install's share directory.
    assert f'{prefix}/share/wifi_place_recognition/models/' in log, log
    return status


def test_colcon_installed_executable_answers(ros, tmp_path):
    colcon = shutil.which('colcon', path=os.path.dirname(sys.executable))
    if colcon is None:
        pytest.skip('colcon is not installed (pip install '
                    'colcon-common-extensions)')
    result = run([colcon, 'build', '--base-paths', str(REPO),
                  '--build-base', 'build', '--install-base', 'install'],
                 cwd=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    prefix = tmp_path / 'install' / 'wifi_place_recognition'
    executable = prefix / 'lib' / 'wifi_place_recognition' / 'classifier_node'
    assert executable.exists()
    for name in ('models/ujiindoorloc.npz', 'package.xml',
                 'config/classifier_node.yaml', 'launch/classifier.launch.py'):
        assert (prefix / 'share' / 'wifi_place_recognition' / name).exists()
    site = next(prefix.glob('lib/python3*/site-packages'))
    assert status_ok(_answer_from_installed(ros, tmp_path, executable,
                                            prefix, site))


def test_pip_installed_console_script_answers(ros, tmp_path):
    prefix = tmp_path / 'prefix'
    source = tmp_path / 'source'  # pip builds in the tree: use a copy
    shutil.copytree(REPO, source, ignore=shutil.ignore_patterns(
        '.venv', '.git', 'build', 'install', 'log', '*.egg-info'))
    # --ignore-installed: without it pip removes this venv's own install.
    result = run([sys.executable, '-m', 'pip', 'install', '--no-deps',
                  '--ignore-installed', '--no-build-isolation', '--prefix',
                  str(prefix), str(source)])
    assert result.returncode == 0, result.stdout + result.stderr
    site = Path(sysconfig.get_path(
        'purelib', vars={'base': str(prefix), 'platbase': str(prefix)}))
    assert status_ok(_answer_from_installed(
        ros, tmp_path, prefix / 'bin' / 'classifier_node', prefix, site))


def status_ok(status):
    """Return True if the status is an answer (not a rejection)."""
    return status.message.startswith('building ')


def test_launch_file_is_valid_python():
    source = (REPO / 'launch' / 'classifier.launch.py').read_text()
    compile(source, 'classifier.launch.py', 'exec')
