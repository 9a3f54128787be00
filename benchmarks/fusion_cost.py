"""
Fusion cost: classifier_node per scan and per odometry message, and its RSS.

Across processes, in each repeat, one node after the other (in a shuffled
order): the echo node (``echo_node.py``, the baseline) and, for the shipped
model and a position-only robot model (``--robot-model``), classifier_node
with fusion off and no odometry, fusion off while odometry flows at 50 Hz,
and fusion on while odometry flows at 10 Hz and at 50 Hz. Each is sent
``--scans`` scans at ``--scan-rate`` Hz on average (intervals drawn from
0.5-1.5 times the period, so that scans do not lock to the odometry's
phase) after 2 s of warm-up with the same traffic. Odometry is a recorded
robot run's (``--robot-run``: ``odom.csv``, ~10 Hz; resampled to the rate,
stamped with the wall clock as sent). Scans: the shipped model gets the
test file's rows grouped by building and floor, evenly spaced so that
each case goes once through every place (the filter restarts at each
change of place); the robot model gets the run's scan recorded nearest
to the odometry being sent (so WiFi and odometry agree, as on a robot).
Per scan:
client round trip (publish -> ``~/place`` received) and in-node time (the
answer's ``latency_ms``), p50/p99; the overhead over the echo node of the
same repeat; the node's RSS (``/proc``) and CPU over the window; the fused
pose's delay (publish -> scan-stamped ``~/pose`` received: it waits for the
odometry covering the scan).

Then, in this process, a real ClassifierNode over the robot run's recorded
timeline (its scans at their stamps, its odometry at 10 Hz and resampled
to 50 Hz, the between-scan timer every 1/``pose_rate`` s), calling the
callbacks directly: per odometry message the adapter's callback
(``OdometryFusion._on_odometry``, which includes ``Fusion.odometry``, the
particle moves and the scans it releases) and ``Fusion.odometry`` alone; per
scan ``ClassifierNode._process`` (classify, answer, hand to the filter).

    python benchmarks/fusion_cost.py --data validationData-public.csv \
        --robot-run robot/b14/b14test2 --robot-model b14.npz
"""

import argparse
import hashlib
import json
import os
from pathlib import Path
import random
import signal
import statistics
import subprocess
import sys
import time

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from wifi_place_recognition.core.atomic import atomic_write
from wifi_place_recognition.core.filter.trajectory import truth_at
from wifi_place_recognition.core.resources import default_model_path
from wifi_place_recognition.data.fingerprints import read_fingerprints
from wifi_place_recognition.data.poses import read_poses
from wifi_place_recognition.ros.classifier_node import ClassifierNode
from wifi_place_recognition.ros.messages import status_values
from wifi_place_recognition.ros.replayer import unique_stamps
from wifi_place_recognition.ros.run_replayer import odometry_message

ROOT = Path(__file__).resolve().parent.parent
NODE = [sys.executable, '-m', 'wifi_place_recognition.ros.classifier_node']
ECHO = [sys.executable, str(ROOT / 'benchmarks' / 'echo_node.py')]
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
WARM_S = 2.0
#: (case name, fusion on, odometry rate Hz or 0).
CASES = (('fusion off', False, 0), ('fusion off, odometry 50 Hz', False, 50),
         ('fusion on, odometry 10 Hz', True, 10),
         ('fusion on, odometry 50 Hz', True, 50))
RATES = (10, 50)
CLOCK_TICK = os.sysconf('SC_CLK_TCK')


def proc_status(pid):
    """Return {VmRSS, VmHWM} of ``pid`` in MiB."""
    out = {}
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        key, _, value = line.partition(':')
        if key in ('VmRSS', 'VmHWM'):
            out[key] = int(value.split()[0]) / 1024
    return out


