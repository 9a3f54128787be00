"""
Odometry fusion without ROS: the timeline, the filter, the drift fit, files.

The stamp order (a scan waits for the odometry that covers its stamp),
each odometry fault, WiFi alone when odometry stops, the model file's
fusion section, ``fit_odometry`` on a run whose odometry drifts, and pose
CSVs with errors that name the file, row and column.
"""

from dataclasses import replace
import math
import sys

from conftest import python_module, run, surveyed_csv
import numpy as np
import pytest
from test_artifact import _header_and_arrays, _write_npz
from wifi_place_recognition.core.artifact import (_digest, load_model,
                                                  ModelFileError, save_model)
from wifi_place_recognition.core.filter.angles import wrap
from wifi_place_recognition.core.filter.fusion import Fusion, FusionLimits
from wifi_place_recognition.core.filter.odometry_fit import (FitError,
                                                             fit_odometry)
from wifi_place_recognition.core.filter.particles import (
    DISAGREED, FusionParams, ParticleFilter, UNKNOWN_VARIANCE)
from wifi_place_recognition.core.filter.pose_spread import SETTLE_SCANS
from wifi_place_recognition.core.filter.sensor import WifiPosition
from wifi_place_recognition.core.filter.trajectory import (
    dead_reckoning, fuse_offline, odometry_alone, score)
from wifi_place_recognition.data.files import DataError
from wifi_place_recognition.data.poses import read_poses

PLACE = (0, 0)


def straight(n=200, speed=0.5, drift=0.0, yaw=0.3):
    """
    Return (truth, odometry) rows (t, x, y, yaw) of a drive along x, 10 Hz.

    The odometry starts at 0, 0 with heading ``yaw`` and loses ``drift``
    rad per metre.
    """
    t = np.arange(n) * 0.1
    truth = np.column_stack([t, speed * t, np.zeros(n), np.zeros(n)])
    odo = [(0.0, 0.0, 0.0, yaw)]
    for k in range(1, n):
        step = speed * 0.1
        _, x, y, a = odo[-1]
        a2 = a - drift * step
        odo.append((t[k], x + step * math.cos((a + a2) / 2),
                    y + step * math.sin((a + a2) / 2), a2))
    return truth, np.array(odo)


def test_a_scan_waits_for_the_odometry_that_covers_its_stamp():
    fusion = Fusion(seed=0)
    truth, odo = straight(n=30)
    for row in odo[:10]:
        assert fusion.odometry(*row) == (None, [])
    assert fusion.scan(1.05, [0.5, 0.0], PLACE) == []   # odometry at 0.9
    fault, released = fusion.odometry(*odo[10])         # t = 1.0
    assert fault is None and released == []
    fault, released = fusion.odometry(*odo[11])         # t = 1.1: covered
    assert [p.stamp for p in released] == [1.05]
    assert released[0].with_odometry and released[0].restarted
    # scans arriving out of order are applied in stamp order
    for row in odo[12:20]:
        fusion.odometry(*row)
    assert fusion.scan(2.5, [1.2, 0.0], PLACE) == []
    assert fusion.scan(2.2, [1.1, 0.0], PLACE) == []
    released = []
    for row in odo[20:30]:
        released += fusion.odometry(*row)[1]
    assert [p.stamp for p in released] == [2.2, 2.5]


def test_each_odometry_fault_is_counted_and_skipped():
    fusion = Fusion(seed=0)
    assert fusion.odometry(1.0, 0.0, 0.0, 0.0)[0] is None
    assert fusion.odometry(1.1, math.nan, 0.0, 0.0)[0] == 'odometry_invalid'
    assert fusion.odometry(1.1, 0.0, math.inf, 0.0)[0] == 'odometry_invalid'
    assert fusion.odometry(0.5, 0.0, 0.0, 0.0)[0] == 'odometry_out_of_order'
    assert fusion.odometry(1.0, 0.01, 0.0, 0.0)[0] is None     # same stamp
    assert fusion.odometry(1.1, 5.0, 0.0, 0.0)[0] == 'odometry_jump'
    assert fusion.odometry(1.2, 5.0, 0.0, 2.0)[0] == 'odometry_jump'  # turn
    assert fusion.odometry(1.3, 5.05, 0.0, 2.0)[0] is None  # re-anchored
    assert fusion.counts['odometry_invalid'] == 2
    assert fusion.counts['odometry_out_of_order'] == 1
    assert fusion.counts['odometry_same_stamp'] == 1
    assert fusion.counts['odometry_jump'] == 2
    assert fusion.counts['odometry'] == 2


def test_a_jump_in_odometry_does_not_move_the_pose():
    fusion = Fusion(seed=0)
    fusion.odometry(0.0, 0.0, 0.0, 0.0)
    fusion.odometry(0.1, 0.0, 0.0, 0.0)
    [start] = fusion.scan(0.05, [3.0, 4.0], PLACE)
    fusion.odometry(0.2, 0.0, 0.0, 0.0)
    fusion.odometry(0.3, 0.0, 0.0, 0.0)     # reset to zero ...
    fusion.odometry(0.4, -80.0, 35.0, 1.0)  # ... then a jump: skipped
    fusion.odometry(0.5, -80.0, 35.0, 1.0)
    [after] = fusion.scan(0.45, [3.0, 4.0], PLACE)
    assert np.linalg.norm(after.xy - start.xy) < 1.0


