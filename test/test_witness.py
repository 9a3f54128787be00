"""
The WiFi witness of a localiser without ROS (core.witness).

Synthetic streams: the robot drives along x at 0.5 m/s, a fused pose and a
localiser pose every second. Checked: agreement, one bad scan, a
sustained disagreement, the yaw only when the fused yaw is known, another
floor's frame, the survey's coverage, a silent localiser, seeds at
start-up and when lost (none from a fused pose built on scans off the
survey), bad input refused with a reason, the state: agrees only when
WiFi compared, cannot tell when nothing was; and the per-pose arithmetic
against numpy's linear algebra.
"""

from dataclasses import replace
import math

import numpy as np
import pytest
from wifi_place_recognition.core.coverage import UNLIKE_SURVEY_ABOVE
from wifi_place_recognition.core.filter.particles import UNKNOWN_VARIANCE
from wifi_place_recognition.core.witness import (AGREES, CANNOT_TELL,
                                                 DISAGREES, LOST,
                                                 WAITING, Witness)
from wifi_place_recognition.core.witness_inputs import Pose, pose_problem
from wifi_place_recognition.core.witness_offline import judge_offline
from wifi_place_recognition.core.witness_pairing import Streams
from wifi_place_recognition.core.witness_params import WitnessParams
from wifi_place_recognition.core.witness_testimony import mahalanobis

SPEED = 0.5


def cov(sd=0.5, yaw_sd=math.radians(3)):
    """Return a 3x3 x, y, yaw covariance."""
    return np.diag([sd ** 2, sd ** 2, yaw_sd ** 2])


def truth(k):
    """Return (xy, yaw) at second ``k``."""
    return np.array([SPEED * k, 0.0]), 0.0


def drive(witness, steps, local=truth, fused_sd=0.5, yaw_sd=math.radians(3),
          frame='map', local_frame='map', start=0, send_seeds=True):
    """
    Feed ``steps`` seconds; return the judgements.

    ``send_seeds``: every seed proposed is sent (``initial_pose_on_lost``).
    """
    out = []
    for k in range(start, start + steps):
        if local is not None:
            xy, yaw = local(k)
            assert witness.localiser(k, local_frame, xy, yaw,
                                     cov(0.1, 0.05)) is None
        xy, yaw = truth(k)
        j = witness.fused(k, frame, xy, yaw, cov(fused_sd, yaw_sd))
        if j is not None:
            if j.seed and send_seeds:
                witness.seeded(j.stamp)
            out.append(j)
    return out


def test_an_agreeing_localiser_stays_ok_with_no_evidence():
    w = Witness()
    judged = drive(w, 60, local=lambda k: (truth(k)[0] + [0.4, -0.3], 0.05))
    assert len(judged) == 60
    assert all(j.ok for j in judged) and w.evidence['fused'] == 0
    assert all(j.sigmas < 1 for j in judged)
    assert not any(j.seed for j in judged)


def test_one_bad_judgement_never_alarms_a_sustained_one_does():
    p = WitnessParams()
    w = Witness(p)
    drive(w, 10)
    w.localiser(10, 'map', [100.0, 0.0], 0.0, cov(0.1))   # one wild pose
    w.fused(10, 'map', *truth(10), cov())
    assert w.ok and 0 < w.evidence['fused'] <= p.max_step
    drive(w, 10, start=11)
    assert w.ok and w.evidence['fused'] == 0
    # sustained: the larger, the sooner
    delays = []
    for offset in (6.0, 20.0):
        w = Witness(p)
        drive(w, 10)
        judged = drive(w, 40, local=lambda k: (truth(k)[0] + [0, offset],
                                               0.0), start=10)
        delays.append(next(j.stamp for j in judged if j.ok is False) - 10)
    assert delays[1] < delays[0] <= 15, delays
    assert delays[1] >= math.ceil(p.alarm / p.max_step) - 1