def cpu_seconds(pid):
    """Return the user + system CPU time of ``pid`` (s)."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICK


def resample(odom, rate):
    """Return the (t, x, y, yaw) rows of ``odom`` every 1/``rate`` s."""
    t = np.arange(odom[0, 0], odom[-1, 0], 1.0 / rate)
    xy, yaw = truth_at(odom, t)     # inside the span: no NaN
    return np.column_stack([t, xy, yaw])


def percentiles(values):
    """Return (p50, p99) of ``values`` (ms), NaN when empty."""
    if not values:
        return float('nan'), float('nan')
    return statistics.median(values), float(np.percentile(values, 99))


class Client:
    """Sends scans and odometry; records answers, poses and health."""

    def __init__(self, node):
        self.node = node
        self.scan_pub = node.create_publisher(JointState, 'wifi/scan',
                                              RELIABLE)
        self.odom_pub = node.create_publisher(Odometry, 'odom', RELIABLE)
        self.sent = {}      # stamp ns -> publish time ns
        self.answers = {}   # stamp ns -> (round trip ms, in-node ms)
        self.poses = {}     # stamp ns -> received time ns
        self.health = {}
        node.create_subscription(DiagnosticArray, '/classifier_node/place',
                                 self._on_place, RELIABLE)
        node.create_subscription(PoseWithCovarianceStamped,
                                 '/classifier_node/pose', self._on_pose,
                                 RELIABLE)
        node.create_subscription(DiagnosticArray, '/diagnostics',
                                 self._on_diagnostics, RELIABLE)

    @staticmethod
    def _ns(stamp):
        return stamp.sec * 10 ** 9 + stamp.nanosec

    def _on_place(self, msg):
        now = time.time_ns()
        stamp = self._ns(msg.header.stamp)
        values = status_values(msg.status[0])
        self.answers[stamp] = ((now - stamp) / 1e6,
                               float(values.get('latency_ms', 'nan')))

    def _on_pose(self, msg):
        self.poses.setdefault(self._ns(msg.header.stamp), time.time_ns())

    def _on_diagnostics(self, msg):
        for status in msg.status:
            if status.name.endswith(': health'):
                self.health = status_values(status)

    def clear(self):
        self.sent.clear()
        self.answers.clear()
        self.poses.clear()

    def send_scan(self, names, rssi):
        ns = time.time_ns()
        msg = JointState(name=names, position=rssi)
        msg.header.stamp = rclpy.time.Time(nanoseconds=ns).to_msg()
        msg.header.frame_id = 'bench'
        self.scan_pub.publish(msg)
        self.sent[ns] = ns
        return ns

    def send_odometry(self, row):
        msg = odometry_message((0.0,) + tuple(row[1:]))
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.odom_pub.publish(msg)

    def spin_until(self, done, timeout):
        deadline = time.monotonic() + timeout
        while not done() and time.monotonic() < deadline:
            rclpy.spin_once(self.node, timeout_sec=0.005)
        return done()


class Traffic:
    """Scans and odometry for one case: what to send, and when."""

    def __init__(self, scans, odom, odom_rate, scan_rate, seed):
        self.scans = scans          # callable(odometry row) -> names, rssi
        self.odom = resample(odom, odom_rate) if odom_rate else None
        self.odom_rate = odom_rate
        self.scan_period = 1.0 / scan_rate
        self.rng = random.Random(seed)
        self.k = 0                  # next odometry row

    def run(self, client, seconds=None, scans=None):
        """Send until ``seconds`` passed or ``scans`` scans were sent."""
        start = now = time.monotonic()
        next_scan = next_odom = now
        sent = 0
        while (seconds is None or now - start < seconds) and \
                (scans is None or sent < scans):
            if self.odom is not None and now >= next_odom:
                client.send_odometry(self.odom[self.k % len(self.odom)])
                self.k += 1
                next_odom += 1.0 / self.odom_rate
            if now >= next_scan:
                row = self.odom[self.k % len(self.odom)] \
                    if self.odom is not None else None
                client.send_scan(*self.scans(row))
                sent += 1
                next_scan += self.scan_period * self.rng.uniform(0.5, 1.5)
            wake = min(next_scan, next_odom if self.odom is not None
                       else next_scan)
            rclpy.spin_once(client.node,
                            timeout_sec=max(0.0, wake - time.monotonic()))
            now = time.monotonic()


def measure(client, argv, traffic, scans, probe):
    """Start one node, send ``traffic``; return its figures."""
    start = time.monotonic()
    proc = subprocess.Popen(argv, env=os.environ.copy(),
                            stderr=subprocess.DEVNULL)
    try:
        while True:     # probe until the first answer
            stamp = client.send_scan(*probe)
            if client.spin_until(lambda: stamp in client.answers, 0.05):
                break
            if time.monotonic() - start > 30 or proc.poll() is not None:
                raise RuntimeError(f'{argv}: no answer within 30 s')
        ready_s = time.monotonic() - start
        client.health = {}
        traffic.run(client, seconds=WARM_S)
        client.spin_until(lambda: False, 0.2)
        client.clear()
        cpu0, t0 = cpu_seconds(proc.pid), time.monotonic()
        traffic.run(client, scans=scans)
        cpu1, t1 = cpu_seconds(proc.pid), time.monotonic()
        memory = proc_status(proc.pid)
        client.spin_until(lambda: len(client.answers) >= len(client.sent),
                          2.0)
        client.spin_until(lambda: False, 1.2)   # a health status, poses
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=20)
    answers = [client.answers[s] for s in client.sent if s in client.answers]
    rtt, inside = [a for a, _ in answers], [b for _, b in answers]
    pose_ms = [(client.poses[s] - s) / 1e6 for s in client.sent
               if s in client.poses]
    health = client.health
    out = {'ready_s': ready_s, 'sent': len(client.sent),
           'answered': len(answers),
           'window_s': t1 - t0,
           'cpu_percent': 100 * (cpu1 - cpu0) / (t1 - t0),
           'rss_mib': memory['VmRSS'], 'peak_rss_mib': memory['VmHWM'],
           'poses': len(client.poses), 'scan_poses': len(pose_ms)}
    out['rtt_p50_ms'], out['rtt_p99_ms'] = percentiles(rtt)
    out['in_node_p50_ms'], out['in_node_p99_ms'] = percentiles(inside)
    out['pose_delay_p50_ms'], out['pose_delay_p99_ms'] = percentiles(pose_ms)
    for key in ('fusion', 'odometry_received', 'fusion_scans_fused',
                'fusion_scans_alone', 'fusion_restarts', 'scans_dropped',
                'rss_mib'):
        if key in health:
            out[f'health_{key}'] = health[key]
    return out


def scan_lists(fp):
    """Return each row of ``fp`` as a scan: (AP names, RSSI list)."""
    out = []
    for row in fp.rssi:
        seen = np.flatnonzero(np.isfinite(row))
        out.append(([fp.ap_ids[j] for j in seen], row[seen].tolist()))
    return out


def by_place(fp):
    """
    Return the scans of ``fp`` grouped by building and floor.

    In file order within a floor: the place changes as rarely as it does
    for a device moving through the buildings (in the test file's order
    it changes every other scan, and each change costs the node a
    logged ``~/current_place``).
    """
    order = np.lexsort((np.arange(len(fp)), fp.floor, fp.building))
    scans = scan_lists(fp)
    return [scans[i] for i in order]


def uji_scans(fp, count):
    """
    Return a scan source going once through ``fp`` by place in ``count`` scans.

    Evenly spaced rows of :func:`by_place`: every case sees every place.
    """
    scans, state = by_place(fp), {'i': 0}

    def next_scan(odometry_row):
        state['i'] += 1
        return scans[state['i'] * len(scans) // count % len(scans)]
    return next_scan


def run_scans(fp, odom):
    """
    Return a scan source giving the run's scan nearest the odometry sent.

    Without odometry, the run's scans in turn.
    """
    scans, times = scan_lists(fp), fp.meta['TIMESTAMP']
    state = {'i': 0}

    def next_scan(odometry_row):
        if odometry_row is None:
            state['i'] += 1
            return scans[state['i'] % len(scans)]
        return scans[int(np.abs(times - odometry_row[0]).argmin())]
    return next_scan


def cross_process(args, models, odom, repeats):
    """Run every case ``repeats`` times; return {repeat: {case: figures}}."""
    node = rclpy.create_node('fusion_cost_bench')
    client = Client(node)
    runs = []
    for repeat in range(repeats):
        cases = [('echo', None, ECHO, 0)]
        for model, (path, source) in models.items():
            for name, fusion, rate in CASES:
                argv = NODE + ['--ros-args', '-p', f'model_path:={path}',
                               '-p', f'fusion:={str(fusion).lower()}']
                cases.append((f'{model}: {name}', model, argv, rate))
        random.Random(repeat).shuffle(cases)
        results = {}
        for name, model, argv, rate in cases:
            print(f'repeat {repeat + 1}/{repeats}: {name} ...',
                  file=sys.stderr, flush=True)
            source = models[model or 'shipped'][1]()    # afresh per case
            traffic = Traffic(source, odom, rate, args.scan_rate, repeat)
            results[name] = measure(client, argv, traffic, args.scans,
                                    source(None))
            results[name]['odometry_hz'] = rate
        runs.append(results)
    node.destroy_node()
    return runs


def timed(f, times):
    """Return ``f`` recording each call's duration (ms) in ``times``."""
    def wrapper(*a, **kw):
        t0 = time.perf_counter()
        try:
            return f(*a, **kw)
        finally:
            times.append((time.perf_counter() - t0) * 1e3)
    return wrapper


