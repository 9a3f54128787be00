"""
Is the robot's localiser lost? WiFi as an independent witness (ROS-free).

:class:`Witness` takes the localiser's poses (e.g. AMCL's), the fused WiFi
+ odometry poses (:mod:`.filter.fusion`) and the scans' own positions (the k-NN
answer) as they arrive, and judges about once per ``period`` seconds of
their stamps whether they agree. Two witnesses, each with its own
evidence:

- the fused pose: paired with the newest localiser pose not after it,
  their distance in standard deviations is the position's Mahalanobis
  distance under the sum of both covariances, plus ``floor_sd`` (m) on
  each axis for what neither covariance knows, plus the distance the fused
  pose moved since the localiser's stamp (AMCL publishes only after it
  moved); the yaw's difference joins only when the fused yaw is known (its
  standard deviation below ``yaw_known_sd``). A fused pose wider than
  ``max_fused_sd`` (a filter that just started) is no evidence either way,
  nor is one while the recent scans' median sigma exceeds
  ``max_scan_sigma``: a scan unlike every surveyed one (the k-NN's sigma
  grows with that) says the robot is off the survey, where the scans snap
  to the nearest surveyed place and may drag the filter with them;
- the scans: the same with the scan's own sigma and ``scan_floor_sd``, and
  only a scan with a sigma up to ``max_scan_sigma`` where the survey covers
  the localiser's position (a reference within ``coverage_m``): a scan
  taken far from the survey snaps to the nearest surveyed place, so there
  it testifies nothing. The scans do not
  wait for the filter, which follows a kidnapped robot only after some
  time.

Evidence is a CUSUM over a witness's judgements: each adds its distance
minus ``agree_sigmas`` (at most ``max_step``); the sum stays between zero
and ``alarm``. At ``alarm`` (either witness) the localiser is lost: one
bad scan never alarms (``max_step`` < ``alarm``), a sustained disagreement
does, the sooner the larger it is. It is found again when both are back at
zero (after about ``alarm / agree_sigmas`` agreeing judgements). A
localiser in another frame than the fused pose's (another floor's map)
adds ``max_step`` per judgement; so does one silent for ``max_age`` s
while the fused pose moved ``silent_m`` from where it was at the
localiser's last stamp.

A pose to seed the localiser with (:attr:`Judgement.seed`) is the fused
pose when it is sure (position standard deviation at most ``sure_sd``,
yaw's at most ``sure_yaw_sd``): at start-up, while no localiser message
has been heard, and when the localiser is lost. The caller says when it
sent one (:meth:`Witness.seeded`): the evidence is cleared (the localiser
starts over) and no other is proposed for ``holdoff`` seconds.

Bad localiser poses (:func:`pose_problem`: not finite, covariance not
positive definite, stamps going backwards, unless far enough back to be
a restarted clock) are refused with a reason;
the caller counts them. Nothing here raises on input.
"""

from collections import deque
from dataclasses import dataclass, fields
import math

import numpy as np

from .filter.angles import wrap
from .filter.particles import UNKNOWN_VARIANCE

#: A localiser stamp this many seconds before the previous one: a new
#: timeline (a clock restarted), not a message out of order.
NEW_TIMELINE_S = 10.0
#: Fused poses kept for the distance moved since a localiser stamp.
HISTORY = 4000
#: Recent scans whose median sigma says whether the robot is surveyed.
COVERAGE_SCANS = 5
#: A fused pose this share of ``period`` after the last judgement is
#: judged (scans a period apart have stamps a little closer, at times).
SLACK = 0.9


