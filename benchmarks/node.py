"""
Node benchmark: classifier_node (numpy) against a torch-inference variant.

For each variant, in one run: time from process start to first answer,
cross-process latency scan-publish -> place-received over >= 1,000 scans in
lockstep (median, p99), in-node processing time (the node's latency_ms),
sustained scans/s under a flood (answered per second, dropped counted),
and the node's RSS. Ratios are torch / numpy from the same run. Then, in
this process (steadier than across processes), the shipped model's
``PlaceRecognizer.classify`` with tracking on, and each of its stages
(the coverage probability: its features and regression, given the
scan's distances to the references).

    python benchmarks/node.py --data validationData-public.csv
"""

import argparse
import json
import os
from pathlib import Path
import signal
import statistics
import subprocess
import sys
import time

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.atomic import atomic_write
from wifi_place_recognition.core.coverage import features, unheard_share
from wifi_place_recognition.core import preprocessing
from wifi_place_recognition.core.recognizer import PlaceRecognizer
from wifi_place_recognition.core.resources import default_model_path
from wifi_place_recognition.core.tracking import PlaceTracker
from wifi_place_recognition.data.fingerprints import read_fingerprints
from wifi_place_recognition.ros.messages import scan_message, status_values

ROOT = Path(__file__).resolve().parent.parent

VARIANTS = {
    'numpy (shipped node)': [sys.executable, '-m',
                             'wifi_place_recognition.ros.classifier_node'],
    'torch (baseline)': [sys.executable, str(ROOT / 'benchmarks' /
                                             'torch_node.py')],
}
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
PASSES = 3      # over the scans, in-process stage profile


