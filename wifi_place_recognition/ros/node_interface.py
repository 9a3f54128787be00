"""
A node's interface table: its parameters declared, and its ``--help``.

A node's table module (:mod:`.classifier_parameters`,
:mod:`.scanner_parameters`, :mod:`.recorder_parameters`) holds ``SUMMARY``,
``TOPICS`` and ``PARAMETERS``; the node declares the parameters with
:func:`declare`, and its executable answers ``--help`` with
:func:`help_text`, which reads the table at run time. Nothing here starts
ROS.
"""

import textwrap

from rcl_interfaces.msg import FloatingPointRange

OPTIONS = ('-h', '--help')
TYPES = {bool: 'bool', int: 'integer', float: 'double', str: 'string'}
WIDTH = 79


def float_range(low, high):
    """Return a descriptor's floating_point_range from ``low`` to ``high``."""
    return [FloatingPointRange(from_value=low, to_value=high)]


def declare(node, parameters):
    """Declare (name, default, descriptor)s on ``node``; return {name: value}."""
    return {name: node.declare_parameter(name, default, descriptor).value
            for name, default, descriptor in parameters}


def asks_for_help(argv):
    """
    Return True if ``-h`` or ``--help`` is an argument.

    Also inside ``--ros-args``, where rcl would refuse it as unknown: no ROS
    argument is spelled so.
    """
    return any(arg in OPTIONS for arg in argv)


def value_text(value):
    """Return a default as ``--ros-args -p NAME:=VALUE`` takes it."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (list, tuple)):
        return f'[{", ".join(map(str, value))}]'
    return repr(value)


def type_text(value):
    """Return the ROS parameter type of a default."""
    if isinstance(value, (list, tuple)):
        return f'{TYPES[type(value[0])]} array'
    return TYPES[type(value)]


def interface_type(cls):
    """Return e.g. ``sensor_msgs/msg/JointState`` for a message class."""
    package, kind = cls.__module__.split('.')[:2]
    return f'{package}/{kind}/{cls.__name__}'


def _limits(descriptor):
    ranges = descriptor.floating_point_range or descriptor.integer_range
    return [f'range [{value_text(r.from_value)}, {value_text(r.to_value)}]'
            for r in ranges]


def _wrapped(text, indent=6):
    return textwrap.wrap(text, WIDTH, initial_indent=' ' * indent,
                         subsequent_indent=' ' * indent)


def help_text(executable, table):
    """Return the help of ``executable`` from its table module ``table``."""
    lines = [f'usage: {executable} [-h] [--ros-args -p NAME:=VALUE ...]',
             f'   or: ros2 run wifi_place_recognition {executable} [-h] '
             f'[--ros-args ...]', '']
    lines += textwrap.wrap(' '.join(table.SUMMARY.split()), WIDTH)
    lines += ['', 'topics and services (relative names follow the node\'s '
              'namespace and remapping):']
    for role, name, cls, what in table.TOPICS:
        lines.append(f'  {role:<11} {name}  [{interface_type(cls)}]')
        lines += _wrapped(what)
    lines += ['', 'parameters (--ros-args -p NAME:=VALUE or --params-file '
              'FILE; read-only: at start-up):']
    for name, default, descriptor in table.PARAMETERS:
        facts = [type_text(default), f'default {value_text(default)}'] + \
            _limits(descriptor) + (['read-only'] if descriptor.read_only
                                   else [])
        lines.append(f'  {name} ({", ".join(facts)})')
        lines += _wrapped(descriptor.description)
    return '\n'.join(lines) + '\n'