def test_the_yaw_is_compared_only_when_the_fused_yaw_is_known():
    turned = lambda k: (truth(k)[0], math.radians(90))   # noqa: E731
    w = Witness()
    judged = drive(w, 30, local=turned, yaw_sd=math.sqrt(UNKNOWN_VARIANCE))
    assert all(j.ok for j in judged) and all(math.isnan(j.yaw_deg)
                                             for j in judged)
    w = Witness()
    judged = drive(w, 30, local=turned)
    assert judged[-1].ok is False
    assert judged[0].yaw_deg == pytest.approx(90)


def test_a_localiser_in_another_floors_frame_is_lost_within_a_few():
    p = WitnessParams()
    w = Witness(p)
    drive(w, 5)
    judged = drive(w, 10, frame='map_f1', start=5)
    first = next(i for i, j in enumerate(judged) if j.ok is False)
    assert first + 1 == math.ceil(p.alarm / p.max_step)
    assert "'map'" in judged[first].reason and 'map_f1' in judged[first].reason


def test_scans_testify_only_on_the_survey_and_when_sure():
    survey = {'map': np.column_stack([np.arange(0, 50, 0.5),
                                      np.zeros(100)])}
    p = WitnessParams()

    def scans(w, dy, sigma, local_dy=0.0):
        """Localiser at the truth (+ local_dy), scans ``dy`` off it."""
        for k in range(40):
            xy, yaw = truth(k)
            w.localiser(k, 'map', xy + [0, local_dy], yaw, cov(0.1))
            w.scan(k, 'map', xy + [0, dy], sigma)
        return w
    assert scans(Witness(p, survey), 15.0, 1.5).ok is False
    # a scan unlike every surveyed one (large sigma): no evidence
    assert scans(Witness(p, survey), 15.0, p.max_scan_sigma + 1).ok
    # the localiser far from the survey: the scans cannot testify
    w = scans(Witness(p, survey), 15.0, 1.5, local_dy=-10)
    assert w.ok and w.evidence['scans'] == 0
    assert w.last.reason == 'localiser pose off the survey'
    # and the fused pose is no evidence while the scans are off the survey
    w = Witness(p, survey)
    for k in range(40):
        xy, yaw = truth(k)
        w.localiser(k, 'map', xy + [0, 15.0], yaw, cov(0.1))
        w.scan(k, 'map', xy, p.max_scan_sigma + 2)
        w.fused(k, 'map', xy, yaw, cov())
    assert w.ok and w.evidence['fused'] == 0


def test_a_wide_scan_testifies_when_its_coverage_says_on_the_survey():
    survey = {'map': np.column_stack([np.arange(0, 50, 0.5),
                                      np.zeros(100)])}
    p = WitnessParams()

    def scans(sigma, coverage):
        """Localiser at the truth, scans 30 m off it."""
        w = Witness(p, survey)
        for k in range(40):
            xy, yaw = truth(k)
            w.localiser(k, 'map', xy, yaw, cov(0.1))
            w.scan(k, 'map', xy + [0, 30.0], sigma, coverage)
        return w
    wide = p.max_scan_sigma + 1
    # a wide scan likely off the survey: no evidence
    w = scans(wide, 0.2)
    assert w.ok and w.evidence['scans'] == 0
    assert w.last.reason == 'scan off the survey (sigma 4.0 m, coverage 0.20)'
    # a wide scan likely on it testifies
    assert scans(wide, 0.9).ok is False
    # the probability alone silences no scan: a sure one testifies
    assert scans(1.5, 0.2).ok is False
    # no probability (a model without a coverage model): the sigma rule
    w = scans(wide, math.nan)
    assert w.ok and w.last.reason == 'scan off the survey (sigma 4.0 m)'
    assert scans(1.5, math.nan).ok is False
    # a probability outside 0-1 is refused, like a scan that is not finite
    for coverage in (-0.1, 1.5, math.inf):
        assert Witness(p, survey).scan(0, 'map', [0, 0], 1.5,
                                       coverage) is None
    assert Witness(p, survey).scan(0, 'map', [0, 0], 1.5, 1.0) is not None