@dataclass(frozen=True)
class WitnessParams:
    """
    How the witness judges (seconds, m, rad, standard deviations).

    The defaults of the thresholds the benchmark chooses (agree_sigmas,
    alarm, floor_sd, max_scan_sigma, yaw_floor_sd, sure_sd, sure_yaw_sd)
    are those it chose on the robot runs of building b24, which gave no
    false alarm on b14's (``benchmarks/witness.py``).
    """

    period: float = 1.0            # s between judgements (fused stamps)
    floor_sd: float = 0.5          # m added on each axis to both covariances
    yaw_floor_sd: float = math.radians(5.0)    # rad, the same for the yaw
    yaw_known_sd: float = math.radians(30.0)   # rad: wider fused yaw unknown
    max_fused_sd: float = 5.0      # m: a wider fused pose is no evidence
    scan_floor_sd: float = 2.0     # m added on each axis for a scan
    coverage_m: float = 2.0        # m: scans testify within this of the survey
    max_scan_sigma: float = 3.0    # m: recent scans wider: the robot is off
    #                                the survey, the fused pose no evidence
    agree_sigmas: float = 3.0      # a judgement this far apart is neutral
    max_step: float = 10.0         # most evidence one judgement adds
    alarm: float = 60.0            # evidence at which the localiser is lost
    max_age: float = 10.0          # s: an older localiser pose is silent
    silent_m: float = 5.0          # m moved with a silent localiser: lost
    sure_sd: float = 2.0           # m: a fused pose this sure may seed
    sure_yaw_sd: float = math.radians(15.0)    # rad, the same for its yaw
    holdoff: float = 30.0          # s between two seeds

    def __post_init__(self):
        """Refuse non-finite or non-positive values, naming the field."""
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or \
                    not isinstance(value, (int, float)) or \
                    not math.isfinite(value) or value <= 0:
                raise ValueError(f'witness parameter {f.name} = {value!r}: '
                                 f'expected a finite number > 0')
        if self.max_step >= self.alarm:
            raise ValueError(f'witness parameter max_step = {self.max_step!r}'
                             f' must be below alarm = {self.alarm!r} (one '
                             f'judgement must never alarm)')


@dataclass
class Pose:
    """A stamped pose in a frame: x, y (m), yaw (rad), cov 3x3 (x, y, yaw)."""

    stamp: float
    frame: str
    xy: np.ndarray
    yaw: float
    cov: np.ndarray

    @property
    def sd(self):
        """Return the position's largest standard deviation (m)."""
        return math.sqrt(max(np.linalg.eigvalsh(self.cov[:2, :2])))

    @property
    def yaw_sd(self):
        """Return the yaw's standard deviation (rad)."""
        return math.sqrt(self.cov[2, 2])


@dataclass
class Judgement:
    """One comparison and the verdict after it."""

    stamp: float
    ok: bool                 # the verdict after this judgement
    sigmas: float = math.nan   # distance in standard deviations
    distance_m: float = math.nan
    yaw_deg: float = math.nan  # NaN: yaw not compared
    evidence: float = 0.0    # the CUSUM after this judgement
    reason: str = ''         # why it is lost, or why nothing was compared
    seed: str = ''           # non-empty: send the fused pose, for this
    fused: Pose = None


def pose_problem(stamp, xy, yaw, cov):
    """
    Return why a pose cannot be judged, or None.

    ``cov``: 3x3 over x, y, yaw; it must be finite, symmetric and positive
    definite (the yaw's variance may be huge: unknown).
    """
    values = [stamp, *np.ravel(xy), yaw]
    if not all(map(math.isfinite, values)):
        return (f'stamp, x, y, yaw = {stamp}, {", ".join(map(str, xy))}, '
                f'{yaw} is not finite')
    cov = np.asarray(cov, np.float64)
    if cov.shape != (3, 3) or not np.isfinite(cov).all():
        return f'covariance {np.round(cov, 6).tolist()} is not finite'
    if not np.allclose(cov, cov.T, rtol=1e-6, atol=1e-9):
        return f'covariance {np.round(cov, 6).tolist()} is not symmetric'
    # the yaw row scaled to 1, so an unknown yaw (1e6) does not swamp x, y
    scale = 1 / np.sqrt(np.maximum(np.diag(cov), 1e-300))
    low = float(np.linalg.eigvalsh(cov * np.outer(scale, scale)).min())
    if not (np.diag(cov) > 0).all() or low <= 1e-9:
        return (f'covariance x, y, yaw diagonal {np.diag(cov).tolist()} is '
                f'not positive definite (smallest scaled eigenvalue '
                f'{low:.3g})')
    return None


