"""
Tracking building, floor and position over a walk (ROS-free, numpy only).

A robot changes floor only by a lift or stairs, so its scans are not
independent. :class:`PlaceTracker` keeps a discrete belief over the model's
(building, floor) classes and runs one forward step of a hidden Markov model
per scan:

- predict: a floor change (within the building) and a building change are
  Poisson events of rates ``floor_rate`` and ``building_rate`` per second,
  so the longer since the last scan, the likelier a change; every scan
  counts for at least ``min_interval`` seconds, so a belief can always be
  overturned by enough evidence;
- update: multiply by the scan's class probabilities raised to
  ``1 / temperature`` (single-scan probabilities are over-confident, and
  neighbouring scans of a walk make correlated errors);
- after a gap longer than the tracker's ``timeout`` (or time running
  backwards) the belief restarts from the scan alone.

An optional position (x, y with a 2x2 covariance per scan) is smoothed by a
Kalman filter with a constant-velocity motion model (white-noise
acceleration of density ``acceleration_noise`` m^2/s^3 per axis, so the
uncertainty grows with the time since the last scan; a new track starts at
rest with a speed uncertainty of ``speed_sd`` m/s). It restarts whenever
the tracked class changes.

:class:`TrackingParams` is what a model file stores; :mod:`.tracking_fit`
chooses them on recorded walks (``fit_tracking``). The defaults are those
chosen on WiFine's ``val/`` walks with the default recipe's WiFine model
(one building: its building rate is a choice, 1/200 of the floor rate).
"""

from dataclasses import asdict, dataclass
import math

import numpy as np

from .params import SectionParams

#: Smallest class probability used as evidence (a softmax can underflow).
MIN_PROBABILITY = 1e-12
#: Seconds without a scan after which the belief restarts.
DEFAULT_TIMEOUT = 600.0


@dataclass(frozen=True)
class TrackingParams(SectionParams):
    """The parameters of :class:`PlaceTracker`; stored in the model file."""

    SECTION = 'tracking'
    POSITIVE = ('temperature',)

    floor_rate: float = 2e-3         # floor changes per second
    building_rate: float = 1e-5      # building changes per second
    min_interval: float = 200.0      # s: a scan counts for at least this
    temperature: float = 1.0         # evidence = probabilities ** (1 / T)
    acceleration_noise: float = 0.01  # m^2/s^3 per axis
    speed_sd: float = 0.19           # m/s per axis, when a track starts
    fit: dict = None                 # how they were chosen (free-form)

    def to_dict(self):
        """Return a JSON-ready dict (``fit`` left out when empty)."""
        out = asdict(self)
        if out['fit'] is None:
            del out['fit']
        return out


@dataclass
class Track:
    """The tracked answer after one scan."""

    index: int                # row of the tracked class in ``classes``
    building: int
    floor: int
    confidence: float         # belief of the tracked class
    belief: np.ndarray        # (k,) sums to 1
    restarted: bool           # the belief started afresh with this scan
    xy: np.ndarray = None     # (2,) smoothed position, or None
    cov: np.ndarray = None    # (2, 2)


def _jump_matrices(classes):
    """
    Return (floor, building) jump matrices, rows = from, columns = to.

    A floor jump goes uniformly to another floor of the same building, a
    building jump uniformly to a class of another building; a class with
    nowhere to go keeps its mass.
    """
    classes = np.asarray(classes, np.int64)
    same = classes[:, None, 0] == classes[None, :, 0]
    other_floor = same & ~np.eye(len(classes), dtype=bool)
    out = []
    for allowed in (other_floor, ~same):
        m = allowed.astype(np.float64)
        counts = m.sum(axis=1, keepdims=True)
        m = np.where(counts > 0, m / np.maximum(counts, 1),
                     np.eye(len(classes)))
        out.append(m)
    return out


