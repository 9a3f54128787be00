"""
Shutdown torture: stop signals at random moments to every node executable.

    python benchmarks/shutdown.py --runs-per-kind 36

For each of classifier_node, wifi_scanner_node and record_fingerprints
(the executables installed next to this interpreter), ``--runs-per-kind``
runs, each sending SIGINT or SIGTERM, once or twice (the second 0-0.2 s
after the first), at a random moment of start-up, idle time or a burst of
scans (test/signals.py), while another process keeps one core busy. Every
run must end with exit code 0 and no traceback. Also measured: how long
after its start each process catches the signals itself (before that,
Python's default dispositions apply) and how long it takes to exit.
"""

import argparse
import json
import os
from pathlib import Path
import random
import statistics
import sys
import tempfile
import time

import numpy as np
import rclpy
from wifi_place_recognition.core.atomic import atomic_write

ROOT = Path(__file__).resolve().parent.parent
# The tests' helpers (not part of the package): the signal harness.
sys.path.insert(0, str(ROOT / 'test'))
from signals import busy_core, Harness, KINDS, ok, plan  # noqa: E402


def summary(outcomes):
    """Return the table row figures of a list of run outcomes."""
    signals = [s for o in outcomes for s in o['signals']]
    exits = [o['exit_after_s'] for o in outcomes]
    guarded = [o['guarded_after_s'] for o in outcomes]
    return {
        'runs': len(outcomes), 'signals': len(signals),
        'sigint': signals.count('SIGINT'), 'sigterm': signals.count('SIGTERM'),
        'double': sum(len(o['signals']) == 2 for o in outcomes),
        'phases': {p: sum(o['phase'] == p for o in outcomes)
                   for p in ('startup', 'idle', 'burst')},
        'clean': sum(map(ok, outcomes)),
        'non_zero_exit': sum(o['exit_code'] not in (0, None)
                             for o in outcomes),
        'hung': sum(o['exit_code'] is None for o in outcomes),
        'tracebacks': sum(o['traceback'] for o in outcomes),
        'exit_after_median_s': statistics.median(exits),
        'exit_after_max_s': max(exits),
        'handlers_after_median_s': statistics.median(guarded),
        'handlers_after_p95_s': float(np.percentile(guarded, 95)),
    }


def main():
    """Run the torture; print a table; write JSON."""
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--runs-per-kind', type=int, default=36)
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--out', type=Path,
                   default=Path(__file__).parent / 'results' / 'shutdown.json')
    args = p.parse_args()
    os.environ.setdefault('ROS_DOMAIN_ID', str(10 + os.getpid() % 90))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    rng = random.Random(args.seed)
    rclpy.init()
    node = rclpy.create_node('shutdown_torture')
    harness = Harness(node)
    outcomes = []
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory() as tmp, busy_core():
        for i, (kind, phase, signals) in enumerate(
                plan(args.runs_per_kind, rng)):
            outcome = harness.run_once(kind, phase, signals, rng,
                                       Path(tmp) / str(i))
            outcomes.append(outcome)
            print(f'{i + 1:3d} {kind:20s} {phase:8s} '
                  f'{"+".join(outcome["signals"]):15s} '
                  f'exit {outcome["exit_code"]} '
                  f'{"TRACEBACK " if outcome["traceback"] else ""}'
                  f'({outcome["exit_after_s"]:.2f} s)',
                  file=sys.stderr, flush=True)
    harness.close()
    node.destroy_node()
    rclpy.try_shutdown()

    results = {kind: summary([o for o in outcomes if o['kind'] == kind])
               for kind in KINDS}
    print(f'\n{len(outcomes)} runs in {time.monotonic() - t0:.0f} s, '
          f'seed {args.seed}, one core kept busy')
    print('| node | runs | signals (INT/TERM) | double | startup/idle/burst '
          '| exit 0, no traceback | non-zero exit | hung | tracebacks '
          '| exit after 1st signal median/max (s) '
          '| handlers set after start median/p95 (s) |')
    print('|---|---|---|---|---|---|---|---|---|---|---|')
    for kind, r in results.items():
        phases = '/'.join(str(n) for n in r['phases'].values())
        print(f'| {kind} | {r["runs"]} | {r["signals"]} ({r["sigint"]}/'
              f'{r["sigterm"]}) | {r["double"]} | {phases} | {r["clean"]} | '
              f'{r["non_zero_exit"]} | {r["hung"]} | {r["tracebacks"]} | '
              f'{r["exit_after_median_s"]:.2f}/{r["exit_after_max_s"]:.2f} | '
              f'{r["handlers_after_median_s"]:.2f}/'
              f'{r["handlers_after_p95_s"]:.2f} |')
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(args.out, 'w') as f:
        json.dump({'seed': args.seed, 'runs_per_kind': args.runs_per_kind,
                   'results': results,
                   'failures': [o for o in outcomes if not ok(o)]},
                  f, indent=1)
    print(f'wrote {args.out}')
    return 0 if all(map(ok, outcomes)) else 1


if __name__ == '__main__':
    sys.exit(main())
