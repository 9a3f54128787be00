"""
Scans that odometry says the robot cannot have produced (no ROS).

Where the survey has no scan, the k-NN positions snap to the nearest
surveyed stretch, or jump, for tens of seconds while the robot drives
on: :class:`TrackMisfit` sees it, the sensor model trusts those scans
less, and the pose follows odometry; a kidnapped robot still restarts.
"""

from dataclasses import replace
import math

import numpy as np
import pytest
from wifi_place_recognition.core.filter.fusion import Fusion
from wifi_place_recognition.core.filter.mismatch import (RecentMismatch,
                                                         UnlikeRun)
from wifi_place_recognition.core.filter.particles import (DISAGREED,
                                                          FusionParams,
                                                          ParticleFilter)
from wifi_place_recognition.core.filter.sensor import (WifiPosition,
                                                       WifiSensorModel)
from wifi_place_recognition.core.filter.track_misfit import TrackMisfit
from wifi_place_recognition.core.filter.trajectory import fuse_offline

SPEED = 0.5     # m/s


def drive(seconds=240.0):
    """
    Return (odometry rows at 10 Hz, scan stamps at 1 Hz, true xy).

    East for half the time, a quarter turn left in 10 s, then north;
    odometry exact, in a frame turned from the map's.
    """
    t = np.arange(0.0, seconds + 0.05, 0.1)
    yaw = np.clip((t - seconds / 2) / 10.0, 0.0, 1.0) * math.pi / 2
    step = np.diff(t, prepend=0.0) * SPEED
    x = np.cumsum(step * np.cos(yaw))
    y = np.cumsum(step * np.sin(yaw))
    turn = 2.0      # the odometry frame's heading in the map
    c, s = math.cos(turn), math.sin(turn)
    odometry = np.column_stack([t, c * x - s * y, s * x + c * y, yaw + turn])
    stamps = np.arange(0.5, seconds, 1.0)
    truth = np.column_stack([np.interp(stamps, t, x),
                             np.interp(stamps, t, y)])
    return odometry, stamps, truth


def noisy(truth, seed=0, sd=1.0):
    """Return scans around the truth (independent errors of ``sd`` m)."""
    return truth + np.random.default_rng(seed).normal(0, sd, truth.shape)


def test_the_misfit_is_small_for_scans_that_follow_the_robot():
    odometry, stamps, truth = drive()
    track = TrackMisfit(30.0)
    rotated = truth @ np.array([[0.0, 1.0], [-1.0, 0.0]])   # any heading
    scans = noisy(rotated + [50.0, -20.0])
    misfits = [track.add(s, xy, o) for s, xy, o in
               zip(stamps, scans, truth)]
    assert misfits[:4] == [None] * 4      # too few scans to say
    assert np.median(misfits[10:]) < 2.0      # about the scans' noise
    assert np.max(misfits[10:]) < 5.0


def test_the_misfit_is_large_for_scans_that_stand_while_the_robot_drives():
    odometry, stamps, truth = drive()
    track = TrackMisfit(30.0)
    snapped = np.repeat(truth[:1], len(truth), axis=0)   # a surveyed spot
    misfits = [track.add(s, xy, o) for s, xy, o in
               zip(stamps, snapped, truth)]
    assert min(misfits[30:]) > 3.0
    assert TrackMisfit(30.0).add(0.0, [0.0, 0.0], [0.0, 0.0]) is None


def test_a_scan_is_as_wide_as_it_is_trusted():
    sensor = WifiSensorModel(FusionParams(sigma_scale=2.0, track_scale=3.0))
    xy = np.zeros(2)
    assert sensor.width(WifiPosition(xy)) == 4.0            # wifi_sd
    assert sensor.width(WifiPosition(xy, sigma=3.0)) == 6.0
    assert sensor.width(WifiPosition(xy, sigma=math.nan)) == 4.0
    assert sensor.width(WifiPosition(xy, 1.0, misfit=5.0)) == 15.0


def snapped(truth, stamps, start=100.0, seconds=30.0):
    """
    Return scans that stay where the survey ends for ``seconds``.

    From ``start`` the robot drives 15 m into an uncovered stretch; its
    scans keep snapping to the last surveyed spot.
    """
    scans = noisy(truth)
    inside = (stamps >= start) & (stamps < start + seconds)
    scans[inside] = noisy(np.repeat(truth[inside][:1], inside.sum(), 0), 1)
    return scans, inside


def run_filter(params, odometry, stamps, scans, seed=0):
    return fuse_offline(odometry, (stamps, scans), Fusion(params, seed=seed))


