"""
Hindsight without ROS: the filter's past poses carried by odometry.

A kept pose moves with odometry exactly (no noise, its drift turning
it); it wins only when the last scans agree with it, lie far from the
filter and sound like the survey, and is not kept before the heading
has settled, nor with a drift
not known (not fitted) or scans weighed by coverage; the cloud moves
there rigidly. Through
:class:`Fusion`: a scripted drive whose scans lie 5 m aside for a minute
(a twin corridor) drags the pose; once they end, the pose is back within
seconds, not the half minute it takes without.
"""

from dataclasses import replace
import math

import numpy as np
import pytest
from test_fusion_node import odometry_of, square
from wifi_place_recognition.core.filter.fusion import Fusion
from wifi_place_recognition.core.filter.hindsight import (
    Hindsight, MIN_AGE_S, SCANS)
from wifi_place_recognition.core.filter.motion import MotionModel
from wifi_place_recognition.core.filter.particles import (
    Estimate, FusionParams, ParticleFilter)
from wifi_place_recognition.core.filter.pose_spread import SETTLE_SCANS

#: A drift known as fit_odometry writes it.
FITTED = FusionParams(drift_sd=0.005)


def hindsight(**change):
    """Return a Hindsight with FITTED's parameters changed."""
    params = replace(FITTED, **change)
    return Hindsight(params, MotionModel(params))


def estimate(x, y, yaw=0.0, yaw_sd=0.05):
    """Return an :class:`Estimate` at x, y heading ``yaw``."""
    cov = np.diag([1.0, 1.0, yaw_sd ** 2])
    return Estimate(np.array([x, y]), yaw, cov)


def settled(keep_s=120.0, drift=0.0):
    """Return a Hindsight that kept the pose (0, 0, east) at t = 0."""
    h = hindsight(hindsight_s=keep_s)
    for k in range(SETTLE_SCANS):
        h.keep(k - SETTLE_SCANS + 1.0, estimate(0, 0), drift, True)
    assert h.stamps.tolist() == [0.0]
    return h


def test_a_kept_pose_moves_with_odometry_exactly():
    h = settled(drift=0.01)
    h.move(10.0, 0.0, 0.0)          # 10 m ahead: the drift turns 0.1 rad
    x, y, yaw, drift = h.state[0]
    assert yaw == pytest.approx(0.1)
    assert (x, y) == pytest.approx((10 * math.cos(0.05),
                                    10 * math.sin(0.05)))
    h.move(0.0, 0.0, math.pi / 2)
    assert h.state[0, 2] == pytest.approx(0.1 + math.pi / 2)


def test_not_kept_before_the_heading_settled_or_while_it_is_vague():
    h = hindsight()
    for k in range(SETTLE_SCANS - 1):
        h.keep(float(k), estimate(0, 0), 0.0, True)
    assert h.stamps.size == 0
    h.keep(100.0, estimate(0, 0, yaw_sd=math.radians(30)), 0.0, True)
    assert h.stamps.size == 0   # settled, but the heading too vague
    h.keep(101.0, estimate(0, 0), 0.0, False)   # lost: count again
    h.keep(102.0, estimate(0, 0), 0.0, True)
    assert h.stamps.size == 0
    for off in (hindsight(hindsight_s=0.0), hindsight(drift_sd=0.04),
                hindsight(coverage_full=0.5)):
        for k in range(2 * SETTLE_SCANS):
            off.keep(float(k), estimate(0, 0), 0.0, True)
        assert off.stamps.size == 0


def scans_at(h, start, scan_xy, filter_xy, n=SCANS):
    """Check ``n`` scans a second apart from ``start``; the last answer."""
    out = None
    for k in range(n):
        out = h.check(start + k, np.array(scan_xy, float),
                      np.array(filter_xy, float))
    return out


def test_a_kept_pose_wins_when_the_scans_agree_with_it_not_the_filter():
    h = settled()
    # the scans say (0.5, 0): near the kept pose, 5 m from the filter
    assert scans_at(h, 60.0, (0.5, 0.0), (0.5, 5.0)) == pytest.approx(
        (0.0, 0.0, 0.0))
    assert h.stamps.size == 0   # it and the younger are dropped
    # scans near the filter: no win
    h = settled()
    assert scans_at(h, 60.0, (0.5, 4.0), (0.5, 5.0)) is None
    # scans far from both (a kidnap): no win
    h = settled()
    assert scans_at(h, 60.0, (20.0, 0.0), (0.5, 5.0)) is None
    # the filter only 2.5 m off the scans: within hindsight_m, no win
    h = settled()
    assert scans_at(h, 60.0, (0.0, 0.0), (0.0, 2.5)) is None
    # too young, or not enough scans yet
    h = settled()
    assert scans_at(h, MIN_AGE_S - SCANS, (0.5, 0.0), (0.5, 5.0)) is None
    h = settled()
    assert scans_at(h, 60.0, (0.5, 0.0), (0.5, 5.0), SCANS - 1) is None
    # dropped once older than keep_s
    h = settled(keep_s=30.0)
    assert scans_at(h, 60.0, (0.5, 0.0), (0.5, 5.0)) is None
    assert h.stamps.size == 0


def test_no_pose_wins_on_a_scan_that_sounds_unlike_the_survey():
    # inside a hole the scans lie metres aside and may agree with a kept
    # pose by chance: compared, but no pose wins on them
    h = settled()
    for k in range(2 * SCANS):
        assert h.check(60.0 + k, np.array([0.5, 0.0]), np.array([0.5, 5.0]),
                       like_survey=False) is None
    assert h.stamps.size == 1
    # once the last SCANS scans sounded like the survey, the pose wins
    assert scans_at(h, 70.0, (0.5, 0.0), (0.5, 5.0), SCANS - 1) is None
    assert h.check(80.0, np.array([0.5, 0.0]), np.array([0.5, 5.0])) == \
        pytest.approx((0.0, 0.0, 0.0))


