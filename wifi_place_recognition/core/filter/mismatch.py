"""
How unlike the survey the robot's recent scans sound (ROS-free).

A scan taken where the survey never went is placed at the nearest
surveyed stretch, but it hears the APs it shares with the references it
resembles most at other strengths than they did: its mismatch
(:meth:`.locator.Locator.mismatch`) is larger than the survey's usual one
on covered ground, which training learns from held-out stretches
(:meth:`.locator.Locator.relative_mismatch`: the ratio, the same in any
building). :class:`RecentMismatch` averages the last few scans' ratios:
one scan is noisy, a hole lasts.
"""

from collections import deque
import math


class RecentMismatch:
    """The mean mismatch (over the usual) of the last ``scans`` scans."""

    def __init__(self, scans):
        self.recent = deque(maxlen=max(int(scans), 1))

    def clear(self):
        """Forget the recent scans (another model, another place)."""
        self.recent.clear()

    def add(self, mismatch):
        """
        Add a scan's mismatch (NaN or None: not known); return the mean.

        The mean of the last ``scans`` known ones; None while none is.
        """
        if mismatch is not None and math.isfinite(mismatch):
            self.recent.append(float(mismatch))
        if not self.recent:
            return None
        return sum(self.recent) / len(self.recent)