def test_a_scan_that_sounds_unlike_the_survey_testifies_nothing():
    survey = {'map': np.column_stack([np.arange(0, 50, 0.5),
                                      np.zeros(100)])}
    p = WitnessParams()
    above = UNLIKE_SURVEY_ABOVE

    def scans(mismatch, coverage=0.9, fused=False):
        """Localiser at the truth, sure scans 30 m off; fused poses too."""
        w = Witness(p, survey)
        for k in range(40):
            xy, yaw = truth(k)
            w.localiser(k, 'map', xy, yaw, cov(0.1))
            w.scan(k, 'map', xy + [0, 30.0], 1.5, coverage, mismatch)
            if fused:
                w.fused(k, 'map', xy + [0, 30.0], yaw, cov())
        return w
    # sure, likely covered, but sounding unlike the survey: no evidence,
    # and the fused pose built on such scans neither
    for fused, reason in ((False, 'scan unlike the survey (mismatch 1.41 '
                                  'times its usual)'),
                          (True, 'off the survey (5 of the last 5 scans do '
                                 'not testify)')):
        w = scans(above + 0.01, fused=fused)
        assert w.ok and w.evidence['scans'] == w.evidence['fused'] == 0
        assert (w.state, w.last.reason) == (CANNOT_TELL, reason)
    # up to the threshold, or not known: the scans testify
    for mismatch in (above, 0.5, math.nan, None):
        assert scans(mismatch).ok is False
    # a mismatch that is not a ratio is refused
    for mismatch in (-0.1, math.inf, 'loud'):
        assert Witness(p, survey).scan(0, 'map', [0, 0], 1.5, 0.9,
                                       mismatch) is None
    assert Witness(p, survey).scan(0, 'map', [0, 0], 1.5, 0.9,
                                   0.0) is not None


def test_a_silent_localiser_is_lost_only_if_the_robot_moved():
    p = WitnessParams()
    w = Witness(p)
    drive(w, 10)
    judged = drive(w, 60, local=None, start=10)
    assert judged[-1].ok is False and 'no localiser pose' in \
        judged[-1].reason
    w = Witness(p)
    drive(w, 10)
    for k in range(10, 70):       # standing still, localiser silent
        w.fused(k, 'map', *truth(10), cov())
    assert w.ok


def test_seeds_at_start_up_once_sure_and_when_lost_once_per_holdoff():
    p = WitnessParams(holdoff=30.0, startup_sure_s=0.0)
    w = Witness(p)
    judged = drive(w, 5, local=None, fused_sd=3.0)
    assert not any(j.seed for j in judged) and w.ok is None
    judged = drive(w, 40, local=None, start=5)
    seeds = [j for j in judged if j.seed]
    assert [j.stamp for j in seeds] == [5, 35]     # again after holdoff
    assert seeds[0].seed.startswith('start-up')
    assert np.allclose(seeds[0].fused.xy, truth(5)[0])
    # lost: one seed, the evidence cleared, found once the localiser agrees
    p = WitnessParams(holdoff=1000.0)
    w = Witness(p)
    drive(w, 10)
    judged = drive(w, 20, local=lambda k: (truth(k)[0] + [20, 0], 0.0),
                   start=10)
    seeds = [j for j in judged if j.seed]
    assert len(seeds) == 1 and seeds[0].seed.startswith('lost')
    assert seeds[0].ok is False
    assert w.evidence['fused'] == p.alarm       # at most the alarm level
    judged = drive(w, 30, start=30)
    found = next(j.stamp for j in judged if j.ok) - 30
    assert found == math.ceil(p.alarm / p.agree_sigmas) - 1, found


