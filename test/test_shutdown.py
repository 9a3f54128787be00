"""Stop signals at random moments: every node exits 0, no traceback."""

import random
import time

from signals import busy_core, Harness, KINDS, ok, plan

RUNS_PER_KIND = 8       # ~12 signals per kind; benchmarks/shutdown.py: more


def test_stop_signals_at_random_moments_end_every_node_cleanly(ros, tmp_path):
    seed = time.time_ns() % 1_000_000
    rng = random.Random(seed)
    harness = Harness(ros)
    outcomes = []
    try:
        with busy_core():
            for i, (kind, phase, signals) in enumerate(
                    plan(RUNS_PER_KIND, rng)):
                outcomes.append(harness.run_once(kind, phase, signals, rng,
                                                 tmp_path / str(i)))
    finally:
        harness.close()
    bad = [o for o in outcomes if not ok(o)]
    assert not bad, (seed, bad)
    # The executables catch the signals before the heavy imports (seen at
    # the first look in nearly every run; a starved poll may look late).
    early = sum(o['guarded_before_rclpy'] for o in outcomes)
    assert early >= 0.75 * len(outcomes), outcomes
    for kind in KINDS:
        mine = [o for o in outcomes if o['kind'] == kind]
        assert {o['phase'] for o in mine} == {'startup', 'idle', 'burst'}
        assert sum(len(o['signals']) for o in mine) >= 10, (kind, mine)
