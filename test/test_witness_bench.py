"""
The witness benchmark's choice of thresholds, in one process and in two.

Synthetic runs (a robot driving along x, the localiser displaced 10 m
half way): ``benchmarks/witness.py``'s ``choose`` with ``--jobs 2`` must
try the same thresholds in the same order, score them the same and
choose the same as with one process.
"""

import json
import math
import subprocess
import sys
from types import SimpleNamespace

from conftest import benchmark, REPO
import numpy as np


def stream(t, xy, sd, yaw_sd=0.05):
    """Return (t, xy, yaw, cov): heading along x, a diagonal covariance."""
    cov = np.tile(np.diag([sd ** 2, sd ** 2, yaw_sd ** 2]), (len(t), 1, 1))
    return t, xy, np.zeros(len(t)), cov


def case(seed):
    """Return a run of 200 s: the truth, scans, fused poses, two episodes."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 200.0)
    xy = np.column_stack([0.5 * t, np.zeros_like(t)])
    local = stream(t, xy, 0.1)
    near = xy + rng.normal(0, 1.0, xy.shape)
    scans = (t, near, np.full(len(t), 2.0), np.full(len(t), math.nan))
    fused = stream(t, xy + rng.normal(0, 0.3, xy.shape), 0.5)
    displaced = stream(t, xy + (t >= 100)[:, None] * [0.0, 10.0], 0.1)
    inside = stream(t, xy + (t >= 100)[:, None] * [0.0, 0.2], 0.1)
    truth = np.column_stack([t, xy, np.zeros_like(t)])
    return SimpleNamespace(
        local=local, truth=truth, inside=[(0, 100.0, inside)],
        scans={k: scans for k in ('full', 'holes')},
        survey={k: xy[::2] for k in ('full', 'holes')},
        fused={k: [fused] * 3 for k in ('full', 'holes')},
        episodes=[(k, 'displaced', 0, 100.0, displaced, fused, scans,
                   truth, xy[::2]) for k in ('full', 'holes')])


#: Run in a fresh interpreter: forking pytest's process, whose earlier tests
#: left threads (ROS executors, DDS), can deadlock the pool's workers.
CHILD = """
import json
from conftest import benchmark
from test_witness_bench import case
witness = benchmark('witness')
witness.GRID = {'agree_sigmas': (3.0, 4.0), 'alarm': (15.0, 60.0)}
witness.SEED_GRID = {'sure_sd': (0.5, 2.0), 'sure_s': (0.0, 60.0)}
witness.HOLD_GRID = {'startup_sure_s': (0.0, 15.0)}
cases = [case(0), case(1)]
two = witness.choose(cases, 2)   # first: nothing held yet
one = witness.choose(cases, 1)
print(json.dumps([[vars(c[0]), c[1]] for c in (one, two)]))
"""


def test_thresholds_tried_in_two_processes_are_those_in_one():
    done = subprocess.run([sys.executable, '-c', CHILD], cwd=REPO / 'test',
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    (one, tried_one), (two, tried_two) = json.loads(done.stdout)
    assert len(tried_one) == 10
    assert one == two
    assert json.dumps(tried_two) == json.dumps(tried_one)
    # the episodes were judged: the thresholds tried differ in delay
    assert len({t['delay_median_s'] for t in tried_one[:4]}) > 1


def test_a_missed_episode_leaves_the_choice_to_the_delays_found(
        monkeypatch):
    # one episode no threshold finds (the localiser 0.5 m off): every
    # candidate misses it, and the faster alarm must still win, not the
    # grid's first (the sum of median and max delay was inf for all)
    witness = benchmark('witness')
    monkeypatch.setattr(witness, 'GRID', {'alarm': (60.0, 15.0)})
    monkeypatch.setattr(witness, 'SEED_GRID', {'sure_s': (0.0,)})
    monkeypatch.setattr(witness, 'HOLD_GRID', {'startup_sure_s': (0.0,)})
    cases = [case(0), case(1)]
    for c in cases:
        t, xy = c.local[0], c.truth[:, 1:3]
        near = stream(t, xy + (t >= 100)[:, None] * [0.0, 0.5], 0.1)
        c.episodes.append(('full', 'displaced', 0, 100.0, near,
                           *c.episodes[0][5:]))
    params, tried = witness.choose(cases, 1)
    assert [t['missed'] for t in tried[:2]] == [2, 2]
    assert math.isinf(tried[0]['delay_max_s'])
    assert tried[1]['found_delay_median_s'] < \
        tried[0]['found_delay_median_s']
    assert params.alarm == 15.0


def test_a_wrong_start_up_seed_counts_before_a_late_one(monkeypatch):
    # the fused pose sure but 5 m aside for the first 20 s, wide once,
    # then sure and right: no hold seeds at once, 5 m off; a hold of 45 s
    # seeds right at 66 s, late. The late one must win (a late seed and
    # a wrong one once counted alike, and the earlier won).
    witness = benchmark('witness')
    monkeypatch.setattr(witness, 'GRID', {'alarm': (60.0,)})
    monkeypatch.setattr(witness, 'SEED_GRID', {'sure_s': (0.0,)})
    monkeypatch.setattr(witness, 'HOLD_GRID',
                        {'startup_sure_s': (0.0, 45.0)})
    cases = [case(0), case(1)]
    for c in cases:
        t, xy = c.local[0], c.truth[:, 1:3]
        aside = stream(t, xy + (t < 20)[:, None] * [0.0, 5.0], 0.5)
        aside[3][20] = np.diag([9.0, 9.0, 0.05 ** 2])   # wide once
        c.fused['full'] = [aside] * 3
    params, tried = witness.choose(cases, 1)
    no_hold, hold = tried[-2:]
    assert no_hold['startup_wrong'] == 6 and no_hold['startup_late'] == 0
    assert hold['startup_wrong'] == 0 and hold['startup_late'] == 6
    assert hold['startup_max_s'] == 21 + 45
    assert params.startup_sure_s == 45.0


def test_a_heading_told_at_the_first_scan_is_the_filters_from_there():
    # a drive north (+y, heading 90 deg) at 0.5 m/s, scans 1 m off; the
    # first scan has no answer: told the heading, the filter knows it from
    # the first scan with a position on; not told, it does not yet
    witness = benchmark('witness')
    from wifi_place_recognition.core.filter.particles import (
        FusionParams, UNKNOWN_VARIANCE)
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 20.0)
    xy = np.column_stack([np.zeros_like(t), 0.5 * t])
    near = xy + rng.normal(0, 1.0, xy.shape)
    near[0] = np.nan
    scans = (t, near, np.full(len(t), 2.0))
    odom_t = np.arange(0.0, 20.0, 0.1)
    odometry = np.column_stack([odom_t, 0.5 * odom_t,
                                np.zeros_like(odom_t), np.zeros_like(odom_t)])
    model = SimpleNamespace(fusion=FusionParams())
    north = math.pi / 2
    _, _, yaw, cov = witness.fused_stream(model, scans, odometry, 0, north)
    assert np.isnan(yaw[0])
    assert np.all(np.abs(yaw[1:] - north) < math.radians(10))
    assert np.all(cov[1:, 2, 2] < UNKNOWN_VARIANCE)
    _, _, _, cov = witness.fused_stream(model, scans, odometry, 0)
    assert cov[1, 2, 2] == UNKNOWN_VARIANCE


def test_start_up_bounds_ask_the_told_stream_and_the_position_alone():
    # the fused pose sure in position (1 m aside), its yaw 30 deg wide:
    # the defaults never seed it; sure in position with any known heading,
    # it seeds after the start-up hold (15 s), 1 m off; the stream told
    # the heading (on the truth, yaw 3 deg) seeds after the hold too, 0 m
    # off; a run that never seeds is counted as such
    witness = benchmark('witness')
    from wifi_place_recognition.core.witness_params import WitnessParams
    c = case(0)
    t, xy = c.local[0], c.truth[:, 1:3]
    wide = stream(t, xy + [0.0, 1.0], 0.5, math.radians(30))
    c.fused['full'] = [wide] * 3
    c.told = [stream(t, xy, 0.5, math.radians(3))] * 3
    assert witness.evaluate(c, WitnessParams())['startup'] == \
        [{'delay_s': math.inf}] * 3
    bounds = witness.startup_bounds(c, WitnessParams())
    for key, off in (('told_heading', 0.0), ('position_only', 1.0)):
        assert [s['delay_s'] for s in bounds[key]] == [15.0] * 3
        assert all(s['m'] == off and s['deg'] == 0 for s in bounds[key])
    assert witness.bounds_line('b0', {'r': bounds}) == (
        'b0: start-up seeds, defaults, told the heading 15-15 s, 0 of 3 off '
        'by > 2 m or 15 deg, at most 0.0 m; any known heading 15-15 s, 0 of '
        '3 off by > 2 m or 15 deg, at most 1.0 m')
    bounds['told_heading'][0] = {'delay_s': math.inf}
    assert ', 1 without a seed;' in witness.bounds_line('b0', {'r': bounds})
