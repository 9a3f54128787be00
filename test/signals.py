"""
Signal the real node executables at random moments (tests, benchmark).

Each run starts one executable (classifier_node, wifi_scanner_node or
record_fingerprints, as installed next to this interpreter), sends SIGINT or
SIGTERM once or twice at a random moment of one phase, and reports how it
ended:

- ``startup``: after the process has installed its own handlers (seen in
  ``/proc/PID/status``), before or while the node comes up;
- ``idle``: the node is up, nothing arrives;
- ``burst``: the node is up and scans keep arriving (the scanner node scans
  every 0.1 s with a slow fake ``iw``).

A second signal follows the first after 0-1 s: it lands in the shutdown
(destroying the node, the interpreter's and DDS's teardown) or after the
exit. Before the process's own code runs (the interpreter's start-up,
0.1-0.3 s) Python's default dispositions apply; that window is measured,
not signalled.
"""

import contextlib
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState

KINDS = ('classifier_node', 'wifi_scanner_node', 'record_fingerprints')
PHASES = ('startup', 'idle', 'burst')
SIGNALS = (signal.SIGINT, signal.SIGTERM)
FIXTURES = Path(__file__).resolve().parent / 'fixtures'
SCAN = ([f'WAP{i:03d}' for i in range(1, 9)], [-60.0] * 8)


@contextlib.contextmanager
def busy_core():
    """Keep one core busy with another process while the block runs."""
    proc = subprocess.Popen([sys.executable, '-c', 'while True: pass'])
    try:
        yield
    finally:
        proc.kill()
        proc.wait()


def handlers_installed(pid):
    """Return True once process ``pid`` catches SIGTERM itself."""
    try:
        lines = Path(f'/proc/{pid}/status').read_text().splitlines()
    except OSError:
        return False
    caught = next((int(line.split()[1], 16) for line in lines
                   if line.startswith('SigCgt:')), 0)
    return bool(caught >> (signal.SIGTERM - 1) & 1)


def rclpy_loaded(pid):
    """Return True once process ``pid`` has loaded rcl (imported rclpy)."""
    try:
        return 'librcl.so' in Path(f'/proc/{pid}/maps').read_text()
    except OSError:
        return False


def _command(kind, folder):
    """Return (argv, env) that start ``kind`` for one run in ``folder``."""
    exe = str(Path(sys.executable).parent / kind)
    env = dict(os.environ)
    if kind == 'classifier_node':
        return [exe], env
    if kind == 'record_fingerprints':
        return [exe, '--ros-args', '-p', f'output:={folder / "rec.csv"}',
                '-p', 'building:=0', '-p', 'floor:=0'], env
    tools = folder / 'bin'
    tools.mkdir(exist_ok=True)
    iw = tools / 'iw'
    iw.write_text(f'#!/bin/sh\nsleep 0.05\ncat "{FIXTURES / "iw_scan.txt"}"\n')
    iw.chmod(0o755)
    env['PATH'] = f'{tools}{os.pathsep}{env.get("PATH", "")}'
    return [exe, '--ros-args', '-p', 'interface:=lo',
            '-p', 'period:=0.1'], env


class Harness:
    """The test side: one rclpy node that sees and feeds the executables."""

    def __init__(self, node):
        self.node = node
        self.pub = node.create_publisher(JointState, 'wifi/scan',
                                         qos_profile_sensor_data)
        self.sub = node.create_subscription(
            JointState, 'wifi/scan', lambda msg: None,
            qos_profile_sensor_data)
        self.stamp = 0

    def close(self):
        """Destroy the publisher and subscription."""
        self.node.destroy_publisher(self.pub)
        self.node.destroy_subscription(self.sub)

    def ready(self, kind):
        """Return True when the node of ``kind`` is matched on wifi/scan."""
        if kind == 'wifi_scanner_node':
            return self.sub.get_publisher_count() > 0
        return self.pub.get_subscription_count() > 0

    def wait(self, seconds, until=None, publish=False):
        """Wait ``seconds`` or until ``until()``; maybe send ~1 kHz scans."""
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline and not (until and until()):
            if publish:
                self.stamp += 1
                msg = JointState(name=SCAN[0], position=SCAN[1])
                msg.header.stamp.sec = self.stamp
                self.pub.publish(msg)
            time.sleep(0.001)

    def run_once(self, kind, phase, signals, rng, folder):
        """
        Start ``kind``, send ``signals`` in ``phase``; return the outcome.

        The outcome is a dict: exit code (None if it hung), traceback seen,
        the delays used, the seconds from the first signal to the exit, and
        when the process caught the signals itself (seconds after start,
        and whether that was before it imported rclpy).
        """
        folder.mkdir(parents=True, exist_ok=True)
        argv, env = _command(kind, folder)
        log = folder / f'{kind}.log'
        started = time.monotonic()
        with log.open('w') as err:
            proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL,
                                    stderr=err, env=env)
        try:
            self.wait(20, lambda: handlers_installed(proc.pid))
            guarded = time.monotonic() - started
            before_rclpy = not rclpy_loaded(proc.pid)
            if phase == 'startup':
                self.wait(rng.uniform(0, 0.6))
            else:
                self.wait(20, lambda: self.ready(kind) or
                          proc.poll() is not None)
                self.wait(rng.uniform(0, 0.3), publish=phase == 'burst')
            burst = phase == 'burst'
            first = time.monotonic()
            delays = []
            for i, sig in enumerate(signals):
                if i:
                    delays.append(rng.uniform(0, 1.0))
                    self.wait(delays[-1], publish=burst)
                if proc.poll() is None:
                    proc.send_signal(sig)
            self.wait(15, lambda: proc.poll() is not None, publish=burst)
            code = proc.poll()
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        text = log.read_text()
        return {'kind': kind, 'phase': phase,
                'signals': [s.name for s in signals], 'delays': delays,
                'exit_code': code, 'traceback': 'Traceback' in text,
                'guarded_after_s': guarded, 'guarded_before_rclpy': before_rclpy,
                'exit_after_s': time.monotonic() - first,
                'log': text[-2000:]}


def plan(runs_per_kind, rng):
    """
    Return [(kind, phase, signals)], ``runs_per_kind`` runs per kind.

    The phases take turns (in a random order per kind), so three runs of a
    kind cover every phase; within a phase every (first signal, single or
    double) combination comes once before any comes again, and any two runs
    in a row of a phase include one double signal.
    """
    runs = []
    for kind in KINDS:
        combos = {}
        for phase in PHASES:
            sigs = rng.sample(SIGNALS, len(SIGNALS))
            doubles = rng.sample((False, True), 2)
            combos[phase] = [(sigs[0], doubles[0]), (sigs[1], doubles[1]),
                             (sigs[1], doubles[0]), (sigs[0], doubles[1])]
        phases = rng.sample(PHASES, len(PHASES))
        for i in range(runs_per_kind):
            phase = phases[i % len(phases)]
            sig, double = combos[phase][i // len(phases) % 4]
            runs.append((kind, phase, [sig] + ([rng.choice(SIGNALS)]
                                               if double else [])))
    return runs


def ok(outcome):
    """Return True for a clean end: exit code 0 and no traceback."""
    return outcome['exit_code'] == 0 and not outcome['traceback']
