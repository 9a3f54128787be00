"""
The labelling rule: the localiser's pose at a scan's stamp (ROS-free).

One rule for the recorders, live, and the bags, offline. A scan taken at
``t`` gets the pose interpolated between the localiser's poses just before
and just after ``t`` (x, y linearly, yaw along the shorter arc) when both
are at most ``max_pose_age`` seconds from ``t`` (and in one frame: a
bag's poses, one building and floor, are taken as one map's); else
the pose nearest ``t``, if that one is (AMCL publishes only after the
robot moved, so while it stands still one side is missing); else none.
:data:`MAX_POSE_AGE`, the default, is chosen on the shared robot runs
(doc/your-building.md, "Bags in").

Live, a scan is labelled once a pose at or after its stamp has arrived,
or once a stamp more than ``max_pose_age`` past it has (:class:`HeldScans`).
"""

from bisect import bisect_left, bisect_right
from collections import deque, namedtuple
import math

#: A pose of the localiser: stamp (s), x, y (m), yaw (rad), frame.
Pose = namedtuple('Pose', 'stamp x y yaw frame')
#: s: the default largest time between a scan and a pose that labels it.
MAX_POSE_AGE = 5.0


def pair(stamps, t, max_age, frames=None):
    """
    Return (i, j, w): the poses that label a scan taken at ``t``, or None.

    ``stamps``: the poses' stamps (s), ascending; ``frames``: their frames
    (None: one frame). Interpolated: ``i`` the last pose at or before
    ``t``, ``j`` the first at or after it, ``w`` the weight of ``j``. The
    nearest pose ``k``: (k, k, 0.0).
    """
    i, j = bisect_right(stamps, t) - 1, bisect_left(stamps, t)
    near = [k for k in (i, j)
            if 0 <= k < len(stamps) and abs(stamps[k] - t) <= max_age]
    if len(near) == 2 and (frames is None or frames[i] == frames[j]):
        span = stamps[j] - stamps[i]
        return i, j, (t - stamps[i]) / span if span > 0 else 0.0
    if not near:
        return None
    k = min(near, key=lambda k: abs(stamps[k] - t))
    return k, k, 0.0


def blend(a, b, w):
    """Return (x, y, yaw) ``w`` of the way from pose ``a`` to pose ``b``."""
    yaw = a.yaw + w * math.remainder(b.yaw - a.yaw, math.tau)
    return (a.x + w * (b.x - a.x), a.y + w * (b.y - a.y),
            math.atan2(math.sin(yaw), math.cos(yaw)))


#: Poses a :class:`HeldScans` keeps by default (about 8 minutes of
#: AMCL's while driving) to label the scans held.
POSE_HISTORY = 500
#: Seconds after every stamp before it from which a scan's stamp is taken
#: for a clock gone wrong (or a long pause): it is labelled at once.
SKEW_S = 60.0


class HeldScans:
    """
    Scans held until the rule can label them, live, in arrival order.

    Poses (objects with ``stamp``, ``x``, ``y``, ``yaw``, ``frame``) are
    kept in stamp order, the newest ``history``. A scan waits until a pose
    at or after its stamp has arrived, or a scan or pose stamped more than
    ``max_age`` after it (the stamps' clock): no later pose can label it
    then. A scan stamped far after everything before it (:meth:`hold`)
    waits for nothing, and at most ``history`` wait. :meth:`release`
    returns the scans ready, each with the poses that label it,
    :meth:`release` with ``everything`` all of them (the recorder stops:
    labelled with what is there).
    """

    def __init__(self, history=POSE_HISTORY):
        self.history = history
        self.stamps, self.poses = [], []
        self.held = deque()         # (stamp, scan)
        self.newest = -math.inf     # the newest stamp seen

    def add_pose(self, pose):
        """Keep a pose of the localiser (in stamp order)."""
        k = bisect_right(self.stamps, pose.stamp)
        self.stamps.insert(k, pose.stamp)
        self.poses.insert(k, pose)
        if len(self.stamps) > self.history:
            del self.stamps[0], self.poses[0]
        self.newest = max(self.newest, pose.stamp)

    def hold(self, stamp, scan, max_age):
        """
        Hold ``scan``, taken at ``stamp`` (s), until it can be labelled.

        A stamp more than :data:`SKEW_S` (or ``max_age``, if longer) after
        every stamp before it (a clock gone wrong, or a long pause) waits
        for nothing.
        """
        self.held.append((stamp, scan,
                          stamp > self.newest + max(SKEW_S, max_age)))
        self.newest = max(self.newest, stamp)

    def release(self, max_age, everything=False):
        """
        Return [(stamp, scan, label)] of the scans ready, in arrival order.

        ``label``: (pose before, pose after, weight of the after) by
        :func:`pair`, the same pose twice for the nearest, or None.
        """
        out = []
        while self.held:
            stamp, scan, ahead = self.held[0]
            # nor does the oldest of more than ``history`` held
            if not (everything or ahead or len(self.held) > self.history
                    or self.stamps and self.stamps[-1] >= stamp
                    or self.newest > stamp + max_age):
                break
            self.held.popleft()
            found = pair(self.stamps, stamp, max_age,
                         [p.frame for p in self.poses])
            out.append((stamp, scan, found and (
                self.poses[found[0]], self.poses[found[1]], found[2])))
        return out