def test_a_start_up_seed_waits_for_a_pose_sure_without_a_break():
    """
    A young filter's covariance narrows before its heading is right.

    Sure from 5 s, wide once at 12 s, sure again from 13 s: the start-up
    seed comes startup_sure_s (15, the default) after 13 s, not after 5;
    0 seeds at once. A re-seed (the localiser lost) does not wait.
    """
    def start_up(params):
        w = Witness(params)
        sds = [3.0] * 5 + [0.5] * 7 + [3.0] + [0.5] * 40
        for k, sd in enumerate(sds):
            j = w.fused(k, 'map', *truth(k), cov(sd))
            if j.seed:
                return j.stamp, j.seed
        return None

    p = WitnessParams()
    assert p.startup_sure_s == 15
    assert start_up(p)[0] == 13 + 15
    assert start_up(replace(p, startup_sure_s=0.0))[0] == 5
    assert start_up(replace(p, startup_sure_s=60.0)) is None
    # lost at once after a wide pose: the re-seed does not wait
    w = Witness(p)
    drive(w, 10, fused_sd=3.0)
    judged = drive(w, 20, local=lambda k: (truth(k)[0] + [20, 0], 0.0),
                   start=10)
    seeds = [j for j in judged if j.seed]
    lost = next(j.stamp for j in judged if j.ok is False)
    assert [j.stamp for j in seeds] == [lost] and lost - 10 < 15
    assert seeds[0].seed.startswith('lost')


def test_a_restarted_clock_starts_the_seeding_over():
    """
    A bag played again: the fused stamps go back, no localiser heard.

    The new timeline's start-up seed comes after its own sure stretch:
    not after the old timeline's last seed plus the holdoff, nor after
    the old stretch's start, whether the stamps go back before it or
    only before the newest one.
    """
    w = Witness(WitnessParams(holdoff=30.0))
    assert [j.stamp for j in drive(w, 20, local=None) if j.seed] == [15]
    assert [j.stamp for j in drive(w, 20, local=None, start=5)
            if j.seed] == [5 + 15]
    # no seed sent on the old timeline: only its sure stretch behind
    p = WitnessParams(startup_sure_s=30.0)
    for first, again in ((10, 0), (100, 110)):
        w = Witness(p)
        old = drive(w, 25, local=None, start=first)
        assert not any(j.seed for j in old)
        seeds = [j.stamp for j in drive(w, 40, local=None, start=again)
                 if j.seed]
        assert seeds == [again + 30], (first, again, seeds)


def test_no_seed_from_a_fused_pose_built_on_scans_off_the_survey():
    survey = {'map': np.column_stack([np.arange(0, 100, 0.5),
                                      np.zeros(200)])}
    p = WitnessParams(holdoff=1000.0)
    wide = p.max_scan_sigma + 2

    def step(w, k, sigma, fused_sd, local_dx=None):
        xy, yaw = truth(k)
        if local_dx is not None:
            w.localiser(k, 'map', xy + [local_dx, 0], yaw, cov(0.1))
        w.scan(k, 'map', xy, sigma)
        j = w.fused(k, 'map', xy, yaw, cov(fused_sd))
        if j is not None and j.seed:
            w.seeded(j.stamp)
        return j

    # start-up: a sure fused pose seeds only once most scans testify
    w = Witness(p, survey)
    judged = [step(w, k, wide, 0.5) for k in range(20)]
    assert not any(j.seed for j in judged)
    judged = [step(w, k, 1.5, 0.5) for k in range(20, 30)]
    seeds = [j for j in judged if j.seed]
    assert [j.stamp for j in seeds] == [22]     # 3 of the last 5 testify
    assert seeds[0].seed.startswith('start-up')
    # lost (found by the scans while the fused pose was too wide), then
    # the scans leave the survey and the fused pose becomes sure: no seed
    # until the scans testify again
    w = Witness(p, survey)
    for k in range(10):
        step(w, k, 1.5, 3.0, local_dx=0.0)
    for k in range(10, 50):
        step(w, k, 1.5, 3.0, local_dx=20.0)
    assert w.ok is False
    for k in range(50, 55):
        step(w, k, wide, 3.0, local_dx=20.0)
    judged = [step(w, k, wide, 0.5, local_dx=20.0) for k in range(55, 70)]
    assert not any(j.seed for j in judged) and w.ok is False
    judged = [step(w, k, 1.5, 0.5, local_dx=20.0) for k in range(70, 80)]
    seeds = [j for j in judged if j.seed]
    assert [j.stamp for j in seeds] == [72]
    assert seeds[0].seed.startswith('lost')


