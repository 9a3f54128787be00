"""The per-scan path (core.pipeline), no ROS: scans and odometry in."""

from dataclasses import replace
import math

import numpy as np

from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.filter.fusion import Fusion
from wifi_place_recognition.core.filter.particles import FusionParams
from wifi_place_recognition.core.filter.trajectory import fuse_offline
from wifi_place_recognition.core.pipeline.scan_pipeline import (
    position_answer, ScanPipeline)
from wifi_place_recognition.core.recognizer import PlaceRecognizer, WARN
from wifi_place_recognition.data.fingerprints import read_fingerprints

from conftest import mac

F0, F1 = (0, 0), (0, 1)


def drive(seconds=60.0, speed=0.5, seed=0):
    """Return (odometry rows t, x, y, yaw at 10 Hz; scan stamps; scans xy)."""
    t = np.arange(0.0, seconds, 0.1)
    odometry = np.column_stack([t, speed * t, 0.2 * t, np.full(len(t), 0.4)])
    stamps = np.arange(0.55, seconds - 1.0, 1.0)
    truth = np.column_stack([speed * stamps, 0.2 * stamps])
    noise = np.random.default_rng(seed).normal(0, 1.5, truth.shape)
    return odometry, stamps, truth + noise


def test_without_odometry_each_answer_is_its_pose_and_a_floor_needs_two():
    pipeline = ScanPipeline(fusion=Fusion(seed=0))
    pipeline.configure(initial_pose_on_change=True)

    def answer(xy, place, stamp, confident=True):
        a = position_answer(xy, 1.0, place)
        return pipeline.answer(a if confident else replace(a, level=WARN),
                               stamp, stamp, source=f'scan {stamp}')
    first = answer([1.0, 1.0], F0, 1.0)
    assert first.place_changed and pipeline.changes.place == F0
    [pose] = first.poses
    assert (pose.source, pose.place, pose.fused, pose.initial) == \
        ('scan 1.0', F0, False, [])
    # one answer of floor 1: its own pose, the place stays
    once = answer([1.0, 1.0], F1, 2.0)
    assert not once.place_changed and once.poses[0].place == F1
    again = answer([1.0, 1.0], F1, 3.0)
    assert again.place_changed and pipeline.changes.place == F1
    assert again.poses[0].initial == ['building 0, floor 0 before']
    # a jump on the same floor: far outside the previous answer's sigma
    jump = answer([30.0, 1.0], F1, 4.0)
    assert jump.poses[0].initial[0].startswith('position jumped 29.0 sigma')
    # a request goes with the next confident answer, not an unconfident one
    pipeline.request_initial_pose()
    assert answer([30.0, 1.0], F1, 5.0, confident=False).poses[0].initial \
        == []
    assert answer([30.0, 1.0], F1, 6.0).poses[0].initial == ['requested']


def test_with_odometry_the_poses_are_fused_and_carry_the_callers_stamps():
    odometry, stamps, scans = drive(seconds=10.0)
    pipeline = ScanPipeline(fusion=Fusion(seed=0))
    # before any odometry: the answer's own position
    [alone] = pipeline.answer(position_answer(scans[0], 2.0), -1.0, -1.0,
                              'early').poses
    assert not alone.fused and alone.cov.shape == (2, 2)
    for row in odometry[:12]:                        # up to t = 1.1 s
        assert pipeline.odometry(*row, now=row[0], source=row[0]).poses == []
    # a scan the odometry covers goes through at once, fused
    [fused] = pipeline.answer(position_answer(scans[0], 2.0), stamps[0],
                              1.1, 'scan 0').poses
    assert (fused.source, fused.fused, fused.cov.shape) == \
        ('scan 0', True, (3, 3))
    # one it does not cover waits for the odometry that does
    assert pipeline.answer(position_answer(scans[1], 2.0), 1.15, 1.15,
                           'scan 1').poses == []
    [released] = pipeline.odometry(*odometry[12], now=1.2,
                                   source='odometry 1.2').poses
    assert released.source == 'scan 1' and released.stamp == 1.15
    # between scans, at the tick: the pose at the newest odometry
    for row in odometry[13:20]:
        pipeline.odometry(*row, now=row[0], source=f'odometry {row[0]:.1f}')
    [between] = pipeline.tick(2.0).poses
    assert between.source == 'odometry 1.9' and between.fused
    assert pipeline.tick(2.1).poses == []       # nothing new: no pose


