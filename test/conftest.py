"""
Shared fixtures and the test tiers.

Fixtures: synthetic fingerprints, a small trained model, ROS set-up. Each
test is marked with its tiers from what it uses (its code, its fixtures
and the helpers they call), so new test files are sorted too:

- ``ros``: ROS 2 (an rclpy node, a node process, messages);
- ``dataset``: UJIIndoorLoc or WiFine (``dataset_file``,
  ``DEFAULT_DATASET``, ``WIFINE``, the datasets of the docs' examples,
  ``EXAMPLE_DATA``);
- ``system``: other processes (the executables, a venv, colcon);
- ``stress``: a busy core, scan floods, signals at random moments;
- ``linter``: flake8, pep257;
- ``unit``: none of these: in-process, synthetic data (``-m unit``).
"""

import fcntl
import importlib
import inspect
import os
from pathlib import Path
import subprocess
import sys
import time
from xml.etree import ElementTree

import numpy as np
import pytest

DOMAIN_IDS = range(10, 100)


def claim_domain_id(ids=DOMAIN_IDS):
    """
    Return (domain id, lock file) for an id no other live test run holds.

    Each id is an exclusive ``flock`` on a file in /tmp, held until the
    returned file is closed (here: for the whole session; the kernel drops
    it when the process dies).
    """
    start = os.getpid() % len(ids)
    for k in range(len(ids)):
        domain = ids[(start + k) % len(ids)]
        try:
            lock = open(f'/tmp/wifi_place_recognition-domain-{domain}.lock',
                        'a')
        except OSError:
            continue
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        return domain, lock
    raise RuntimeError(f'every ROS domain id in {ids.start}..{ids.stop - 1} '
                       f'is held by another live test run')


# Every test run gets its own DDS domain, set before any rclpy.init();
# child processes inherit it through the environment.
DOMAIN_ID, _DOMAIN_LOCK = claim_domain_id()
os.environ['ROS_DOMAIN_ID'] = str(DOMAIN_ID)
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'

TEST_DIR = Path(__file__).resolve().parent
REPO = TEST_DIR.parent
FIXTURES = TEST_DIR / 'fixtures'
#: Where the tests that need UJIIndoorLoc read it, however pytest is
#: started: $WIFI_PR_DATASET, else the shared copy beside the repository
#: if it is there (None: those tests are skipped).
DEFAULT_DATASET = REPO.parent / 'shared' / 'datasets' / 'ujiindoorloc'
DATASET = os.environ.get('WIFI_PR_DATASET') or (
    str(DEFAULT_DATASET) if DEFAULT_DATASET.is_dir() else None)


def dataset_file(name):
    """Return a UJIIndoorLoc file from ``DATASET``, or skip the test."""
    if not DATASET or not (Path(DATASET) / name).exists():
        pytest.skip(f'UJIIndoorLoc not available: set WIFI_PR_DATASET '
                    f'(default: {DEFAULT_DATASET})')
    return Path(DATASET) / name


