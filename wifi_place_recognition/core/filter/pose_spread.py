"""
How sure the fused pose is: from how far the recent scans lie from it.

The particles' spread is the posterior of a deliberately wide sensor
model (a scan at least ``wifi_sd`` wide, over an outlier floor): on
surveyed ground it is wider than the pose's error, and where the scans of
a survey hole drag the particles along together it is narrower.
:class:`ScanOffsets` keeps the offsets of the last scans from the pose
after each was applied: their mean is where the scans, averaged along the
track, say the pose is wrong (their noise averages out, a pose that
crosses a hole on odometry or is left behind after one keeps them long).
Its length is the pose's standard deviation on each axis, once the
filter has settled (:attr:`ScanOffsets.settled`): a filter whose heading
was only just found follows the scans it found it from, biased or not,
and their offsets are small while it may be metres off; until then they
are a least width for the particles' spread, which a young filter's
error can exceed too (ROS-free).
"""

from collections import deque

import numpy as np

#: Scans applied with the heading known before the offsets are the pose's
#: variance (before: the least of the particles' spread).
SETTLE_SCANS = 30
#: The least standard deviation (m) reported: keeps the covariance
#: positive when the offsets happen to cancel.
LEAST_SD = 0.01


class ScanOffsets:
    """The offsets (m) of the last ``scans`` scans from the fused pose."""

    def __init__(self, scans):
        self.scans = int(scans)
        self.offsets = deque(maxlen=self.scans)
        self.known = 0      # scans applied since the heading was known
        self._variance = None

    def clear(self):
        """Forget them (the filter started afresh)."""
        self.offsets.clear()
        self.known = 0
        self._variance = None

    def add(self, scan_xy, pose_xy, heading_known):
        """
        Add a scan's position and the pose after it was applied.

        While the heading is not known, forget them all; with ``scans`` 0
        keep nothing. The variance is worked out here, once per scan, not
        per pose asked for.
        """
        if not self.scans:
            return
        if not heading_known:
            self.clear()
            return
        self.offsets.append(np.asarray(scan_xy, np.float64) -
                            np.asarray(pose_xy, np.float64))
        self.known += 1
        if len(self.offsets) == self.scans:
            mean = np.mean(self.offsets, axis=0)
            self._variance = max(float(mean @ mean), LEAST_SD ** 2)

    @property
    def settled(self):
        """
        Return True once the offsets are the pose's variance.

        After :data:`SETTLE_SCANS` scans (and ``scans``) added with the
        heading known; before, :meth:`variance` is a least one.
        """
        return self.known >= max(SETTLE_SCANS, self.scans)

    def variance(self):
        """
        Return the variance on each axis (m^2) the offsets say, or None.

        The squared length of the offsets' mean (at least
        :data:`LEAST_SD` squared); None until ``scans`` scans were added
        with the heading known, and with ``scans`` 0 (not used).
        """
        return self._variance