def test_the_oldest_pose_wins_and_the_older_ones_are_compared_anew():
    h = settled()                               # (0, 0), kept at 0 s
    h.keep(10.0, estimate(0, 3), 0.0, True)     # (0, 3), kept at 10 s
    h.keep(20.0, estimate(0, 3.2), 0.0, True)   # (0, 3.2), kept at 20 s
    assert h.stamps.tolist() == [0.0, 10.0, 20.0]
    # the scans agree with both younger poses, not with (0, 0): the one
    # kept at 10 s wins, the one kept after it goes, the older stays
    assert scans_at(h, 60.0, (0.0, 3.5), (0.0, 8.0)) == pytest.approx(
        (0.0, 3.0, 0.0))
    assert h.stamps.tolist() == [0.0]
    assert h.seen.tolist() == [0]               # compared anew
    # once the scans agree with it (and not with the moved pose), it wins
    assert scans_at(h, 70.0, (0.0, 0.5), (0.0, 4.0)) == pytest.approx(
        (0.0, 0.0, 0.0))


def test_the_cloud_moves_rigidly_to_a_pose():
    pf = ParticleFilter(FusionParams(particles=500), seed=0)
    pf.start(np.array([10.0, 0.0]), yaw=0.0, sd=1.0, yaw_sd=0.1)
    before = pf.estimate()
    pf.shift((0.0, 5.0), math.pi / 2)
    after = pf.estimate()
    assert after.xy == pytest.approx([0.0, 5.0], abs=1e-9)
    assert after.yaw == pytest.approx(math.pi / 2)
    # the spread turned with it: x and y swap
    assert after.cov[0, 0] == pytest.approx(before.cov[1, 1], rel=1e-3)
    assert after.cov[1, 1] == pytest.approx(before.cov[0, 0], rel=1e-3)


def twin_drive(params, start=40.0, end=100.0, laps=1.7, unlike_s=0.0):
    """
    Return (errors, in the twin, fusion) of a drive round a square.

    Odometry without drift, a scan a second 1 m noisy, 5 m aside (-y)
    from ``start`` to ``end`` s; for ``unlike_s`` s after ``end`` the
    scans' mismatch is twice the usual, the usual after that (not known
    before ``end``, nor with ``unlike_s`` 0).
    """
    fusion = Fusion(params, seed=0)
    truth = square(laps=laps)
    odometry = odometry_of(truth, drift=0.0)
    rng = np.random.default_rng(1)
    errors, twin = [], []
    for i in range(len(truth) - 1):
        fusion.odometry(*odometry[i])
        if i % 10 != 9:
            continue
        fusion.odometry(*odometry[i + 1])       # covers the scan
        t, x, y, _ = truth[i]
        inside = start <= t - truth[0, 0] < end
        scan = np.array([x, y - 5.0 * inside]) + rng.normal(0, 1.0, 2)
        since = t - truth[0, 0] - end
        mismatch = None if since < 0 or not unlike_s else \
            2.0 if since < unlike_s else 1.0
        pose = fusion.scan(t, scan, (0, 0), mismatch=mismatch)[-1]
        errors.append(math.hypot(pose.xy[0] - x, pose.xy[1] - y))
        twin.append(inside)
    return np.array(errors), np.array(twin), fusion


def test_a_pose_dragged_by_a_twin_is_moved_back_to_where_odometry_says():
    errors, twin, fusion = twin_drive(FITTED)
    after = np.flatnonzero(twin)[-1] + 1
    assert errors[after - 1] > 4.0, errors      # dragged
    assert fusion.counts['hindsight_moves'] == 1
    # back within 2 m 5 s after the twin ends; 15 s without hindsight
    assert errors[after:after + 5].min() < 2.0, errors[after:]
    assert errors[after + 5:].max() < 2.0, errors[after:]
    for params in (replace(FITTED, hindsight_s=0), FusionParams()):
        errors, _, fusion = twin_drive(params)      # off; drift not known
        assert fusion.counts['hindsight_moves'] == 0
        assert errors[after:after + 10].min() > 2.0, errors[after:]


def test_no_pose_is_gone_back_to_while_the_scans_sound_unlike_the_survey():
    # the 8 s after the twin sound unlike the survey: the move waits until
    # the last 5 scans sounded like it (the mismatch, averaged over 5
    # scans, clears 4 s after they end), 16 s after the twin (2 s without)
    errors, twin, fusion = twin_drive(FITTED, unlike_s=8.0)
    after = np.flatnonzero(twin)[-1] + 1
    assert fusion.counts['hindsight_moves'] == 1
    assert errors[after:after + 12].min() > 2.0, errors[after:]
    assert errors[after + 17:after + 30].max() < 1.0, errors[after:]


def test_no_pose_to_go_back_to_when_the_twin_comes_before_the_heading():
    # from 10 s on, before the heading settled: every pose kept is dragged
    errors, twin, fusion = twin_drive(FITTED, 10.0, 70.0, 1.5)
    assert fusion.counts['hindsight_moves'] == 0


def test_hindsight_parameters_are_checked():
    with pytest.raises(ValueError, match='hindsight_m = 0'):
        FusionParams(hindsight_m=0)
    with pytest.raises(ValueError, match='hindsight_s = -1'):
        FusionParams(hindsight_s=-1)
