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
is known (:attr:`.particles.FusionParams.drift_known`, as
``fit_odometry`` writes it) and every scan is believed
(``coverage_full`` 0, the default; with scans weighed by coverage, those
off the survey no longer drag the pose, the filter crosses a hole on
odometry, and scans still biased at the hole's edge agreed with a past
pose gone astray): one every
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
the poses kept after it are dropped, the older compared anew). No pose
wins unless those scans all sounded like the survey: inside a hole the
scans lie metres aside and may agree with a kept pose by chance.
ROS-free.
"""

import math

import numpy as np

from .pose_spread import SETTLE_SCANS

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


class Hindsight:
    """
    Past poses of the filter, and the one the recent scans favour.

    ``params``: the filter's :class:`.particles.FusionParams`
    (``hindsight_s``: how long a pose is kept, 0: none; ``hindsight_m``:
    the filter's mean offset from the scans from which a kept pose can
    win; none kept with the drift not known, ``drift_known``: scans
    biased the same way for seconds could agree with a pose gone astray,
    or ``coverage_full`` above 0); ``motion``: the filter's
    :class:`.motion.MotionModel`.
    """

    def __init__(self, params, motion):
        self.keep_s = float(params.hindsight_s) if \
            params.drift_known and not params.coverage_full \
            else 0.0
        self.offset_m = float(params.hindsight_m)
        self.motion = motion
        self.clear()

    def clear(self):
        """Forget the kept poses (the filter started afresh)."""
        self.stamps = np.empty(0)           # when each pose was kept
        self.state = np.empty((0, 4))       # each, carried: x, y, yaw, drift
        self.offsets = np.empty((0, SCANS, 2))  # the last scans' from each
        self.seen = np.empty(0, int)        # scans compared since kept
        self.filter_offsets = np.zeros((SCANS, 2))  # the same, the filter's
        self.slot = 0                       # where the next scan's go
        self.last = None    # when the last pose was kept
        self.known = 0      # scans in a row with the heading known
        self.like = 0       # scans in a row that sounded like the survey

    def move(self, forward, lateral, turn):
        """Carry every kept pose by one odometry step."""
        if self.stamps.size:
            self.motion.carry(self.state, forward, lateral, turn)

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
        self.stamps = np.append(self.stamps, stamp)
        self.state = np.vstack([self.state, [*estimate.xy, estimate.yaw,
                                             drift]])
        self.offsets = np.concatenate([self.offsets,
                                       np.zeros((1, SCANS, 2))])
        self.seen = np.append(self.seen, 0)
        self.last = stamp

    def _keep_only(self, rows):
        self.stamps, self.state, self.offsets, self.seen = (
            a[rows] for a in (self.stamps, self.state, self.offsets,
                              self.seen))

    def check(self, stamp, xy, before, like_survey=True):
        """
        Return the kept pose (x, y, yaw) the last scans favour, or None.

        ``xy``: the scan's position; ``before``: the filter's position
        before the scan was applied; ``like_survey``: False when the scan
        sounds unlike the survey (its offsets are still recorded; no pose
        wins until the last :data:`SCANS` scans sounded like it). The
        oldest pose that wins is returned (kept before a drag began; the
        younger may have been kept during it); it and the younger are
        dropped, the older are compared anew (one may win once the scans
        of the drag have left their window). Poses older than ``keep_s``
        are dropped.
        """
        self.like = self.like + 1 if like_survey else 0
        if self.stamps.size and stamp - self.stamps[0] > self.keep_s:
            self._keep_only(stamp - self.stamps <= self.keep_s)  # in order
        if not self.stamps.size:
            return None
        self.offsets[:, self.slot] = xy - self.state[:, :2]
        self.filter_offsets[self.slot] = xy - before
        self.slot = (self.slot + 1) % SCANS
        self.seen += 1
        own = math.hypot(*self.filter_offsets.mean(axis=0))
        theirs = np.hypot(*self.offsets.mean(axis=1).T)
        away = np.hypot(*(self.state[:, :2] - before).T)
        wins = (stamp - self.stamps >= MIN_AGE_S) & (self.seen >= SCANS) & \
            (theirs <= RATIO * own) & (away >= MIN_MOVE_M)
        if self.like < SCANS or own <= self.offset_m or not wins.any():
            return None
        i = int(np.argmax(wins))            # the oldest
        pose = tuple(float(v) for v in self.state[i, :3])
        self._keep_only(slice(0, i))        # kept before it: compared anew
        self.seen[:] = 0
        self.last = stamp
        return pose