def test_a_scan_left_without_odometry_goes_alone_and_says_so():
    odometry, stamps, scans = drive(seconds=5.0)
    pipeline = ScanPipeline(fusion=Fusion(seed=0))
    for row in odometry:
        pipeline.odometry(*row, now=row[0])
    t = odometry[-1, 0]
    waiting = pipeline.answer(position_answer(scans[-1], 2.0), t + 0.5,
                              t + 0.5, 'late')
    assert waiting.poses == [] and waiting.problems == []
    assert pipeline.tick(t + 1.0).poses == []    # within odom_timeout
    out = pipeline.tick(t + 2.0)
    assert [p.source for p in out.poses] == ['late']
    assert out.problems == ['no odometry covering 1 scan(s) within 1 s: '
                            'fused alone (WiFi only)']
    problem, counts = pipeline.fusion.health(t + 2.0)
    assert problem == 'no odometry for 2.0 s'
    assert counts['fusion_scans_alone'] == 1
    # odometry silent beyond odom_timeout: the next scan goes at once
    stale = pipeline.answer(position_answer(scans[-1], 2.0), t + 2.5,
                            t + 2.5, 'stale')
    assert [p.source for p in stale.poses] == ['stale'], stale.problems
    # a refused odometry pose is a problem named by its message
    fault = pipeline.odometry(t + 3.0, math.nan, 0.0, 0.0, now=t + 3.0,
                              what='stamp 8: x nan')
    assert fault.problems == ['odometry invalid: odometry message skipped '
                              '(stamp 8: x nan)']


def test_a_fused_change_of_floor_reseeds_with_the_filters_start_there():
    odometry, stamps, scans = drive(seconds=10.0)
    pipeline = ScanPipeline(fusion=Fusion(seed=0))
    pipeline.configure(initial_pose_on_change=True)
    seeds = []
    o = 0
    for k, stamp in enumerate(stamps):
        while odometry[o, 0] <= stamp:
            seeds += pipeline.odometry(*odometry[o], now=odometry[o, 0]).poses
            o += 1
        place = F0 if k < 4 else F1
        seeds += pipeline.answer(position_answer(scans[k], 2.0, place),
                                 stamp, stamp, k).poses
    seeds = [(p.source, p.place, p.initial) for p in seeds if p.initial]
    # the second answer of floor 1 (scan 5) starts the filter there
    assert seeds == [(5, F1, ['building 0, floor 0 before'])], seeds


def test_scans_are_recognised_rejected_and_counted(surveyed_model):
    pipeline = ScanPipeline(PlaceRecognizer(load_model(surveyed_model)))
    assert pipeline.fusion is not None      # a position model: fused
    names = [mac(i) for i in range(30)]
    out = pipeline.scan(names, [-60.0] * 30, 1.0, 1.0, source='s1',
                        dropped=2)
    assert out.rejected is None and math.isfinite(out.latency_ms)
    assert out.answer.position is not None and out.place_changed
    assert [p.source for p in out.poses] == ['s1']    # no odometry yet
    bad = pipeline.scan(names, [-60.0] * 29, 2.0, 2.0)
    assert bad.answer is None and bad.poses == []
    assert bad.rejected.reason == 'length_mismatch'
    # two scans of the survey itself: covered; the one above, alike on
    # every AP, sounds like nowhere the survey went
    fp = read_fingerprints(surveyed_model.parent / 'a.csv')
    for row in (0, 1):
        heard = np.flatnonzero(np.isfinite(fp.rssi[row]))
        covered = pipeline.scan([fp.ap_ids[j] for j in heard],
                                fp.rssi[row, heard], 3.0 + row, 3.0 + row)
        assert covered.answer.coverage >= 0.5 > out.answer.coverage
    assert dict(pipeline.counts) == {
        'received': 6, 'answered': 3, 'rejected': 1, 'dropped': 2,
        'rejected/length_mismatch': 1, 'off_survey': 1}
    assert pipeline.reset() == ['fused pose']       # tracking off
    pipeline.configure(fusion=False)
    assert pipeline.reset() == []


