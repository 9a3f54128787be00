"""The fusion benchmark's hole exits: when the robot is back on the survey."""

import math

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
