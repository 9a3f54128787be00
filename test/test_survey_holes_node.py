"""
classifier_node driving through places its survey never covered (DDS).

A scripted drive round surveyed_csv's building with odometry; on one side
the scans snap to the spot where the survey ends (the robot drives 15 m
on), and on another they jump 8 m aside for 6 s. The fused ``~/pose``
follows odometry there, with no jump, its ellipse growing while the
scans are not trusted; the health counts the scans trusted less. Scans
5 m off for a minute that move as the robot does (a corridor the survey
took for another) are believed: the pose is dragged, and once they end it
is moved back to where odometry carried the pose it had before them
(hindsight, with the odometry's drift known; counted in the health).
Where the survey really has a hole (a model trained without a third of
the floor), the scans taken there sound unlike the references they are
placed at: the node widens them and counts them.
"""

import math

from conftest import FAST, python_module, run, surveyed_csv, wait_until
import numpy as np
import pytest
from ros_helpers import running_node
from test_fusion_node import (Drive, health, odometry_of, RELIABLE_ODOM,
                              square)
from test_place_changes import ORIGIN
from wifi_place_recognition.core.artifact import load_model, save_model
from wifi_place_recognition.core.filter.particles import FusionParams


@pytest.fixture
def fitted_model(surveyed_model, tmp_path):
    """Return surveyed_model with a known drift (as fit_odometry writes)."""
    model = load_model(surveyed_model)
    model.fusion = FusionParams(drift_sd=0.005, fit={'drift': 'known'})
    save_model(model, tmp_path / 'fitted.npz')
    return tmp_path / 'fitted.npz'


def snap_and_jump():
    """
    Return where a drive's scans say the robot is, by time and place.

    ``where(since, x, y)`` -> (x, y, kind): 'snap' on the first lap's
    second side, taken, in the survey's eyes, where it ends; 'jump' for
    6 s of the second lap's second side, 8 m aside; '' elsewhere, where
    the robot is.
    """
    snap_from = []

    def where(since, x, y):
        if 30 <= since < 45:
            snap_from[:] = snap_from or [x, y]
            return (*snap_from, 'snap')
        if 130 <= since < 136:
            return x - 8.0, y, 'jump'
        return x, y, ''
    return where


def twin(since, x, y):
    """Return where a twin puts the scans: 5 m off (-y), from 60 to 120 s."""
    if 60 <= since < 120:
        return x, y - 5.0, 'twin'
    return x, y, ''


def drive_with_holes(drive, laps, where, every=10):
    """
    Drive the square ``laps`` times; return true xy, fused xy, sd, kind.

    Arrays, one row per scan; odometry without drift (the pose can follow
    it closely); each scan is taken where ``where(since, x, y)`` says: (x,
    y, kind).
    """
    truth = square(laps=laps)
    odometry = odometry_of(truth, drift=0.0)
    out = []
    for i in range(len(truth)):
        drive.send_odometry(odometry[i])
        if i % every != every - 1 or i + 1 >= len(truth):
            continue
        drive.send_odometry(odometry[i + 1])     # covers the scan
        t, x, y, _ = truth[i]
        sx, sy, kind = where(t - truth[0, 0], x, y)
        _, pose = drive.scan(t, sx, sy)
        p = pose.pose.pose.position
        cov = np.array(pose.pose.covariance).reshape(6, 6)
        out.append(((x + ORIGIN[0], y + ORIGIN[1]), (p.x, p.y),
                    math.sqrt(cov[0, 0] + cov[1, 1]), kind))
    return tuple(np.array(column) for column in zip(*out))