def test_without_odometry_scans_are_applied_alone_after_the_timeout():
    fusion = Fusion(limits=FusionLimits(odom_timeout=0.5), seed=0)
    fusion.odometry(0.0, 0.0, 0.0, 0.0)
    fusion.odometry(0.1, 0.0, 0.0, 0.0)
    assert fusion.scan(0.05, [1.0, 1.0], PLACE)      # covered: fused
    assert fusion.scan(3.0, [1.0, 1.0], PLACE, arrival=100.0) == []
    assert fusion.expire(100.4) == []
    [alone] = fusion.expire(100.6)
    assert not alone.with_odometry and alone.stamp == 3.0
    assert fusion.counts['scans_alone'] == 1
    # odometry returns: fused again
    fusion.odometry(3.5, 0.0, 0.0, 0.0)
    fusion.odometry(3.6, 0.1, 0.0, 0.0)
    [back] = fusion.scan(3.55, [1.0, 1.0], PLACE)
    assert back.with_odometry


def test_two_confident_scans_of_another_floor_restart_there():
    fusion = Fusion(seed=0)
    fusion.odometry(0.0, 0.0, 0.0, 0.0)
    fusion.odometry(3.0, 0.0, 0.0, 0.0)
    [first] = fusion.scan(0.5, [0.0, 0.0], (0, 0), confident=False)
    assert first.restarted and fusion.place == (0, 0)   # a start: any scan
    # another floor: unconfident, then confident once: not applied
    for stamp, confident in ((1.0, False), (1.5, True), (2.0, False),
                             (2.5, True)):
        [kept] = fusion.scan(stamp, [20.0, 0.0], (0, 1), confident)
        assert not kept.restarted and fusion.place == (0, 0)
        assert np.linalg.norm(kept.xy) < 3.0
    assert fusion.counts['scans_other_place'] == 4
    [moved] = fusion.scan(2.8, [20.0, 0.0], (0, 1))    # twice in a row
    assert moved.restarted and fusion.place == (0, 1)
    assert np.linalg.norm(moved.xy - [20.0, 0.0]) < 3.0
    assert moved.cov[2, 2] == 1e6           # a start: the heading unknown
    assert fusion.scan(2.9, [math.nan, 0.0], (0, 1)) is None
    assert fusion.counts['scans_without_position'] == 1


def test_each_pose_carries_the_place_the_filter_was_on_for_it():
    fusion = Fusion(seed=0)
    fusion.odometry(0.0, 0.0, 0.0, 0.0)
    fusion.odometry(1.0, 0.0, 0.0, 0.0)
    [start] = fusion.scan(0.5, [0.0, 0.0], (0, 0))
    assert start.place == (0, 0)
    # two scans of floor 1 before the odometry covering them: one batch
    assert fusion.scan(1.5, [20.0, 0.0], (0, 1)) == []
    assert fusion.scan(2.5, [20.0, 0.0], (0, 1)) == []
    still, moved = fusion.odometry(2.6, 0.0, 0.0, 0.0)[1]
    assert (still.place, still.restarted) == ((0, 0), False)
    assert (moved.place, moved.restarted) == ((0, 1), True)
    assert fusion.pose().place == (0, 1)


def test_a_long_gap_without_odometry_starts_afresh_and_a_short_one_spreads():
    fusion = Fusion(limits=FusionLimits(odom_timeout=0.5), seed=0)
    truth, odo = straight(n=600)
    at = np.arange(5, 600, 10)
    xy, yaw, cov = fuse_offline(odo, (truth[at, 0] + 0.01,
                                      truth[at, 1:3]), fusion)
    assert cov[-1, 2, 2] < 0.1                         # heading found
    t = truth[-1, 0]
    assert fusion.scan(t + 2.0, truth[-1, 1:3], PLACE, arrival=0.0) == []
    assert fusion.expire(0.4) == []
    [short] = fusion.expire(0.6)
    assert not short.restarted and short.cov[2, 2] > cov[-1, 2, 2]
    fusion.scan(t + 60.0, truth[-1, 1:3], PLACE, arrival=1.0)
    [long] = fusion.expire(2.0)
    assert long.restarted and long.cov[2, 2] == 1e6


def test_a_clock_that_restarts_starts_a_new_odometry_timeline():
    fusion = Fusion(seed=0)
    truth, odo = straight(n=300)
    at = np.arange(5, 300, 10)
    fuse_offline(odo, (truth[at, 0] + 0.01, truth[at, 1:3]), fusion)
    before = fusion.counts['scans_fused']
    # the clock goes back 100 s for good; the robot drives on 10 m
    later = odo[-1, 1:] + np.column_stack([np.arange(1, 201) * 0.05,
                                           np.zeros((200, 2))])
    stamps = odo[-1, 0] - 100.0 + np.arange(1, 201) * 0.1
    faults = [fusion.odometry(t, *pose)[0] for t, pose in
              zip(stamps, later)]
    assert faults[0] == 'odometry_clock_reset' and not any(faults[1:])
    [after] = fusion.scan(stamps[-2], [truth[-1, 1] + 10.0, 0.0], PLACE)
    assert fusion.counts['scans_fused'] == before + 1
    assert abs(after.xy[0] - truth[-1, 1] - 10.0) < 2.0