def in_process(model_path, scans, scan_times, odom, rate, fusion):
    """
    Replay the run's timeline through a ClassifierNode's callbacks.

    Return {figure: (p50 ms, p99 ms, max ms, n)}.
    """
    node = ClassifierNode(parameter_overrides=[
        Parameter('model_path', value=str(model_path)),
        Parameter('fusion', value=fusion)])
    try:
        adapter = node.odometry
        core, callback, process, timer = [], [], [], []
        adapter.fusion.odometry = timed(adapter.fusion.odometry, core)
        stream = resample(odom, rate) if rate != 10 else odom
        stamps = unique_stamps(scan_times)
        pose_period = 1.0 / node.get_parameter('pose_rate').value
        events = sorted(
            [(t, 0, k) for k, t in enumerate(stream[:, 0])] +
            [(t, 1, k) for k, t in enumerate(scan_times)] +
            [(t, 2, 0) for t in np.arange(stream[0, 0], stream[-1, 0],
                                          pose_period)])
        clock = time.perf_counter
        released = []
        for t, kind, k in events:
            if kind == 0:
                msg = odometry_message(stream[k])
                before = adapter.fusion.counts['scans_fused']
                t0 = clock()
                adapter._on_odometry(msg)
                callback.append((clock() - t0) * 1e3)
                if adapter.fusion.counts['scans_fused'] != before:
                    released.append(callback[-1])
            elif kind == 1:
                names, rssi = scans[k % len(scans)]
                msg = JointState(name=names, position=rssi)
                msg.header.stamp = stamps[k]
                t0 = clock()
                node._process(msg, t0)
                process.append((clock() - t0) * 1e3)
            else:
                t0 = clock()
                adapter._on_timer()
                timer.append((clock() - t0) * 1e3)
        counts = dict(adapter.fusion.counts)
    finally:
        node.destroy_node()

    def summary(values):
        p50, p99 = percentiles(values)
        return [p50, p99, max(values, default=float('nan')), len(values)]
    return {'odometry callback': summary(callback),
            'Fusion.odometry': summary(core),
            'odometry callback releasing a scan': summary(released),
            'scan (_process)': summary(process),
            'between-scan timer': summary(timer),
            'counts': counts}


