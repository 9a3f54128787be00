"""
Odometry + WiFi on stamped streams: the filter's timeline (ROS-free).

:class:`Fusion` takes odometry poses (``odom`` frame) and scan answers
(``map`` frame position, with the recognised place) as they
arrive, and applies them to a :class:`.particles.ParticleFilter` in stamp
order: a scan waits until odometry covering its stamp has arrived, and is
applied at the odometry pose interpolated to its stamp. Between scans the
particles move in steps of ``step_m`` / ``step_rad``; the pose in between
is the filter's estimate carried forward by the odometry since.

Odometry is input like any other (:meth:`Fusion.odometry` returns why a
message was refused): a non-finite pose or a stamp before the previous
one is counted and skipped; a jump faster than ``max_speed`` /
``max_turn_rate`` (a reset to zero, a teleport) is counted and the filter
continues from the jumped pose as if the robot had not moved; a stamp
more than ``clock_reset`` before the previous one (a clock restarted) is
counted and starts a new odometry timeline. A stamp equal to the previous
one is skipped and counted as no fault (the next pose carries its
motion). A scan that waited ``odom_timeout`` seconds (on the clock of its
``arrival``) without odometry covering it is applied alone: the particles
spread by ``idle_speed`` and ``idle_turn_rate`` per second since the last
scan, or start afresh at the scan when that spread exceeds a start's.
:meth:`Fusion.set_pose` starts the filter at a pose known otherwise (a
dock's, an operator's), heading included, which a start from a scan
lacks. Two confident scans in a row of another building/floor restart
the filter there (a lift); a scan of another place is otherwise not
applied, and gets the current pose. Each scan is weighed as far as it is
trusted: its misfit to odometry over the last seconds
(:class:`.track_misfit.TrackMisfit`) widens it (the scans it widened are
counted: ``scans_off_track``), and so does the recent scans' mismatch
with the survey (:class:`.mismatch.RecentMismatch`; the scans widened
more than halfway: ``scans_unlike_survey``), the more the longer they
have sounded unlike it to a settled filter that knows the odometry's
drift (:class:`.mismatch.UnlikeRun`: a hole's scans count about as
one). When the scans keep disagreeing with the particles (a kidnapped robot:
:meth:`.particles.ParticleFilter.update`), the filter starts afresh at
the first of the last ``reset_after`` scans and applies them again with
the odometry between them (when each of them was applied with odometry):
it restarts with their evidence, not one scan's.
A pose dragged aside by scans from a place the survey took for another
is moved back to a past pose of the filter carried forward by odometry
once the recent scans agree with that one and not with it, and sound
like the survey (:mod:`.hindsight`: with a fitted drift, every scan
believed; counted: ``hindsight_moves``).
Between scans the particles move up to ``move_lag`` behind the newest
odometry. Once the filter has settled, the pose's covariance on x and y
is how far the last ``pose_scans`` scans lie from it
(:mod:`.pose_spread`), not the particles' spread; before, the
particles' spread, at least as wide as that.
"""

from collections import Counter, deque
from dataclasses import dataclass
import math

import numpy as np

from ..place_switch import PlaceSwitch
from .angles import wrap
from .hindsight import Hindsight
from .mismatch import RecentMismatch, UnlikeRun
from .particles import DISAGREED, ParticleFilter, UNKNOWN_VARIANCE
from .pose_spread import ScanOffsets
from .track_misfit import TrackMisfit

#: Why odometry or a scan was not applied (counted in ``Fusion.counts``).
ODOMETRY_FAULTS = ('odometry_invalid', 'odometry_out_of_order',
                   'odometry_jump', 'odometry_clock_reset')


@dataclass(frozen=True)
class FusionLimits:
    """What the timeline accepts, and how it steps (seconds, m, rad)."""

    odom_timeout: float = 1.0     # s: a scan waits this long for odometry
    clock_reset: float = 1.0      # s: a stamp this far back: a new timeline
    move_lag: float = 1.0         # s: particles move up to this far behind
    #                               the newest odometry (a scan on its way)
    max_speed: float = 3.0        # m/s: faster is a jump
    max_turn_rate: float = 6.0    # rad/s: faster is a jump
    step_m: float = 0.5           # move the particles every this far
    step_rad: float = 0.3         # ... or this much turned
    history: int = 2000           # odometry poses kept at most

    def __post_init__(self):
        """Refuse non-positive or non-finite limits, naming the field."""
        for name, value in vars(self).items():
            if not (isinstance(value, (int, float)) and math.isfinite(value)
                    and value > 0):
                raise ValueError(f'{name} = {value!r}: expected a finite '
                                 f'number > 0')


