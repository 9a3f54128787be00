"""
Whether a scan labelled by the robot's localiser is trusted (ROS-free).

A robot that knows where it is can survey as it works: each WiFi scan
labelled with the localiser's pose (AMCL's) is a survey scan, but only
while that pose can be trusted, for a poisoned survey is worse than a thin
one. :func:`untrusted` says why a scan is not, or None: the localiser's
poses must label the scan by the labelling rule (:mod:`.pose_label`,
within ``max_pose_age`` seconds), their x and y standard deviations be
at most ``max_sd`` metres, and no jump of the localiser (:func:`is_jump`)
be in the ``settle_s`` seconds before the scan or since; the WiFi
witness (localization_monitor's state) must say neither ``lost`` nor
``disagrees`` (evidence against the localiser gathering), and must have
started (not ``waiting``) and not stopped (:data:`GONE`: its latched
state outlives it, so a dead witness's ``agrees`` must not count). Its
``cannot_tell`` does not block: inside a survey hole WiFi cannot
testify, and that is where recording matters; except after a jump: a
jump may be a correction or the localiser going wrong, and only WiFi can
tell which, so after one nothing is recorded until the witness says
``agrees`` at least ``settle_s`` after it (``settle_s`` no shorter than
the witness's ``max_age``, 10 s, for which an earlier comparison still
says ``agrees``). The building and floor come from the current place;
with none yet, nothing is trusted. :class:`TrustGate` applies the rule
live, to the streams as they come (what trusted_recorder runs, and the
self-update benchmark offline).
"""

from dataclasses import dataclass
import math

from .pose_label import blend, HeldScans, MAX_POSE_AGE
from .witness import AGREES, CANNOT_TELL, DISAGREES, LOST

#: The witness's state once its publisher is gone (a stopped monitor).
GONE = 'gone'

#: Why a scan was not trusted, and what that means.
REASONS = {
    'no_place': 'no current place (building, floor): none yet, or its '
                'publisher gone',
    'witness_waiting': 'the WiFi witness has not started',
    'witness_gone': 'the WiFi witness stopped (its publisher is gone)',
    'lost': 'the WiFi witness says the localiser is lost',
    'disagrees': 'the WiFi witness disagrees with the localiser so far',
    'no_pose': 'no localiser pose near the scan in time',
    'uncertain': 'the localiser is not sure of its pose',
    'jumped': 'the localiser jumped a moment ago',
    'unconfirmed': 'the localiser jumped and WiFi has not agreed since',
}


@dataclass(frozen=True)
class TrustParams:
    """When a localiser pose may label a scan (see the module)."""

    max_sd: float = 0.2         # m: largest x or y standard deviation
    jump_m: float = 0.5         # m beyond what max_speed covers: a jump
    max_speed: float = 1.0      # m/s the robot can drive
    settle_s: float = 10.0      # s after a jump: nothing trusted
    max_pose_age: float = MAX_POSE_AGE  # s between a scan and its poses


@dataclass(frozen=True)
class LocaliserPose:
    """A pose of the localiser: stamp (s), x, y (m), yaw (rad), frame, sd."""

    stamp: float
    x: float
    y: float
    yaw: float
    frame: str
    sd: float                   # m: the larger of the x and y deviations

    @staticmethod
    def sd_of(cov_xx, cov_yy):
        """Return the larger standard deviation of two variances (m^2)."""
        return math.sqrt(max(cov_xx, cov_yy))


def is_jump(before, after, params):
    """
    Return True if the localiser jumped from pose ``before`` to ``after``.

    A jump: another frame, or a step longer than ``jump_m`` plus what
    ``max_speed`` covers between their stamps (a re-seed, a recovery, a
    localiser that caught up with its error).
    """
    if after.frame != before.frame:
        return True
    step = math.hypot(after.x - before.x, after.y - before.y)
    driven = params.max_speed * abs(after.stamp - before.stamp)
    return step > params.jump_m + driven


def untrusted(stamp, pose, last_jump, witness, place, params,
              confirmed=True):
    """
    Return why the scan taken at ``stamp`` (s) is not trusted, or None.

    ``pose``: the localiser's :class:`LocaliserPose` labelling the scan by
    :mod:`.pose_label` (its sd the larger of the poses it comes from;
    None: no pose labels it); ``last_jump``: the stamp of its newest jump
    (None: none); ``witness``: the WiFi witness's state (None: not heard
    yet; :data:`GONE`: stopped); ``place``: the current (building,
    floor) or None; ``confirmed``:
    whether the witness agreed with the localiser, ``settle_s`` or more
    after its last jump, before the scan. The reason is a key of
    :data:`REASONS`.
    """
    if place is None:
        return 'no_place'
    if witness not in (AGREES, CANNOT_TELL):
        return {LOST: 'lost', DISAGREES: 'disagrees',
                GONE: 'witness_gone'}.get(witness, 'witness_waiting')
    if pose is None or abs(pose.stamp - stamp) > params.max_pose_age:
        return 'no_pose'
    if not pose.sd <= params.max_sd:
        return 'uncertain'
    if last_jump is not None and last_jump >= stamp - params.settle_s:
        return 'jumped'
    if not confirmed:
        return 'unconfirmed'
    return None


class TrustGate:
    """
    The rule applied live: the localiser, the witness, the place, scans.

    Feed the localiser's poses (:meth:`pose`), the witness's state and
    the current place as they change (attributes ``witness`` and
    ``place``) and the scans (:meth:`scan`) in arrival order; each scan
    is held, with the witness's state and the place when it came, until
    the labelling rule can label it (:class:`.pose_label.HeldScans`).
    :meth:`release` judges the scans ready. ``params`` may be replaced
    between calls.
    """

    def __init__(self, params=TrustParams()):
        self.params = params
        self.held = HeldScans()
        self.last_jump = None       # stamp of the localiser's newest jump
        self.confirmed = True       # the witness agreed since that jump
        self.witness = None         # the witness's state (None: not heard)
        self.place = None           # (building, floor) or None

    def pose(self, new):
        """
        Take a :class:`LocaliserPose`; return the pose before it on a jump.

        None when it did not jump (:func:`is_jump`).
        """
        old = self.held.poses[-1] if self.held.poses else None
        jumped = old is not None and is_jump(old, new, self.params)
        if jumped:
            self.last_jump, self.confirmed = new.stamp, False
        self.held.add_pose(new)
        return old if jumped else None

    def scan(self, stamp, scan):
        """Hold ``scan`` (anything), taken at ``stamp`` (s)."""
        if not self.confirmed and self.witness == AGREES and \
                stamp >= self.last_jump + self.params.settle_s:
            self.confirmed = True
        self.held.hold(stamp, (scan, self.witness, self.place,
                               self.confirmed), self.params.max_pose_age)

    def release(self, everything=False):
        """
        Return [(stamp, scan, pose, place, why)] of the scans judged now.

        ``pose``: the :class:`LocaliserPose` labelling it (None: none),
        ``place`` the (building, floor) when it came, ``why`` the key of
        :data:`REASONS` against it or None (trusted). ``everything``:
        also those still waiting for a pose (a stop).
        """
        out = []
        ready = self.held.release(self.params.max_pose_age, everything)
        for stamp, (scan, witness, place, confirmed), label in ready:
            pose = None
            if label is not None:
                before, after, w = label
                pose = LocaliserPose(stamp, *blend(before, after, w),
                                     before.frame, max(before.sd, after.sd))
            why = untrusted(stamp, pose, self.last_jump, witness, place,
                            self.params, confirmed)
            out.append((stamp, scan, pose, place, why))
        return out