class PositionFilter:
    """
    Constant-velocity Kalman filter on x, y (state x, y, vx, vy).

    Between scans the state moves with its velocity and the covariance grows
    by white-noise acceleration of density ``acceleration_noise``; a track
    starts at the first position, at rest, with speed uncertainty
    ``speed_sd``. Its 4x4 algebra is written out on floats: at this size
    numpy's per-call cost is most of the time.
    """

    def __init__(self, params):
        self.params = params
        self.reset()

    def reset(self):
        """Forget the track."""
        self.state = None     # [x, y, vx, vy]
        self.cov = None       # 4x4 nested lists

    @property
    def xy(self):
        """Return the position (2,) and its covariance (2, 2), or Nones."""
        if self.state is None:
            return None, None
        return (np.array(self.state[:2]),
                np.array([row[:2] for row in self.cov[:2]]))

    def predict(self, dt):
        """Move the track ``dt`` seconds forward (no-op without a track)."""
        if self.state is None:
            return
        x, y, vx, vy = self.state
        self.state = [x + dt * vx, y + dt * vy, vx, vy]
        p = self.cov
        # F P F^T with F = [[I, dt I], [0, I]]: rows, then columns
        p = [[p[i][j] + dt * p[i + 2][j] for j in range(4)]
             if i < 2 else list(p[i]) for i in range(4)]
        for row in p:
            row[0] += dt * row[2]
            row[1] += dt * row[3]
        q = self.params.acceleration_noise * dt
        for i in (0, 1):    # white-noise acceleration, per axis
            p[i][i] += q * dt * dt / 3
            p[i][i + 2] += q * dt / 2
            p[i + 2][i] += q * dt / 2
            p[i + 2][i + 2] += q
        self.cov = p

    def update(self, xy, cov):
        """Add a position ``xy`` (2,) with covariance ``cov`` (2, 2)."""
        try:
            (zx, zy), ((r00, r01), (r10, r11)) = \
                [float(v) for v in xy], [[float(v) for v in row]
                                         for row in cov]
            finite = all(map(math.isfinite, (zx, zy, r00, r01, r10, r11)))
        except (TypeError, ValueError):     # wrong shape or not numbers
            finite = False
        if not finite:
            raise ValueError('a position needs finite xy (2,) and cov '
                             '(2, 2)')
        if self.state is None:
            v = self.params.speed_sd ** 2
            self.state = [zx, zy, 0.0, 0.0]
            self.cov = [[r00, r01, 0.0, 0.0], [r10, r11, 0.0, 0.0],
                        [0.0, 0.0, v, 0.0], [0.0, 0.0, 0.0, v]]
            return
        p = self.cov
        a, b = p[0][0] + r00, p[0][1] + r01
        c, d = p[1][0] + r10, p[1][1] + r11
        det = a * d - b * c
        inverse = ((d / det, -b / det), (-c / det, a / det))
        gain = [(row[0] * inverse[0][0] + row[1] * inverse[1][0],
                 row[0] * inverse[0][1] + row[1] * inverse[1][1])
                for row in p]
        ex, ey = zx - self.state[0], zy - self.state[1]
        self.state = [s + k0 * ex + k1 * ey
                      for s, (k0, k1) in zip(self.state, gain)]
        p = [[p[i][j] - k0 * p[0][j] - k1 * p[1][j] for j in range(4)]
             for i, (k0, k1) in enumerate(gain)]
        self.cov = [[(p[i][j] + p[j][i]) / 2 for j in range(4)]
                    for i in range(4)]


class PlaceTracker:
    """
    Online filter over building/floor classes (and optionally position).

    ``classes`` is the model's (k, 2) array of [building, floor]. Feed every
    answered scan to :meth:`update`; :meth:`reset` forgets everything. A gap
    of more than ``timeout`` seconds restarts the belief.
    """

    def __init__(self, classes, params=None, timeout=DEFAULT_TIMEOUT):
        self.classes = np.asarray(classes, np.int64)
        self.params = params or TrackingParams()
        self.timeout = timeout
        self.floor_jump, self.building_jump = _jump_matrices(self.classes)
        self.position = PositionFilter(self.params)
        self.reset()

    def reset(self):
        """Forget the belief, the position and the last scan time."""
        self.belief = None
        self.index = -1
        self.last_time = None
        self.position.reset()

    def predict(self, belief, dt):
        """Return the belief moved forward by ``dt`` seconds."""
        p = self.params
        dt = max(dt, p.min_interval)
        to_building = -math.expm1(-p.building_rate * dt)
        to_floor = -math.expm1(-p.floor_rate * dt)
        return ((1.0 - to_building - to_floor) * belief
                + to_floor * (belief @ self.floor_jump)
                + to_building * (belief @ self.building_jump))

    def update(self, time, proba, xy=None, cov=None):
        """
        Add one scan at ``time`` (s) with class probabilities ``proba``.

        ``xy`` (2,) and ``cov`` (2, 2) are the scan's position estimate, if
        the model has one. Return the :class:`Track` after this scan.
        """
        evidence = np.maximum(np.asarray(proba, np.float64), MIN_PROBABILITY)
        if evidence.shape != (len(self.classes),) or \
                not np.isfinite(evidence).all():
            raise ValueError(f'expected {len(self.classes)} finite class '
                             f'probabilities, got shape {evidence.shape}')
        evidence **= 1.0 / self.params.temperature
        dt = None if self.last_time is None else time - self.last_time
        restarted = (self.belief is None or dt < 0
                     or dt > self.timeout)
        belief = evidence if restarted else \
            self.predict(self.belief, dt) * evidence
        self.belief = belief / belief.sum()
        self.last_time = time
        index = int(self.belief.argmax())
        if restarted or index != self.index:
            self.position.reset()
        self.index = index
        self.position.predict(dt)
        if xy is not None:
            self.position.update(xy, cov)
        building, floor = self.classes[index]
        track = Track(index, int(building), int(floor),
                      float(self.belief[index]), self.belief, restarted)
        track.xy, track.cov = self.position.xy
        return track


def track_walk(tracker, times, proba, xy=None, cov=None):
    """
    Run ``tracker`` (reset first) over one walk; return its tracks.

    ``times`` (n,), ``proba`` (n, k); ``xy`` (n, 2) and ``cov`` (n, 2, 2)
    are optional.
    """
    tracker.reset()
    return [tracker.update(times[i], proba[i],
                           None if xy is None else xy[i],
                           None if cov is None else cov[i])
            for i in range(len(times))]