def test_the_pose_follows_odometry_where_the_survey_has_no_scan(
        ros, tmp_path, surveyed_model):
    with running_node(ros, tmp_path, surveyed_model,
                      'holes_node', *RELIABLE_ODOM) as (client, proc, _):
        drive = Drive(ros, client, 'holes_node')
        true, fused, sd, kind = drive_with_holes(drive, 1.8,
                                                 snap_and_jump())
        error = np.linalg.norm(fused - true, axis=1)
        for k in ('snap', 'jump'):
            assert (kind == k).sum() >= 5, kind
            # the scans were up to 15 m (snap) and 8 m (jump) off
            assert error[kind == k].max() < 2.5, (k, error[kind == k])
        # no jump: each pose moved about as far as the robot (1 m a scan)
        steps = np.linalg.norm(np.diff(fused, axis=0), axis=1)
        inside = (kind[1:] != '') | (kind[:-1] != '')
        assert steps[inside].max() < 2.0, steps[inside]
        # the ellipse grows through the stretch the scans are not trusted
        snap = np.flatnonzero(kind == 'snap')
        assert sd[snap[-1]] > sd[snap[0] - 1], sd[snap[0] - 1:snap[-1] + 1]
        assert wait_until(lambda: int(health(client)[
            'fusion_scans_off_track']) >= 5, 10, ros), health(client)


def test_a_pose_dragged_by_a_twin_corridor_comes_back(
        ros, tmp_path, fitted_model):
    with running_node(ros, tmp_path, fitted_model,
                      'twin_node', *RELIABLE_ODOM) as (client, proc, _):
        drive = Drive(ros, client, 'twin_node')
        # 190 s: the heading known before the twin (about 40 s), 70 s after
        true, fused, _, kind = drive_with_holes(drive, 1.9, twin)
        error = np.linalg.norm(fused - true, axis=1)
        after = np.flatnonzero(kind == 'twin')[-1] + 1
        assert error[after - 1] > 3.0, error    # dragged
        # then it comes back: below 1 m within 30 s of covered scans (one
        # a second; issue 35's goal; 5 s today, 38 s without hindsight),
        # never farther off than where the twin ended
        assert (error[after:after + 30] < 1.0).any(), error[after:]
        assert error[after:].max() < error[after - 1] + 0.5, error[after:]
        assert wait_until(lambda: int(health(client)[
            'fusion_hindsight_moves']) >= 1, 10, ros), health(client)


@pytest.fixture
def holed_model(tmp_path):
    """
    Return a model of surveyed_csv's floor 0 with a survey hole.

    Not surveyed where x < 20 and y > 20 (m). The drive's square (8 to
    32 m, counter-clockwise from the south-west corner) enters that
    quarter a minute after it starts, its heading known, and drives 24 m
    in it round the north-west corner.
    """
    csv = surveyed_csv(tmp_path / 'all.csv', floors=(0,))
    lines = csv.read_text().splitlines()
    x = lines[0].split(',').index('X')

    def surveyed(line):
        cells = line.split(',')
        xy = np.array([float(cells[x]), float(cells[x + 1])]) - ORIGIN
        return not (xy[0] < 20.0 and xy[1] > 20.0)
    kept = [lines[0]] + [line for line in lines[1:] if surveyed(line)]
    (tmp_path / 'holed.csv').write_text('\n'.join(kept) + '\n')
    result = run(python_module(
        'cli.train_model', '--data', tmp_path / 'holed.csv', '-o',
        tmp_path / 'holed.npz', *FAST, '--epochs', '20'))
    assert result.returncode == 0, result.stderr
    assert load_model(tmp_path / 'holed.npz').position.usual_mismatch > 0
    return tmp_path / 'holed.npz'


def test_scans_from_a_survey_hole_are_widened_and_counted(
        ros, tmp_path, holed_model):
    with running_node(ros, tmp_path, holed_model,
                      'holed_node', *RELIABLE_ODOM) as (client, proc, _):
        drive = Drive(ros, client, 'holed_node')
        true, fused, _, _ = drive_with_holes(
            drive, 1.0, lambda since, x, y: (x, y, ''))
        at = true - ORIGIN
        hole = (at[:, 0] < 17.0) & (at[:, 1] > 23.0)   # 3 m into it
        error = np.linalg.norm(fused - true, axis=1)
        # the scans there are answered at the hole's edge; the node
        # widens them (their misfit to odometry widens most of them too)
        assert hole.sum() >= 15, hole.sum()
        assert error[hole].max() < 3.5, error[hole]
        assert wait_until(lambda: int(health(client)[
            'fusion_scans_unlike_survey']) >= 10, 10, ros), health(client)
