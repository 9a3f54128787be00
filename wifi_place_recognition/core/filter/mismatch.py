"""
How unlike the survey the robot's recent scans sound (ROS-free).

A scan taken where the survey never went is placed at the nearest
surveyed stretch, but it hears the APs it shares with the references it
resembles most at other strengths than they did: its mismatch
(:meth:`.locator.Locator.mismatch`) is larger than the survey's usual one
on covered ground, which training learns from held-out stretches
(:meth:`.locator.Locator.relative_mismatch`: the ratio, the same in any
building). :class:`RecentMismatch` averages the last few scans' ratios:
one scan is noisy, a hole lasts. :class:`UnlikeRun` counts how long a
run of such scans has lasted: all along a hole its scans are placed at
the same surveyed stretch, so their errors are one, not many.
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


class UnlikeRun:
    """
    How many scans in a row sound unlike the survey, met by a settled filter.

    A run is counted from a scan that sounds unlike the survey while the
    filter can follow odometry through it: settled
    (:attr:`.pose_spread.ScanOffsets.settled`: its heading known, its
    pose where the scans have said for a while) with the odometry's drift
    known (:attr:`.particles.FusionParams.drift_known`: without, a pose
    that follows odometry through a long hole goes astray;
    ``benchmarks/fusion.py`` run before this rule, not fitted: b24's
    largest error after 60 s 6.7 -> 15.9 m). A young filter may hold a
    wrong heading that those scans still correct, so a run it meets is
    not counted, to its end; nor is one without odometry (the scans
    applied alone, or after an odometry jump: :class:`.fusion.Fusion`
    clears it). With ``pose_scans`` 0 the filter never settles
    (:class:`.pose_spread.ScanOffsets` keeps nothing): no run counts.
    """

    def __init__(self):
        self.scans = 0          # in the run so far
        self.counted = False    # met by a settled filter

    def clear(self):
        """Forget the run (the filter started afresh)."""
        self.scans = 0

    def add(self, unlike, settled, drift_known):
        """Add a scan; return the run's length, this scan included (0: none)."""
        if not unlike:
            self.scans = 0
            return 0
        if not self.scans:
            self.counted = settled and drift_known
        self.scans += 1
        return self.scans if self.counted else 0
