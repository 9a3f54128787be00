"""
The nodes' executables, and the stop request that SIGINT/SIGTERM make.

With ``-h`` or ``--help`` (anywhere among its arguments) an executable
prints its help from the node's interface table and exits 0, before
anything of ROS starts (so ``ros2 run ... --help`` works). Otherwise it
catches SIGINT and SIGTERM before it imports its node (rclpy and numpy take
a few hundred milliseconds), so a signal at any moment of start-up, or a
repeated one during shutdown, only requests the stop that
:func:`.runner.run` carries out. This module imports nothing heavy for that
reason.

Before the node, an executable also blocks the code generator that
``rosidl_generator_py`` imports when it can (for building packages, never
used at run time; it brings lark and empy): 2.4 MiB less per process.
"""

import importlib
import signal
import sys

from .node_interface import asks_for_help, help_text

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
#: Imported only if it can be (rosidl_generator_py falls back quietly);
#: nothing a running node needs.
BUILD_TIME_ONLY = ('rosidl_generator_py.generate_py_impl',)
_requests = []


def _request_stop(signum, frame):
    # Lock-free: the handler may interrupt any code of the main thread.
    _requests.append(signum)


def catch_stop_signals():
    """From now on SIGINT/SIGTERM (any number of them) request a stop."""
    for sig in STOP_SIGNALS:
        signal.signal(sig, _request_stop)


def ignore_stop_signals():
    """
    Ignore SIGINT/SIGTERM from now on: the process is exiting.

    Python's finalization resets Python-level handlers to the default
    action (an ignored signal it leaves alone), and the DDS teardown after
    it takes about half a second: a late signal would kill the process.
    """
    for sig in STOP_SIGNALS:
        signal.signal(sig, signal.SIG_IGN)


def stop_requested():
    """Return True once a stop signal arrived."""
    return bool(_requests)


def block_build_time_imports():
    """Make :data:`BUILD_TIME_ONLY` unimportable (unless already imported)."""
    for name in BUILD_TIME_ONLY:
        sys.modules.setdefault(name, None)


def _main(module, table):
    if asks_for_help(sys.argv[1:]):
        sys.stdout.write(help_text(module, importlib.import_module(
            f'{__package__}.{table}')))
        return 0
    catch_stop_signals()
    block_build_time_imports()
    return importlib.import_module(f'{__package__}.{module}').main()


def classifier_node():
    """Run ``classifier_node``; return its exit code."""
    return _main('classifier_node', 'classifier_parameters')


def wifi_scanner_node():
    """Run ``wifi_scanner_node``; return its exit code."""
    return _main('wifi_scanner_node', 'scanner_parameters')


def record_fingerprints():
    """Run ``record_fingerprints``; return its exit code."""
    return _main('record_fingerprints', 'recorder_parameters')


def localization_monitor():
    """Run ``localization_monitor``; return its exit code."""
    return _main('localization_monitor', 'monitor_parameters')


def trusted_recorder():
    """Run ``trusted_recorder``; return its exit code."""
    return _main('trusted_recorder', 'trusted_parameters')
