"""
A particle filter over x, y, yaw fed by odometry and WiFi positions.

:mod:`.fusion` runs it on stamped streams. :class:`ParticleFilter`
starts from a scan (unknown heading), moves by the :mod:`.motion` model,
weighs by its :mod:`.sensor` model (a piece it is given), resamples when
the effective sample size falls, and starts afresh when the scans keep
disagreeing with the particles (a kidnapped robot); :class:`FusionParams`
are the parameters of every piece (a model file's ``fusion`` section).
"""

from collections import deque
from dataclasses import asdict, dataclass
import math

import numpy as np

from ..params import SectionParams
from .angles import wrap
from .motion import MotionModel
from .sensor import WifiSensorModel

#: Variance (rad^2) of a heading the filter does not know.
UNKNOWN_VARIANCE = 1e6
#: The odometry's drift is known with a prior this narrow (rad per m;
#: ``fit_odometry`` writes its fit's standard error, at least 0.005, 0.005
#: on the shared runs; the default 0.04 is a drift not known): only then
#: may the pose be carried on odometry alone (hindsight's past poses, a
#: long run of scans unlike the survey), which with a drift not yet
#: learned goes astray.
KNOWN_DRIFT_SD = 0.01
#: Below this mean resultant length of the headings, the yaw is unknown.
MIN_RESULTANT = 0.5
#: The reported position is the mean of the particles heading within this
#: (rad) of the mean heading (:meth:`ParticleFilter.estimate`).
HEADING_WINDOW = math.radians(60.0)
#: Why :meth:`ParticleFilter.update` started afresh.
DISAGREED, NOTHING_FITS = 'disagreed', 'nothing fits'


@dataclass(frozen=True)
class FusionParams(SectionParams):
    """
    The parameters of the odometry + WiFi filter (stored in a model file).

    Noise figures are one standard deviation.
    """

    SECTION = 'fusion'
    POSITIVE = ('particles', 'wifi_sd', 'wifi_outlier', 'start_sd',
                'reset_sigmas', 'reset_after', 'reset_window', 'track_s',
                'hindsight_m', 'mismatch_width')
    SIGNED = ('drift_mean',)

    particles: int = 3000
    distance_noise: float = 0.02      # fraction of the distance driven
    turn_noise: float = 0.05          # fraction of the turn
    heading_noise: float = 0.005      # rad per sqrt(m) driven
    drift_mean: float = 0.0           # rad per m: the heading drift expected
    drift_sd: float = 0.04            # rad per m: spread of the drift prior
    drift_walk: float = 0.002         # rad per m, per sqrt(m) driven
    wifi_sd: float = 4.0              # m: a scan position's least width
    sigma_scale: float = 0.0          # width at least the scan's sigma x this
    track_s: float = 30.0             # s: scans compared with odometry
    track_scale: float = 2.0          # width at least their misfit x this
    wifi_outlier: float = 0.5         # likelihood floor (share of the peak)
    coverage_full: float = 0.0        # P(covered) from which a scan counts
    #                                   fully (0: every scan, coverage unused)
    mismatch_scans: int = 5           # recent scans' mismatch averaged (0:
    #                                   mismatch unused; .mismatch)
    mismatch_full: float = 1.1        # scans as wide as wifi_sd up to this
    #                                   many times the survey's usual
    #                                   mismatch ...
    mismatch_none: float = 1.6        # ... and mismatch_width from this many
    mismatch_width: float = 16.0      # m
    mismatch_run_power: float = 0.5   # a run of scans that sound unlike
    #                                   the survey, met by a settled
    #                                   filter (pose_scans > 0) with the
    #                                   drift known: each widened by the
    #                                   run's length to this power (0:
    #                                   each alike, round 34's;
    #                                   .mismatch.UnlikeRun)
    start_sd: float = 3.0             # m: spread of a start around a scan
    reset_sigmas: float = 3.0         # a scan this many sd off disagrees
    reset_track_sigmas: float = 2.0   # one its misfit did not widen: from
    #                                   this many (0: as any; .sensor)
    reset_after: int = 10             # so many of the last reset_window
    reset_window: int = 30            # scans: start afresh (= reset_after:
    #                                   so many in a row)
    idle_speed: float = 0.5           # m/s: spread per second without odometry
    idle_turn_rate: float = 0.5       # rad/s: the same for the heading
    pose_scans: int = 10              # the pose's covariance from the last
    #                                   so many scans' offsets (0: the
    #                                   particles' spread; .pose_spread)
    hindsight_s: float = 120.0        # s: past poses kept, carried by
    #                                   odometry (0: none; .hindsight)
    hindsight_m: float = 3.0          # m: the scans' mean offset from the
    #                                   pose from which one of them can win
    fit: dict = None                  # how they were chosen (free-form)

    def __post_init__(self):
        """Refuse values that would make the filter meaningless."""
        super().__post_init__()
        for name, top in (('particles', 10 ** 6), ('reset_after', 10 ** 6),
                          ('reset_window', 10 ** 6), ('pose_scans', 10 ** 4),
                          ('mismatch_scans', 10 ** 4)):
            value = getattr(self, name)
            if value != int(value) or value > top:
                raise ValueError(f'fusion parameter {name} = {value!r}: '
                                 f'expected a whole number up to {top}')
        if self.reset_window < self.reset_after:
            raise ValueError(f'fusion parameters reset_after = '
                             f'{self.reset_after!r}, reset_window = '
                             f'{self.reset_window!r}: expected reset_window '
                             f'>= reset_after')
        if self.coverage_full > 1:
            raise ValueError(f'fusion parameter coverage_full = '
                             f'{self.coverage_full!r}: expected 0 to 1')
        if not self.mismatch_none > self.mismatch_full > 0:
            raise ValueError(f'fusion parameters mismatch_full = '
                             f'{self.mismatch_full!r}, mismatch_none = '
                             f'{self.mismatch_none!r}: expected 0 < '
                             f'mismatch_full < mismatch_none')
        if self.mismatch_run_power > 1:
            raise ValueError(f'fusion parameter mismatch_run_power = '
                             f'{self.mismatch_run_power!r}: expected 0 to 1')
        if self.wifi_outlier >= 1:
            raise ValueError(f'fusion parameter wifi_outlier = '
                             f'{self.wifi_outlier!r}: expected < 1')

    @property
    def drift_known(self):
        """Return True when the drift prior is narrow (:data:`KNOWN_DRIFT_SD`)."""
        return self.drift_sd <= KNOWN_DRIFT_SD

    def to_dict(self):
        """
        Return a JSON-ready dict of the values that differ from the defaults.

        A model file keeps what was fitted (and how): the other values
        follow the code's defaults.
        """
        default = FusionParams()
        return {k: v for k, v in asdict(self).items()
                if v != getattr(default, k)}


