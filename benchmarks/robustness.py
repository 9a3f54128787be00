"""
Robustness figures: fuzzed scans, a flood, hostile model files, torn writes.

    python benchmarks/robustness.py --data validationData-public.csv

1. ``--fuzz`` malformed and random scans (test/fuzz.py) are
   published to a running classifier_node; its health counts are read back.
2. A flood of valid scans for ``--flood-seconds``: node RSS at start, peak
   and end, answered/dropped counts, the node's own processing time
   (``latency_ms``) for the scans it answered. (The flooding client reads
   answers late, so its end-to-end latencies would measure itself.)
3. Every kind of bad or hostile model file goes to evaluate_model and to
   classifier_node: each must be refused and the pickle marker never appear.
4. A process rewriting a large model is SIGKILLed ``--kills`` times: the file
   must load after every kill.
"""

import argparse
import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.atomic import atomic_write
from wifi_place_recognition.core.resources import default_model_path
from wifi_place_recognition.data.fingerprints import read_fingerprints
from wifi_place_recognition.ros.messages import status_values

from node import Bench, RELIABLE, rss_mib

ROOT = Path(__file__).resolve().parent.parent
# The tests' helpers (not part of the package): fuzzed scans, hostile files.
sys.path.insert(0, str(ROOT / 'test'))
#: The environment of a child process that imports them too.
HELPERS_ENV = dict(os.environ, PYTHONPATH=os.pathsep.join(
    p for p in (str(ROOT / 'test'), os.environ.get('PYTHONPATH')) if p))
from fuzz import fuzz_scans, hostile_model_files  # noqa: E402

NODE = [sys.executable, '-m', 'wifi_place_recognition.ros.classifier_node']
EVALUATE = [sys.executable, '-m', 'wifi_place_recognition.cli.evaluate_model']


class Health:
    """The node's 1 Hz health status, as the latest dict of values."""

    def __init__(self, node):
        self.latest = None
        node.create_subscription(DiagnosticArray, '/diagnostics',
                                 self._on_diag, RELIABLE)

    def _on_diag(self, msg):
        for status in msg.status:
            if status.name.endswith('health'):
                self.latest = status_values(status)

    def settled(self, bench, timeout=30):
        """Return the counts once two health reports in a row agree."""
        last, deadline = None, time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.latest = None
            bench.spin_until(lambda: self.latest is not None, 3)
            counts = {k: int(self.latest[f'scans_{k}']) for k in
                      ('received', 'answered', 'rejected', 'dropped')}
            if counts == last:
                return counts
            last = counts
        return last


def fuzz_and_flood(fp, args):
    """Run parts 1 and 2 against one node process; return figures."""
    rclpy.init()
    node = rclpy.create_node('robustness_bench')
    bench, health = Bench(node), Health(node)
    proc = subprocess.Popen(NODE, env=os.environ.copy(),
                            stderr=subprocess.DEVNULL)
    try:
        while True:
            stamp = bench.send(fp, 0)
            if bench.spin_until(lambda: stamp in bench.answers, 0.1):
                break
        model = load_model(default_model_path())
        sent = 0
        for msg in fuzz_scans(model.ap_ids, args.fuzz, seed=args.seed):
            bench.pub.publish(msg)
            sent += 1
            if sent % 200 == 0:
                bench.spin_until(lambda: False, 0.01)
        fuzz_counts = health.settled(bench)
        alive = proc.poll() is None
        bench.answers.clear()
        stamp = bench.send(fp, 1)
        answered_after = bench.spin_until(lambda: stamp in bench.answers, 2)

        bench.answers.clear()
        rss = [rss_mib(proc.pid)]
        t0 = time.monotonic()
        flood_sent = 0
        while time.monotonic() - t0 < args.flood_seconds:
            for _ in range(50):
                bench.send(fp, flood_sent % len(fp))
                flood_sent += 1
            rclpy.spin_once(node, timeout_sec=0)
            rss.append(rss_mib(proc.pid))
        bench.spin_until(lambda: False, 1.0)
        flood_counts = health.settled(bench)
        rss.append(rss_mib(proc.pid))
        latencies = [b for _, b in bench.answers.values()]
        crashed = proc.poll() is not None
    finally:
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=10)
        node.destroy_node()
        rclpy.try_shutdown()
    return {
        'fuzz': {'scans_sent': sent, 'node_counts': fuzz_counts,
                 'alive_after': alive,
                 'valid_scan_answered_after': answered_after,
                 'counts_balance': fuzz_counts['received'] ==
                 fuzz_counts['answered'] + fuzz_counts['rejected'] +
                 fuzz_counts['dropped']},
        'flood': {'seconds': args.flood_seconds, 'scans_sent': flood_sent,
                  'rss_start_mib': rss[0], 'rss_peak_mib': max(rss),
                  'rss_end_mib': rss[-1],
                  'node_counts_total': flood_counts,
                  'answered_seen': len(latencies),
                  'in_node_latency_median_ms': float(np.median(latencies)),
                  'in_node_latency_p99_ms': float(
                      np.percentile(latencies, 99))},
        'crashes': int(crashed or not alive),
        'node_exit_code': code,
    }