def test_the_offline_path_gives_the_nodes_fused_poses():
    """fuse_offline (the benchmarks') against the pipeline as the node runs."""
    odometry, stamps, scans = drive()
    sigma = np.random.default_rng(1).uniform(1.0, 6.0, len(stamps))
    params = FusionParams(sigma_scale=1.0)  # each scan's own sigma counts
    offline = fuse_offline(odometry, (stamps, scans, sigma),
                           Fusion(params, seed=0))
    # the node: its own timer (pose_rate 10 Hz, poses between scans),
    # arrivals on its clock a little after the stamps
    pipeline = ScanPipeline(fusion=Fusion(params, seed=0))
    events = sorted([(t + 0.02, 0, row) for t, row in
                     zip(odometry[:, 0], odometry)] +
                    [(t + 0.03, 1, k) for k, t in enumerate(stamps)] +
                    [(t, 2, None) for t in np.arange(0.05, 61.0, 0.1)],
                    key=lambda e: (e[0], e[1]))
    node = np.full((len(stamps), 2), np.nan)
    yaw, cov = np.full(len(stamps), np.nan), np.full((len(stamps), 3, 3),
                                                     np.nan)
    for now, kind, item in events:
        out = pipeline.odometry(*item, now=now) if kind == 0 else \
            pipeline.answer(position_answer(scans[item], sigma[item]),
                            stamps[item], now, item) if kind == 1 else \
            pipeline.tick(now)
        for p in out.poses:
            if p.source is not None:
                node[p.source], yaw[p.source], cov[p.source] = \
                    p.xy, p.yaw, p.cov
    assert np.isfinite(node).all()
    np.testing.assert_array_equal(offline[0], node)
    np.testing.assert_array_equal(offline[1], yaw)
    np.testing.assert_array_equal(offline[2], cov)


def test_a_set_pose_names_its_place_by_its_frame_or_is_refused():
    """One place per frame, or the current one of a frame for several."""
    pipeline = ScanPipeline(fusion=Fusion(seed=0))
    xy = np.array([1.0, 2.0])
    assert 'no place' in pipeline.set_pose(0.0, xy, 0.0, 0.1, 0.1, [])
    # one frame for every floor: only once the current place is known
    both = [(0, 0), (0, 1)]
    assert 'several places' in pipeline.set_pose(0.0, xy, 0.0, 0.1, 0.1,
                                                 both)
    pipeline.answer(position_answer([5.0, 5.0], 2.0, (0, 1)), 1.0, 1.0)
    assert pipeline.set_pose(1.5, xy, 0.0, 0.1, 0.1, both) is None
    fusion = pipeline.fusion.fusion
    assert fusion.place == (0, 1) and fusion.counts['set_pose'] == 1
    assert 'yaw_sd' in pipeline.set_pose(2.0, xy, 0.0, 0.1, -1.0, both)
    pipeline.configure(fusion=False)
    assert pipeline.set_pose(2.0, xy, 0.0, 0.1, 0.1, both) == \
        'fusion is off'
    assert 'no position output' in ScanPipeline().set_pose(
        2.0, xy, 0.0, 0.1, 0.1, both)
