"""
The witness's streams paired in time (ROS-free).

:class:`Streams` keeps the localiser's newest pose (one stamped before it
is refused, unless the clock restarted), the fused poses' recent track
(how far the robot moved since a localiser stamp: AMCL publishes only
after it moved), the recent scans' positions (how far, on average, they
lie from that track) and when each witness is next due to judge (about
once per ``period`` of stamps).
"""

from collections import deque
import math

import numpy as np

from .witness_inputs import Pose, pose_problem

#: A localiser stamp this many seconds before the previous one: a new
#: timeline (a clock restarted), not a message out of order.
NEW_TIMELINE_S = 10.0
#: Fused poses kept for the distance moved since a localiser stamp, and
#: scans for their offset from the fused track.
HISTORY = 4000
#: A fused pose this share of ``period`` after the last judgement is
#: judged (scans a period apart have stamps a little closer, at times).
SLACK = 0.9


class Streams:
    """The localiser's newest pose, the fused track, the judgements due."""

    def __init__(self):
        self.local = None        # newest localiser Pose
        self.heard = False       # any localiser message, even refused
        self._behind = None      # the last stamp refused as before
        self.history = deque(maxlen=HISTORY)  # fused (stamp, x, y)
        self.scans = deque(maxlen=HISTORY)    # (stamp, frame, x, y)
        self.judged = {'fused': -math.inf, 'scans': -math.inf}

    def localiser(self, stamp, frame, xy, yaw, cov):
        """
        Take one localiser pose; return (why refused or None, restarted).

        A stamp before the previous one is refused, unless it follows
        another refused one and both lie more than :data:`NEW_TIMELINE_S`
        before it: a clock restarted (a bag or a simulation started
        again), taken with ``restarted`` True. A stale message resent
        stays refused.
        """
        self.heard = True
        problem = pose_problem(stamp, xy, yaw, cov)
        if problem is not None:
            return problem, False
        restarted = self.local is not None and stamp < self.local.stamp
        if restarted:
            behind, self._behind = self._behind, stamp
            if not (behind is not None and behind < stamp <
                    self.local.stamp - NEW_TIMELINE_S):
                return (f'stamp {stamp:.3f} s is before the previous one '
                        f'({self.local.stamp:.3f} s)'), False
        self._behind = None
        self.local = Pose.of(stamp, frame, xy, yaw, cov)
        return None, restarted

    def starts_over(self, stamp):
        """Return True if a fused pose at ``stamp`` begins a new timeline."""
        return bool(self.history) and stamp < self.history[-1][0]

    def fused(self, pose, period):
        """Add a fused Pose to the track; return True if a judgement is due."""
        if self.starts_over(pose.stamp):
            self.history.clear()        # a new timeline
            self.judged['fused'] = -math.inf
        self.history.append((pose.stamp, *pose.xy))
        return self.due('fused', pose.stamp, period)

    def scan(self, stamp, frame, xy):
        """Keep a scan's position for :meth:`scan_offset`."""
        if self.scans and stamp < self.scans[-1][0]:
            self.scans.clear()          # a new timeline
        self.scans.append((stamp, frame, *xy))

    def scan_offset(self, since, frame):
        """
        Return how far the scans since ``since`` lie from the fused track (m).

        The length of the mean offset of the scans in ``frame`` stamped
        from ``since`` on, within the track's span, from the fused
        position at each one's stamp (interpolated along the track); None
        if there is none.
        """
        if not self.history:
            return None
        track = []
        for row in reversed(self.history):     # back to the first before
            track.append(row)
            if row[0] < since:
                break
        track = np.array(track[::-1])
        rows = []
        for row in reversed(self.scans):
            if row[0] < max(since, track[0, 0]):
                break
            if row[1] == frame and row[0] <= track[-1, 0]:
                rows.append(row)
        if not rows:
            return None
        stamps = np.array([r[0] for r in rows])
        at = np.column_stack([np.interp(stamps, track[:, 0], track[:, i])
                              for i in (1, 2)])
        offsets = np.array([r[2:] for r in rows]) - at
        return float(np.linalg.norm(offsets.mean(axis=0)))

    def due(self, witness, stamp, period):
        """Return True if ``witness`` judges at ``stamp`` (``period`` s on)."""
        if stamp < self.judged[witness]:
            self.judged[witness] = -math.inf      # a new timeline
        if stamp - self.judged[witness] < SLACK * period:
            return False
        self.judged[witness] = stamp
        return True

    def moved_since(self, stamp):
        """Return how far the fused pose moved since ``stamp`` (m)."""
        if not self.history:
            return 0.0
        first = self.history[-1]
        for row in reversed(self.history):    # back to the first at stamp
            if row[0] < stamp:
                break
            first = row
        return float(math.dist(first[1:], self.history[-1][1:]))
