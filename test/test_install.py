"""
The install layouts: colcon, ``pip install .`` and the source checkout.

Each finds the shipped model by itself: colcon through its environment
script (``AMENT_PREFIX_PATH``), ``pip install .`` and the source checkout
with no ROS environment variable at all.
"""

import ast
import json
import os
from pathlib import Path
import shutil
import sys
import sysconfig
from xml.etree import ElementTree

from conftest import REPO, run
import numpy as np
import pytest
from ros_helpers import Client, NodeProcess
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.ros import (classifier_parameters,
                                        monitor_parameters,
                                        scanner_parameters,
                                        trusted_parameters)
import yaml

PROBE = (['WAP001', 'WAP002', 'WAP003', 'WAP004'], [-60.0, -70.0, -80.0, -50.0])
SHIPPED = Path('share', 'wifi_place_recognition', 'models', 'ujiindoorloc.npz')


def _without(*names):
    """Return this process's environment less the variables ``names``."""
    return {k: v for k, v in os.environ.items() if k not in names}


def _answer_from_installed(ros, tmp_path, executable, prefix, env):
    """Start an installed node on its default model; probe it."""
    proc = NodeProcess(tmp_path, [str(executable)], 'installed_node', env=env)
    client = Client(ros, 'installed_node')
    try:
        status = client.wait_ready(proc, PROBE)
    finally:
        client.close()
        code, log = proc.stop()
    assert code == 0, log
    # The shipped model was found in the install's share directory.
    assert f'model {prefix / SHIPPED}:' in log, log
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
                 'config/classifier_node.yaml', 'launch/classifier.launch.py',
                 'config/wifi_localization.yaml',
                 'config/diagnostic_analyzers.yaml',
                 'launch/wifi_localization.launch.py'):
        assert (prefix / 'share' / 'wifi_place_recognition' / name).exists()
    # What `source install/setup.bash` sets for this package.
    site = next(prefix.glob('lib/python3*/site-packages'))
    env = dict(os.environ, AMENT_PREFIX_PATH=str(prefix),
               PYTHONPATH=str(site))
    assert status_ok(_answer_from_installed(ros, tmp_path, executable,
                                            prefix, env))


def _labelled_csv(path, model, rows=20, seed=0):
    """Write scans labelled with ``model``'s own answers; return the path."""
    rng = np.random.default_rng(seed)
    rssi = np.full((rows, len(model.ap_ids)), np.nan)
    for row in rssi:
        row[rng.choice(len(row), 8, replace=False)] = rng.integers(-95, -40, 8)
    building, floor, _, _ = model.predict(rssi)
    lines = [','.join(model.ap_ids + ('BUILDINGID', 'FLOOR'))]
    lines += [','.join(['100' if np.isnan(v) else str(int(v)) for v in row]
                       + [str(b), str(f)])
              for row, b, f in zip(rssi, building, floor)]
    path.write_text('\n'.join(lines) + '\n')
    return path


