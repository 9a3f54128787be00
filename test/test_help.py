"""
Every executable answers ``--help`` and ``-h``, and starts nothing.

The ROS executables' help must list every parameter of the node's table
with its default, range and description, and every topic; the running
nodes must declare exactly those parameters and use exactly those topics.
"""

import ast
import os
from pathlib import Path
import subprocess
import sys

from conftest import REPO, run, wait_until
import pytest
from rcl_interfaces.srv import ListParameters
from wifi_place_recognition.ros import (classifier_parameters,
                                        monitor_parameters,
                                        recorder_parameters,
                                        scanner_parameters,
                                        trusted_parameters)
from wifi_place_recognition.ros.node_interface import interface_type

BIN = Path(sys.executable).parent
TABLES = {'classifier_node': classifier_parameters,
          'wifi_scanner_node': scanner_parameters,
          'record_fingerprints': recorder_parameters,
          'localization_monitor': monitor_parameters,
          'trusted_recorder': trusted_parameters}


def _console_scripts():
    """Return {executable: entry point} from setup.py's console_scripts."""
    tree = ast.parse((REPO / 'setup.py').read_text())
    listed = next(ast.literal_eval(node.value) for node in tree.body
                  if isinstance(node, ast.Assign) and
                  getattr(node.targets[0], 'id', '') == 'console_scripts')
    return dict(map(str.strip, entry.split('=')) for entry in listed)


EXECUTABLES = _console_scripts()
OFFLINE = sorted(name for name, entry in EXECUTABLES.items()
                 if '.ros.' not in entry)


def test_every_node_executable_has_an_interface_table():
    assert set(TABLES) == set(EXECUTABLES) - set(OFFLINE)


def _default(value):
    """Return how the help must show a default."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, list):
        return '[' + ', '.join(value) + ']'
    return str(value)


def _flat(text):
    return ' '.join(text.split())


def _command(executable, option, folder, last, module=False):
    """
    Return (argv, env): ``executable`` with ``option`` in ``folder``.

    ``module``: run as ``python -m wifi_place_recognition.ros.<executable>``.

    Before (``last``) or after the option come the arguments that would
    start it for real (scanning with tools that leave a mark, recording
    into ``out/``). ROS_LOG_DIR shows whether rclpy.init ran: it creates a
    log file there.
    """
    env = dict(os.environ, ROS_LOG_DIR=str(folder / 'ros_log'))
    args = ['--ros-args', '-p', 'tracking:=true']
    if executable == 'wifi_scanner_node':
        tools = folder / 'bin'
        tools.mkdir()
        for tool in ('iw', 'nmcli'):
            (tools / tool).write_text(f'#!/bin/sh\ntouch "{folder}/scanned"\n')
            (tools / tool).chmod(0o755)
        env['PATH'] = f'{tools}{os.pathsep}{env["PATH"]}'
        args = ['--ros-args', '-p', 'interface:=lo', '-p', 'period:=0.1']
    elif executable == 'record_fingerprints':
        args = ['--ros-args', '-p', f'output:={folder / "out" / "rec.csv"}',
                '-p', 'building:=0', '-p', 'floor:=0']
    elif executable == 'trusted_recorder':
        args = ['--ros-args', '-p', f'output:={folder / "out" / "rec.csv"}']
    command = [sys.executable, '-m', f'wifi_place_recognition.ros.{executable}'
               ] if module else [str(BIN / executable)]
    return command + ([*args, option] if last else [option, *args]), env


@pytest.mark.parametrize('module', [False, True], ids=['script', 'python-m'])
@pytest.mark.parametrize('last', [False, True], ids=['first', 'last'])
@pytest.mark.parametrize('option', ['--help', '-h'])
@pytest.mark.parametrize('executable', sorted(TABLES))
def test_a_node_executable_prints_its_interface_and_starts_nothing(
        tmp_path, executable, option, last, module):
    argv, env = _command(executable, option, tmp_path, last, module)
    try:
        result = run(argv, env=env, cwd=tmp_path, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail(f'{executable} {option} did not return: it started')
    assert result.returncode == 0, result.stderr
    assert result.stderr == ''
    # Nothing started: no rclpy.init (its log file), no scan, no file.
    assert sorted(p.name for p in tmp_path.iterdir()) == (
        ['bin'] if executable == 'wifi_scanner_node' else [])
    text = result.stdout
    assert text.startswith(f'usage: {executable} [-h] [--ros-args'), text
    table = TABLES[executable]
    lines = text.splitlines()
    for name, default, descriptor in table.PARAMETERS:
        assert descriptor.description, f'{name}: no description'
        line = next((x for x in lines if x.startswith(f'  {name} (')), None)
        assert line is not None, f'{name} is not in the help'
        assert f'default {_default(default)}' in line, line
        for r in descriptor.floating_point_range or descriptor.integer_range:
            assert f'[{r.from_value}, {r.to_value}]' in line, line
        assert ('read-only' in line) == descriptor.read_only, line
        assert _flat(descriptor.description) in _flat(text), name
    for role, name, cls, what in table.TOPICS:
        assert f'{name}  [{interface_type(cls)}]' in text, name
        assert _flat(what) in _flat(text), name


@pytest.mark.parametrize('option', ['--help', '-h'])
@pytest.mark.parametrize('tool', OFFLINE)
def test_an_offline_tool_answers_help_and_starts_nothing(tmp_path, tool,
                                                         option):
    env = dict(os.environ, ROS_LOG_DIR=str(tmp_path / 'ros_log'))
    result = run([str(BIN / tool), option], env=env, cwd=tmp_path,
                 timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f'usage: {tool} [-h]'), result.stdout
    assert '--help' in result.stdout
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize('tool', OFFLINE)
def test_an_offline_tool_runs_as_a_module_too(tmp_path, tool):
    module = EXECUTABLES[tool].split(':')[0]
    env = dict(os.environ, ROS_LOG_DIR=str(tmp_path / 'ros_log'))
    result = run([sys.executable, '-m', module, '--help'], env=env,
                 cwd=tmp_path, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f'usage: {tool} [-h]'), result.stdout


# The running nodes declare the tables' parameters and use their topics. ------
def _resolve(name, node, params):
    name = name.format(**params)
    if name.startswith('~'):
        return f'/{node}{name[1:]}'
    return name if name.startswith('/') else f'/{name}'


def _graph(ros, node):
    """Return {(role, name, type)} of ``node`` as the ROS graph shows it."""
    found = set()
    for role, query in (
            ('publishes', ros.get_publisher_names_and_types_by_node),
            ('subscribes', ros.get_subscriber_names_and_types_by_node),
            ('service', ros.get_service_names_and_types_by_node)):
        for name, types in query(node, '/'):
            found |= {(role, name, t) for t in types}
    return found


def _every_node(ros, node):
    """Return the entities every rclpy node has, named as ``node``'s."""
    own = _graph(ros, ros.get_name())
    return {(role, name.replace(f'/{ros.get_name()}/', f'/{node}/'), t)
            for role, name, t in own}