class Witness:
    """
    The verdict on a localiser from the WiFi evidence (see the module).

    :meth:`localiser` takes the localiser's poses, :meth:`fused` the fused
    ones and :meth:`scan` the scans' positions; the latter two return a
    :class:`Judgement` when they judged. :attr:`ok` is the verdict: None
    until a localiser pose arrived. ``survey``: {frame: (n, 2) surveyed
    positions} (None: every place is covered; a frame not in it: none).
    """

    def __init__(self, params=None, survey=None):
        self.params = params or WitnessParams()
        self.survey = survey
        self.local = None        # newest localiser Pose
        self.heard = False       # any localiser message, even refused
        self._behind = None      # the last stamp refused as before
        self.history = deque(maxlen=HISTORY)  # fused (stamp, x, y)
        self.sigmas = deque(maxlen=COVERAGE_SCANS)   # recent scans' sigma
        self.evidence = {'fused': 0.0, 'scans': 0.0}
        self.since = {'fused': None, 'scans': None}  # stamp it rose from 0
        self.ok = None
        self.judged = {'fused': -math.inf, 'scans': -math.inf}
        self.last_seed = -math.inf
        self.last = None         # the last Judgement

    def localiser(self, stamp, frame, xy, yaw, cov):
        """
        Take one localiser pose; return why it was refused, or None.

        A stamp before the previous one is refused, unless it follows
        another refused one and both lie more than :data:`NEW_TIMELINE_S`
        before it: a clock restarted (a bag or a simulation started
        again), taken, the evidence cleared. A stale message resent stays
        refused.
        """
        self.heard = True
        problem = pose_problem(stamp, xy, yaw, cov)
        if problem is None and self.local is not None and \
                stamp < self.local.stamp:
            behind, self._behind = self._behind, stamp
            if not (behind is not None and behind < stamp <
                    self.local.stamp - NEW_TIMELINE_S):
                return (f'stamp {stamp:.3f} s is before the previous one '
                        f'({self.local.stamp:.3f} s)')
            for witness in self.evidence:
                self.evidence[witness], self.since[witness] = 0.0, None
        if problem is not None:
            return problem
        self._behind = None
        self.local = Pose(float(stamp), frame, np.asarray(xy, np.float64),
                          float(yaw), np.asarray(cov, np.float64))
        if self.ok is None:
            self.ok = True
        return None

    def fused(self, stamp, frame, xy, yaw, cov):
        """
        Take one fused pose; return a Judgement, or None if none is due.

        A pose refused by :func:`pose_problem` returns None (the caller
        counts it).
        """
        if pose_problem(stamp, xy, yaw, cov) is not None:
            return None
        pose = Pose(float(stamp), frame, np.asarray(xy, np.float64),
                    float(yaw), np.asarray(cov, np.float64))
        if self.history and stamp < self.history[-1][0]:
            self.history.clear()        # a new timeline
            self.judged['fused'] = -math.inf
        self.history.append((pose.stamp, *pose.xy))
        if not self._due('fused', stamp):
            return None
        judgement = self._judge_fused(pose)
        judgement.fused = pose
        judgement.seed = self._seed(pose, judgement)
        self.last = judgement
        return judgement

    def scan(self, stamp, frame, xy, sigma):
        """
        Take one scan's own position and sigma (m); return a Judgement.

        None if none is due, or the scan is not finite.
        """
        values = [stamp, *np.ravel(xy), sigma]
        if len(values) != 4 or not all(map(math.isfinite, values)) or \
                sigma < 0:
            return None
        self.sigmas.append(float(sigma))
        if not self._due('scans', stamp):
            return None
        judgement = self._judge_scan(float(stamp), frame,
                                     np.asarray(xy, np.float64), sigma)
        self.last = judgement
        return judgement

    def _due(self, witness, stamp):
        if stamp < self.judged[witness]:
            self.judged[witness] = -math.inf      # a new timeline
        if stamp - self.judged[witness] < SLACK * self.params.period:
            return False
        self.judged[witness] = stamp
        return True

    def _seed(self, pose, judgement):
        p = self.params
        sure = pose.sd <= p.sure_sd and pose.yaw_sd <= p.sure_yaw_sd
        if not sure or pose.stamp - self.last_seed < p.holdoff:
            return ''
        if not self.heard:
            why = 'start-up: no localiser pose yet'
        elif judgement.ok is False:
            why = f'lost: {judgement.reason}'
        else:
            return ''
        return why

    def seeded(self, stamp):
        """
        Say that a proposed seed was sent at ``stamp``: the localiser starts over.

        The evidence is cleared, and no other seed is proposed for
        ``holdoff`` seconds. A seed not sent changes nothing: a lost
        localiser stays lost.
        """
        self.last_seed = float(stamp)
        for witness in self.evidence:
            self.evidence[witness], self.since[witness] = 0.0, None

    def _moved_since(self, stamp):
        """Return how far the fused pose moved since ``stamp`` (m)."""
        if not self.history:
            return 0.0
        stamps = np.array([h[0] for h in self.history])
        i = int(np.clip(np.searchsorted(stamps, stamp), 0, len(stamps) - 1))
        return float(math.dist(self.history[i][1:], self.history[-1][1:]))

    def _paired(self, stamp, witness):
        """
        Return (localiser pose, metres moved since it) or a Judgement.

        The Judgement when there is nothing to compare: no localiser pose,
        or a silent one (evidence if the robot moved).
        """
        p, local = self.params, self.local
        if local is None:
            return Judgement(stamp, self.ok, reason='no localiser pose')
        age = stamp - local.stamp
        moved = self._moved_since(local.stamp)
        if age > p.max_age:
            if moved > p.silent_m and witness == 'fused':
                return self._step(witness, stamp, p.max_step, reason=(
                    f'no localiser pose for {age:.0f} s while the robot '
                    f'moved {moved:.1f} m'))
            return self._judgement(stamp, f'localiser silent for '
                                   f'{age:.0f} s')
        return local, moved

    def _judge_fused(self, pose):
        p = self.params
        paired = self._paired(pose.stamp, 'fused')
        if isinstance(paired, Judgement):
            return paired
        local, moved = paired
        if local.frame != pose.frame:
            return self._step('fused', pose.stamp, p.max_step, reason=(
                f'localiser in frame {local.frame!r}, WiFi says '
                f'{pose.frame!r}'))
        if pose.sd > p.max_fused_sd:
            return self._judgement(pose.stamp, f'fused pose too wide '
                                   f'({pose.sd:.1f} m)')
        if self.sigmas and np.median(self.sigmas) > p.max_scan_sigma:
            return self._judgement(pose.stamp, f'off the survey (scans\' '
                                   f'sigma {np.median(self.sigmas):.1f} m)')
        extra = p.floor_sd ** 2 + moved ** 2
        d2, distance = _mahalanobis(local.xy - pose.xy, local.cov[:2, :2] +
                                    pose.cov[:2, :2] + extra * np.eye(2))
        yaw_deg = math.nan
        if pose.yaw_sd <= p.yaw_known_sd and \
                local.cov[2, 2] < UNKNOWN_VARIANCE:
            turn = float(wrap(local.yaw - pose.yaw))
            d2 += turn ** 2 / (local.cov[2, 2] + pose.cov[2, 2] +
                               p.yaw_floor_sd ** 2)
            yaw_deg = math.degrees(turn)
        return self._compared('fused', pose.stamp, d2, distance, yaw_deg)

    def _judge_scan(self, stamp, frame, xy, sigma):
        p = self.params
        paired = self._paired(stamp, 'scans')
        if isinstance(paired, Judgement):
            return paired
        local, moved = paired
        if local.frame != frame:
            return self._judgement(stamp, 'scan of another frame')
        if sigma > p.max_scan_sigma:
            return self._judgement(stamp, f'scan off the survey (sigma '
                                   f'{sigma:.1f} m)')
        if not self._covered(frame, local.xy):
            return self._judgement(stamp, 'localiser pose off the survey')
        extra = sigma ** 2 + p.scan_floor_sd ** 2 + moved ** 2
        d2, distance = _mahalanobis(local.xy - xy, local.cov[:2, :2] +
                                    extra * np.eye(2))
        return self._compared('scans', stamp, d2, distance, math.nan)

    def _covered(self, frame, xy):
        if self.survey is None:
            return True
        refs = self.survey.get(frame)
        if refs is None or not len(refs):
            return False
        return float(np.min(np.sum((refs - xy) ** 2, axis=1))) <= \
            self.params.coverage_m ** 2

    def _compared(self, witness, stamp, d2, distance, yaw_deg):
        p = self.params
        sigmas = math.sqrt(d2)
        reason = (f'{distance:.1f} m ({sigmas:.1f} sigma) from the WiFi '
                  f'{"pose" if witness == "fused" else "scans"}' +
                  ('' if math.isnan(yaw_deg) else f', yaw {yaw_deg:.0f} deg'))
        judgement = self._step(witness, stamp, min(sigmas - p.agree_sigmas,
                                                   p.max_step), reason)
        judgement.sigmas, judgement.distance_m = sigmas, distance
        judgement.yaw_deg = yaw_deg
        return judgement

    def _step(self, witness, stamp, step, reason):
        """Add ``step`` to a witness's evidence; return the judgement."""
        before = self.evidence[witness]
        now = self.evidence[witness] = min(max(0.0, before + step),
                                           self.params.alarm)
        if before == 0 and now > 0:
            self.since[witness] = stamp
        elif now == 0:
            self.since[witness] = None
        if now >= self.params.alarm:
            self.ok = False
        elif not any(self.evidence.values()) and self.ok is False:
            self.ok = True
        return self._judgement(stamp, reason if self.ok is False or step > 0
                               else '')

    def _judgement(self, stamp, reason):
        return Judgement(stamp, self.ok, evidence=max(self.evidence.values()),
                         reason=reason)

    def disagreeing_for(self, now):
        """Return for how long (s) at ``now`` some evidence has been > 0."""
        since = [s for s in self.since.values() if s is not None]
        return max(0.0, now - min(since)) if since else 0.0

    @property
    def score(self):
        """Return the larger evidence as a share of the alarm level."""
        return max(self.evidence.values()) / self.params.alarm