def test_pip_install_in_a_fresh_venv_needs_no_ros_variables(ros, tmp_path):
    venv = tmp_path / 'venv'
    source = tmp_path / 'source'  # pip builds in the tree: use a copy
    shutil.copytree(REPO, source, ignore=shutil.ignore_patterns(
        '.venv', '.git', 'build', 'install', 'log', '*.egg-info'))
    env = _without('AMENT_PREFIX_PATH', 'PYTHONPATH')
    result = run([sys.executable, '-m', 'venv', '--without-pip', venv])
    assert result.returncode == 0, result.stderr
    python = venv / 'bin' / 'python'
    site = run([python, '-c', 'import sysconfig; '
                'print(sysconfig.get_path("purelib"))'], env=env).stdout
    # The dependencies (numpy, rclpy and the messages, setuptools to build)
    # come from this test's environment; the package is installed anew.
    Path(site.strip(), 'dependencies.pth').write_text(
        sysconfig.get_path('purelib') + '\n')
    result = run([sys.executable, '-m', 'pip', '--python', python, 'install',
                  '--no-deps', '--no-build-isolation', source], env=env,
                 cwd=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr

    where = run([python, '-c', 'import wifi_place_recognition as p; '
                 'from wifi_place_recognition.core.resources import '
                 'default_model_path; print(p.__file__, default_model_path())'],
                env=env, cwd=tmp_path)
    assert where.returncode == 0, where.stderr
    package, model_path = where.stdout.split()
    assert Path(package).is_relative_to(venv), package
    assert Path(model_path) == venv / SHIPPED
    model = load_model(REPO / 'models' / 'ujiindoorloc.npz')
    data = _labelled_csv(tmp_path / 'scans.csv', model)
    evaluated = run([venv / 'bin' / 'evaluate_model', '--data', data,
                     '--json'], env=env, cwd=tmp_path)
    assert evaluated.returncode == 0, evaluated.stderr
    assert json.loads(evaluated.stdout)['building_floor_accuracy'] == 1.0
    # Where `ros2 run wifi_place_recognition classifier_node` looks.
    assert status_ok(_answer_from_installed(
        ros, tmp_path, venv / 'lib' / 'wifi_place_recognition' /
        'classifier_node', venv, env))


def test_source_checkout_uses_its_models_folder(tmp_path):
    result = run([sys.executable, '-c', 'from wifi_place_recognition.core.'
                  'resources import default_model_path as d; print(d())'],
                 env=_without('AMENT_PREFIX_PATH'), cwd=tmp_path)
    assert result.stdout.strip() == str(REPO / 'models' / 'ujiindoorloc.npz'), \
        result.stderr


#: Python module -> rosdep key, where they differ.
ROSDEP_KEYS = {'numpy': 'python3-numpy', 'torch': 'python3-torch',
               'sklearn': 'python3-sklearn'}


def _imported(files, lazy=True):
    """
    Return the rosdep keys of what ``files`` import (not stdlib, not us).

    ``lazy=False``: only the imports at module level, which every use needs
    (not those inside functions: optional features).
    """
    keys = set()
    for path in files:
        tree = ast.parse(path.read_text())
        nodes = ast.walk(tree) if lazy else tree.body
        for node in nodes:
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.partition('.')[0]
                if top not in sys.stdlib_module_names and \
                        top != 'wifi_place_recognition':
                    keys.add(ROSDEP_KEYS.get(top, top))
    return keys


def test_package_xml_declares_what_runs_and_nothing_else():
    root = ElementTree.parse(REPO / 'package.xml').getroot()
    declared = {tag: {e.text for e in root.iter(tag)}
                for tag in ('depend', 'exec_depend', 'test_depend')}
    run_deps = declared['depend'] | declared['exec_depend']
    package = REPO / 'wifi_place_recognition'
    training = set(package.glob('training/*.py'))
    runs = (set(package.rglob('*.py')) - training) | \
        set(REPO.glob('launch/*.py'))
    # The nodes, the tools and the launch file: all they always import is
    # declared, and nothing they never import.
    assert _imported(runs, lazy=False) <= run_deps
    assert run_deps <= _imported(runs)
    # Training needs torch on top: a test (and pip extra) dependency.
    assert _imported(training, lazy=False) - run_deps == {'python3-torch'}
    assert 'python3-torch' in declared['test_depend'] - run_deps


def status_ok(status):
    """Return True if the status is an answer (not a rejection)."""
    return status.message.startswith('building ')


def _calls(tree, name):
    return [node for node in ast.walk(tree) if isinstance(node, ast.Call)
            and getattr(node.func, 'id', None) == name]


def test_launch_file_declares_described_arguments_it_uses():
    # launch and launch_ros are not on PyPI: check the file's structure.
    tree = ast.parse((REPO / 'launch' / 'classifier.launch.py').read_text())
    parameters, = [ast.literal_eval(node.value) for node in tree.body
                   if isinstance(node, ast.Assign) and
                   node.targets[0].id == 'PARAMETERS']
    declared = {}
    for call in _calls(tree, 'DeclareLaunchArgument'):
        kwargs = {k.arg: k.value for k in call.keywords}
        assert 'default_value' in kwargs, ast.dump(call)
        if isinstance(call.args[0], ast.Constant):
            name = call.args[0].value
            assert isinstance(kwargs.get('description'), ast.Constant) and \
                len(kwargs['description'].value) > 20, name
            declared[name] = kwargs['default_value']
        else:   # one per PARAMETERS entry, empty: the params file's value
            assert kwargs['default_value'].value == ''
            declared.update({name: kwargs['default_value']
                             for name in parameters})
    assert all(len(text) > 20 for text in parameters.values()), parameters
    # the parameters set from arguments are the node's, of the same name
    node_parameters = {p[0] for p in classifier_parameters.PARAMETERS}
    assert set(parameters) <= node_parameters, parameters
    used = {call.args[0].value for call in _calls(tree, 'LaunchConfiguration')
            if isinstance(call.args[0], ast.Constant)}
    assert set(declared) == used | set(parameters) == {
        'params_file', 'scan_topic', 'odom_topic', 'initialpose_topic',
        'model_path', 'tracking', 'frame_id', 'publish_initial_pose',
        'initial_pose_on_change'}
    assert declared['scan_topic'].value == 'wifi/scan'
    assert declared['odom_topic'].value == 'odom'
    assert declared['initialpose_topic'].value == 'initialpose'
    config = [a.value for a in ast.walk(declared['params_file'])
              if isinstance(a, ast.Constant)]
    assert (REPO / config[-2] / config[-1]).is_file(), config
    node, = _calls(tree, 'Node')
    kwargs = {k.arg: k.value for k in node.keywords}
    assert kwargs['executable'].value == 'classifier_node'
    remapped = [pair.elts[0].value for pair in kwargs['remappings'].elts]
    assert remapped == ['wifi/scan', 'odom', 'initialpose'], remapped


def _assigned(tree, name):
    """Return the literal value of a module-level ``name = ...``."""
    value, = [ast.literal_eval(node.value) for node in tree.body
              if isinstance(node, ast.Assign) and
              node.targets[0].id == name]
    return value


def test_robot_launch_file_switches_each_node_and_shares_the_model():
    # launch and launch_ros are not on PyPI: check the file's structure.
    tree = ast.parse((REPO / 'launch' / 'wifi_localization.launch.py')
                     .read_text())
    nodes, parameters, remaps = (_assigned(tree, name) for name in
                                 ('NODES', 'PARAMETERS', 'REMAPS'))
    tables = {'wifi_scanner_node': scanner_parameters,
              'classifier_node': classifier_parameters,
              'localization_monitor': monitor_parameters,
              'trusted_recorder': trusted_parameters}
    # one switch per node, each an executable of the package
    assert {s: e for s, (e, _) in nodes.items()} == {
        'scanner': 'wifi_scanner_node', 'classifier': 'classifier_node',
        'monitor': 'localization_monitor', 'recorder': 'trusted_recorder'}
    # the recorder writes a survey: only when asked
    assert _assigned(tree, 'OFF') == ('recorder',)
    scripts = (REPO / 'setup.py').read_text()
    assert all(f"'{e} = " in scripts for e, _ in nodes.values())
    # the model and the frames set on both nodes that use them
    assert parameters['model_path'][0] == parameters['frame_id'][0] == (
        'classifier_node', 'localization_monitor')
    for name, (owners, description) in parameters.items():
        assert len(description) > 20, name
        for owner in owners:
            assert name in {p[0] for p in tables[owner].PARAMETERS}, \
                (name, owner)
    # each remapped topic is one a node uses, under that name
    for argument, (topic, default, description) in remaps.items():
        assert topic == default and len(description) > 20, argument
        assert any(topic == t[1] for table in tables.values()
                   for t in table.TOPICS), topic
    declared = {}
    for call in _calls(tree, 'DeclareLaunchArgument'):
        kwargs = {k.arg: k.value for k in call.keywords}
        assert {'default_value', 'description'} <= set(kwargs), \
            ast.dump(call)
        if isinstance(call.args[0], ast.Constant):
            declared[call.args[0].value] = kwargs['default_value']
        else:   # one per entry of a table
            table = {'switch': nodes, 'argument': remaps,
                     'name': parameters}[call.args[0].id]
            declared.update(dict.fromkeys(table, kwargs['default_value']))
    assert set(declared) == {'params_file'} | set(nodes) | set(remaps) | \
        set(parameters)
    used = {call.args[0].value for call in _calls(tree, 'LaunchConfiguration')
            if isinstance(call.args[0], ast.Constant)}
    assert used == {'params_file'}, used     # the others through the tables
    config = [a.value for a in ast.walk(declared['params_file'])
              if isinstance(a, ast.Constant)]
    assert config[-2:] == ['config', 'wifi_localization.yaml'], config
    node, = _calls(tree, 'Node')
    kwargs = {k.arg: k.value for k in node.keywords}
    assert {'executable', 'name', 'condition', 'parameters',
            'remappings'} <= set(kwargs)
    condition, = _calls(kwargs['condition'], 'IfCondition')


def test_robot_params_file_holds_every_nodes_defaults():
    config = yaml.safe_load((REPO / 'config' / 'wifi_localization.yaml')
                            .read_text())
    tables = {'wifi_scanner_node': scanner_parameters,
              'classifier_node': classifier_parameters,
              'localization_monitor': monitor_parameters,
              'trusted_recorder': trusted_parameters}
    assert list(config) == list(tables)
    for node, table in tables.items():
        values = config[node]['ros__parameters']
        assert list(values) == [p[0] for p in table.PARAMETERS], node
        for name, default, _ in table.PARAMETERS:
            assert values[name] == default, (node, name)
            assert type(values[name]) is type(default), (node, name)


def test_diagnostic_analyzer_example_groups_every_node_and_is_shown():
    path = REPO / 'config' / 'diagnostic_analyzers.yaml'
    analyzer = yaml.safe_load(path.read_text())['analyzers'][
        'ros__parameters']['wifi_localization']
    assert analyzer['type'] == 'diagnostic_aggregator/GenericAnalyzer'
    nodes = _assigned(ast.parse((REPO / 'launch' /
                                 'wifi_localization.launch.py').read_text()),
                      'NODES')
    assert analyzer['startswith'] == [e for e, _ in nodes.values()]
    # doc/nav2.md shows the file as it is
    assert path.read_text() in (REPO / 'doc' / 'nav2.md').read_text()