#: Filter seeds: the figures are compared seed by seed and by their median,
#: not on one random path.
SEEDS = range(10)


def worst_errors(odometry, stamps, truth, scans, where):
    """
    Return each seed's largest error (m) at the scans ``where``.

    (trusted: the defaults, alike: every scan trusted alike, as before).
    """
    def worst(params, seed):
        xy = run_filter(params, odometry, stamps, scans, seed)[0]
        return np.linalg.norm(xy - truth, axis=1)[where].max()
    return tuple(np.array([worst(params, seed) for seed in SEEDS])
                 for params in (FusionParams(), FusionParams(track_scale=0.0)))


def test_through_an_uncovered_stretch_the_pose_follows_odometry():
    odometry, stamps, truth = drive()
    scans, inside = snapped(truth, stamps, start=40.0)   # a young filter
    # the scans were up to 15 m off; taken as independent, as before,
    # they drag the pose towards them
    trusted, alike = worst_errors(odometry, stamps, truth, scans, inside)
    assert np.median(trusted) < 3.0, trusted
    assert np.median(trusted) < 0.9 * np.median(alike), (trusted, alike)
    assert (trusted < alike).sum() >= 8, (trusted, alike)
    # the ellipse grows through the stretch, then shrinks again
    _, _, cov = run_filter(FusionParams(), odometry, stamps, scans)
    spread = np.sqrt(cov[:, 0, 0] + cov[:, 1, 1])
    before = spread[np.flatnonzero(inside)[0] - 1]
    assert spread[inside].max() > before
    assert spread[-1] < spread[inside].max()


def test_a_run_of_scans_that_jumped_does_not_drag_the_pose():
    odometry, stamps, truth = drive()
    scans = noisy(truth)
    jumped = (stamps >= 100) & (stamps < 110)   # 8 m off within 2 s
    scans[jumped] += [0.0, 8.0]
    trusted, alike = worst_errors(odometry, stamps, truth, scans, jumped)
    assert np.median(trusted) < 3.0, trusted
    assert np.median(trusted) < 0.7 * np.median(alike), (trusted, alike)
    assert (trusted < alike).sum() >= 9, (trusted, alike)
    # scans that stay off longer than track_s are the robot's track
    # (a kidnap): the filter follows them or restarts there


def test_a_kidnapped_robot_still_restarts_where_the_scans_are():
    odometry, stamps, truth = drive()
    scans = noisy(truth)
    scans[stamps >= 120] += [30.0, 20.0]     # carried off; odometry on
    fusion = Fusion(seed=0)
    xy, _, _ = fuse_offline(odometry, (stamps, scans), fusion)
    error = np.linalg.norm(xy - (truth + np.where(
        stamps[:, None] >= 120, [30.0, 20.0], 0.0)), axis=1)
    assert fusion.counts['restarts'] >= 2
    assert error[stamps >= 180].max() < 3.0


def test_a_robot_carried_into_a_hole_restarts_there():
    # Carried 27 m by a filter that settled and knows the drift, into a
    # place whose scans sound unlike the survey for a minute (1.3 times
    # the usual: each 8.8 m wide). A run of them pulls like one scan, but
    # each still disagrees at the width its mismatch gives: the filter
    # restarts there within seconds, not once they sound like the survey
    # again (about 70 s with the run's width in the restart test).
    odometry, stamps, truth = drive()
    after = stamps >= 120
    carried = truth + np.where(after[:, None], [25.0, 10.0], 0.0)
    mismatch = np.where(after & (stamps < 180), 1.3, 1.0)
    found = []
    for seed in range(5):
        fusion = Fusion(FusionParams(drift_sd=0.005), seed=seed)
        xy = fuse_offline(odometry, (stamps, noisy(carried, seed),
                                     np.full(len(stamps), np.nan),
                                     [None] * len(stamps), mismatch),
                          fusion)[0]
        near = after & (np.linalg.norm(xy - carried, axis=1) < 2.0)
        found.append(stamps[near][0] - 120.0)
        assert fusion.counts['restarts'] == 2     # the start, the kidnap
    assert np.median(found) < 30.0, found


