"""
Is the robot's localiser lost? WiFi as an independent witness (ROS-free).

:class:`Witness` takes the localiser's poses (e.g. AMCL's), the fused WiFi
+ odometry poses (:mod:`.filter.fusion`) and the scans' own positions (the
k-NN answer) as they arrive, and judges about once per ``period`` seconds
of their stamps whether they agree. Two witnesses, each with its own
evidence:

- the fused pose: paired with the newest localiser pose not after it,
  their distance in standard deviations is the position's Mahalanobis
  distance under the sum of both covariances, plus ``floor_sd`` (m) on
  each axis for what neither covariance knows, plus the distance the fused
  pose moved since the localiser's stamp (AMCL publishes only after it
  moved); the yaw's difference joins only when the fused yaw is known (its
  standard deviation below ``yaw_known_sd``). A fused pose wider than
  ``max_fused_sd`` (a filter that just started, or one whose recent scans
  lie metres aside of it: :mod:`.filter.pose_spread`) is no evidence
  either way: it could not tell the localiser a few metres off,
  nor is one while most recent scans do not testify (a scan that sounds
  unlike the survey, or one unlike every surveyed one that the coverage
  probability does not call covered, says the robot is off the survey),
  where the scans snap to the nearest surveyed place and may drag the
  filter with them;
- the scans: the same with the scan's own sigma and ``scan_floor_sd``, and
  only a scan that testifies (:func:`.witness_testimony.scan_doubt`: it
  does not sound unlike the survey, and its sigma is up to
  ``max_scan_sigma`` or its coverage probability says it is on the
  survey) where the survey covers the localiser's
  position (a reference within ``coverage_m``): a scan taken far from the
  survey snaps to the nearest surveyed place, so there it testifies
  nothing. The scans do not wait for the filter, which follows a
  kidnapped robot only after some time.

Evidence is a CUSUM over a witness's judgements (:mod:`.witness_evidence`):
each adds its distance minus ``agree_sigmas`` (at most ``max_step``); the
sum stays between zero and ``alarm``. At ``alarm`` (either witness) the
localiser is lost: one bad scan never alarms (``max_step`` < ``alarm``),
a sustained disagreement does, the sooner the larger it is. It is found
again when both are back at zero (after about ``alarm / agree_sigmas``
agreeing judgements). A localiser in another frame than the fused pose's
(another floor's map) adds ``max_step`` per judgement; so does one silent
for ``max_age`` s while the fused pose moved ``silent_m`` from where it
was at the localiser's last stamp.

:attr:`Witness.state` tells the verdict apart from what backs it:
:data:`WAITING` (no localiser pose yet), :data:`AGREES` (a witness
testified within ``max_age`` s of the newest stamp and the localiser is
not lost), :data:`CANNOT_TELL` (not lost, but nothing was compared: no
fused pose or scan yet, the fused pose too wide, the scans off the survey,
the localiser silent) and :data:`LOST`; :attr:`Witness.why` says why.

A pose to seed the localiser with (:attr:`Judgement.seed`,
:mod:`.witness_seeding`) is the fused pose when it is sure and on the
survey (not while most recent scans do not testify, nor while the scans
of the last ``sure_s`` seconds lie on average farther than ``sure_sd``
from its track: a pose dragged by scans off the survey): at start-up,
while no localiser message has been heard, once it has stayed sure for
``startup_sure_s`` seconds, and when the localiser is lost. The caller
says when it sent one (:meth:`Witness.seeded`): the evidence is cleared
(the localiser starts over) and no other is proposed for ``holdoff``
seconds.

Bad localiser poses (:func:`.witness_inputs.pose_problem`: not finite,
covariance not positive definite; :mod:`.witness_pairing`: stamps going
backwards, unless far enough back to be a restarted clock) are refused
with a reason; the caller counts them. Nothing here raises on input.
:func:`.witness_offline.judge_offline` runs it over recorded streams.
"""

from collections import deque
from dataclasses import dataclass
import math

import numpy as np

from .witness_evidence import Evidence, WITNESSES
from .witness_inputs import Pose, pose_problem, scan_is_valid
from .witness_pairing import Streams
from .witness_params import WitnessParams
from .witness_seeding import Seeding
from .witness_testimony import (covered, fused_distance, scan_distance,
                                scan_doubt)

