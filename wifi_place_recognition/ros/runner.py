"""
The one place for a node's life cycle: start, spin, shutdown.

rclpy's own signal handlers are not installed: SIGINT and SIGTERM only
request a stop (see :mod:`.executables`), so a signal never shuts the
context down under a running executor, and a repeated one is a no-op. The
spin loop notices the request within ``POLL_S``, then destroys the node and
shuts the context down itself. From then on the signals are ignored: the
interpreter's teardown (about half a second of DDS clean-up) would otherwise
die of a late one.
"""

import contextlib
import functools
from pathlib import Path
import re
import sys

import rclpy
from rclpy.exceptions import NameValidationException, ParameterException
from rclpy.executors import SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

from .executables import (catch_stop_signals, ignore_stop_signals,
                          stop_requested)

POLL_S = 0.1


def names_the_node(init):
    """
    Decorate a node's ``__init__``: its errors carry the node's logger.

    So :func:`run` logs a start-up error under the node's (remapped) name.
    """
    @functools.wraps(init)
    def checked(node, *args, **kwargs):
        try:
            init(node, *args, **kwargs)
        except Exception as exc:
            with contextlib.suppress(AttributeError):  # no node was made
                exc.node_logger = node.get_logger()
            raise
    return checked


def ros_args_problem(args=None):
    """
    Return why the ``--ros-args`` of ``args`` (default sys.argv) are bad.

    None if rcl parses them. Checked before ``rclpy.init``, whose failure
    rcl also logs on a line of its own.
    """
    try:
        remove_ros_args(args)
    except rclpy_implementation.UnknownROSArgsError as exc:
        return f'unknown ROS arguments {exc}'
    except rclpy_implementation.RCLInvalidROSArgsError as exc:
        # rcl's text, without its prefix and source positions
        text = str(exc).removeprefix('Failed to parse ROS arguments: ')
        return re.sub(r', at \S+:\d+', '', text)
    return None


def _cannot_start(exc):
    logger = getattr(exc, 'node_logger', None) or \
        rclpy.logging.get_logger(Path(sys.argv[0]).stem)
    logger.error(f'cannot start: {exc}')


def run(make_node, args=None, startup_errors=(ValueError,)):
    """
    Spin ``make_node()`` until SIGINT/SIGTERM; return the exit code.

    A bad parameter, or a ``startup_errors`` exception, while constructing
    the node (a bad model file, a missing output) is logged as one line and
    gives exit code 1. After it returns, SIGINT and SIGTERM are ignored: the
    process is exiting.
    """
    catch_stop_signals()
    try:
        return _run(make_node, args, startup_errors)
    finally:
        ignore_stop_signals()


def _run(make_node, args, startup_errors):
    problem = ros_args_problem(args)
    if problem:
        _cannot_start(f'--ros-args: {problem}')
        return 1
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RuntimeError as exc:
        _cannot_start(exc)
        return 1
    try:
        try:
            node = make_node()
        except (ParameterException, NameValidationException) + \
                tuple(startup_errors) as exc:
            _cannot_start(exc)
            return 1
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        try:
            while not stop_requested():
                executor.spin_once(timeout_sec=POLL_S)
        finally:
            executor.shutdown()
            node.destroy_node()
    finally:
        rclpy.try_shutdown()
    return 0
