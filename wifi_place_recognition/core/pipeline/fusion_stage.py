"""
The odometry fusion on the caller's clock: answers and odometry in, poses out.

:class:`FusionStage` feeds odometry and each answered scan's position to
a :class:`.filter.fusion.Fusion` in stamp order, and gives back the fused
poses with the caller's own stamp (``source``): one per scan, and with a
``pose_rate``, the pose at the newest odometry between scans (at
:meth:`FusionStage.tick`). ``now`` is the caller's clock (a monotonic one
on a robot, the stamps offline): a scan that finds odometry silent for
``odom_timeout`` seconds goes through at once, fused alone, and
:meth:`FusionStage.tick` lets a scan that waited ``odom_timeout`` through
alone. A pose is ``relocated`` when the filter started afresh on the
place it was on (the scans kept disagreeing with it, or WiFi alone for
long). Odometry faults (:data:`.filter.fusion.ODOMETRY_FAULTS`), scans
fused alone and errors inside the filter are problems (counted, never
raised); :meth:`FusionStage.health` says which one is recent.
"""

from dataclasses import replace
import math

from ..filter.fusion import ODOMETRY_FAULTS
from .outputs import Pose

#: Seconds after a problem during which health names it.
WARN_S = 10.0
#: Names of :class:`.filter.fusion.Fusion` counts in the health status
#: (after the odometry's own counts, in this order).
HEALTH_NAMES = {'odometry': 'odometry_received',
                'scans_fused': 'fusion_scans_fused',
                'scans_alone': 'fusion_scans_alone',
                'scans_other_place': 'fusion_scans_other_place',
                'scans_late': 'fusion_scans_late',
                'scans_off_track': 'fusion_scans_off_track',
                'scans_unlike_survey': 'fusion_scans_unlike_survey',
                'scans_without_position': 'fusion_scans_without_position',
                'restarts': 'fusion_restarts',
                'scans_replayed': 'fusion_scans_replayed',
                'hindsight_moves': 'fusion_hindsight_moves',
                'set_pose': 'fusion_set_pose',
                'scans_before_set_pose': 'fusion_scans_before_set_pose'}
#: Scans kept waiting for odometry at most (more: the oldest forgotten).
MAX_WAITING = 100
_NONE = object()