def test_scans_that_sound_unlike_the_survey_do_not_drag_the_pose():
    # A hole beside a surveyed stretch: for 60 s the scans are answered 6
    # m aside, moving as the robot does (their misfit says nothing), but
    # they sound unlike the references they are placed at (twice the
    # survey's usual mismatch; 1 elsewhere). Widened, they hold the
    # particles together and drag them less (not nothing: 60 scans all 6
    # m aside, the worst a hole can be); widened the more the longer the
    # run (the filter settled when it began), far less.
    odometry, stamps, truth = drive()
    scans = noisy(truth)
    inside = (stamps >= 100) & (stamps < 160)
    scans[inside] += [0.0, 6.0]
    mismatch = np.where(inside, 2.0, 1.0)
    answers = (stamps, scans, np.full(len(stamps), np.nan),
               [None] * len(stamps), mismatch)

    def errors(params, seed):
        fusion = Fusion(params, seed=seed)
        xy = fuse_offline(odometry, answers, fusion)[0]
        return np.linalg.norm(xy - truth, axis=1), fusion.counts
    fitted = FusionParams(drift_sd=0.005)   # the drift known (exact here)
    widened = [errors(fitted, s) for s in SEEDS]
    each = [errors(replace(fitted, mismatch_run_power=0), s) for s in SEEDS]
    believed = [errors(replace(fitted, mismatch_scans=0), s) for s in SEEDS]
    worst, alike, dragged = (np.array([e[inside].max() for e, _ in runs])
                             for runs in (widened, each, believed))
    assert np.median(dragged) > 6.0, dragged
    assert np.median(alike) < 0.8 * np.median(dragged), (alike, dragged)
    assert (alike < dragged).sum() >= 9, (alike, dragged)
    assert np.median(worst) < 0.6 * np.median(alike), (worst, alike)
    assert (worst < alike).sum() >= 9, (worst, alike)
    # counted in the health; back on covered ground, the last 5 scans'
    # mean decides: as the filter that believed them, or sooner
    assert all(c['scans_unlike_survey'] == pytest.approx(inside.sum(), abs=3)
               for _, c in widened)
    after = (stamps >= 180) & (stamps < 200)
    assert np.median([e[after].max() for e, _ in each]) < 2.0
    assert np.median([e[after].max() for e, _ in widened]) < 1.0
    # the drift not fitted: the run is not counted, each scan alike
    np.testing.assert_array_equal(
        errors(FusionParams(), 0)[0],
        errors(FusionParams(mismatch_run_power=0), 0)[0])


def test_a_scan_is_as_wide_as_it_sounds_like_the_survey():
    recent = RecentMismatch(3)
    assert recent.add(None) is None and recent.add(math.nan) is None
    assert [recent.add(v) for v in (1.0, 2.0, math.nan, 3.0, 4.0)] == \
        [1.0, 1.5, 1.5, 2.0, 3.0]
    recent.clear()
    assert recent.add(None) is None
    sensor = WifiSensorModel(FusionParams(mismatch_full=1.2,
                                          mismatch_none=1.6,
                                          mismatch_width=20.0))
    xy = np.zeros(2)
    for mismatch, width in ((None, 4.0), (0.5, 4.0), (1.2, 4.0), (1.4, 12.0),
                            (1.6, 20.0), (3.0, 20.0)):
        scan = WifiPosition(xy, mismatch=mismatch)
        assert sensor.width(scan) == pytest.approx(width), mismatch
        # widened, it still testifies: a kidnap is still found
        assert sensor.trust(scan) == 1.0 and sensor.testifies(scan)
    # the widest of its reasons
    assert sensor.width(WifiPosition(xy, misfit=15.0, mismatch=1.4)) == 30.0
    off = WifiSensorModel(FusionParams(mismatch_scans=0))
    assert off.width(WifiPosition(xy, mismatch=3.0)) == 4.0
    # the 9th scan of a run: beyond wifi_sd 3 times as wide; a scan that
    # sounds like the survey is not widened however long the run
    assert sensor.width(WifiPosition(xy, mismatch=1.6, unlike_run=9)) == \
        pytest.approx(4.0 + 3 * 16.0)
    assert sensor.width(WifiPosition(xy, mismatch=1.4, unlike_run=9)) == \
        pytest.approx(4.0 + 3 * 8.0)
    assert sensor.width(WifiPosition(xy, mismatch=1.0, unlike_run=9)) == 4.0
    alike = WifiSensorModel(FusionParams(mismatch_run_power=0))
    assert alike.width(WifiPosition(xy, mismatch=3.0, unlike_run=9)) == 16.0
    with pytest.raises(ValueError, match='mismatch_run_power = 1.5'):
        FusionParams(mismatch_run_power=1.5)
    for full, none in ((1.6, 1.2), (1.2, 1.2), (0.0, 1.0)):
        with pytest.raises(ValueError, match=f'mismatch_full = {full!r}'):
            FusionParams(mismatch_full=full, mismatch_none=none)
    with pytest.raises(ValueError, match='mismatch_width = 0'):
        FusionParams(mismatch_width=0)