@dataclass
class Estimate:
    """The filter's pose: mean and covariance over x, y, yaw."""

    xy: np.ndarray     # (2,) m
    yaw: float         # rad
    cov: np.ndarray    # (3, 3): x, y, yaw


class ParticleFilter:
    """
    Particles over x, y, yaw (and the odometry's heading drift).

    :meth:`start` from a scan; then :meth:`move` per odometry step and
    :meth:`update` per scan; :meth:`estimate` for the pose.
    """

    def __init__(self, params=None, seed=0, sensor=None):
        self.params = params or FusionParams()
        self.motion = MotionModel(self.params)
        self.sensor = sensor or WifiSensorModel(self.params)
        self._seed = seed
        self._rng = None
        self.state = None
        self.weight = None
        self.disagreeing = 0
        self.most_disagreeing = 0
        self._recent = deque(maxlen=int(self.params.reset_window))

    @property
    def rng(self):
        """
        Return the random generator, made at the first start.

        Lazily: importing ``numpy.random`` adds about 2 MiB to a process
        (classifier_node with fusion off never needs it).
        """
        if self._rng is None:
            self._rng = np.random.default_rng(self._seed)
        return self._rng

    @property
    def started(self):
        """Return True once a scan started the filter."""
        return self.state is not None

    def start(self, xy, yaw=None, sd=None, yaw_sd=0.0):
        """
        Spread particles around a position: every heading, or ``yaw``'s.

        ``sd`` (m): the position's spread (default ``start_sd``, a scan's);
        with ``yaw`` (rad), the headings spread ``yaw_sd`` (rad) around it.
        """
        n = int(self.params.particles)
        self.state = self._fresh(n, xy, yaw, sd, yaw_sd)
        self.weight = np.full(n, 1.0 / n)
        self._forget_disagreeing()

    def _fresh(self, n, xy, yaw=None, sd=None, yaw_sd=0.0):
        """Return ``n`` particles around ``xy`` (see :meth:`start`)."""
        p = self.params
        state = np.empty((n, 4))
        sd = p.start_sd if sd is None else sd
        state[:, :2] = xy + sd * self.rng.standard_normal((n, 2))
        state[:, 2] = self.rng.uniform(-math.pi, math.pi, n) if yaw is None \
            else wrap(yaw + yaw_sd * self.rng.standard_normal(n))
        state[:, 3] = p.drift_mean + p.drift_sd * self.rng.standard_normal(n)
        return state

    def move(self, forward, lateral, turn):
        """Apply one odometry step (robot frame at its start)."""
        self.motion.move(self.state, forward, lateral, turn, self.rng)

    def spread(self, seconds):
        """Let ``seconds`` pass without odometry."""
        self.motion.spread(self.state, seconds, self.rng)

    def update(self, scan):
        """
        Weigh the particles by a measurement; return why it restarted.

        ``scan``: what the sensor model weighs (a :class:`WifiPosition`).
        When ``reset_after`` of the last ``reset_window`` scans are ones
        the sensor model finds too far from the estimate, the filter starts
        afresh at the scan (:data:`DISAGREED`): the robot was carried away
        (kidnapped), or the filter went wrong. Not only in a row: a scan
        now and then near enough (noise, one its misfit or mismatch
        widened) does not start the count again, as long as the scans'
        mismatch is known (without it the scans of a hole disagree now
        and then too: then only ``reset_after`` in a row count). It starts
        afresh too when no particle fits the scan (:data:`NOTHING_FITS`).
        '' when it did not restart. ``most_disagreeing``: the most of
        ``reset_window`` scans that disagreed so far (``reset_after`` once
        it restarted; below it, how near).
        """
        disagrees = self.sensor.disagrees(*self.position(), scan)
        if not (disagrees or self.sensor.mismatch_known(scan)):
            self._recent.clear()
        self._recent.append(disagrees)
        self.disagreeing = int(sum(self._recent))
        self.most_disagreeing = max(self.most_disagreeing, self.disagreeing)
        if self.disagreeing >= self.params.reset_after:
            self.start(self.sensor.centre(scan))
            return DISAGREED
        self.weight = self.weight * self.sensor.likelihood(self.state, scan)
        total = self.weight.sum()
        if not (math.isfinite(total) and total > 0):
            self.start(self.sensor.centre(scan))
            return NOTHING_FITS
        self.weight /= total
        if 1.0 / (self.weight ** 2).sum() < len(self.weight) / 2:
            self._resample()
        return ''

    def shift(self, xy, yaw):
        """
        Move the cloud rigidly so that its pose is ``xy``, ``yaw``.

        Turned about its pose and carried there, its weights and spread
        kept (:mod:`.hindsight`).
        """
        estimate = self.estimate()
        turn = float(wrap(yaw - estimate.yaw))
        c, s = math.cos(turn), math.sin(turn)
        d = self.state[:, :2] - estimate.xy
        self.state[:, 0] = xy[0] + c * d[:, 0] - s * d[:, 1]
        self.state[:, 1] = xy[1] + s * d[:, 0] + c * d[:, 1]
        self.state[:, 2] = wrap(self.state[:, 2] + turn)
        self._forget_disagreeing()

    def _forget_disagreeing(self):
        """Count the scans that disagree afresh (a start, a shift)."""
        self._recent.clear()
        self.disagreeing = 0

    def drift(self):
        """Return the mean heading drift of the particles (rad per m)."""
        return float(self.weight @ self.state[:, 3])

    def _resample(self):
        """Low-variance resampling."""
        n = len(self.weight)
        positions = (self.rng.random() + np.arange(n)) / n
        cumulative = np.cumsum(self.weight)
        cumulative[-1] = 1.0
        self.state = self.state[np.searchsorted(cumulative, positions)]
        self.weight = np.full(n, 1.0 / n)

    def position(self):
        """Return the particles' weighted mean (x, y) and its covariance."""
        xy = self.weight @ self.state[:, :2]
        delta = self.state[:, :2] - xy
        return xy, (delta * self.weight[:, None]).T @ delta

    def estimate(self):
        """
        Return the pose and its covariance.

        The yaw is the particles' weighted mean heading; the position the
        weighted mean of the particles heading within
        :data:`HEADING_WINDOW` of it (of all, if none is). After a start
        with every heading the particles spread on a ring round the start
        as the robot drives, and the mean of all lies inside it, where no
        particle is; once the headings gather, the two agree. The
        covariance is the whole cloud's about that pose. While the
        headings are spread round the circle (their mean resultant length
        below :data:`MIN_RESULTANT`), the yaw is unknown: its variance
        :data:`UNKNOWN_VARIANCE`.
        """
        w = self.weight
        c, s = w @ np.cos(self.state[:, 2]), w @ np.sin(self.state[:, 2])
        yaw = math.atan2(s, c)
        turn = wrap(self.state[:, 2] - yaw)
        ahead = w * (np.abs(turn) < HEADING_WINDOW)
        if not ahead.any():     # no particle heads near the mean heading
            ahead = w
        xy = ahead @ self.state[:, :2] / ahead.sum()
        delta = np.column_stack([self.state[:, :2] - xy, turn])
        cov = (delta * w[:, None]).T @ delta
        if math.hypot(c, s) < MIN_RESULTANT:
            cov[2, :] = cov[:, 2] = 0.0
            cov[2, 2] = UNKNOWN_VARIANCE
        return Estimate(xy, yaw, cov)