class FusionStage:
    """
    A :class:`.filter.fusion.Fusion` fed on the caller's clock.

    Each method takes ``problems`` (a list the problems are appended to)
    and returns [(:class:`.outputs.Pose`, relocated)].
    """

    def __init__(self, fusion, pose_rate=10.0):
        self.fusion = fusion
        self.pose_rate = pose_rate
        self.enabled = True
        self.counts_internal = 0
        self._last_problem = (None, -math.inf)   # (what, now)
        self._published_stamp = None
        self._place = None        # of the last pose given
        self._sources = {}        # scan stamp -> the caller's
        self._odometry_stamp = (None, None)   # the newest good one's
        self._odometry_arrival = -math.inf    # now, at the newest good one

    @property
    def active(self):
        """Return True when enabled and odometry has arrived."""
        return self.enabled and self.fusion.odometry_stamp is not None

    def configure(self, odom_timeout=None, pose_rate=None, enabled=None):
        """Change the timeout (s), the rate between scans (Hz), on/off."""
        if odom_timeout is not None:
            self.fusion.limits = replace(self.fusion.limits,
                                         odom_timeout=odom_timeout)
        if pose_rate is not None:
            self.pose_rate = pose_rate
        if enabled is not None:
            if not enabled:
                self.reset()
            self.enabled = enabled

    def reset(self):
        """Forget the filter and odometry: the next scan starts afresh."""
        self.fusion.reset()
        self._sources.clear()
        self._place = None

    def set_pose(self, stamp, xy, yaw, sd, yaw_sd, place):
        """Start the filter at a known pose (:meth:`.Fusion.set_pose`)."""
        self.fusion.set_pose(stamp, xy, yaw, sd, yaw_sd, place)
        self._place = place

    def scan(self, answer, place, confident, stamp, source, now, problems):
        """Feed one answer (:class:`.recognizer.Place`) at ``stamp`` (s)."""
        return self._guarded('on a scan', now, problems, self._scan, answer,
                             place, confident, stamp, source, now, problems)

    def odometry(self, stamp, x, y, yaw, now, source, what, problems):
        """Feed one odometry pose; ``what`` names it in a refusal."""
        if not self.enabled:
            return []
        return self._guarded('on odometry', now, problems, self._odometry,
                             stamp, x, y, yaw, now, source, what, problems)

    def tick(self, now, problems):
        """Let late scans through alone; the pose between scans, if due."""
        if not self.enabled:
            return []
        return self._guarded('in the fusion timer', now, problems,
                             self._tick, now, problems)

    def _guarded(self, where, now, problems, step, *args):
        """Run ``step``; an error is counted and a problem, never raised."""
        try:
            return step(*args)
        except Exception as exc:   # never let the filter stop the caller
            self.counts_internal += 1
            self._problem(f'internal error {where}: {exc!r}', now, problems)
            return []

    def _scan(self, answer, place, confident, stamp, source, now, problems):
        timeout = self.fusion.limits.odom_timeout
        stale = now - self._odometry_arrival > timeout
        self._sources[stamp] = source
        # The answer's fields handed to the filter: the one call site.
        released = self.fusion.scan(
            stamp, answer.scan_position, place, confident,
            now - 2 * timeout if stale else now,    # stale: no waiting
            answer.scan_sigma, coverage=getattr(answer, 'coverage', None),
            mismatch=getattr(answer, 'mismatch', None))
        if released is None:
            del self._sources[stamp]
            self._problem('a scan without a finite position: not fused', now,
                          problems)
            return []
        poses = self._emit(released)
        if stale:
            poses += self._expire(now, problems)
        if len(self._sources) > MAX_WAITING:     # never released: forget
            for key in list(self._sources)[:-MAX_WAITING]:
                del self._sources[key]
        return poses

    def _odometry(self, stamp, x, y, yaw, now, source, what, problems):
        fault, fused = self.fusion.odometry(stamp, x, y, yaw)
        if not fault:
            self._odometry_stamp = (stamp, source)
            self._odometry_arrival = now
        else:
            self._problem(f'{fault.replace("_", " ")}: odometry message '
                          f'skipped ({what})', now, problems)
        return self._emit(fused)

    def _tick(self, now, problems):
        poses = self._expire(now, problems)
        if self.pose_rate and \
                self.fusion.odometry_stamp != self._published_stamp:
            pose = self.fusion.pose()
            if pose is not None:
                poses += self._emit([pose])
        return poses

    def _expire(self, now, problems):
        """Release the scans that waited too long, fused alone; say so."""
        fused = self.fusion.expire(now)
        if fused:
            self._problem(f'no odometry covering {len(fused)} scan(s) '
                          f'within {self.fusion.limits.odom_timeout:g} s: '
                          f'fused alone (WiFi only)', now, problems)
        return self._emit(fused)

    def _emit(self, fused):
        out = []
        for pose in fused:
            source = self._sources.pop(pose.stamp, _NONE)
            if source is _NONE:     # between scans: the newest odometry's
                seconds, source = self._odometry_stamp
                if seconds != pose.stamp:
                    continue
            self._published_stamp = pose.stamp
            out.append((Pose(pose.stamp, source, pose.xy, pose.cov,
                             pose.place, pose.yaw),
                        pose.restarted and pose.place == self._place))
            self._place = pose.place
        return out

    def _problem(self, what, now, problems):
        self._last_problem = (what, now)
        problems.append(what)

    def health(self, now):
        """Return (problem or None, {count name: value}) for diagnostics."""
        counts = self.fusion.counts
        values = {HEALTH_NAMES.get(k, k): counts.get(k, 0) for k in
                  ('odometry', 'odometry_same_stamp') + ODOMETRY_FAULTS +
                  tuple(HEALTH_NAMES)[1:]}
        values['fusion_internal_errors'] = self.counts_internal
        what, when = self._last_problem
        silent = now - self._odometry_arrival
        if self.active and silent > self.fusion.limits.odom_timeout:
            return f'no odometry for {silent:.1f} s', values
        return (what if now - when < WARN_S else None), values