def test_a_run_of_unlike_scans_counts_once_the_filter_settled():
    run = UnlikeRun()
    fitted = FusionParams(drift_sd=0.005).drift_known    # fit_odometry's
    assert fitted and not FusionParams().drift_known
    # met by a young filter: not counted to its end, though it settles
    assert [run.add(True, s, fitted) for s in (False, True, True)] == \
        [0, 0, 0]
    # a scan that sounds like the survey ends it; the next is counted
    assert [run.add(u, True, fitted) for u in (False, True, True, True)] \
        == [0, 1, 2, 3]
    run.clear()     # the filter started afresh: a new run, young again
    assert run.add(True, False, fitted) == 0
    # the drift not fitted: odometry cannot be followed through a hole
    assert [run.add(u, True, False) for u in (False, True, True)] == \
        [0, 0, 0]
    # the filter keeps none across a set pose or an odometry jump
    fusion = Fusion(FusionParams(drift_sd=0.005))
    for forget in (lambda: fusion.set_pose(0.0, (0.0, 0.0), 0.0, 0.5, 0.1,
                                           (0, 0)),
                   lambda: fusion.odometry(1.0, 0.0, 0.0, 0.0) and
                   fusion.odometry(1.1, 50.0, 0.0, 0.0)):
        fusion.unlike_run.add(False, True, True)     # no run yet
        fusion.unlike_run.add(True, True, True)
        assert fusion.unlike_run.add(True, True, True) == 2
        forget()
        assert fusion.unlike_run.add(True, False, True) == 0


def test_an_odometry_jump_starts_the_scans_track_again():
    # odometry reset to zero mid-drive: its old frame is not the new one,
    # so the scans after it are not taken for scans off the track
    odometry, stamps, truth = drive()
    jumped = odometry.copy()
    later = jumped[:, 0] >= 100.0
    jumped[later, 1:3] -= jumped[later][0, 1:3] + [40.0, 0.0]
    off = []
    for odo in (odometry, jumped):
        fusion = Fusion(seed=0)
        fuse_offline(odo, (stamps, noisy(truth)), fusion)
        off.append(fusion.counts['scans_off_track'])
    assert fusion.counts['odometry_jump'] == 1
    assert off[1] <= off[0] + 5, off     # the scans' noise alone: off[0]


def test_a_scan_on_track_disagrees_sooner():
    """
    Scans on track disagree from ``reset_track_sigmas`` sd (2 by default).

    A robot carried about a scan's 3 sd (12 m): its scans, once they move
    as odometry says (their misfit widens them no more), disagree from 2
    sd; ten of them restart the filter there. Scans widened by their
    misfit (snapped from a hole) still need 3, as every scan does with
    ``reset_track_sigmas`` 0.
    """
    params = FusionParams()
    sensor = WifiSensorModel(params)
    cov = np.eye(2) * 1.0       # the particles: 1 m spread
    on = WifiPosition(np.array([11.0, 0.0]), misfit=1.0)
    off = WifiPosition(np.array([11.0, 0.0]), misfit=3.0)    # widened
    unknown = WifiPosition(np.array([11.0, 0.0]))   # no track yet
    assert not sensor.off_track(on) and sensor.off_track(off)
    assert sensor.disagrees(np.zeros(2), cov, on)
    assert not sensor.disagrees(np.zeros(2), cov, off)
    assert not sensor.disagrees(np.zeros(2), cov, unknown)
    assert params.reset_track_sigmas == 2
    assert not WifiSensorModel(FusionParams(reset_track_sigmas=0)).disagrees(
        np.zeros(2), cov, on)
    # within 2 sd (8.2 m here) a scan on track agrees
    assert not sensor.disagrees(np.zeros(2), cov, WifiPosition(
        np.array([7.5, 0.0]), misfit=1.0))
    # as far as 3 sd, any scan disagrees
    assert sensor.disagrees(np.zeros(2), cov, WifiPosition(
        np.array([13.0, 0.0]), misfit=3.0))
    # a run of unlike scans changes neither the width nor the limit: 20 m
    # off is 2.3 sd of a scan 8.8 m wide (mismatch 1.3), off its track
    for run in (0, 30):
        assert not sensor.disagrees(np.zeros(2), cov, WifiPosition(
            np.array([20.0, 0.0]), misfit=8.0, mismatch=1.3,
            unlike_run=run))
    pf = ParticleFilter(params, seed=0)
    pf.start(np.zeros(2), sd=0.5)
    why = [pf.update(on) for _ in range(params.reset_after)]
    assert why[-1] == DISAGREED and not any(why[:-1])
    assert np.linalg.norm(pf.position()[0] - on.xy) < 1.0