def test_the_timeline_s_three_limits_act_apart():
    # clock_reset alone decides when a stamp back is a new timeline
    fusion = Fusion(limits=FusionLimits(odom_timeout=5.0, clock_reset=0.5))
    fusion.odometry(10.0, 0.0, 0.0, 0.0)
    assert fusion.odometry(9.8, 0.0, 0.0, 0.0)[0] == 'odometry_out_of_order'
    assert fusion.odometry(9.0, 0.0, 0.0, 0.0)[0] == 'odometry_clock_reset'
    # move_lag alone decides how far behind the newest odometry the
    # particles stay between scans
    for lag in (0.5, 3.0):
        fusion = Fusion(limits=FusionLimits(move_lag=lag), seed=0)
        truth, odo = straight(n=100)
        fusion.odometry(*odo[0])
        fusion.scan(0.0, [0.0, 0.0], PLACE)
        for row in odo[1:]:
            fusion.odometry(*row)
        assert abs(fusion.anchor[0] - (odo[-1, 0] - lag)) <= 1.0 + 1e-9, \
            (lag, fusion.anchor[0])


def test_the_filter_finds_the_heading_and_follows_a_drifting_odometry():
    """Odometry losing 2 degrees per metre; scans with 1 m noise."""
    drift = math.radians(2.0)
    truth, odo = straight(n=1200, drift=drift)
    rng = np.random.default_rng(1)
    at = np.arange(5, 1200, 10)
    stamps = truth[at, 0] + 0.01
    scans = truth[at, 1:3] + rng.normal(0, 1.0, (len(at), 2))
    late = slice(len(at) // 2, None)
    single = np.linalg.norm(scans - truth[at, 1:3], axis=1)[late].mean()
    for params, share in ((FusionParams(), 0.8),     # drift unknown
                          (FusionParams(drift_mean=drift, drift_sd=0.005),
                           0.3)):                     # drift fitted
        xy, yaw, cov = fuse_offline(odo, (stamps, scans),
                                    Fusion(params, seed=0))
        error = np.linalg.norm(xy - truth[at, 1:3], axis=1)
        assert error[late].mean() < share * single, (params, share)
    assert np.degrees(np.abs(wrap(yaw[late]))).max() < 5
    figures = score(stamps, truth[at, 1:3], xy, truth[at, 3], yaw, cov)
    assert 0.8 <= figures['in_95_ellipse'] <= 1.0


def test_the_pose_lies_on_the_ring_a_start_spreads_not_inside_it():
    """
    A start with every heading, then 10 m straight ahead.

    The particles lie on a ring of 10 m round the start, each heading
    away from it; the scans favour those heading near 0 (weights of a
    von Mises of concentration 0.5: the heading still unknown). The
    robot is at (10, 0): the mean of every particle lies about 2.4 m from
    the start, the pose on the ring's heavier side.
    """
    pf = ParticleFilter(FusionParams(), seed=0)
    pf.start([0.0, 0.0])
    pf.move(10.0, 0.0, 0.0)
    pf.weight = np.exp(0.5 * np.cos(pf.state[:, 2]))
    pf.weight /= pf.weight.sum()
    estimate = pf.estimate()
    assert estimate.cov[2, 2] == UNKNOWN_VARIANCE
    assert np.linalg.norm(pf.position()[0]) < 3.0      # inside the ring
    assert np.linalg.norm(estimate.xy - [10.0, 0.0]) < 2.5, estimate.xy
    spread = np.linalg.norm(pf.state[:, :2] - estimate.xy, axis=1)
    assert np.trace(estimate.cov[:2, :2]) == \
        pytest.approx(pf.weight @ spread ** 2)
    # no particle heads within the window of the mean heading: all count
    pf.state[:, :2] = [[0.0, 5.0], [0.0, -5.0]] * (len(pf.weight) // 2)
    pf.state[:, 2] = [math.pi / 2, -math.pi / 2] * (len(pf.weight) // 2)
    pf.weight[:] = 1.0 / len(pf.weight)
    assert np.allclose(pf.estimate().xy, [0.0, 0.0])


def test_the_pose_is_as_sure_as_the_last_scans_lie_near_it():
    """
    A drive with scans of 1 m noise; from 60 s on they lie 6 m aside.

    Once 30 scans were applied with the heading known, x and y each have
    the variance of the last ten scans' mean offset from the pose (the
    particles' spread before, and with ``pose_scans`` 0); scans that move
    off make it wider; with odometry alone it grows as the particles
    spread.
    """
    truth, odo = straight(n=1200)
    at = np.arange(5, 1200, 10)
    stamps = truth[at, 0] + 0.01
    scans = truth[at, 1:3] + np.random.default_rng(2).normal(0, 1.0,
                                                             (len(at), 2))
    scans[stamps > 60] += [0.0, 6.0]
    xy, _, cov = fuse_offline(odo, (stamps, scans), Fusion(seed=0))
    known = np.flatnonzero(cov[:, 2, 2] < UNKNOWN_VARIANCE)
    assert 0 < known[0] < 30, known[0]
    assert cov[known[0] - 1, 2, 2] == UNKNOWN_VARIANCE
    settled = known[0] + SETTLE_SCANS - 1
    assert cov[settled - 1, 0, 1] != 0.0     # the particles' spread
    offsets = scans - xy
    for i in range(settled, len(at)):
        mean = offsets[i - 9:i + 1].mean(axis=0)
        assert cov[i, 0, 0] == cov[i, 1, 1] == pytest.approx(mean @ mean)
        assert cov[i, 0, 1] == cov[i, 0, 2] == cov[i, 1, 2] == 0.0
    aside = stamps > 60
    assert np.sqrt(cov[aside, 0, 0]).max() > \
        2 * np.sqrt(cov[settled:][~aside[settled:], 0, 0]).max()
    cloud = fuse_offline(odo, (stamps, scans),
                         Fusion(FusionParams(pose_scans=0), seed=0))[2]
    assert cloud[known[0], 0, 1] != 0.0     # the particles' own
    assert not np.allclose(cloud[known[-1]], cov[known[-1]])
    # odometry alone after the last scan: the spread the particles gain
    fusion = Fusion(seed=0)
    fuse_offline(odo[:1000], (stamps[:90], scans[:90]), fusion)
    for row in odo[1000:]:
        fusion.odometry(*row)
    gained = np.trace(fusion.filter.estimate().cov[:2, :2]) / 2 - \
        fusion.spread
    assert gained > 0.1
    assert fusion.pose().cov[0, 0] == \
        pytest.approx(fusion.offsets.variance() + gained)


def test_a_young_filter_is_at_least_as_wide_as_its_scans_offsets():
    """
    Scans 8 m aside from just after the heading is found: it follows them.

    Until the filter has settled, the covariance is the particles', but
    at least the variance the last 10 scans' offsets say (the cloud
    alone is narrower there), widened alike on x and y.
    """
    truth, odo = straight(n=1200)
    at = np.arange(5, 1200, 10)
    stamps = truth[at, 0] + 0.01
    scans = truth[at, 1:3] + np.random.default_rng(2).normal(0, 1.0,
                                                             (len(at), 2))
    cov = fuse_offline(odo, (stamps, scans), Fusion(seed=0))[2]
    known = np.flatnonzero(cov[:, 2, 2] < UNKNOWN_VARIANCE)[0]
    scans[known + 1:known + 40] += [0.0, 8.0]
    xy, _, cov = fuse_offline(odo, (stamps, scans), Fusion(seed=0))
    assert np.flatnonzero(cov[:, 2, 2] < UNKNOWN_VARIANCE)[0] == known
    cloud = fuse_offline(odo, (stamps, scans),
                         Fusion(FusionParams(pose_scans=0), seed=0))[2]
    offsets = scans - xy
    young = range(known + 9, known + SETTLE_SCANS - 1)
    widened = 0
    for i in young:
        mean = offsets[i - 9:i + 1].mean(axis=0)
        variance = np.trace(cov[i, :2, :2]) / 2
        assert variance >= mean @ mean - 1e-9
        if variance > np.trace(cloud[i, :2, :2]) / 2 + 1e-9:
            widened += 1
            assert variance == pytest.approx(mean @ mean)
            assert cov[i, 0, 0] - cloud[i, 0, 0] == \
                pytest.approx(cov[i, 1, 1] - cloud[i, 1, 1])
            np.testing.assert_allclose(cov[i, 2], cloud[i, 2])
    assert widened >= 10
    assert cov[young[0] - 1] == pytest.approx(cloud[young[0] - 1])
    assert cov[young[-1] + 1, 0, 1] == 0.0     # settled: the offsets'


def test_a_kidnapped_robot_restarts_with_the_scans_that_disagreed():
    """
    Carried 30 m aside at 60 s, odometry none the wiser; scans 0.5 m noise.

    The filter starts afresh at the first of the ten scans that kept
    disagreeing and applies them again with the odometry between them:
    ten scans on, it is within 1.2 m (starting at the tenth alone, with
    every heading: about 2.3 m).
    """
    truth, odo = straight(n=1200)
    at = np.arange(5, 1200, 10)
    stamps = truth[at, 0] + 0.01
    true_xy = truth[at, 1:3] + np.where(stamps[:, None] > 60, [0, 30.0], 0)
    scans = true_xy + np.random.default_rng(0).normal(0, 0.5, (len(at), 2))
    fusion = Fusion(seed=0)
    poses, j, before = [], 0, None
    for row in odo:
        while j < len(at) and stamps[j] <= row[0]:
            if before is None and stamps[j] > 60:
                before = fusion.filter.most_disagreeing
            poses += fusion.scan(stamps[j], scans[j], PLACE)
            j += 1
        poses += fusion.odometry(*row)[1]
    restarts = [i for i, pose in enumerate(poses) if pose.restarted]
    assert [round(poses[i].stamp) for i in restarts] == [1, 70]
    assert fusion.counts['scans_replayed'] == 10
    # how near the filter came to a restart: before the kidnap, not near;
    # after it, all the way
    assert before == 0
    assert fusion.filter.most_disagreeing == fusion.filter.params.reset_after
    i = restarts[1] + 10
    assert np.linalg.norm(poses[i].xy - true_xy[i]) < 1.2, poses[i].xy


def test_a_set_pose_starts_the_filter_with_its_heading_carried_by_odometry():
    """
    A pose known otherwise (a dock's): heading included, at its stamp.

    Set at 1.0 s while odometry runs to 2.0 s (the robot drove 0.5 m
    along x): the filter starts there, carried by the motion since; a
    scan still waiting from before a later one is dropped; bad values
    are refused.
    """
    fusion = Fusion(seed=0)
    truth, odo = straight(n=60)         # true heading 0, odometry's 0.3
    for row in odo[:21]:                # to 2.0 s
        fusion.odometry(*row)
    fusion.set_pose(1.0, [0.5, 0.0], 0.0, 0.1, math.radians(2), PLACE)
    assert fusion.counts['set_pose'] == 1
    pose = fusion.pose()
    assert np.allclose(pose.xy, [1.0, 0.0], atol=0.05), pose.xy
    assert abs(pose.yaw) < math.radians(1) and pose.cov[2, 2] < 0.01
    assert pose.place == PLACE
    assert fusion.scan(2.05, [9.0, 9.0], PLACE) == []     # waits
    fusion.set_pose(2.1, [1.05, 0.0], 0.0, 0.1, math.radians(2), PLACE)
    assert fusion.counts['scans_before_set_pose'] == 1
    assert fusion.pending == []
    for name, args in (('stamp', (math.nan, [0, 0], 0, 0.1, 0.1)),
                       ('yaw', (1.0, [0, 0], math.inf, 0.1, 0.1)),
                       ('position', (1.0, [0, math.nan], 0, 0.1, 0.1)),
                       ('sd', (1.0, [0, 0], 0, -1.0, 0.1)),
                       ('yaw_sd', (1.0, [0, 0], 0, 0.1, math.nan))):
        with pytest.raises(ValueError, match=name):
            fusion.set_pose(*args, PLACE)
    assert fusion.counts['set_pose'] == 2
    # a heading not known: every heading, round the set position
    fusion.set_pose(2.1, [5.0, 5.0], None, 0.1, 0.0, PLACE)
    estimate = fusion.filter.estimate()
    assert np.allclose(estimate.xy, [5.0, 5.0], atol=0.05)
    assert estimate.cov[2, 2] == UNKNOWN_VARIANCE


def test_scans_that_keep_disagreeing_restart_the_filter_now_and_then_near():
    """
    Scans 20 m off, every third one near: ten of the last thirty restart.

    What a robot carried away sees when its scans are noisy, or some are
    widened by their misfit or mismatch: a scan now and then near enough
    does not start the count again (``reset_window``); with a window of
    ``reset_after`` (ten in a row) they never restart it, nor without the
    scans' mismatch (the scans of a hole disagree now and then too).
    """
    def restarts(params, mismatch=1.0):
        far = WifiPosition(np.array([20.0, 0.0]), misfit=1.0,
                           mismatch=mismatch)
        near = replace(far, xy=np.array([1.0, 0.0]))
        scans = [near if i % 3 == 2 else far for i in range(30)]
        pf = ParticleFilter(params, seed=0)
        pf.start(np.zeros(2), sd=0.5)
        why = [pf.update(scan) for scan in scans]
        return [i for i, w in enumerate(why) if w == DISAGREED], pf

    params = FusionParams()
    assert params.reset_window == 30 and params.reset_after == 10
    at, pf = restarts(params)
    assert at == [13]       # the tenth far scan, the fourteenth
    assert pf.most_disagreeing == params.reset_after
    at, pf = restarts(FusionParams(reset_window=10))
    assert at == [] and pf.most_disagreeing == 7    # of ten, at most
    for unknown in (dict(mismatch=None), dict(params=FusionParams(
            mismatch_scans=0))):
        at, pf = restarts(**{'params': params, **unknown})
        assert at == [] and pf.most_disagreeing == 2    # in a row


def test_a_set_pose_before_any_odometry_is_anchored_at_its_stamp():
    """
    Set at 0 s, odometry from 0 s, the first scan at 2.45 s.

    The motion before that scan counts too: the pose is given from the
    first odometry on, not from the first scan.
    """
    fusion = Fusion(seed=0)
    fusion.set_pose(0.0, [3.0, 4.0], math.pi / 2, 0.2, 0.05, PLACE)
    truth, odo = straight(n=40, yaw=0.0)    # drives 1.95 m ahead
    released = []
    for row in odo[:11]:
        released += fusion.odometry(*row)[1]
    pose = fusion.pose()    # 0.5 m along the set heading (+y), not from x
    assert np.allclose(pose.xy, [3.0, 4.5], atol=0.1), pose.xy
    released += fusion.scan(2.45, [3.0, 5.225], PLACE) or []
    for row in odo[11:]:
        released += fusion.odometry(*row)[1]
    assert [p.restarted for p in released] == [False]
    pose = fusion.pose()
    assert np.allclose(pose.xy, [3.0, 5.95], atol=0.3), pose.xy
    assert abs(wrap(pose.yaw - math.pi / 2)) < math.radians(3)


def test_fusion_parameters_are_checked_and_kept_in_the_model_file(
        tmp_path, surveyed_model):
    with pytest.raises(ValueError, match='wifi_sd = 0'):
        FusionParams(wifi_sd=0)
    with pytest.raises(ValueError, match='particles = 2.5'):
        FusionParams(particles=2.5)
    for bad in (-1, 2.5, 10 ** 5):
        with pytest.raises(ValueError, match=f'pose_scans = {bad}'):
            FusionParams(pose_scans=bad)
    with pytest.raises(ValueError, match='heading_noise = nan'):
        FusionParams(heading_noise=math.nan)
    with pytest.raises(ValueError, match='reset_after = 12, reset_window = '
                       '11: expected reset_window >= reset_after'):
        FusionParams(reset_after=12, reset_window=11)
    with pytest.raises(ValueError, match='unknown fusion parameter'):
        FusionParams.from_dict({'wifi_sigma': 3})
    model = load_model(surveyed_model)
    assert model.fusion is None
    model.fusion = FusionParams(drift_mean=-0.02, fit={'windows': 4})
    save_model(model, tmp_path / 'fused.npz')
    again = load_model(tmp_path / 'fused.npz')
    assert again.fusion == model.fusion
    # the file keeps what differs from the defaults
    assert model.fusion.to_dict() == {'drift_mean': -0.02,
                                      'fit': {'windows': 4}}
    header, arrays = _header_and_arrays(tmp_path / 'fused.npz')
    header.pop('sha256')
    header['fusion'] = {'drift_mean': 'a lot'}
    header['sha256'] = _digest(header, {k: v for k, v in arrays.items()
                                        if k != 'header'})
    with pytest.raises(ModelFileError, match='fusion section: fusion '
                                             'parameter drift_mean'):
        load_model(_write_npz(tmp_path / 'bad.npz', header, arrays))


def test_fit_odometry_finds_the_drift():
    truth, odo = straight(n=1500, drift=math.radians(1.4))
    # a run that turns: the truth turns, the odometry turns less
    at = np.arange(0, 1500, 10)
    params, report = fit_odometry(odo, truth[at, 0], truth[at, 1:3],
                                  truth[at, 3])
    assert report['drift_deg_per_m'] == pytest.approx(1.4, abs=0.05)
    assert params.drift_mean == pytest.approx(math.radians(1.4), abs=1e-3)
    assert params.fit['windows'] == report['windows']
    with pytest.raises(FitError, match='covers 1.0 m'):
        fit_odometry(odo[:21], truth[:21:10, 0], truth[:21:10, 1:3],
                     truth[:21:10, 3])
    with pytest.raises(FitError, match='finite'):
        fit_odometry(np.full((5, 4), np.nan), truth[at, 0], truth[at, 1:3],
                     truth[at, 3])


def turning(n=3000, drift=math.radians(1.4), turn_at=(100.0, 130.0),
            rate=None):
    """
    Return (truth, odometry) of a drive at 0.5 m/s, 10 Hz, that turns.

    The truth turns 270 degrees between ``turn_at`` seconds (or at ``rate``
    rad/s, one per row); the odometry starts at 0, 0 with another heading
    and loses ``drift`` rad per metre.
    """
    t = np.arange(n) * 0.1
    if rate is None:
        rate = np.where((t > turn_at[0]) & (t <= turn_at[1]),
                        1.5 * math.pi / (turn_at[1] - turn_at[0]), 0.0)
    yaw = np.cumsum(rate * 0.1)
    odo_yaw = yaw + 0.3 - drift * 0.05 * np.arange(n)

    def path(heading):
        return np.concatenate([[0.0], np.cumsum(0.05 * heading[1:])])
    truth = np.column_stack([t, path(np.cos(yaw)), path(np.sin(yaw)),
                             wrap(yaw)])
    odo = np.column_stack([t, path(np.cos(odo_yaw)), path(np.sin(odo_yaw)),
                           wrap(odo_yaw)])
    return truth, odo


def test_fit_odometry_follows_a_spin_between_slow_scans():
    # a turn of 270 degrees in 3 s, with a scan every 3 s: the true yaw
    # alone cannot tell a spin of 4.7 rad from one of -1.6 rad
    truth, odo = turning(turn_at=(100.0, 103.0))
    at = np.arange(5, len(truth), 30)
    report = fit_odometry(odo, truth[at, 0], truth[at, 1:3], truth[at, 3])[1]
    assert report['drift_deg_per_m'] == pytest.approx(1.4, abs=0.05)


def test_fit_odometry_refuses_a_yaw_not_in_radians():
    # weaving gently left and right (under 0.2 rad between two scans),
    # back to the start heading, with a small drift: in degrees, the net
    # turn looks like a drift of 17 deg per m; mirrored, like none
    t = np.arange(2400) * 0.1
    truth, odo = turning(n=2400, drift=math.radians(0.3),
                         rate=0.15 * np.sin(2 * math.pi * t / 40))
    at = np.arange(0, len(truth), 10)
    fitted = fit_odometry(odo, truth[at, 0], truth[at, 1:3], truth[at, 3])
    assert fitted[1]['drift_deg_per_m'] == pytest.approx(0.3, abs=0.05)
    degrees = odo.copy()
    degrees[:, 3] = np.degrees(odo[:, 3])
    with pytest.raises(FitError, match=r'^odometry: in the \d+ stretches '
                                       r'of 3 m of the scans in which it or '
                                       r'the truth turns 0.2 rad or more, '
                                       r'its turn \(the fitted drift added '
                                       r'back\) differs from the true one by '
                                       r'[\d.]+ deg \(median\): not this '
                                       r'run.s odometry, or a yaw not in '
                                       r'radians'):
        fit_odometry(degrees, truth[at, 0], truth[at, 1:3], truth[at, 3],
                     names=('the scans', 'odometry'))
    mirrored = odo.copy()           # clockwise yaw
    mirrored[:, 3] = -odo[:, 3]
    with pytest.raises(FitError, match=r'deg \(median\): the two turn '
                                       r'opposite ways \(one yaw is '
                                       r'clockwise; REP 103'):
        fit_odometry(mirrored, truth[at, 0], truth[at, 1:3], truth[at, 3])


def test_fit_odometry_does_not_judge_turns_across_an_odometry_gap():
    # the odometry lost for 5 s while the robot turns 270 degrees in 3 s:
    # across the gap its turn is interpolated, unlike the truth's
    truth, odo = turning(turn_at=(100.0, 103.0))
    at = np.arange(0, len(truth), 10)
    lost = odo[(odo[:, 0] < 99.0) | (odo[:, 0] > 104.0)]
    report = fit_odometry(lost, truth[at, 0], truth[at, 1:3],
                          truth[at, 3])[1]
    assert report['drift_deg_per_m'] == pytest.approx(1.4, abs=0.05)
    assert report['windows_across_odometry_gaps'] == 2


def test_fit_odometry_leaves_out_the_stretches_across_an_odometry_gap():
    truth, odo = turning()
    at = np.arange(0, len(truth), 10)
    whole = fit_odometry(odo, truth[at, 0], truth[at, 1:3], truth[at, 3])[1]
    assert whole['drift_deg_per_m'] == pytest.approx(1.4, abs=0.05)
    # 40 s of odometry lost while the robot turns 270 degrees
    lost = odo[(odo[:, 0] < 95.0) | (odo[:, 0] > 135.0)]
    params, report = fit_odometry(lost, truth[at, 0], truth[at, 1:3],
                                  truth[at, 3])
    assert report['drift_deg_per_m'] == pytest.approx(1.4, abs=0.05)
    assert whole['windows_across_odometry_gaps'] == 0
    assert report['windows_across_odometry_gaps'] == 7   # 20 m: 7 of 3 m
    assert report['windows'] == whole['windows'] - 7 == params.fit['windows']
    assert report['odometry_distance_ratio'] == pytest.approx(1.0, abs=1e-3)
    # a gap within the node's default odom_timeout (1 s) is bridged, a
    # longer one is not
    for drop, across in (((99.95, 100.75), 0), ((99.95, 100.95), 1)):
        gap = odo[(odo[:, 0] < drop[0]) | (odo[:, 0] > drop[1])]
        assert round(np.diff(gap[:, 0]).max(), 6) == 0.9 + 0.2 * across
        assert fit_odometry(gap, truth[at, 0], truth[at, 1:3], truth[at, 3]
                            )[1]['windows_across_odometry_gaps'] == across


def test_fit_errors_name_the_files_and_both_time_spans():
    truth, odo = turning(n=600)
    at = np.arange(0, 600, 10)
    names = ('run/scans.csv', 'run/odom.csv')
    restamped = odo.copy()
    restamped[:, 0] += 1000.0
    with pytest.raises(FitError) as error:
        fit_odometry(restamped, truth[at, 0], truth[at, 1:3], truth[at, 3],
                     names=names)
    assert str(error.value) == (
        "run/scans.csv: the run covers 0.0 m with a true pose inside the "
        "odometry's time span: run/odom.csv spans 1000.000 to 1059.900 s "
        "(59.9 s), the posed scans 0.000 to 59.000 s (59.0 s), 60 of them "
        "outside; fitting needs 3 stretches of 3 m")
    with pytest.raises(FitError, match='^run/odom.csv: need two or more'):
        fit_odometry(odo[:1], truth[at, 0], truth[at, 1:3], truth[at, 3],
                     names=names)
    gapped = odo[(odo[:, 0] < 10.0) | (odo[:, 0] > 50.0)]
    with pytest.raises(FitError, match='8 stretch.es. across an odometry '
                                       'gap longer than 1 s left out'):
        fit_odometry(gapped, truth[at, 0], truth[at, 1:3], truth[at, 3],
                     names=names)


def test_odometry_alone_is_nan_outside_the_odometry_and_starts_inside():
    truth, odo = straight(n=600)
    stamps = truth[::10, 0]
    middle = odo[(odo[:, 0] >= 20.0) & (odo[:, 0] <= 40.0)]
    first = int(np.searchsorted(stamps, 20.0))
    xy, yaw = dead_reckoning(middle, stamps, truth[first * 10, 1:3],
                             truth[first * 10, 3], stamps[first])
    inside = (stamps >= 20.0) & (stamps <= 40.0)
    assert np.isnan(xy[~inside]).all() and np.isnan(yaw[~inside]).all()
    np.testing.assert_allclose(xy[inside], truth[::10][inside, 1:3],
                               atol=1e-6)
    with pytest.raises(ValueError, match='^dead reckoning from 0.000 s: '
                                         'outside the odometry.s time span '
                                         '20.000 to 40.000 s'):
        dead_reckoning(middle, stamps, truth[0, 1:3], truth[0, 3], stamps[0])
    # odometry alone (replay_run, benchmarks/fusion.py) starts at the first
    # true pose inside the odometry, not at the run's first scan
    true_xy, true_yaw = truth[::10, 1:3].copy(), truth[::10, 3].copy()
    true_xy[first] = np.nan                     # no true pose at 20 s
    alone_xy, alone_yaw = odometry_alone(middle, stamps, true_xy, true_yaw)
    np.testing.assert_allclose(alone_xy, xy, atol=1e-6)
    assert np.isnan(alone_yaw[~inside]).all()
    assert np.isnan(odometry_alone(middle, stamps[:first], true_xy[:first],
                                   true_yaw[:first])[0]).all()


def test_pose_files_name_what_is_wrong(tmp_path):
    good = tmp_path / 'odom.csv'
    good.write_text('TIMESTAMP,X,Y,YAW\n1.0,0,0,0.5\n1.1,0.1,0,0.5\n')
    assert read_poses(good).tolist() == [[1.0, 0, 0, 0.5],
                                         [1.1, 0.1, 0, 0.5]]
    cases = {'TIMESTAMP,X,Y\n1,2,3\n': 'no column.s. YAW',
             'TIMESTAMP,X,Y,YAW\n1,2,,3\n': "row 2, column Y: value ''",
             'TIMESTAMP,X,Y,YAW\n1,2,3,nan\n': 'row 2, column YAW',
             'TIMESTAMP,X,Y,YAW\n2,0,0,0\n1,0,0,0\n':
                 'row 3, column TIMESTAMP: 1.0 is earlier',
             'TIMESTAMP,X,Y,YAW\n1,2,3\n': 'row 2 has 3 fields',
             'TIMESTAMP,X,Y,YAW\n': 'no poses'}
    for text, message in cases.items():
        bad = tmp_path / 'bad.csv'
        bad.write_text(text)
        with pytest.raises(DataError, match=message):
            read_poses(bad)
    with pytest.raises(DataError, match='cannot read'):
        read_poses(tmp_path / 'missing.csv')


def test_fit_odometry_command_writes_the_fusion_section(tmp_path,
                                                        surveyed_model):
    truth, odo = straight(n=1500, drift=math.radians(-1.0))
    np.savetxt(tmp_path / 'odom.csv', odo, delimiter=',',
               header='TIMESTAMP,X,Y,YAW', comments='', fmt='%.6f')
    survey = surveyed_csv(tmp_path / 'survey.csv', scans_per_floor=150,
                          floors=(0,))
    lines = survey.read_text().splitlines()
    at = np.arange(0, 1500, 10)
    header = lines[0] + ',TIMESTAMP,YAW'
    rows = [line + f',{truth[i, 0]:.3f},{truth[i, 3]:.4f}'
            for line, i in zip(lines[1:], at)]
    # X, Y of the run: the truth (surveyed_csv's X, Y replaced)
    cols = header.split(',')
    x, y = cols.index('X'), cols.index('Y')
    fixed = []
    for row, i in zip(rows, at):
        cells = row.split(',')
        cells[x], cells[y] = f'{truth[i, 1]:.3f}', f'{truth[i, 2]:.3f}'
        fixed.append(','.join(cells))
    scans = tmp_path / 'scans.csv'
    scans.write_text('\n'.join([header] + fixed) + '\n')
    out = tmp_path / 'fitted.npz'
    result = run(python_module('cli.fit_odometry', '--model', surveyed_model,
                               '--data', scans, '--odometry',
                               tmp_path / 'odom.csv', '-o', out))
    assert result.returncode == 0, result.stderr
    assert 'heading drift -1.000 deg/m' in result.stdout
    assert load_model(out).fusion.drift_mean == pytest.approx(
        math.radians(-1.0), abs=1e-4)
    # bad input: one error line, exit 2, nothing written
    no_yaw = tmp_path / 'no_yaw.csv'
    no_yaw.write_text(survey.read_text())
    for args, message in (
            (['--data', no_yaw, '--odometry', tmp_path / 'odom.csv'],
             'needs TIMESTAMP, X, Y and YAW'),
            (['--data', scans, '--odometry', survey],
             'no column(s) TIMESTAMP, YAW'),
            (['--data', scans, '--odometry', tmp_path / 'none.csv'],
             'cannot read')):
        bad = run(python_module('cli.fit_odometry', '--model',
                                surveyed_model, *args, '-o',
                                tmp_path / 'x.npz'))
        assert bad.returncode == 2 and message in bad.stderr, bad.stderr
        assert 'Traceback' not in bad.stderr
        assert not (tmp_path / 'x.npz').exists()


def test_numpy_random_is_imported_only_when_the_filter_starts():
    # about 2 MiB of the node's RSS with fusion off
    # (benchmarks/fusion_cost.py)
    code = ('import sys\n'
            'from wifi_place_recognition.core.filter.fusion import Fusion\n'
            'fusion = Fusion()\n'
            'fusion.odometry(1.0, 0.0, 0.0, 0.0)\n'
            'print("numpy.random" in sys.modules)\n'
            'fusion.scan(1.0, (0.0, 0.0), (0, 0))\n'
            'print(fusion.filter.started, "numpy.random" in sys.modules)\n')
    done = run([sys.executable, '-c', code])
    assert done.stdout.split() == ['False', 'True', 'True'], done.stderr
