"""``ros2 run`` after ``pip install .``: the executables in lib/<package>."""

import os
from pathlib import Path
import shutil
import sys
import sysconfig

from conftest import REPO, run

PACKAGE = 'wifi_place_recognition'


def test_pip_install_puts_every_executable_where_ros2_run_looks(tmp_path):
    source = tmp_path / 'source'    # pip builds in the tree: use a copy
    shutil.copytree(REPO, source, ignore=shutil.ignore_patterns(
        '.venv', '.git', 'build', 'install', 'log', '*.egg-info',
        '__pycache__', 'benchmarks', 'test'))
    prefix = tmp_path / 'prefix'
    # --ignore-installed: without it pip first uninstalls the package from
    # the running environment (the test's own .venv) to install it here.
    result = run([sys.executable, '-m', 'pip', 'install', '--no-deps',
                  '--no-build-isolation', '--no-index', '--ignore-installed',
                  '--prefix', prefix, source], cwd=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    kept = run([sys.executable, '-m', 'pip', 'show', '-q', PACKAGE])
    assert kept.returncode == 0, 'the running environment lost the package'
    installed = sorted(p.name for p in (prefix / 'bin').iterdir())
    ros2_run = prefix / 'lib' / PACKAGE     # what `ros2 run` executes
    assert sorted(p.name for p in ros2_run.iterdir()) == installed
    assert 'classifier_node' in installed
    for name in installed:
        assert os.access(ros2_run / name, os.X_OK), name
    # Runs the node of this install: a bad parameter is its one-line error.
    site = sysconfig.get_path('purelib', vars={'base': prefix,
                                               'platbase': prefix})
    env = dict(os.environ, PYTHONPATH=site)
    where = run([sys.executable, '-c', f'import {PACKAGE}; '
                 f'print({PACKAGE}.__file__)'], env=env, cwd=tmp_path)
    assert Path(where.stdout.strip()).is_relative_to(prefix), where
    node = run([ros2_run / 'classifier_node', '--ros-args', '-p',
                'max_aps:=0'], env=env, cwd=tmp_path, timeout=30)
    assert node.returncode == 1, node.stderr
    assert '[classifier_node]: cannot start: ' in node.stderr
    assert 'max_aps out of range' in node.stderr, node.stderr
    # `ros2 run ... --help` reaches the executable, which answers it.
    for name in ('classifier_node', 'wifi_scanner_node',
                 'record_fingerprints'):
        shown = run([ros2_run / name, '--help'], env=env, cwd=tmp_path,
                    timeout=30)
        assert shown.returncode == 0, shown.stderr
        assert shown.stdout.startswith(f'usage: {name} [-h]'), shown.stdout
