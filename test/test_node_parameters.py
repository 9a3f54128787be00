"""
The nodes' parameters: declared = doc/parameters.md's tables.

classifier_node's as the node declares them, and its config file too;
wifi_scanner_node's and record_fingerprints' from their tables.
"""

import importlib
import re

from conftest import REPO
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from wifi_place_recognition.ros.classifier_node import ClassifierNode
import yaml


def _declared(model_path):
    """
    Return {name: (default, descriptor)} as the node declares them.

    Its own: not those every rclpy node has, nor QoS overrides.
    """
    plain = Node('plain')
    every_node = set(plain.get_parameters_by_prefix(''))
    plain.destroy_node()
    declared = {}

    class Declaring(ClassifierNode):
        def declare_parameter(self, name, value=None, descriptor=None,
                              **kwargs):
            if name not in every_node and \
                    not name.startswith('qos_overrides.'):
                declared[name] = (value, descriptor)
            return super().declare_parameter(name, value, descriptor,
                                             **kwargs)

    node = Declaring(parameter_overrides=[
        Parameter('model_path', value=str(model_path))])
    node.destroy_node()
    return declared


def _docs_table(node):
    """Return {name: (default, range, runtime)} of a node's docs table."""
    text = (REPO / 'doc' / 'parameters.md').read_text()
    section = text.split(f'\n## {node}\n')[1].split('\n## ')[0]
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip('|').split('|')]
        if len(cells) == 4 and re.fullmatch(r'`\w+`', cells[0]):
            rows[cells[0].strip('`')] = tuple(cells[1:])
    return rows


def _text(value):
    """Return a default as the config file and the docs write it."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, list):
        return '[' + ', '.join(value) + ']'
    return str(value) if value != '' else '""'


def test_config_file_and_docs_table_match_the_declared_parameters(
        ros, synthetic):
    declared = _declared(synthetic[1])
    config = yaml.safe_load((REPO / 'config' / 'classifier_node.yaml')
                            .read_text())['classifier_node']['ros__parameters']
    table = _docs_table('classifier_node')
    assert list(config) == list(declared) == list(table)
    for name, (default, descriptor) in declared.items():
        assert config[name] == default, name
        assert type(config[name]) is type(default), name
        _check_row(name, default, descriptor, table[name])


@pytest.mark.parametrize('node,module', [
    ('wifi_scanner_node', 'scanner_parameters'),
    ('record_fingerprints', 'recorder_parameters'),
    ('localization_monitor', 'monitor_parameters'),
    ('trusted_recorder', 'trusted_parameters')])
def test_docs_tables_match_the_scanner_and_recorder_parameters(node, module):
    parameters = importlib.import_module(
        f'wifi_place_recognition.ros.{module}').PARAMETERS
    table = _docs_table(node)
    assert list(table) == [name for name, _, _ in parameters]
    for name, default, descriptor in parameters:
        _check_row(name, default, descriptor, table[name])


def _check_row(name, default, descriptor, row):
    """Assert a docs table row shows a parameter's default, range, runtime."""
    shown, limits, runtime = row
    quoted = re.match(r'`([^`]*)`', shown)
    first = quoted.group(1) if quoted else re.split(r'[:= ]', shown)[0]
    assert first == _text(default), (name, shown)
    ranges = descriptor.floating_point_range or descriptor.integer_range
    found = re.findall(r'\[(-?[\d.e+]+), (-?[\d.e+]+)\]', limits)
    assert [tuple(map(float, f)) for f in found] == [
        (r.from_value, r.to_value) for r in ranges], (name, limits)
    assert runtime.startswith('read-only') == descriptor.read_only, \
        (name, runtime)
