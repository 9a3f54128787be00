"""
How well a robot's recent scans move as its odometry says (ROS-free).

A scan's trust, from what the robot knows at run time: where the survey
has no scan, the k-NN positions snap to the nearest surveyed stretch (or
jump) while odometry says the robot drives on; where it has, they follow
the robot. :class:`TrackMisfit` measures the difference over the last
seconds; :class:`.sensor.WifiSensorModel` widens a scan by it.
"""

from collections import deque

import numpy as np


class TrackMisfit:
    """
    How far the recent scans' positions are from moving as odometry says.

    The scans of the last ``track_s`` seconds and the odometry poses at
    their stamps: the odometry track turned and shifted onto the scans'
    track (least squares, heading unknown), and what is left: its root
    mean square, or the newest scan's if larger (a scan that leaves the
    track is trusted less at once). Scans that snap to a surveyed stretch
    while the robot drives elsewhere, or jump while it stands, leave
    metres; scans that follow the robot leave about their own noise.
    """

    #: Fewer scans, or a shorter odometry track (m): no figure.
    MIN_SCANS = 5
    MIN_PATH = 2.0

    def __init__(self, seconds):
        self.seconds = seconds
        self.track = deque()    # (stamp, scan x + y j, odometry x + y j)

    def clear(self):
        """Forget the track (a restart, a gap in odometry)."""
        self.track.clear()

    def add(self, stamp, xy, odometry):
        """
        Add a scan and the odometry (x, y) at its stamp; return the misfit.

        None while the track is too short to say (:data:`MIN_SCANS`,
        :data:`MIN_PATH`).
        """
        self.track.append((stamp, complex(xy[0], xy[1]),
                           complex(odometry[0], odometry[1])))
        while self.track[0][0] < stamp - self.seconds:
            self.track.popleft()
        if len(self.track) < self.MIN_SCANS:
            return None
        _, scans, odo = np.array(self.track).T
        if np.abs(np.diff(odo)).sum() < self.MIN_PATH:
            return None
        left = np.abs(track_fit(scans, odo)[1])
        return float(max(np.sqrt((left * left).mean()), left[-1]))


def track_fit(scans, odometry):
    """
    Turn and shift an odometry track onto the scans' track (least squares).

    ``scans``, ``odometry``: positions as complex numbers (x + y j), one
    per scan. Return (turn, left): the unit complex number that turns the
    odometry (its angle: the map heading minus the odometry's), and what
    is left of each scan after the fit (complex, m).
    """
    scans = scans - scans.mean()
    odometry = odometry - odometry.mean()
    turn = np.vdot(odometry, scans)
    turn = turn / abs(turn) if turn else 1.0
    return turn, scans - odometry * turn