def test_no_seed_while_the_scans_of_the_last_minute_lie_aside():
    """
    A pose dragged by scans off the survey, and coming back.

    For 50 s the scans lie 4.5 m aside of the fused track and the fused
    pose is wide; then they lie on it and the pose is sure at once (its
    covariance comes from the last few scans). The start-up seed waits
    until the scans of the last sure_s (60) seconds lie within sure_sd
    (2 m) of the track on average: at 84 s, 26 of its 60 scans aside
    (83 s: 27, 2.02 m). Each scan, half a second after a fused pose, is
    compared with the track between two.
    """
    def seeds(params, aside=4.5):
        w, out = Witness(params), []
        for k in range(120):
            j = w.fused(k, 'map', *truth(k), cov(3.0 if k < 50 else 0.5))
            if j is not None and j.seed:
                w.seeded(j.stamp)
                out.append(j.stamp)
            w.scan(k + 0.5, 'map', truth(k + 0.5)[0] +
                   [aside if k < 50 else 0.0, 0.0], 1.0)
        return out

    p = WitnessParams(holdoff=1000.0, startup_sure_s=0.0)
    assert p.sure_s == 60
    assert seeds(p) == [84]
    assert seeds(p, aside=0.0) == [50]
    assert seeds(replace(p, sure_s=0.0)) == [50]       # not asked


def test_a_seed_not_sent_leaves_a_lost_localiser_lost():
    # initial_pose_on_lost off: the seeds proposed are not sent, so
    # nothing starts the localiser over and the verdict stays lost
    w = Witness()
    drive(w, 10, send_seeds=False)
    judged = drive(w, 120, local=lambda k: (truth(k)[0] + [20, 0], 0.0),
                   start=10, send_seeds=False)
    lost = next(i for i, j in enumerate(judged) if j.ok is False)
    assert all(j.ok is False for j in judged[lost:]), \
        [j.stamp for j in judged[lost:] if j.ok]
    assert any(j.seed for j in judged[lost:])     # proposed, not sent
    assert all(j.evidence == w.params.alarm for j in judged[lost:]), \
        [j.evidence for j in judged[lost:]]


def test_a_localiser_heard_is_not_seeded_as_absent():
    # its poses refused (a zero covariance): it is there, not missing
    w = Witness()
    for k in range(60):
        assert w.localiser(k, 'map', truth(k)[0], 0.0, np.zeros((3, 3)))
        judgement = w.fused(k, 'map', *truth(k), cov())
        assert judgement is None or not judgement.seed, judgement.seed
    # a clock restarted: far back is a new timeline, near back refused
    w = Witness()
    drive(w, 30)
    assert w.localiser(28.5, 'map', truth(28)[0], 0.0, cov(0.1)) is not None
    for _ in range(3):      # a stale message resent stays refused
        assert w.localiser(2.0, 'map', truth(2)[0], 0.0, cov(0.1))
    assert w.localiser(3.0, 'map', truth(3)[0], 0.0, cov(0.1)) is None
    assert w.local.stamp == 3.0     # the clock runs on from its restart