def rss_mib(pid):
    """Return the resident set size of ``pid`` in MiB."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) / 1024
    return float('nan')


class Bench:
    """Client side: publishes scans, records answers and their latency."""

    def __init__(self, node):
        self.node = node
        self.pub = node.create_publisher(JointState, 'wifi/scan', RELIABLE)
        self.answers = {}
        self.sub = node.create_subscription(
            DiagnosticArray, '/classifier_node/place', self._on_place,
            RELIABLE)

    def _on_place(self, msg):
        now = time.time_ns()
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        values = status_values(msg.status[0])
        self.answers[stamp] = ((now - stamp) / 1e6,
                               float(values.get('latency_ms', 'nan')))

    def send(self, fp, row):
        """Publish row ``row`` stamped with the wall clock; return stamp."""
        ns = time.time_ns()
        stamp = rclpy.time.Time(nanoseconds=ns).to_msg()
        self.pub.publish(scan_message(fp.ap_ids, fp.rssi[row], stamp))
        return ns

    def spin_until(self, done, timeout):
        deadline = time.monotonic() + timeout
        while not done() and time.monotonic() < deadline:
            rclpy.spin_once(self.node, timeout_sec=0.005)
        return done()


def measure(bench, argv, fp, scans, flood_s):
    """Start one variant and measure it; return a dict of figures."""
    start = time.monotonic()
    proc = subprocess.Popen(argv, env=os.environ.copy(),
                            stderr=subprocess.DEVNULL)
    try:
        stamp = None
        while True:  # probe until the first answer
            stamp = bench.send(fp, 0)
            if bench.spin_until(lambda: stamp in bench.answers, 0.05):
                break
            if time.monotonic() - start > 30:
                raise RuntimeError('node did not answer within 30 s')
        ready_s = time.monotonic() - start
        bench.answers.clear()
        rows = np.arange(scans) % len(fp)
        for row in rows:
            stamp = bench.send(fp, row)
            bench.spin_until(lambda: stamp in bench.answers, 2.0)
        lockstep = list(bench.answers.values())
        rss = rss_mib(proc.pid)
        bench.answers.clear()
        sent, t0 = 0, time.monotonic()
        while time.monotonic() - t0 < flood_s:
            bench.send(fp, sent % len(fp))
            sent += 1
            rclpy.spin_once(bench.node, timeout_sec=0)
        bench.spin_until(lambda: False, 0.5)
        flood_answered = len(bench.answers)
        peak_rss = rss_mib(proc.pid)
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=10)
    cross = [a for a, _ in lockstep]
    inside = [b for _, b in lockstep]
    return {
        'ready_s': ready_s, 'answered': len(lockstep), 'sent': scans,
        'cross_median_ms': statistics.median(cross),
        'cross_p99_ms': float(np.percentile(cross, 99)),
        'in_node_median_ms': statistics.median(inside),
        'in_node_p99_ms': float(np.percentile(inside, 99)),
        'flood_sent_per_s': sent / flood_s,
        'flood_answered_per_s': flood_answered / flood_s,
        'rss_mib': rss, 'rss_after_flood_mib': peak_rss,
    }


def stages(fp, passes):
    """
    Return {stage: (median ms, p99 ms)} of classify and its stages.

    Each scan of ``fp`` (its detected APs, as a node receives them) goes
    through the stages one by one, then through ``classify`` as a whole;
    scans are 5 s apart so that the tracker keeps its belief.
    """
    model = load_model(default_model_path())
    recognizer = PlaceRecognizer(model)
    recognizer.configure(tracking=True, tracking_timeout=60.0)
    tracker = PlaceTracker(model.classes, model.tracking, 60.0)
    scans = []
    for row in fp.rssi:
        seen = np.flatnonzero(np.isfinite(row))
        scans.append(([fp.ap_ids[j] for j in seen], row[seen].tolist()))
    times = {k: [] for k in ('map', 'inputs', 'forward', 'position',
                             'coverage', 'tracking', 'classify')}
    locator = model.position
    clock, t = time.perf_counter, 0.0
    for _ in range(passes):
        for names, rssi in scans:
            t += 5.0
            t0 = clock()
            scan = recognizer.mapper.map(names, rssi)
            t1 = clock()
            inputs = model.relative(scan.columns, scan.rssi)
            t2 = clock()
            proba = recognizer.forward(scan.columns, inputs)
            t3 = clock()
            c = int(proba.argmax())
            xy, sigma = locator.locate(scan.columns, scan.rssi, c)
            t4 = clock()
            distance = locator.distances(
                scan.columns,
                preprocessing.signal(scan.rssi, locator.representation), c)
            t5 = clock()
            if model.coverage is not None:
                model.coverage.probability(features(
                    locator, distance, c, unheard_share(
                        locator, scan.columns, c, scan.unknown)))
            t6 = clock()
            tracker.update(t, proba, xy, np.eye(2) * sigma ** 2)
            t7 = clock()
            recognizer.classify(names, rssi, t + 2.5)
            t8 = clock()
            for key, a, b in (('map', t0, t1), ('inputs', t1, t2),
                              ('forward', t2, t3), ('position', t3, t4),
                              ('coverage', t5, t6), ('tracking', t6, t7),
                              ('classify', t7, t8)):
                times[key].append((b - a) * 1e3)
    return {k: (statistics.median(v), float(np.percentile(v, 99)))
            for k, v in times.items()}


def main():
    """Measure both variants; print a table; write JSON."""
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--data', required=True, help='UJIIndoorLoc-format CSV')
    p.add_argument('--scans', type=int, default=1000)
    p.add_argument('--flood-seconds', type=float, default=5.0)
    p.add_argument('--out', type=Path,
                   default=Path(__file__).parent / 'results' / 'node.json')
    args = p.parse_args()
    os.environ.setdefault('ROS_DOMAIN_ID', str(10 + os.getpid() % 90))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    fp = read_fingerprints(args.data, role='test')
    rclpy.init()
    node = rclpy.create_node('node_bench')
    bench = Bench(node)
    results = {}
    for name, argv in VARIANTS.items():
        print(f'measuring {name} ...', file=sys.stderr, flush=True)
        results[name] = measure(bench, argv, fp, args.scans,
                                args.flood_seconds)
    node.destroy_node()
    rclpy.try_shutdown()

    base, other = results.values()
    rows = [('start to first answer (s)', 'ready_s'),
            ('cross-process latency median (ms)', 'cross_median_ms'),
            ('cross-process latency p99 (ms)', 'cross_p99_ms'),
            ('in-node processing median (ms)', 'in_node_median_ms'),
            ('in-node processing p99 (ms)', 'in_node_p99_ms'),
            ('flood: answered scans/s', 'flood_answered_per_s'),
            ('flood: sent scans/s', 'flood_sent_per_s'),
            ('RSS after lockstep (MiB)', 'rss_mib'),
            ('RSS after flood (MiB)', 'rss_after_flood_mib')]
    names = list(results)
    print(f'\n{args.scans} lockstep scans from {fp.source}; flood '
          f'{args.flood_seconds:g} s; answered {base["answered"]}/'
          f'{args.scans} and {other["answered"]}/{args.scans}')
    print(f'| figure | {names[0]} | {names[1]} | ratio torch/numpy |')
    print('|---|---|---|---|')
    for label, key in rows:
        print(f'| {label} | {base[key]:.3f} | {other[key]:.3f} | '
              f'{other[key] / base[key]:.2f} |')
    profile = stages(fp, PASSES)
    print(f'\nin this process, shipped model, tracking on, {len(fp)} scans '
          f'x {PASSES}')
    print('| stage | median (ms) | p99 (ms) |')
    print('|---|---|---|')
    for key, (median, p99) in profile.items():
        print(f'| {key} | {median:.3f} | {p99:.3f} |')
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(args.out, 'w') as f:
        json.dump({'data': fp.source, 'scans': args.scans,
                   'flood_seconds': args.flood_seconds,
                   'results': results, 'in_process_ms': profile}, f,
                  indent=1)
    print(f'wrote {args.out}')


if __name__ == '__main__':
    main()
