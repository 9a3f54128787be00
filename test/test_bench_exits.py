"""The fusion benchmark's pieces: hole exits timed, a run's drift measured."""

import math
from types import SimpleNamespace

import numpy as np


def test_a_hole_exit_is_timed_from_the_first_covered_scan(fusion):
    # a scan a second: 12 in a hole, 40 covered, 3 in a hole (too few),
    # 40 covered, 20 in a hole, 10 covered (too short to time)
    hole = np.array([1] * 12 + [0] * 40 + [1] * 3 + [0] * 40 + [1] * 20 +
                    [0] * 10, bool)
    # the scans' clocks jitter by microseconds: timed to 0.01 s
    jitter = 1e-6 * np.random.default_rng(0).random(len(hole))
    stamps = 100.0 + np.arange(len(hole)) + jitter
    error = np.where(hole, 5.0, 0.5)
    error[12:20] = 3.0          # 8 s to come back after the first
    assert fusion.hole_exits(stamps, error, hole) == [
        {'at_s': 12.0, 'error_m': 3.0, 'below_1m_after_s': 8.0}]
    error[12:55] = 3.0          # not back before the next hole
    exits = fusion.hole_exits(stamps, error, hole)
    assert len(exits) == 1 and math.isinf(exits[0]['below_1m_after_s'])
    # a scan without a true position is neither in a hole nor covered
    error[:] = np.where(hole, 5.0, 0.5)
    error[12] = np.nan
    assert fusion.hole_exits(stamps, error, hole) == [
        {'at_s': 13.0, 'error_m': 0.5, 'below_1m_after_s': 0.0}]


def test_a_runs_drift_is_measured_stretch_by_stretch(fusion):
    # a straight line at 0.5 m/s for 130 s, the odometry losing 1 degree
    # per metre over the first 40 m and 2 after: stretches of 20 m lose
    # 1, 1 and 2 (the last 5 m are no stretch)
    t = np.arange(0.0, 130.0, 0.1)
    x = 0.5 * t
    rate = np.radians(np.where(x < 40, 1.0, 2.0))
    lost = np.concatenate([[0.0], np.cumsum(rate[1:] * np.diff(x))])
    run = SimpleNamespace(odometry=np.column_stack([t, x, 0 * t, -lost]),
                          stamps=t[::10], xy=np.column_stack([x, 0 * t])[::10],
                          yaw=0 * t[::10])
    steady = fusion.drift_steadiness(run)
    assert steady['stretches'] == 3
    assert abs(steady['drift_deg_per_m'] - 4 / 3) < 0.02
    assert abs(steady['stretch_sd_deg_per_m'] - math.sqrt(1 / 3)) < 0.02
    run.stamps, run.xy, run.yaw = run.stamps[:80], run.xy[:80], run.yaw[:80]
    assert 'fitting needs 3 stretches of 20 m' in fusion.drift_steadiness(
        run)['error']
