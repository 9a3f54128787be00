"""The labelling rule (core.pose_label), no ROS: one rule, live and offline."""

import math

import numpy as np
import pytest
from wifi_place_recognition.core.pose_label import (blend, HeldScans, pair,
                                                    Pose)
from wifi_place_recognition.data.bags import pose_labels

STAMPS = [10.0, 12.0, 20.0]
POSES = [Pose(10.0, 0.0, 0.0, 0.0, 'map'), Pose(12.0, 2.0, -4.0, 1.0, 'map'),
         Pose(20.0, 2.0, -4.0, 1.0, 'map')]


def label(t, max_age=5.0, poses=POSES):
    found = pair([p.stamp for p in poses], t, max_age,
                 [p.frame for p in poses])
    return found and blend(poses[found[0]], poses[found[1]], found[2])


def test_a_scan_between_two_poses_gets_the_pose_interpolated():
    assert pair(STAMPS, 10.5, 5.0) == (0, 1, 0.25)
    assert label(10.5) == pytest.approx((0.5, -1.0, 0.25))
    assert label(12.0) == pytest.approx((2.0, -4.0, 1.0))   # on a pose
    assert label(16.0) == pytest.approx((2.0, -4.0, 1.0))   # 4 s from both


def test_one_side_missing_or_too_old_gives_the_nearest_within_max_age():
    # before the first pose, after the last: the nearest
    assert pair(STAMPS, 8.0, 5.0) == (0, 0, 0.0)
    assert pair(STAMPS, 24.0, 5.0) == (2, 2, 0.0)
    # the pose after 6 s away, the one before 2 s: the one before
    assert pair([10.0, 18.0], 12.0, 5.0) == (0, 0, 0.0)
    assert pair([10.0, 18.0], 16.0, 5.0) == (1, 1, 0.0)
    # the two poses in different frames (another floor's map): the nearest
    other = POSES[:1] + [POSES[1]._replace(frame='map_f1')]
    assert label(11.5, poses=other) == pytest.approx((2.0, -4.0, 1.0))
    assert label(10.5, poses=other) == pytest.approx((0.0, 0.0, 0.0))


def test_no_pose_within_max_age_labels_nothing():
    assert pair([], 10.0, 5.0) is None
    assert pair(STAMPS, 4.9, 5.0) is None
    assert pair(STAMPS, 25.1, 5.0) is None
    assert pair([10.0, 30.0], 20.0, 5.0) is None
    assert pair(STAMPS, 4.9, 6.0) == (0, 0, 0.0)


def test_yaw_turns_the_shorter_way_across_plus_minus_pi():
    a = Pose(0.0, 0.0, 0.0, math.pi - 0.1, 'map')
    b = Pose(1.0, 0.0, 0.0, -math.pi + 0.1, 'map')
    yaw = blend(a, b, 0.25)[2]
    assert yaw == pytest.approx(math.pi - 0.05)
    assert blend(a, b, 0.75)[2] == pytest.approx(-math.pi + 0.05)
    assert abs(blend(a, b, 0.5)[2]) == pytest.approx(math.pi)
    assert blend(b, a, 0.25)[2] == pytest.approx(-math.pi + 0.05)


def test_the_bags_label_by_the_same_rule():
    poses = np.array([[p.stamp, p.x, p.y, p.yaw] for p in POSES])
    stamps = np.array([4.0, 8.0, 10.5, 16.0, 24.0, 26.0])
    xy, yaw = pose_labels(poses, stamps)
    for n, t in enumerate(stamps):
        expected = label(t)
        if expected is None:
            assert np.isnan(xy[n]).all() and np.isnan(yaw[n])
        else:
            assert (*xy[n], yaw[n]) == pytest.approx(expected)
    assert np.isnan(xy[[0, 5]]).all() and np.isfinite(xy[1:5]).all()


def test_held_scans_wait_for_a_pose_after_them_or_max_age():
    held = HeldScans(history=3)
    held.add_pose(POSES[0])
    held.hold(10.5, 'a', 5.0)
    held.hold(11.0, 'b', 5.0)
    assert held.release(5.0) == []          # no pose after them yet
    held.add_pose(POSES[1])
    (t, scan, (before, after, w)), (_, scan2, _) = held.release(5.0)
    assert (t, scan, before, after, w) == (10.5, 'a', POSES[0], POSES[1],
                                           0.25)
    assert scan2 == 'b'
    # standing still: no pose after; held until a stamp 5 s later
    held.hold(13.0, 'c', 5.0)
    held.hold(16.5, 'd', 5.0)
    assert held.release(5.0) == []
    held.hold(18.5, 'e', 5.0)
    (t, scan, (before, after, w)), = held.release(5.0)
    assert (scan, before, after) == ('c', POSES[1], POSES[1])
    # stopping: the rest, labelled with what is there, in order
    assert [(s, lab and lab[0].stamp) for _, s, lab in
            held.release(5.0, everything=True)] == [('d', 12.0), ('e', None)]
    # a late pose goes to its place; the oldest beyond history are dropped
    held.add_pose(POSES[2])
    held.add_pose(Pose(11.0, 1.0, 1.0, 0.0, 'map'))
    assert held.stamps == [11.0, 12.0, 20.0]


def test_a_scan_stamped_far_ahead_holds_up_nothing():
    held = HeldScans(history=50)
    held.add_pose(POSES[0])
    held.hold(10.5, 'a', 5.0)
    held.hold(10.5 + 1000.0, 'skewed', 5.0)     # a clock gone wrong
    held.hold(11.0, 'b', 5.0)
    held.add_pose(POSES[1])
    released = [scan for _, scan, _ in held.release(5.0)]
    assert released == ['a', 'skewed', 'b']
    # however many wait for a pose, at most ``history`` are held
    held = HeldScans(history=50)
    for k in range(60):
        held.hold(100.0 + 0.01 * k, k, 5.0)
    released = held.release(5.0)
    assert [scan for _, scan, _ in released] == list(range(10))
    assert len(held.held) == 50