@dataclass
class FusedPose:
    """The fused pose at one stamp, in the map frame."""

    stamp: float
    xy: np.ndarray       # (2,) m
    yaw: float           # rad
    cov: np.ndarray      # (3, 3): x, y, yaw
    with_odometry: bool  # False: the scan was applied alone (odometry stale)
    restarted: bool      # the filter started afresh at this scan
    place: tuple         # (building, floor) the filter was on for it


def relative(a, b):
    """Return (forward, lateral, turn) from pose ``a`` to ``b`` (x, y, yaw)."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    c, s = math.cos(a[2]), math.sin(a[2])
    return c * dx + s * dy, -s * dx + c * dy, float(wrap(b[2] - a[2]))


def compose(xy, yaw, step):
    """Return (xy, yaw) after ``step`` (forward, lateral, turn)."""
    forward, lateral, turn = step
    c, s = math.cos(yaw), math.sin(yaw)
    return (np.array([xy[0] + c * forward - s * lateral,
                      xy[1] + s * forward + c * lateral]),
            float(wrap(yaw + turn)))


class Fusion:
    """
    The filter fed by stamped odometry and scans, in stamp order.

    ``sensor``: the filter's sensor model (default: a
    :class:`.sensor.WifiSensorModel` of ``params``); it builds each scan's
    measurement from its answer (position, sigma, misfit).

    :meth:`odometry` and :meth:`scan` return the fused poses of the scans
    they let through (a scan may wait for odometry); :meth:`expire` lets
    scans through alone once odometry is late; :meth:`pose` is the pose at
    the newest odometry, between scans.
    """

    def __init__(self, params=None, limits=None, seed=0, sensor=None):
        self.filter = ParticleFilter(params, seed, sensor)
        self.switch = PlaceSwitch()
        self.misfit = TrackMisfit(self.filter.params.track_s)
        self.offsets = ScanOffsets(self.filter.params.pose_scans)
        self.mismatch = RecentMismatch(self.filter.params.mismatch_scans)
        self.unlike_run = UnlikeRun()
        self.hindsight = Hindsight(self.filter.params, self.filter.motion)
        self.limits = limits or FusionLimits()
        self.counts = Counter()
        self.reset()

    def reset(self):
        """Forget everything but the counts: the next scan starts afresh."""
        self.odom = deque(maxlen=self.limits.history)  # (t, x, y, yaw)
        self.pending = []       # (stamp, xy, place or None: not applied,
        #                         arrival, sigma, coverage, mismatch), in
        #                         stamp order
        self.anchor = None      # the odometry pose the particles are at
        self.set_at = None      # a set pose's stamp, waiting for odometry
        self.place = None
        self.switch.reset()     # to another place: PlaceSwitch's rule
        self.last_scan = None   # stamp of the last scan applied
        self.filter.state = None
        self.misfit.clear()     # the recent scans' track
        self.offsets.clear()    # the recent scans' offsets from the pose
        self.hindsight.clear()  # the filter's past poses
        self.mismatch.clear()   # the recent scans' mismatch
        self.unlike_run.clear()  # how long they have sounded unlike it
        self.spread = 0.0       # the particles' variance at the last scan
        self.applied = deque(maxlen=self.filter.params.reset_after)
        #                         the last scans applied with odometry since
        #                         the filter started, for a restart: (stamp,
        #                         xy, sigma, coverage, recent mismatch,
        #                         odometry pose)

    def set_pose(self, stamp, xy, yaw, sd, yaw_sd, place):
        """
        Start the filter at a known pose (a dock's, an operator's).

        ``xy`` (m, map frame) and ``yaw`` (rad) at ``stamp`` on ``place``
        (building, floor), spread by ``sd`` (m) and ``yaw_sd`` (rad);
        ``yaw`` None: not known (every heading, as a start from a scan).
        Where odometry covers the stamp, a pose with a yaw is carried to
        the newest odometry by the motion since; before any odometry, the
        odometry at its stamp (the first after it) anchors it, as soon as
        odometry reaches the stamp. Scans waiting from before
        ``stamp`` are dropped (counted: ``scans_before_set_pose``).
        ValueError (naming the value) on a non-finite pose or stamp, or a
        spread not finite and >= 0.
        """
        xy = np.asarray(xy, np.float64)
        for name, value in (('stamp', stamp), ('yaw', yaw)):
            if value is not None and not math.isfinite(value):
                raise ValueError(f'set_pose: {name} {value!r} is not finite')
        if xy.shape != (2,) or not np.isfinite(xy).all():
            raise ValueError(f'set_pose: position {xy.tolist()!r}: expected '
                             f'two finite numbers')
        for name, value in (('sd', sd), ('yaw_sd', yaw_sd)):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f'set_pose: {name} {value!r}: expected a '
                                 f'finite number >= 0')
        kept = [item for item in self.pending if item[0] >= stamp]
        self.counts['scans_before_set_pose'] += len(self.pending) - len(kept)
        self.pending = kept
        self.anchor, self.set_at = None, stamp
        if self.odom:
            if yaw is not None:
                xy, yaw = compose(xy, yaw, relative(
                    self._odometry_at(stamp)[1:], self.odom[-1][1:]))
            self.anchor, self.set_at = self.odom[-1], None
        self.filter.start(xy, yaw, sd, yaw_sd)
        self.place = place
        self.switch.reset()
        self.misfit.clear()
        self.offsets.clear()
        self.unlike_run.clear()
        self.hindsight.clear()
        self.applied.clear()
        self.last_scan = stamp
        self.counts['set_pose'] += 1

    @property
    def odometry_stamp(self):
        """Return the newest odometry stamp, or None."""
        return self.odom[-1][0] if self.odom else None

    def odometry(self, stamp, x, y, yaw):
        """
        Take one odometry pose; return (fault or None, fused poses).

        The fault is one of :data:`ODOMETRY_FAULTS` (the pose is skipped).
        """
        pose = (float(stamp), float(x), float(y), float(yaw))
        if not all(map(math.isfinite, pose)):
            return self._fault('odometry_invalid'), []
        if self.odom:
            last = self.odom[-1]
            dt = pose[0] - last[0]
            if dt == 0:     # the next pose carries its motion
                self.counts['odometry_same_stamp'] += 1
                return None, []
            if dt < -self.limits.clock_reset:     # a new timeline
                self._reanchor(pose)
                return self._fault('odometry_clock_reset'), []
            if dt <= 0:
                return self._fault('odometry_out_of_order'), []
            step = relative(last[1:], pose[1:])
            if math.hypot(step[0], step[1]) > self.limits.max_speed * dt or \
                    abs(step[2]) > self.limits.max_turn_rate * dt:
                self._reanchor(pose)
                return self._fault('odometry_jump'), []
        self.odom.append(pose)
        self.counts['odometry'] += 1
        if self.set_at is not None and pose[0] >= self.set_at and \
                self.anchor is None:     # a pose set before any odometry
            self.anchor, self.set_at = self._odometry_at(self.set_at), None
        return None, self._advance()

    def _fault(self, reason):
        self.counts[reason] += 1
        return reason

    def _reanchor(self, pose):
        """
        After a jump: continue from ``pose`` as if no motion happened.

        The scans' track starts again: its odometry was in the old frame.
        """
        self.odom.clear()
        self.odom.append(pose)
        self.misfit.clear()
        self.hindsight.clear()  # carried by the old frame's odometry
        self.unlike_run.clear()  # followed on the old frame's odometry
        self.applied.clear()    # their odometry poses: the old frame
        if self.anchor is not None:
            self.anchor = pose

    def scan(self, stamp, xy, place, confident=True, arrival=None,
             sigma=None, coverage=None, mismatch=None):
        """
        Take one scan's answer; return the fused poses now available.

        ``place``: its (building, floor); the second confident scan in a
        row of another place restarts the filter there, any other scan of
        another place is not applied (its pose is the filter's).
        ``arrival``: when it arrived, on the clock :meth:`expire` is given
        (default: its stamp). ``sigma``: the scan's own (m; None: not
        known); ``coverage``: P(taken where the survey covers; None: not
        known); ``mismatch``: how unlike its nearest references it sounds,
        over the survey's usual (:meth:`.locator.Locator.relative_mismatch`;
        None or NaN: not known). A scan
        without a finite position is refused (counted, None returned).
        """
        xy = np.asarray(xy, np.float64)
        if not (xy.shape == (2,) and np.isfinite(xy).all() and
                math.isfinite(stamp)):
            self.counts['scans_without_position'] += 1
            return None
        moved = place != self.place and self.place is not None
        if moved:
            self.counts['scans_other_place'] += 1
        apply = self.switch.switches(self.place, place, confident) or \
            not moved
        self.pending.append((float(stamp), xy, place if apply else None,
                             float(stamp if arrival is None else arrival),
                             sigma, coverage, mismatch))
        self.pending.sort(key=lambda item: item[0])
        return self._advance()

    def expire(self, now):
        """
        Apply alone the scans that waited for odometry beyond the timeout.

        ``now``: the current time on the clock of the scans' ``arrival``.
        """
        out = []
        while self.pending and \
                now - self.pending[0][3] > self.limits.odom_timeout and \
                not self._covered(self.pending[0][0]):
            out.append(self._apply(self.pending.pop(0), odometry=False))
        return [pose for pose in out if pose is not None] + self._advance()

    def _covered(self, stamp):
        return bool(self.odom) and self.odom[-1][0] >= stamp

    def _advance(self):
        """Apply the pending scans that odometry covers, in stamp order."""
        out = []
        while self.pending and self._covered(self.pending[0][0]):
            out.append(self._apply(self.pending.pop(0), odometry=True))
        out = [pose for pose in out if pose is not None]
        if not self.pending and self.anchor is not None and self.odom:
            # not up to the newest: a scan still on its way lands after it
            target = self._odometry_at(self.odom[-1][0] -
                                       self.limits.move_lag)
            step = relative(self.anchor[1:], target[1:])
            if target[0] > self.anchor[0] and (
                    math.hypot(step[0], step[1]) >= self.limits.step_m or
                    abs(step[2]) >= self.limits.step_rad):
                self._move_to(target)
        return out

    def _odometry_at(self, stamp):
        """Return the odometry pose interpolated to ``stamp``."""
        odom = self.odom
        if stamp >= odom[-1][0]:
            return odom[-1]
        i = len(odom) - 1
        while i > 0 and odom[i - 1][0] > stamp:
            i -= 1
        if i == 0:
            return odom[0]
        (t0, x0, y0, a0), (t1, x1, y1, a1) = odom[i - 1], odom[i]
        f = (stamp - t0) / (t1 - t0)
        return (stamp, x0 + f * (x1 - x0), y0 + f * (y1 - y0),
                float(wrap(a0 + f * wrap(a1 - a0))))

    def _move_to(self, pose):
        step = relative(self.anchor[1:], pose[1:])
        self.filter.move(*step)
        self.hindsight.move(*step)
        self.anchor = pose
        while len(self.odom) > 2 and self.odom[1][0] <= pose[0]:
            self.odom.popleft()

    def _apply(self, scan, odometry):
        """Apply one pending scan (place None: only move to it); its pose."""
        stamp, xy, place, _, sigma, coverage, mismatch = scan
        if place is None and not self.filter.started:
            return None
        self.set_at = None      # a scan anchors the particles from now on
        restart = place is not None and (not self.filter.started or
                                         place != self.place)
        if odometry:
            at = self._odometry_at(stamp)   # the scan's own odometry pose
            late = self.anchor is not None and stamp < self.anchor[0]
            self.counts['scans_late'] += late
            # a late scan does not move the particles back
            pose = self._odometry_at(self.anchor[0]) if late and \
                not restart else at
            if restart or self.anchor is None:
                self.anchor = pose
            else:
                self._move_to(pose)
        else:
            self.anchor = None
            gap = stamp - self.last_scan if self.last_scan is not None \
                else 0.0
            if self.filter.params.idle_speed * gap > \
                    self.filter.params.start_sd and place is not None:
                restart = True      # WiFi alone long enough: no prior
            elif self.filter.started:
                self.filter.spread(max(gap, 0.0))
        if restart:
            self.filter.start(xy)
            self.offsets.clear()
            self.place = place
        if not odometry or restart:     # the scans' track starts again
            self.misfit.clear()
            self.unlike_run.clear()     # no odometry to follow, or young
            self.applied.clear()
            self.hindsight.clear()
        if place is not None:
            misfit = self.misfit.add(stamp, xy, at[1:3]) if odometry \
                else None
            sensor = self.filter.sensor
            recent = self.mismatch.add(mismatch)
            scan = sensor.measurement(xy, sigma, misfit, coverage, recent)
            unlike = sensor.sounds_like_survey(scan) < 1.0
            run = self.unlike_run.add(unlike, self.offsets.settled,
                                      self.filter.params.drift_known)
            if run:
                scan = sensor.measurement(xy, sigma, misfit, coverage,
                                          recent, run)
            self.counts['scans_off_track'] += sensor.off_track(scan)
            self.counts['scans_unlike_survey'] += \
                sensor.sounds_like_survey(scan) < 0.5
            if odometry:
                self.applied.append((stamp, xy, sigma, coverage, recent,
                                     at))
            before = self.filter.estimate().xy if \
                self.hindsight.stamps.size else None
            why = self.filter.update(scan)
            if why:
                restart = True
                self.misfit.clear()
                self.offsets.clear()
                self.unlike_run.clear()
                self.hindsight.clear()
                if why == DISAGREED and \
                        len(self.applied) == self.applied.maxlen:
                    self._replay()
                self.applied.clear()
            elif before is not None:
                self._look_back(stamp, xy, before, not unlike)
        self.counts['restarts'] += restart
        self.last_scan = stamp
        self.counts['scans_fused' if odometry else 'scans_alone'] += 1
        estimate = self.filter.estimate()
        if place is not None:
            self.offsets.add(xy, estimate.xy,
                             estimate.cov[2, 2] < UNKNOWN_VARIANCE)
            if odometry and self.hindsight.keep_s:     # hindsight on
                self.hindsight.keep(stamp, estimate, self.filter.drift(),
                                    estimate.cov[2, 2] < UNKNOWN_VARIANCE)
        self.spread = np.trace(estimate.cov[:2, :2]) / 2
        return FusedPose(stamp, estimate.xy, estimate.yaw,
                         self._covariance(estimate), odometry, restart,
                         self.place)

    def _look_back(self, stamp, xy, before, like_survey):
        """Move the particles to a past pose the last scans favour."""
        pose = self.hindsight.check(stamp, xy, before, like_survey)
        if pose is not None:
            self.filter.shift(pose[:2], pose[2])
            self.counts['hindsight_moves'] += 1

    def _covariance(self, estimate):
        """
        Return the pose's covariance.

        Once the filter has settled (:class:`.pose_spread.ScanOffsets`):
        the variance of the last ``pose_scans`` scans' offsets on x and y,
        plus what the particles spread since the last scan (odometry
        alone), and the particles' yaw variance; before, the particles'
        covariance, widened alike on x and y to at least the offsets'
        variance once ``pose_scans`` of them were kept with the heading
        known (a young filter that settled its heading wrong is metres
        off with a cloud narrower than that).
        """
        variance = self.offsets.variance()
        if variance is None:
            return estimate.cov
        cloud = np.trace(estimate.cov[:2, :2]) / 2     # on each axis
        if not self.offsets.settled:
            cov = estimate.cov.copy()
            cov[:2, :2] += max(variance - cloud, 0.0) * np.eye(2)
            return cov
        grown = max(cloud - self.spread, 0.0)
        cov = np.zeros((3, 3))
        cov[0, 0] = cov[1, 1] = variance + grown
        cov[2, 2] = estimate.cov[2, 2]
        return cov

    def _replay(self):
        """
        Start afresh at the first scan kept, and apply them all again.

        Each with its position, sigma, coverage and mismatch, and its
        misfit on the new track; the particles moved by the odometry
        between them, and on to where the particles were (:attr:`anchor`).
        """
        sensor = self.filter.sensor
        self.misfit.clear()
        before = None
        for stamp, xy, sigma, coverage, recent, at in self.applied:
            misfit = self.misfit.add(stamp, xy, at[1:3])
            scan = sensor.measurement(xy, sigma, misfit, coverage, recent)
            if before is None:
                self.filter.start(sensor.centre(scan))
            else:
                self.filter.move(*relative(before[1:], at[1:]))
            before = at
            self.filter.update(scan)
        self.filter.move(*relative(before[1:], self.anchor[1:]))
        self.counts['scans_replayed'] += len(self.applied)

    def pose(self):
        """
        Return the pose at the newest odometry, between scans, or None.

        The filter's estimate carried forward by the odometry since its
        last step (the covariance as at that step: :meth:`_covariance`).
        """
        if not self.filter.started or self.anchor is None or not self.odom:
            return None
        estimate = self.filter.estimate()
        xy, yaw = compose(estimate.xy, estimate.yaw,
                          relative(self.anchor[1:], self.odom[-1][1:]))
        return FusedPose(self.odom[-1][0], xy, yaw,
                         self._covariance(estimate), True, False, self.place)
