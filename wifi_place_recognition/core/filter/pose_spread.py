"""
How sure the fused pose is: from how far the recent scans lie from it.

The particles' spread is the posterior of a deliberately wide sensor
model (a scan at least ``wifi_sd`` wide, over an outlier floor): on
surveyed ground it is wider than the pose's error, and where the scans of
a survey hole drag the particles along together it is narrower.
:class:`ScanOffsets` keeps the offsets of the last scans from the pose
after each was applied: their mean is where the scans, averaged along the
track, say the pose is wrong (their noise averages out, a drag or a pose
left behind by scans that moved on does not). Its length is the pose's
standard deviation on each axis (ROS-free).
"""

from collections import deque

import numpy as np

#: The least standard deviation (m) reported: keeps the covariance
#: positive when the offsets happen to cancel.
LEAST_SD = 0.01


class ScanOffsets:
    """The offsets (m) of the last ``scans`` scans from the fused pose."""

    def __init__(self, scans):
        self.offsets = deque(maxlen=max(int(scans), 1))
        self.scans = int(scans)

    def clear(self):
        """Forget them (the filter started afresh)."""
        self.offsets.clear()

    def add(self, scan_xy, pose_xy):
        """Add a scan's position and the pose after it was applied."""
        self.offsets.append(np.asarray(scan_xy, np.float64) -
                            np.asarray(pose_xy, np.float64))

    def variance(self):
        """
        Return the pose's variance on each axis (m^2), or None.

        The squared length of the offsets' mean (at least
        :data:`LEAST_SD` squared); None while fewer than ``scans`` scans
        were added since the start, or with ``scans`` 0 (not used).
        """
        if not self.scans or len(self.offsets) < self.scans:
            return None
        mean = np.mean(self.offsets, axis=0)
        return max(float(mean @ mean), LEAST_SD ** 2)