def summarise(runs):
    """Return {case: {figure: [median, min, max]}} over the repeats."""
    out = {}
    for case in runs[0]:
        figures = {}
        for key in runs[0][case]:
            values = [r[case][key] for r in runs]
            if all(isinstance(v, (int, float)) for v in values):
                figures[key] = [statistics.median(values), min(values),
                                max(values)]
        for key in ('rtt_p50_ms', 'rtt_p99_ms', 'in_node_p50_ms',
                    'in_node_p99_ms'):
            values = [r[case][key] - r['echo'][key] for r in runs]
            figures[f'{key[:-3]}_over_echo_ms'] = [
                statistics.median(values), min(values), max(values)]
        rate = runs[0][case]['odometry_hz']
        if rate:    # CPU over the same model's without odometry, per message
            base = case.split(':')[0] + ': fusion off'
            values = [(r[case]['cpu_percent'] - r[base]['cpu_percent']) *
                      10 / rate for r in runs]
            figures['cpu_ms_per_odometry'] = [
                statistics.median(values), min(values), max(values)]
        out[case] = figures
    return out


def cell(figure, digits=2):
    median, low, high = figure
    return f'{median:.{digits}f} ({low:.{digits}f}-{high:.{digits}f})'


def main():
    """Measure; print tables; write JSON."""
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--data', required=True,
                   help='the shipped model\'s test file (UJIIndoorLoc CSV)')
    p.add_argument('--robot-run', type=Path, required=True,
                   help='a robot run folder (scans.csv, odom.csv)')
    p.add_argument('--robot-model', type=Path, required=True,
                   help='a position-only model trained on another run')
    p.add_argument('--scans', type=int, default=240,
                   help='scans per case and repeat (default: %(default)s)')
    p.add_argument('--scan-rate', type=float, default=8.0,
                   help='mean scans per second (default: %(default)s)')
    p.add_argument('--repeats', type=int, default=3)
    p.add_argument('--out', type=Path, default=Path(__file__).parent /
                   'results' / 'fusion-cost.json')
    args = p.parse_args()
    os.environ.setdefault('ROS_DOMAIN_ID', str(10 + os.getpid() % 90))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    uji = read_fingerprints(args.data, role='test')
    run = read_fingerprints(args.robot_run / 'scans.csv', role='test')
    odom = read_poses(args.robot_run / 'odom.csv')
    shipped = default_model_path()
    per_case = args.scans + int(WARM_S * args.scan_rate * 1.5) + 10
    models = {'shipped': (shipped, lambda: uji_scans(uji, per_case)),
              'robot': (args.robot_model, lambda: run_scans(run, odom))}
    rclpy.init()
    runs = cross_process(args, models, odom, args.repeats)
    summary = summarise(runs)
    local = {}
    for model, path, scans in (('shipped', shipped, by_place(uji)),
                               ('robot', args.robot_model, scan_lists(run))):
        for rate in RATES:
            for fusion in (True, False):
                key = (f'{model}: fusion {"on" if fusion else "off"}, '
                       f'odometry {rate} Hz')
                print(f'in process: {key} ...', file=sys.stderr, flush=True)
                local[key] = in_process(path, scans, run.meta['TIMESTAMP'],
                                        odom, rate, fusion)
    rclpy.try_shutdown()

    print(f'\nacross processes: {args.repeats} repeats x {args.scans} scans '
          f'at {args.scan_rate:g} Hz per case; median (range) over repeats; '
          f'odometry from {args.robot_run}')
    print('| case | round trip p50 / p99 (ms) | in node p50 / p99 (ms) | '
          'round trip p50 over echo (ms) | fused pose delay p50 (ms) | '
          'CPU (%) | CPU per odometry message (ms) | RSS (MiB) |')
    print('|---|---|---|---|---|---|---|---|')
    for case, f in summary.items():
        pose = cell(f['pose_delay_p50_ms'], 1) \
            if not np.isnan(f['pose_delay_p50_ms'][0]) else '-'
        print(f'| {case} | {cell(f["rtt_p50_ms"])} / {cell(f["rtt_p99_ms"])}'
              f' | {cell(f["in_node_p50_ms"], 3)} / '
              f'{cell(f["in_node_p99_ms"], 3)} | '
              f'{cell(f["rtt_p50_over_echo_ms"])} | {pose} | '
              f'{cell(f["cpu_percent"], 1)} | '
              f'{cell(f["cpu_ms_per_odometry"]) if "cpu_ms_per_odometry" in f else "-"}'
              f' | {cell(f["rss_mib"], 1)} |')
    print(f'\nin this process: {run.source} timeline '
          f'({len(run)} scans, odometry 10 Hz recorded or 50 Hz resampled); '
          f'p50 / p99 / max (ms), n')
    print('| model, case | odometry callback | Fusion.odometry | callback '
          'releasing a scan | scan (_process) | between-scan timer |')
    print('|---|---|---|---|---|---|')
    for key, r in local.items():
        print(f'| {key} | ' + ' | '.join(
            f'{r[k][0]:.3f} / {r[k][1]:.3f} / {r[k][2]:.2f}, {r[k][3]}'
            for k in ('odometry callback', 'Fusion.odometry',
                      'odometry callback releasing a scan',
                      'scan (_process)', 'between-scan timer')) + ' |')
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(args.out, 'w') as f:
        json.dump({'data': uji.source, 'robot_run': str(args.robot_run),
                   'robot_model': str(args.robot_model),
                   'model_sha256': {
                       model: hashlib.sha256(
                           Path(path).read_bytes()).hexdigest()
                       for model, (path, _) in models.items()},
                   'scans': args.scans, 'scan_rate': args.scan_rate,
                   'repeats': args.repeats, 'warm_s': WARM_S,
                   'summary': summary, 'runs': runs, 'in_process': local},
                  f, indent=1)
    print(f'wrote {args.out}')


if __name__ == '__main__':
    main()