def test_bad_poses_are_refused_with_a_reason():
    assert pose_problem(0.0, [1, 2], 0.0, cov()) is None
    assert pose_problem(0.0, [1, 2], 0.0, np.diag([1, 1, 1e6])) is None
    assert 'not finite' in pose_problem(0.0, [math.nan, 2], 0.0, cov())
    assert 'not symmetric' in pose_problem(
        0.0, [1, 2], 0.0, cov() + np.triu(np.ones((3, 3)), 1))
    assert 'positive definite' in pose_problem(
        0.0, [1, 2], 0.0, np.diag([1.0, -1.0, 1.0]))
    assert 'positive definite' in pose_problem(
        0.0, [1, 2], 0.0, np.ones((3, 3)))
    w = Witness()
    assert w.localiser(5.0, 'map', [0, 0], 0.0, cov()) is None
    assert '4.000 s is before' in w.localiser(4.0, 'map', [9, 9], 0.0, cov())
    assert w.local.stamp == 5.0
    assert w.fused(6.0, 'map', [math.nan, 0], 0.0, cov()) is None
    assert w.scan(6.0, 'map', [0, 0], math.inf) is None


def test_the_per_pose_arithmetic_matches_numpys_linear_algebra():
    # closed forms on every pose and scan: the verdict, the fused pose's
    # sd, the Mahalanobis distance, the distance moved since a stamp
    rng = np.random.default_rng(0)
    for k in range(3000):
        a = rng.normal(size=(3, 3)) * rng.choice([1e-3, 1.0, 1e3], 3)
        c = [a @ a.T, (a + a.T) / 2, a[:, :2] @ a[:, :2].T][k % 3]
        d = np.diag(c)
        scaled = c / np.sqrt(np.outer(np.abs(d), np.abs(d)))
        expected = bool((d > 0).all() and np.linalg.eigvalsh(scaled).min()
                        > 1e-9)
        assert (pose_problem(0.0, [1, 2], 0.0, c) is None) == expected, c
        if (d[:2] > 0).all():
            pose = Pose.of(0.0, 'map', [0, 0], 0.0, c)
            assert pose.sd ** 2 == pytest.approx(max(np.linalg.eigvalsh(
                c[:2, :2])), rel=1e-9, abs=1e-12)
        delta = rng.normal(size=2) * 10
        m = (a @ a.T)[:2, :2] + 1e-3 * np.eye(2)
        assert mahalanobis(delta, m) == pytest.approx(
            (delta @ np.linalg.solve(m, delta), np.linalg.norm(delta)),
            rel=1e-6)
    streams = Streams()
    stamps = np.sort(rng.choice(np.arange(50.0), 60))   # repeats
    for t in stamps:
        streams.fused(Pose.of(t, 'map', rng.normal(size=2), 0.0, cov()), 1.0)
    xy = np.array([h[1:] for h in streams.history])
    for t in np.arange(-1.0, 52.0, 0.5):
        i = min(np.searchsorted(stamps, t), len(stamps) - 1)
        assert streams.moved_since(t) == pytest.approx(
            np.linalg.norm(xy[i] - xy[-1]))


def test_parameters_are_checked_naming_the_field():
    with pytest.raises(ValueError, match='alarm = 0'):
        WitnessParams(alarm=0)
    with pytest.raises(ValueError, match='floor_sd = nan'):
        WitnessParams(floor_sd=math.nan)
    with pytest.raises(ValueError, match='max_step = 30.0 must be below'):
        WitnessParams(max_step=30.0, alarm=30.0)
    assert WitnessParams(sure_s=0).sure_s == 0      # 0: not asked
    with pytest.raises(ValueError, match=r'sure_s = -1: .* number >= 0'):
        WitnessParams(sure_s=-1)


