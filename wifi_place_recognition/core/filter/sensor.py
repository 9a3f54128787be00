"""
The filter's sensor model: a WiFi scan's position, as far as it is trusted.

:class:`WifiPosition` is the measurement (the scan's k-NN position, its
sigma, its misfit to odometry); :class:`WifiSensorModel` weighs particles
by it. Another model (e.g. a per-AP radio map) brings its own measurement
type and the same methods: ``measurement`` (from a scan's answer),
``off_track``, ``centre``, ``trust``, ``sounds_like_survey``,
``mismatch_known``, ``testifies``, ``disagrees``, ``likelihood``.
"""

from dataclasses import dataclass, replace
import math

import numpy as np


@dataclass(frozen=True)
class WifiPosition:
    """One scan's k-NN position, as :class:`WifiSensorModel` weighs it."""

    xy: np.ndarray             # (2,) m, map frame
    sigma: float = None        # m: the scan's own (None: not known)
    misfit: float = None       # m: the recent scans' (:class:`TrackMisfit`)
    coverage: float = None     # P(taken where the survey covers); None: 1
    mismatch: float = None     # the recent scans' mismatch over the
    #                            survey's usual (.mismatch); None: not known
    unlike_run: int = 0        # scans in a row, this one included, that
    #                            sounded unlike the survey to a settled
    #                            filter (.mismatch.UnlikeRun); 0: none

    @property
    def covered(self):
        """Return P(covered), 1 when not known."""
        c = self.coverage
        return 1.0 if c is None or not math.isfinite(c) else \
            min(max(float(c), 0.0), 1.0)


class WifiSensorModel:
    """
    The likelihood of a particle's position given one scan's position.

    A Gaussian around the scan's k-NN position over a floor of
    ``wifi_outlier`` (a scan placed far off does not wipe out the
    particles). Its width is the scan's trust: at least ``wifi_sd``, at
    least the scan's own sigma times ``sigma_scale``, and at least the
    recent scans' misfit to odometry times ``track_scale``: where the
    survey has no scan, the k-NN snaps to the nearest surveyed stretch
    for as long as the robot is away from it, its errors along the run are
    not independent, and scans that move unlike the robot are trusted
    less, so the pose follows odometry there. So are scans while the
    recent ones sound unlike the survey (their ``mismatch``): as wide as
    ``wifi_sd`` up to ``mismatch_full`` times the survey's usual, and
    ``mismatch_width`` from ``mismatch_none`` times; they still hold the
    particles together, a hole's scans lying near where the robot is.
    A hole's scans are placed at the same surveyed stretch all along it,
    so a run of them counts about as one: met by a settled filter that
    knows the odometry's drift (:class:`.mismatch.UnlikeRun`), each
    is widened by the run's length (its ``unlike_run``) to the power
    ``mismatch_run_power`` beyond ``wifi_sd``, and the pose follows
    odometry through a long hole instead of being dragged along it; the
    run widens the pull only, not the restart test (:meth:`disagrees`).
    With ``coverage_full`` > 0 a scan counts as far as it was likely
    taken where the survey covers (its ``coverage``): one likely off the
    survey moves the particles little and never counts towards a
    restart.
    """

    def __init__(self, params):
        self.params = params

    def width(self, scan):
        """Return how wide (m) a :class:`WifiPosition` is weighed."""
        p = self.params
        width = p.wifi_sd
        if scan.sigma is not None and math.isfinite(scan.sigma):
            width = max(width, p.sigma_scale * scan.sigma)
        if scan.misfit is not None:
            width = max(width, p.track_scale * scan.misfit)
        unlike = 1.0 - self.sounds_like_survey(scan)
        run = max(scan.unlike_run, 1) ** p.mismatch_run_power
        return max(width,
                   p.wifi_sd + unlike * run * (p.mismatch_width - p.wifi_sd))

    def measurement(self, xy, sigma, misfit, coverage=None, mismatch=None,
                    unlike_run=0):
        """Return the :class:`WifiPosition` of a scan's answer."""
        return WifiPosition(xy, sigma, misfit, coverage, mismatch, unlike_run)

    def off_track(self, scan):
        """Return True when the scan's misfit widened it."""
        return self.width(scan) > self.width(replace(scan, misfit=None))

    def centre(self, scan):
        """Return where a start from ``scan`` spreads its particles."""
        return scan.xy

    def disagrees(self, xy, cov, scan):
        """
        Return True when ``scan`` lies reset_sigmas sd off the particles.

        ``xy``, ``cov``: the particles' mean position and its covariance.
        With the scan's width before its misfit, and as if no run of
        unlike scans had widened it: scans that jump away from odometry
        for good (a kidnapped robot) keep disagreeing, even while they
        sound unlike the survey (a robot carried into a hole is found
        there). A scan whose misfit did not widen it (the recent scans
        move as odometry says) disagrees from ``reset_track_sigmas`` sd
        (2 by default; 0: as any): a robot carried about a scan's 3 sd
        (12 m) is found sooner. So would the scans of a hole beside a
        parallel surveyed stretch, which move as odometry says too, if
        they sounded like the survey (the mismatch widens them) and fitted
        odometry within half a scan's width (their misfit widens them
        otherwise).
        """
        if not self.testifies(scan):
            return False
        p = self.params
        scan = replace(scan, unlike_run=0)
        width = self.width(replace(scan, misfit=None))
        cov = cov + np.eye(2) * width ** 2
        delta = scan.xy - xy
        limit = p.reset_sigmas
        if p.reset_track_sigmas and scan.misfit is not None and \
                not self.off_track(scan):
            limit = min(limit, p.reset_track_sigmas)
        return delta @ np.linalg.solve(cov, delta) > limit ** 2

    def trust(self, scan):
        """
        Return how far ``scan`` counts (0 to 1) by its coverage.

        min(P(covered) / ``coverage_full``, 1); 1 with ``coverage_full`` 0
        (coverage unused).
        """
        full = self.params.coverage_full
        return 1.0 if not full else min(scan.covered / full, 1.0)

    def sounds_like_survey(self, scan):
        """
        Return how much ``scan``'s recent mismatch sounds like the survey.

        1 up to ``mismatch_full`` times the usual, 0 from ``mismatch_none``
        times, linear between; 1 when not known or ``mismatch_scans`` is 0.
        """
        if not self.mismatch_known(scan):
            return 1.0
        p = self.params
        return min(max((p.mismatch_none - scan.mismatch) /
                       (p.mismatch_none - p.mismatch_full), 0.0), 1.0)

    def mismatch_known(self, scan):
        """Return True when ``scan``'s recent mismatch is known and used."""
        return bool(self.params.mismatch_scans) and scan.mismatch is not None

    def testifies(self, scan):
        """Return True when ``scan`` counts at least half (covered ground)."""
        return self.trust(scan) >= 0.5

    def likelihood(self, state, scan):
        """
        Return how likely each particle is, given ``scan`` (peak 1).

        A scan off the survey explains nothing: the Gaussian over its floor
        counts as far as the scan is trusted (:meth:`trust`), a flat 1 the
        rest.
        """
        p = self.params
        width = self.width(scan)
        d2 = ((state[:, :2] - scan.xy) ** 2).sum(axis=1)
        trust = self.trust(scan)
        floor = p.wifi_outlier + (1 - p.wifi_outlier) * (1 - trust)
        return (1 - p.wifi_outlier) * trust * \
            np.exp(-d2 / (2 * width * width)) + floor
