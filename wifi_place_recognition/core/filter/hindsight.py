"""
Hindsight: the filter's past poses, carried forward by odometry alone.

Scans from a place the survey took for another (a twin corridor, a hole
answered at the survey's edge) that move as the robot does are believed:
they drag the particles along and hold them together, and once the robot
is back on covered ground the dragged cloud comes back slowly. Entering
and leaving look alike to the scans (the same track, metres aside); what
tells them apart is history: the pose the filter had before the drag,
carried forward by odometry, is where the robot is when the scans agree
with it again.

:class:`Hindsight` keeps such poses when the odometry's heading drift
is known (a prior of at most :data:`MAX_DRIFT_SD`, as ``fit_odometry``
writes) and every scan is believed (``coverage_full`` 0, the default;
with scans weighed by coverage, those off the survey no longer drag the
pose, the filter crosses a hole on odometry, and scans still biased at
the hole's edge agreed with a past pose gone astray): one every
:data:`EVERY_S` seconds once the heading has been known for
:data:`.pose_spread.SETTLE_SCANS` scans in a row and while its standard
deviation is at most :data:`MAX_YAW_SD`, for ``hindsight_s`` seconds,
each moved by the odometry steps the particles move by (with the
particles' mean heading drift, no noise). At each scan it compares the
last :data:`SCANS` scans' mean offset from the filter's position (before
each was applied) with their mean offset from each kept pose: when the
filter's is longer than ``hindsight_m`` and a pose kept at least
:data:`MIN_AGE_S` ago, at least :data:`MIN_MOVE_M` away, has at most
:data:`RATIO` of it, the filter moves there (to the oldest such pose;
the poses kept after it are dropped, the older compared anew). ROS-free.
"""

from collections import deque
from dataclasses import dataclass, field
import math

import numpy as np

from .pose_spread import SETTLE_SCANS

#: Poses are kept only with a drift prior this narrow (rad per m;
#: ``fit_odometry`` writes its fit's standard error, at least 0.005, 0.005
#: on the shared runs; the default 0.04 is a drift not known):
#: a pose carried with a drift not yet learned goes astray, and scans
#: biased the same way for seconds can then agree with it.
MAX_DRIFT_SD = 0.01
#: A pose is kept every so many seconds (s).
EVERY_S = 10.0
#: ... while the filter's heading is known to this standard deviation.
MAX_YAW_SD = math.radians(20.0)
#: A kept pose is compared with the filter's once it is this old (s).
MIN_AGE_S = 20.0
#: The mean offset of this many scans is compared.
SCANS = 5
#: A kept pose wins with at most this share of the filter's offset.
RATIO = 0.6
#: ... and lying at least this far (m) from the filter's position.
MIN_MOVE_M = 2.0


def _offsets():
    return deque(maxlen=SCANS)


@dataclass
class Kept:
    """One past pose carried forward, and the last scans' offsets."""

    stamp: float
    state: np.ndarray                          # (1, 4): x, y, yaw, drift
    offsets: deque = field(default_factory=_offsets)          # from it
    filter_offsets: deque = field(default_factory=_offsets)   # the filter's


class Hindsight:
    """
    Past poses of the filter, and the one the recent scans favour.

    ``params``: the filter's :class:`.particles.FusionParams`
    (``hindsight_s``: how long a pose is kept, 0: none; ``hindsight_m``:
    the filter's mean offset from the scans from which a kept pose can
    win; none kept with ``drift_sd`` above :data:`MAX_DRIFT_SD` or
    ``coverage_full`` above 0); ``motion``: the filter's
    :class:`.motion.MotionModel`.
    """

    def __init__(self, params, motion):
        self.keep_s = float(params.hindsight_s) if \
            params.drift_sd <= MAX_DRIFT_SD and not params.coverage_full \
            else 0.0
        self.offset_m = float(params.hindsight_m)
        self.motion = motion
        self.clear()

    def clear(self):
        """Forget the kept poses (the filter started afresh, or moved)."""
        self.kept = []
        self.last = None    # when the last pose was kept
        self.known = 0      # scans in a row with the heading known

    def move(self, forward, lateral, turn):
        """Carry every kept pose by one odometry step."""
        for kept in self.kept:
            self.motion.carry(kept.state, forward, lateral, turn)

    def keep(self, stamp, estimate, drift, heading_known):
        """
        Keep the filter's pose after a scan at ``stamp`` (see the module).

        ``estimate``: the filter's :class:`.particles.Estimate`; ``drift``:
        the particles' mean heading drift (rad per m); ``heading_known``:
        the filter knows its heading at all.
        """
        self.known = self.known + 1 if heading_known else 0
        if self.keep_s <= 0 or self.known < SETTLE_SCANS or \
                estimate.cov[2, 2] > MAX_YAW_SD ** 2 or \
                (self.last is not None and stamp - self.last < EVERY_S):
            return
        self.kept.append(Kept(stamp, np.array(
            [[estimate.xy[0], estimate.xy[1], estimate.yaw, drift]])))
        self.last = stamp

    def check(self, stamp, xy, before):
        """
        Return the kept pose (x, y, yaw) the last scans favour, or None.

        ``xy``: the scan's position; ``before``: the filter's position
        before the scan was applied. The oldest pose that wins is
        returned (kept before a drag began; the younger may have been
        kept during it); it and the younger are dropped, the older are
        compared anew (one may win once the scans of the drag have left
        their window). Poses older than ``keep_s`` are dropped.
        """
        self.kept = [k for k in self.kept if stamp - k.stamp <= self.keep_s]
        for i, kept in enumerate(self.kept):    # the oldest first
            kept.offsets.append(xy - kept.state[0, :2])
            kept.filter_offsets.append(xy - before)
            if stamp - kept.stamp < MIN_AGE_S or len(kept.offsets) < SCANS:
                continue
            own = math.hypot(*np.mean(kept.filter_offsets, axis=0))
            theirs = math.hypot(*np.mean(kept.offsets, axis=0))
            away = math.hypot(*(kept.state[0, :2] - before))
            if own > self.offset_m and theirs <= RATIO * own and \
                    away >= MIN_MOVE_M:
                self.kept = self.kept[:i]   # kept before it: compared anew
                for older in self.kept:
                    older.offsets.clear()
                    older.filter_offsets.clear()
                self.last = stamp
                return tuple(float(v) for v in kept.state[0, :3])
        return None