def _parameters(ros, node):
    client = ros.create_client(ListParameters, f'/{node}/list_parameters')
    try:
        assert client.wait_for_service(timeout_sec=30), node
        future = client.call_async(ListParameters.Request())
        assert wait_until(future.done, 30, ros), node
        return set(future.result().result.names)
    finally:
        ros.destroy_client(client)


NODES = {
    'classifier_node': [],      # the shipped model has positions
    'wifi_scanner_node': ['-p', 'interface:=lo', '-p', 'sources:=[nmcli]'],
    'record_fingerprints': ['-p', 'pose_topic:=/amcl_pose',
                            '-p', 'odom_topic:=odom'],
    'localization_monitor': [],     # the shipped model
    'trusted_recorder': [],
}


@pytest.mark.parametrize('executable', sorted(NODES))
def test_a_running_node_declares_the_tables_parameters_and_topics(
        ros, tmp_path, executable):
    table = TABLES[executable]
    args = list(NODES[executable])
    if executable in ('record_fingerprints', 'trusted_recorder'):
        args += ['-p', f'output:={tmp_path / "rec.csv"}']
    env = dict(os.environ, PATH=f'{tmp_path}{os.pathsep}/usr/bin:/bin')
    params = {name: default for name, default, _ in table.PARAMETERS}
    params.update(a.split(':=') for a in args if ':=' in a)
    expected = {(role, _resolve(name, executable, params),
                 interface_type(cls)) for role, name, cls, _ in table.TOPICS}
    expected |= _every_node(ros, executable)
    proc = subprocess.Popen([str(BIN / executable), '--ros-args', *args],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, env=env)
    try:
        wait_until(lambda: executable in ros.get_node_names() and
                   _graph(ros, executable) >= expected, 60, ros)
        found = _graph(ros, executable)
        declared = _parameters(ros, executable)
    finally:
        proc.terminate()
        _, log = proc.communicate(timeout=30)
    assert proc.returncode == 0, log
    assert found == expected, (sorted(found - expected),
                               sorted(expected - found), log)
    every = set(ros.get_parameters_by_prefix(''))
    own = {p for p in declared - every if not p.startswith('qos_overrides.')}
    assert own == set(params), (own, set(params))