#: Recent scans: while most of them do not testify, the fused pose neither
#: testifies nor seeds.
RECENT_SCANS = 5
#: The states of :attr:`Witness.state`.
WAITING, AGREES, DISAGREES, CANNOT_TELL, LOST = (
    'waiting', 'agrees', 'disagrees', 'cannot_tell', 'lost')


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
    testified: bool = False  # it changed the evidence


class Witness:
    """
    The verdict on a localiser from the WiFi evidence (see the module).

    :meth:`localiser` takes the localiser's poses, :meth:`fused` the fused
    ones and :meth:`scan` the scans' positions; the latter two return a
    :class:`Judgement` when they judged. :attr:`ok` is the verdict: None
    until a localiser pose arrived; :attr:`state` and :attr:`why` what
    backs it. ``survey``: {frame: (n, 2) surveyed positions} (None: every
    place is covered; a frame not in it: none).
    """

    def __init__(self, params=None, survey=None):
        self.params = params or WitnessParams()
        self.survey = survey
        self.streams = Streams()
        self.evidence = Evidence()
        self.seeding = Seeding()
        self.recent = deque(maxlen=RECENT_SCANS)  # did each recent scan
        self.testified = dict.fromkeys(WITNESSES)  # (stamp, why) last
        self.ok = None
        self.last = None         # the last Judgement

    @property
    def local(self):
        """Return the localiser's newest Pose (None: none yet)."""
        return self.streams.local

    def localiser(self, stamp, frame, xy, yaw, cov):
        """
        Take one localiser pose; return why it was refused, or None.

        A restarted clock (see :class:`.witness_pairing.Streams`) clears
        the evidence.
        """
        problem, restarted = self.streams.localiser(stamp, frame, xy, yaw,
                                                    cov)
        if restarted:
            self.evidence.clear()
        if problem is None and self.ok is None:
            self.ok = True
        return problem

    def fused(self, stamp, frame, xy, yaw, cov):
        """
        Take one fused pose; return a Judgement, or None if none is due.

        A pose refused by :func:`.witness_inputs.pose_problem` returns
        None (the caller counts it).
        """
        if pose_problem(stamp, xy, yaw, cov) is not None:
            return None
        pose = Pose.of(stamp, frame, xy, yaw, cov)
        if self.streams.starts_over(pose.stamp):
            self.seeding = Seeding()    # no seed nor sure stretch behind
        if not self.streams.fused(pose, self.params.period):
            return None
        off = self._off_survey()
        judgement = self._judge_fused(pose, off)
        judgement.fused = pose
        judgement.seed = self.seeding.propose(
            pose, self.streams.heard, judgement, self.params,
            self.streams.scan_offset, off)
        self.last = judgement
        return judgement

    def scan(self, stamp, frame, xy, sigma, coverage=math.nan,
             mismatch=math.nan):
        """
        Take one scan's own position and sigma (m); return a Judgement.

        ``coverage``: its coverage probability, ``mismatch``: its relative
        mismatch (NaN or None: none). None if no judgement is due, or the
        scan is not valid (:func:`.witness_inputs.scan_is_valid`).
        """
        try:
            coverage, mismatch = (math.nan if v is None else float(v)
                                  for v in (coverage, mismatch))
        except (TypeError, ValueError):
            return None
        if not scan_is_valid(stamp, xy, sigma, coverage, mismatch):
            return None
        doubt = scan_doubt(sigma, coverage, mismatch, self.params)
        self.recent.append(not doubt)
        stamp, xy = float(stamp), np.asarray(xy, np.float64)
        self.streams.scan(stamp, frame, xy)
        if not self.streams.due('scans', stamp, self.params.period):
            return None
        self.last = self._judge_scan(stamp, frame, xy, doubt, sigma)
        return self.last

    def seeded(self, stamp):
        """
        Say that a proposed seed was sent at ``stamp``: the localiser restarts.

        The evidence is cleared, and no other seed is proposed for
        ``holdoff`` seconds. A seed not sent changes nothing: a lost
        localiser stays lost.
        """
        self.seeding.sent(stamp)
        self.evidence.clear()

    @property
    def state(self):
        """
        Return the state: WAITING, AGREES, DISAGREES, CANNOT_TELL or LOST.

        DISAGREES: WiFi compared recently and evidence is gathering, not
        yet at the alarm (the localiser may be going wrong).
        """
        if self.ok is None:
            return WAITING
        if self.ok is False:
            return LOST
        if not self._recent_testimony():
            return CANNOT_TELL
        return AGREES if self.evidence.level == 0 else DISAGREES

    @property
    def why(self):
        """Return why the state is what it is ('' when it agrees)."""
        state = self.state
        if state == WAITING:
            return 'no localiser pose yet'
        if state == LOST:       # the witness with the most evidence
            witness = max((w for w in WITNESSES if self.testified[w]),
                          key=lambda w: (self.evidence[w],
                                         self.testified[w][0]))
            return self.testified[witness][1]
        if state == AGREES:
            return ''
        if state == DISAGREES:
            return f'{self.score:.0%} of the alarm'
        if self.last is None:
            return 'no WiFi pose or scan yet'
        if not self.last.testified:
            return self.last.reason
        return (f'no WiFi pose or scan for '
                f'{self._now() - self.last.stamp:.0f} s')

    def disagreeing_for(self, now):
        """Return for how long (s) at ``now`` some evidence has been > 0."""
        return self.evidence.disagreeing_for(now)

    @property
    def score(self):
        """Return the larger evidence as a share of the alarm level."""
        return self.evidence.level / self.params.alarm

    def _now(self):
        """Return the newest stamp: the localiser's or a judgement's."""
        return max(self.local.stamp if self.local else -math.inf,
                   self.last.stamp if self.last else -math.inf)

    def _off_survey(self):
        """
        Return why the fused pose is no evidence nor seed, or ''.

        While most of the recent scans do not testify (off the survey),
        the fused pose is built on them.
        """
        doubted = self.recent.count(False)
        if doubted > len(self.recent) / 2:
            return (f'off the survey ({doubted} of the last '
                    f'{len(self.recent)} scans do not testify)')
        return ''

    def _recent_testimony(self):
        now = self._now()
        return any(t is not None and now - self.params.max_age <= t[0] <= now
                   for t in self.testified.values())

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
        moved = self.streams.moved_since(local.stamp)
        if age > p.max_age:
            if moved > p.silent_m and witness == 'fused':
                return self._step(witness, stamp, p.max_step, reason=(
                    f'no localiser pose for {age:.0f} s while the robot '
                    f'moved {moved:.1f} m'))
            return self._judgement(stamp, f'localiser silent for '
                                   f'{age:.0f} s')
        return local, moved

    def _judge_fused(self, pose, off):
        """Judge a fused pose; ``off``: why it is off the survey, or ''."""
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
        if off:
            return self._judgement(pose.stamp, off)
        d2, distance, yaw_deg = fused_distance(local, pose, moved, p)
        return self._compared('fused', pose.stamp, d2, distance, yaw_deg)

    def _judge_scan(self, stamp, frame, xy, doubt, sigma):
        paired = self._paired(stamp, 'scans')
        if isinstance(paired, Judgement):
            return paired
        local, moved = paired
        if local.frame != frame:
            return self._judgement(stamp, 'scan of another frame')
        if doubt:
            return self._judgement(stamp, doubt)
        if not covered(self.survey, frame, local.xy, self.params.coverage_m):
            return self._judgement(stamp, 'localiser pose off the survey')
        d2, distance = scan_distance(local, xy, sigma, moved, self.params)
        return self._compared('scans', stamp, d2, distance, math.nan)

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
        now = self.evidence.add(witness, stamp, step, self.params.alarm)
        self.testified[witness] = (stamp, reason)
        if now >= self.params.alarm:
            self.ok = False
        elif not self.evidence.level and self.ok is False:
            self.ok = True
        judgement = self._judgement(stamp, reason if self.ok is False or
                                    step > 0 else '')
        judgement.testified = True
        return judgement

    def _judgement(self, stamp, reason):
        return Judgement(stamp, self.ok, evidence=self.evidence.level,
                         reason=reason)