def hostile_files(data, folder):
    """Part 3: every bad model file to evaluate_model and classifier_node."""
    marker = folder / 'PWNED'
    files = hostile_model_files(default_model_path(), folder, marker)
    refused = {}
    for kind, path in files.items():
        ev = subprocess.run(EVALUATE + ['--model', str(path), '--data', data],
                            capture_output=True, text=True)
        nd = subprocess.run(NODE + ['--ros-args', '-p',
                                    f'model_path:={path}'],
                            capture_output=True, text=True, timeout=60)
        refused[kind] = {
            'evaluate_model': ev.returncode == 2 and
            'Traceback' not in ev.stderr,
            'classifier_node': nd.returncode == 1 and
            'Traceback' not in nd.stderr}
    return {'files': len(files), 'refused': refused,
            'all_refused': all(all(r.values()) for r in refused.values()),
            'marker_created': marker.exists()}


def torn_writes(folder, kills, seed):
    """Part 4: SIGKILL a model writer; count loads that still succeed."""
    path = folder / 'rewritten.npz'
    rng = np.random.default_rng(seed)
    survived = 0
    code = ('import sys; from fuzz import '
            'rewrite_forever; rewrite_forever(sys.argv[1])')
    for _ in range(kills):
        proc = subprocess.Popen([sys.executable, '-c', code, str(path)],
                                stdout=subprocess.PIPE, text=True,
                                env=HELPERS_ENV)
        proc.stdout.readline()
        time.sleep(rng.uniform(0, 0.3))
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        try:
            load_model(path)
            survived += 1
        except ValueError:
            pass
    return {'kills': kills, 'loadable_after_kill': survived}


def main():
    """Run all four parts; print a table; write JSON."""
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--data', required=True, help='UJIIndoorLoc-format CSV')
    p.add_argument('--fuzz', type=int, default=10_000)
    p.add_argument('--flood-seconds', type=float, default=30.0)
    p.add_argument('--kills', type=int, default=20)
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--out', type=Path, default=Path(__file__).parent /
                   'results' / 'robustness.json')
    args = p.parse_args()
    os.environ.setdefault('ROS_DOMAIN_ID', str(10 + os.getpid() % 90))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    fp = read_fingerprints(args.data, role='test')
    result = fuzz_and_flood(fp, args)
    with tempfile.TemporaryDirectory() as tmp:
        result['hostile'] = hostile_files(args.data, Path(tmp))
        result['torn'] = torn_writes(Path(tmp), args.kills, args.seed)
    f, fl, h, t = (result['fuzz'], result['flood'], result['hostile'],
                   result['torn'])
    rows = [
        ('scans fuzzed', f['scans_sent']),
        ('node: received / answered / rejected / dropped',
         ' / '.join(str(f['node_counts'][k]) for k in
                    ('received', 'answered', 'rejected', 'dropped'))),
        ('received = answered + rejected + dropped', f['counts_balance']),
        ('crashes', result['crashes']),
        ('valid scan answered after the fuzz',
         f['valid_scan_answered_after']),
        (f'flood {fl["seconds"]:g} s: scans sent', fl['scans_sent']),
        ('flood: RSS start / peak / end (MiB)',
         f'{fl["rss_start_mib"]:.1f} / {fl["rss_peak_mib"]:.1f} / '
         f'{fl["rss_end_mib"]:.1f}'),
        ('flood: answered scans seen', fl['answered_seen']),
        ('flood: in-node latency of answered scans median / p99 (ms)',
         f'{fl["in_node_latency_median_ms"]:.3f} / '
         f'{fl["in_node_latency_p99_ms"]:.3f}'),
        ('hostile model files refused by evaluate_model and the node',
         f'{sum(all(r.values()) for r in h["refused"].values())}'
         f'/{h["files"]}'),
        ('pickle marker created', h['marker_created']),
        ('torn writes survived (SIGKILL mid-write)',
         f'{t["loadable_after_kill"]}/{t["kills"]}'),
    ]
    print('| figure | value |\n|---|---|')
    for label, value in rows:
        print(f'| {label} | {value} |')
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(args.out, 'w') as out:
        json.dump(result, out, indent=1)
    print(f'wrote {args.out}')


if __name__ == '__main__':
    main()