def test_judge_offline_takes_the_streams_in_stamp_order():
    t = np.arange(30.0)
    xy = np.column_stack([SPEED * t, np.zeros(30)])
    covs = np.repeat(cov()[None], 30, axis=0)
    fused = (t, xy, np.zeros(30), covs)
    local = (t + 0.5, xy + [0, 20], np.zeros(30), covs)
    judged = judge_offline(local, fused)
    assert judged[0].reason == 'no localiser pose'
    assert judged[-1].ok is False
    seeds = [j.stamp for j in judge_offline(None, fused) if j.seed]
    assert seeds[0] == WitnessParams().startup_sure_s    # sure from 0 s


def test_a_fused_pose_too_wide_to_tell_5_m_apart_does_not_agree():
    """
    The localiser 5 m off; a fused pose 3 m wide (its scans lie aside).

    It cannot tell 5 m apart: no evidence either way, never ``agrees``
    (a recorder takes ``agrees`` after a jump as the localiser checked).
    One 1 m wide gathers evidence against the localiser.
    """
    def off(k):
        return truth(k)[0] + [0.0, 5.0], 0.0
    for fused_sd, state in ((3.0, CANNOT_TELL), (1.0, DISAGREES)):
        w = Witness()
        judged = drive(w, 8, local=off, fused_sd=fused_sd)
        assert {j.ok for j in judged} == {True}
        assert w.state == state, (fused_sd, w.state, w.why)


def test_the_state_says_agrees_only_when_wifi_compared():
    p = WitnessParams()
    w = Witness(p)
    assert (w.state, w.why) == (WAITING, 'no localiser pose yet')
    w.localiser(0, 'map', *truth(0), cov(0.1))
    assert w.ok and (w.state, w.why) == (CANNOT_TELL,
                                         'no WiFi pose or scan yet')
    w.fused(0, 'map', *truth(0), cov(p.max_fused_sd + 1))   # a wide filter
    assert w.ok and (w.state, w.why) == (CANNOT_TELL,
                                         'fused pose too wide (3.0 m)')
    drive(w, 5, start=1)
    assert (w.state, w.why) == (AGREES, '')
    # the WiFi stops, the localiser goes on: the comparison grows old
    for k in range(6, 6 + int(p.max_age)):
        w.localiser(k, 'map', *truth(k), cov(0.1))
    assert w.state == AGREES
    w.localiser(16, 'map', *truth(16), cov(0.1))
    assert w.ok and (w.state, w.why) == (CANNOT_TELL,
                                         'no WiFi pose or scan for 11 s')
    # scans off the survey: nothing to compare, nor is the fused pose
    for k in range(17, 20):
        w.localiser(k, 'map', *truth(k), cov(0.1))
        w.scan(k, 'map', truth(k)[0], p.max_scan_sigma + 1)
    assert (w.state, w.why) == (CANNOT_TELL,
                                'scan off the survey (sigma 4.0 m)')
    w.fused(20, 'map', *truth(20), cov())
    assert (w.state, w.why) == (CANNOT_TELL, 'off the survey (3 of the '
                                'last 3 scans do not testify)')
    # scans like the surveyed ones, a displaced localiser: lost, and why
    for k in range(21, 40):
        w.localiser(k, 'map', truth(k)[0] + [20, 0], 0.0, cov(0.1))
        w.scan(k, 'map', truth(k)[0], 1.0)
        w.fused(k, 'map', *truth(k), cov())
    assert w.state == LOST and w.why.startswith('20.0 m ('), w.why


def test_wifi_that_disagrees_before_the_alarm_does_not_agree():
    # the localiser on another floor's frame: evidence builds for a few
    # judgements before the alarm; none of them says "agrees"
    w = Witness(WitnessParams())
    states, whys = [], []
    for k in range(12):
        w.localiser(k, 'map_b0_f1', *truth(k), cov(0.1))
        w.fused(k, 'map_b0_f2', *truth(k), cov())
        states.append(w.state)
        whys.append(w.why)
    assert AGREES not in states, list(zip(states, whys))
    assert DISAGREES in states and states[-1] == LOST
    assert whys[states.index(DISAGREES)].endswith('of the alarm'), whys
