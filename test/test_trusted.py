"""The rule of a trusted scan (core.trusted), no ROS."""

from dataclasses import replace

from wifi_place_recognition.core.trusted import (
    is_jump, LocaliserPose, REASONS, TrustGate, TrustParams, untrusted)

P = TrustParams()
HERE = LocaliserPose(100.0, 5.0, 5.0, 0.0, 'map', 0.1)


def verdict(stamp=100.5, pose=HERE, last_jump=None, witness='agrees',
            place=(0, 1), confirmed=True):
    return untrusted(stamp, pose, last_jump, witness, place, P, confirmed)


def test_a_confident_localiser_labels_the_scan_also_where_wifi_cannot_tell():
    assert verdict() is None
    assert verdict(witness='cannot_tell') is None
    # evidence gathering against the localiser: not yet lost, not trusted
    assert verdict(witness='disagrees') == 'disagrees'


def test_nothing_is_trusted_while_lost_waiting_or_uncertain():
    assert verdict(witness='lost') == 'lost'
    assert verdict(witness='waiting') == 'witness_waiting'
    assert verdict(witness=None) == 'witness_waiting'
    assert verdict(witness='gone') == 'witness_gone'
    assert verdict(place=None) == 'no_place'
    assert verdict(pose=None) == 'no_pose'
    assert verdict(stamp=100.0 + P.max_pose_age + 0.1) == 'no_pose'
    assert verdict(pose=replace(HERE, sd=P.max_sd + 0.01)) == 'uncertain'
    assert verdict(pose=replace(HERE, sd=float('nan'))) == 'uncertain'
    assert verdict(last_jump=100.5 - P.settle_s + 0.1) == 'jumped'
    assert verdict(last_jump=100.5 - P.settle_s - 0.1) is None
    assert verdict(last_jump=101.0) == 'jumped'   # since the scan
    # settled, but WiFi has not agreed since the jump
    assert verdict(last_jump=100.5 - P.settle_s - 0.1,
                   confirmed=False) == 'unconfirmed'
    assert set(REASONS) == {'no_place', 'witness_waiting', 'witness_gone',
                            'lost', 'disagrees', 'no_pose', 'uncertain',
                            'jumped', 'unconfirmed'}


def test_a_jump_is_a_step_faster_than_driving_or_another_frame():
    # 1 s later: up to jump_m + max_speed * 1 s is driving
    near = replace(HERE, stamp=101.0, x=HERE.x + 1.4)
    far = replace(HERE, stamp=101.0, x=HERE.x + 1.6)
    assert not is_jump(HERE, near, P)
    assert is_jump(HERE, far, P)
    assert is_jump(HERE, replace(HERE, frame='map_f1'), P)
    assert LocaliserPose.sd_of(0.01, 0.04) == 0.2


def test_the_gate_labels_a_scan_with_the_poses_around_it_and_its_witness():
    gate = TrustGate()
    gate.witness, gate.place = 'agrees', (0, 1)
    assert gate.pose(HERE) is None
    gate.scan(100.5, 'a')
    gate.witness = 'lost'       # after the scan came: not its witness
    assert gate.release() == []     # waits for a pose after it
    assert gate.pose(replace(HERE, stamp=101.0, x=6.0)) is None
    [(stamp, scan, pose, place, why)] = gate.release()
    assert (stamp, scan, place, why) == (100.5, 'a', (0, 1), None)
    assert (pose.x, pose.sd) == (5.5, 0.1)
    gate.scan(101.5, 'b')       # while lost
    gate.witness = 'cannot_tell'
    gate.scan(101.6, 'c')
    jumped = replace(HERE, stamp=102.0, x=20.0)
    assert gate.pose(jumped).x == 6.0       # the pose before the jump
    assert [r[-1] for r in gate.release()] == ['lost', 'jumped']
    # agreeing before settle_s confirms nothing (a comparison made before
    # the jump may still say so); settled, WiFi cannot tell: not yet
    settled = 102.0 + P.settle_s
    gate.witness = 'agrees'
    gate.scan(settled - 0.5, 'd')
    gate.witness = 'cannot_tell'
    gate.scan(settled + 0.5, 'e')
    gate.witness = 'agrees'
    gate.pose(replace(jumped, stamp=settled + 1))
    assert [r[-1] for r in gate.release()] == ['jumped', 'unconfirmed']
    gate.scan(settled + 1.5, 'f')      # agrees, settled: confirmed
    gate.witness = 'cannot_tell'
    gate.scan(settled + 2.5, 'g')      # and stays so
    gate.pose(replace(jumped, stamp=settled + 3))
    assert [r[-1] for r in gate.release()] == [None, None]