def mac(i):
    """Return a MAC address for AP number ``i``."""
    return 'AA:BB:CC:00:%02X:%02X' % (i // 256, i % 256)


def synthetic_csv(path, scans_per_class=60, n_aps=24, seed=0, phones=4,
                  scans_seed=None):
    """
    Write a generic fingerprint CSV: 2 buildings x 2 floors, MAC columns.

    Each class has its own strong APs; every scan draws RSSI around them.
    ``seed`` draws the building and, unless ``scans_seed`` is given, the
    scans: another ``scans_seed`` gives new scans of the same building.
    """
    rng = np.random.default_rng(seed)
    classes = [(0, 0), (0, 1), (1, 0), (1, 1)]
    centres = rng.uniform(-95, -40, size=(len(classes), n_aps))
    for k in range(len(classes)):
        centres[k, rng.choice(n_aps, n_aps // 2, replace=False)] = np.nan
    if scans_seed is not None:
        rng = np.random.default_rng(scans_seed)
    lines = [','.join([mac(i) for i in range(n_aps)]
                      + ['FLOOR', 'BUILDINGID', 'PHONEID'])]
    for k, (b, f) in enumerate(classes):
        for s in range(scans_per_class):
            rssi = np.round(centres[k] + rng.normal(0, 3, n_aps))
            cells = ['100' if np.isnan(v) else str(int(v)) for v in rssi]
            lines.append(','.join(cells + [str(f), str(b),
                                           str(s % phones)]))
    Path(path).write_text('\n'.join(lines) + '\n')
    return path


def surveyed_csv(path, scans_per_floor=200, n_aps=30, seed=0, phones=4,
                 scans_seed=None, floors=(0, 1)):
    """
    Write a generic CSV with X, Y: one building, 2 floors of 40 m x 40 m.

    ``floors`` chooses which of the two floors are surveyed.
    APs stand at random places on either floor; RSSI falls with distance
    (log-distance path loss, 12 dB more through the floor), so the
    position can be learned from the scan. ``seed`` draws the building,
    ``scans_seed`` (default: ``seed``) the scans.
    """
    rng = np.random.default_rng(seed)
    ap_xy = rng.uniform(0, 40, (n_aps, 2))
    ap_floor = rng.integers(0, 2, n_aps)
    if scans_seed is not None:
        rng = np.random.default_rng(scans_seed)
    lines = [','.join([mac(i) for i in range(n_aps)]
                      + ['X', 'Y', 'FLOOR', 'BUILDINGID', 'PHONEID'])]
    for floor in floors:
        for s in range(scans_per_floor):
            xy = rng.uniform(0, 40, 2)
            d = np.linalg.norm(ap_xy - xy, axis=1) + 1.0
            rssi = -30 - 25 * np.log10(d) - 12 * (ap_floor != floor) \
                + rng.normal(0, 2, n_aps)
            cells = ['100' if v < -85 else str(int(round(v))) for v in rssi]
            lines.append(','.join(cells + [f'{xy[0] - 7600:.2f}',
                                           f'{xy[1] + 4864900:.2f}',
                                           str(floor), '0', str(s % phones)]))
    Path(path).write_text('\n'.join(lines) + '\n')
    return path


FAST = ['--sae-layers', '32,16', '--classifier-layers', '16',
        '--sae-epochs', '3', '--epochs', '15', '--batch-size', '32',
        '--folds', '2', '--ensemble', '1', '--quiet']


@pytest.fixture(scope='session')
def synthetic(tmp_path_factory):
    """Return (csv path, trained model path) for the synthetic building."""
    from wifi_place_recognition.cli.train_model import main
    folder = tmp_path_factory.mktemp('synthetic')
    csv_path = synthetic_csv(folder / 'fingerprints.csv')
    model_path = folder / 'model.npz'
    assert main(['--data', str(csv_path), '-o', str(model_path)] + FAST) == 0
    return csv_path, model_path


@pytest.fixture(scope='session')
def surveyed_model(tmp_path_factory):
    """Return the path of a model with positions (surveyed_csv's floors)."""
    folder = tmp_path_factory.mktemp('surveyed')
    model = folder / 'model.npz'
    result = run(python_module(
        'cli.train_model', '--data', surveyed_csv(folder / 'a.csv'), '-o',
        model, *FAST, '--epochs', '20'))
    assert result.returncode == 0, result.stderr
    return model


def benchmark(name):
    """Return the benchmark module benchmarks/<name>.py."""
    sys.path.insert(0, str(REPO / 'benchmarks'))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(str(REPO / 'benchmarks'))


@pytest.fixture(scope='module')
def fusion():
    """Return the benchmark module benchmarks/fusion.py."""
    return benchmark('fusion')


def run(args, **kwargs):
    """Run a command with the whole environment; return CompletedProcess."""
    kwargs.setdefault('timeout', 300)
    return subprocess.run(args, capture_output=True, text=True,
                          env=kwargs.pop('env', os.environ.copy()), **kwargs)


def save_unchecked(model, path):
    """
    Write ``model`` as ``save_model`` does, without its check.

    A file that ``load_model`` must refuse, as a hand or another program
    could write it (``save_model`` refuses to).
    """
    from wifi_place_recognition.core import artifact
    build = artifact._build
    artifact._build = lambda header, arrays: None
    try:
        artifact.save_model(model, path)
    finally:
        artifact._build = build


def python_module(module, *args):
    """Return the argv that runs a package module with this interpreter."""
    return [sys.executable, '-m', f'wifi_place_recognition.{module}',
            *map(str, args)]


def wait_until(predicate, timeout, spin=None):
    """Poll (or spin ``spin``) until ``predicate()``; return its last value."""
    deadline = time.monotonic() + timeout
    while not predicate() and time.monotonic() < deadline:
        if spin is not None:
            import rclpy
            rclpy.spin_once(spin, timeout_sec=0.02)
        else:
            time.sleep(0.02)
    return predicate()


def process_alive(pid):
    """Return True if process ``pid`` exists and is not a zombie."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return Path(f'/proc/{pid}/stat').read_text().split()[2] != 'Z'


@pytest.fixture
def fake_tools(tmp_path, monkeypatch):
    """Put fake ``iw`` and ``nmcli`` on PATH; return their folder."""
    folder = tmp_path / 'bin'
    folder.mkdir()

    def install(name, script):
        path = folder / name
        path.write_text('#!/bin/sh\n' + script)
        path.chmod(0o755)
    install.folder = folder
    monkeypatch.setenv('PATH', f'{folder}{os.pathsep}/usr/bin:/bin')
    return install


@pytest.fixture(scope='module')
def ros():
    """Return an rclpy node for the test's side (one context per module)."""
    import rclpy
    rclpy.init()
    node = rclpy.create_node('test_client')
    yield node
    node.destroy_node()
    rclpy.try_shutdown()


# Test tiers -------------------------------------------------------------------
#: Every ROS package the package declares (package.xml), and its ROS side.
ROS_PACKAGES = {e.text for tag in ('depend', 'exec_depend') for e in
                ElementTree.parse(REPO / 'package.xml').getroot().iter(tag)
                if not e.text.startswith('python3-')} | {
    'rclpy', 'wifi_place_recognition.ros'}
#: What marks a test ``dataset``, ``system``, ``stress`` when it reaches it.
DATASET_NAMES = {'dataset_file', 'DATASET', 'DEFAULT_DATASET', 'WIFINE',
                 'EXAMPLE_DATA'}
SYSTEM_NAMES = {'run', 'python_module', 'subprocess'}
STRESS_NAMES = {'busy_core', 'fuzz_scans', 'Harness'}


def _origin(value):
    """Return the dotted module a global value comes from ('' if none)."""
    if inspect.ismodule(value):
        return value.__name__
    return getattr(value, '__module__', None) or ''


def _reached(item):
    """
    Return {name: value} of the globals a test reaches.

    From the test function and its fixtures, through every function and
    class of the test folder they use (helpers, conftest), transitively.
    """
    defs = item._fixtureinfo.name2fixturedefs
    todo = [item.function] + [d.func for name in item.fixturenames
                              for d in defs.get(name, ())]
    seen, reached = set(), {}
    while todo:
        obj = inspect.unwrap(todo.pop())
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if inspect.isclass(obj):
            todo += [v for v in vars(obj).values() if inspect.isfunction(v)]
            continue
        codes = [obj.__code__]
        while codes:
            code = codes.pop()
            codes += [c for c in code.co_consts if inspect.iscode(c)]
            for name in code.co_names:
                if name not in obj.__globals__:
                    continue
                value = reached[name] = obj.__globals__[name]
                if (inspect.isfunction(value) or inspect.isclass(value)) \
                        and _in_test_dir(value):
                    todo.append(value)
    return reached


def _in_test_dir(value):
    try:
        return Path(inspect.getfile(value)).parent == TEST_DIR
    except TypeError:
        return False


def tiers(item):
    """Return the marker names (tiers) of a collected test."""
    if item.get_closest_marker('linter'):
        return {'linter'}
    reached = _reached(item)
    found = set()
    origins = {_origin(v) for v in reached.values()}
    if 'ros' in item.fixturenames or any(
            o == p or o.startswith(p + '.')
            for o in origins for p in ROS_PACKAGES):
        found.add('ros')
    for tier, names in (('dataset', DATASET_NAMES),
                        ('system', SYSTEM_NAMES), ('stress', STRESS_NAMES)):
        if names & reached.keys():
            found.add(tier)
    return found or {'unit'}


def pytest_collection_modifyitems(items):
    """Mark every test with its tiers (see the module docstring)."""
    for item in items:
        if isinstance(item, pytest.Function):
            for tier in tiers(item):
                item.add_marker(tier)
