"""
classifier_node's scan-to-answer latency, idle and while a model updates.

classifier_node runs the shipped model; this process sends UJIIndoorLoc
scans one at a time over DDS (the next once the answer is back) and takes
each scan's round trip (``benchmarks/node.py``'s Bench). Three phases,
repeated: idle; while ``update_model`` trains a candidate at its defaults
(nice +10, torch on one thread); while it trains at nice 0 with torch's
own thread count. Each training phase starts 25 s after the updater (past
reading the data) and the updater is stopped after it. Medians and
percentiles of the round trips per phase; the goal: the median while a
candidate trains within 1 ms of idle. Table on stdout, JSON in
``benchmarks/results/update-cost.json``.

    python benchmarks/update_cost.py [--data ../shared/datasets/ujiindoorloc]
                                     [--scans 2000] [--repeats 2]
"""

import argparse
import json
import os
from pathlib import Path
import signal
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
import rclpy
from wifi_place_recognition.core.atomic import atomic_write
from wifi_place_recognition.core.resources import default_model_path
from wifi_place_recognition.data.fingerprints import read_fingerprints

sys.path.insert(0, str(Path(__file__).resolve().parent))
from node import Bench  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_DATA = ROOT.parent / 'shared' / 'datasets' / 'ujiindoorloc'
#: (phase, niceness, torch threads; None: no update running)
PHASES = (('idle', None, None),
          ('training at nice 10, 1 thread (the defaults)', 10, 1),
          ('training at nice 0, torch\'s own threads', 0, 0))
#: Seconds from the updater's start to the measurement (reading the data).
TRAINING_AFTER_S = 25.0


def lockstep(bench, fp, n):
    """Send ``n`` scans one at a time; return the round trips' figures."""
    bench.answers.clear()
    for row in np.arange(n) % len(fp):
        stamp = bench.send(fp, row)
        bench.spin_until(lambda: stamp in bench.answers, 2.0)
    trips = [a for a, _ in bench.answers.values()]
    return {'answered': len(trips), 'p50_ms': statistics.median(trips),
            'p90_ms': float(np.percentile(trips, 90)),
            'p99_ms': float(np.percentile(trips, 99))}


def updater(folder, data, nice, threads):
    """Start ``update_model`` on the dataset; return the process."""
    return subprocess.Popen(
        [sys.executable, '-m', 'wifi_place_recognition.cli.update_model',
         '--folder', str(folder), '--model', str(default_model_path()),
         '--survey', str(data / 'trainingData.csv'), '--recorded',
         str(data / 'validationData-public.csv'), '--nice', str(nice),
         '--threads', str(threads), '--quiet'],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def main():
    """Measure each phase ``--repeats`` times; print, write JSON."""
    p = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    p.add_argument('--data', type=Path, default=DEFAULT_DATA)
    p.add_argument('--scans', type=int, default=2000)
    p.add_argument('--repeats', type=int, default=2)
    p.add_argument('--out', type=Path,
                   default=ROOT / 'benchmarks' / 'results' /
                   'update-cost.json')
    args = p.parse_args()
    os.environ.setdefault('ROS_DOMAIN_ID', str(10 + os.getpid() % 90))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    fp = read_fingerprints(args.data / 'validationData-public.csv',
                           role='test')
    rclpy.init()
    node = rclpy.create_node('update_cost_bench')
    bench = Bench(node)
    proc = subprocess.Popen([sys.executable, '-m',
                             'wifi_place_recognition.ros.classifier_node'],
                            stderr=subprocess.DEVNULL)
    runs = []
    print(f'{"phase":48s} {"p50 ms":>7s} {"p90 ms":>7s} {"p99 ms":>7s}')
    try:
        while True:     # the node is up once it answers
            stamp = bench.send(fp, 0)
            if bench.spin_until(lambda: stamp in bench.answers, 0.1):
                break
        lockstep(bench, fp, 200)        # warm-up
        with tempfile.TemporaryDirectory() as tmp:
            for rep in range(args.repeats):
                for phase, nice, threads in PHASES:
                    up = None
                    if nice is not None:
                        folder = Path(tmp) / f'models-{rep}-{nice}'
                        folder.mkdir()
                        up = updater(folder, args.data, nice, threads)
                        time.sleep(TRAINING_AFTER_S)
                        if up.poll() is not None:
                            raise SystemExit('error: the update ended '
                                             'before the measurement')
                    run = lockstep(bench, fp, args.scans)
                    if up is not None:
                        run['still_training'] = up.poll() is None
                        up.send_signal(signal.SIGINT)
                        up.wait(timeout=30)
                    run.update(phase=phase, repeat=rep)
                    runs.append(run)
                    print(f'{phase:48s} {run["p50_ms"]:7.2f} '
                          f'{run["p90_ms"]:7.2f} {run["p99_ms"]:7.2f}',
                          flush=True)
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=10)
        node.destroy_node()
        rclpy.try_shutdown()
    idle = statistics.median(r['p50_ms'] for r in runs
                             if r['phase'] == PHASES[0][0])
    summary = {phase: statistics.median(r['p50_ms'] for r in runs
                                        if r['phase'] == phase) - idle
               for phase, _, _ in PHASES[1:]}
    for phase, extra in summary.items():
        print(f'median over idle, {phase}: {extra:+.2f} ms')
    with atomic_write(args.out, 'w') as f:
        json.dump({'protocol': __doc__.strip(), 'scans': args.scans,
                   'runs': runs, 'median_p50_over_idle_ms': summary}, f,
                  indent=1)
    print(f'wrote {args.out}')


if __name__ == '__main__':
    main()