def _mahalanobis(delta, cov):
    """Return (squared Mahalanobis distance, Euclidean distance)."""
    return (float(delta @ np.linalg.solve(cov, delta)),
            float(np.linalg.norm(delta)))


def judge_offline(localiser, fused, params=None, frame='map', scans=None,
                  survey=None):
    """
    Run a :class:`Witness` over stamped streams; return its judgements.

    ``localiser`` and ``fused``: (stamps (n,), xy (n, 2), yaw (n,),
    cov (n, 3, 3)) in stamp order, in ``frame`` (``localiser`` may be
    None: it never published); ``scans``: (stamps, xy, sigma) or None;
    ``survey``: the surveyed positions (None: everywhere). Taken in stamp
    order (the localiser's first, then the scans', at equal stamps); rows
    with NaN are skipped.
    """
    witness = Witness(params, None if survey is None else {frame: survey})
    events = [(float(t), 2, i) for i, t in enumerate(fused[0])]
    if localiser is not None:
        events += [(float(t), 0, i) for i, t in enumerate(localiser[0])]
    if scans is not None:
        events += [(float(t), 1, i) for i, t in enumerate(scans[0])]
    out = []
    for stamp, kind, i in sorted(events):
        if kind == 0:
            witness.localiser(stamp, frame, localiser[1][i],
                              localiser[2][i], localiser[3][i])
            continue
        judgement = witness.fused(stamp, frame, fused[1][i], fused[2][i],
                                  fused[3][i]) if kind == 2 else \
            witness.scan(stamp, frame, scans[1][i], scans[2][i])
        if judgement is not None:
            if judgement.seed:
                witness.seeded(stamp)   # offline, every seed is sent
            out.append(judgement)
    return out
