"""Scan in, place out: the ROS-free core that classifier_node wraps."""

from dataclasses import dataclass

import numpy as np

from .model import ScanForward
from .scan import ScanMapper
from .tracking import DEFAULT_TIMEOUT, PlaceTracker

OK, WARN = 'ok', 'warn'


@dataclass
class Place:
    """The answer after one scan: tracked when tracking, and the scan's own."""

    building: int
    floor: int
    confidence: float
    probabilities: np.ndarray   # one per model class
    known_aps: int
    unknown_aps: int
    clipped: int
    level: str                  # OK or WARN
    message: str
    scan_building: int          # this scan alone
    scan_floor: int
    scan_confidence: float
    position: np.ndarray = None  # (2,) metres (tracked when tracking)
    position_cov: np.ndarray = None  # (2, 2) m^2
    scan_position: np.ndarray = None  # (2,) this scan alone
    scan_sigma: float = float('nan')  # m, this scan alone
    coverage: float = None      # P(this scan is where the survey covers)
    scan_knn_sigma: float = float('nan')  # m, before the edge widening
    mismatch: float = float('nan')  # unlike its nearest references, over
    #                                 the survey's usual (NaN: not known)

    @property
    def position_sigma(self):
        """Return the position's standard deviation (m), NaN without one."""
        if self.position_cov is None:
            return float('nan')
        return float(np.sqrt(np.trace(self.position_cov) / 2))


class PlaceRecognizer:
    """
    Classify single scans with a :class:`PlaceModel` and two thresholds.

    The level is WARN when the confidence is below ``min_confidence`` or
    fewer than ``min_known_aps`` APs of the scan are known to the model.
    :meth:`classify` raises :class:`ScanRejected` for a scan it cannot use.
    ``forward(columns, inputs)`` turns a scan's detected APs
    (:meth:`PlaceModel.relative`) into class probabilities (default: the numpy
    :class:`ScanForward` of ``model``). A model with a position output
    also places the scan (:class:`.locator.Locator`). With ``tracking``
    (:meth:`configure`), scans given a time are tracked over time and the
    answer is the tracked one (``tracker``).
    """

    def __init__(self, model, min_confidence=0.5, min_known_aps=3,
                 max_aps=4096, forward=None):
        self.model = model
        self.forward = forward or ScanForward(model)
        self.mapper = ScanMapper(model.ap_ids, max_aps)
        self.min_confidence = min_confidence
        self.min_known_aps = min_known_aps
        self.tracking_timeout = DEFAULT_TIMEOUT
        self.tracker = None

    def configure(self, min_confidence=None, min_known_aps=None,
                  max_aps=None, tracking=None, tracking_timeout=None):
        """
        Change the settings given (None: keep).

        ``tracking_timeout`` (s) also applies to the running tracker;
        ``tracking`` true starts tracking afresh (the model file's
        parameters), false stops it.
        """
        if min_confidence is not None:
            self.min_confidence = min_confidence
        if min_known_aps is not None:
            self.min_known_aps = min_known_aps
        if max_aps is not None:
            self.mapper.max_aps = max_aps
        if tracking_timeout is not None:
            self.tracking_timeout = tracking_timeout
            if self.tracker is not None:
                self.tracker.timeout = tracking_timeout
        if tracking is not None:
            self.tracker = PlaceTracker(
                self.model.classes, self.model.tracking,
                self.tracking_timeout) if tracking else None

    def classify(self, names, rssi, time=None):
        """
        Return a :class:`Place` for parallel AP name / RSSI sequences.

        ``time`` (s) is when the scan was taken; tracking needs it.
        """
        scan = self.mapper.map(names, rssi)
        columns = scan.columns
        inputs = self.model.relative(columns, scan.rssi)
        proba = self.forward(columns, inputs)
        best = int(proba.argmax())
        scan_building, scan_floor = (int(v) for v in self.model.classes[best])
        scan_confidence = float(proba[best])
        xy = cov = coverage = None
        sigma = knn_sigma = mismatch = float('nan')
        if self.model.position is not None:
            xy, sigma, coverage, knn_sigma, mismatch = self.model.locate(
                columns, scan.rssi, best, scan.unknown)
            cov = np.eye(2) * sigma ** 2
        scan_xy = xy
        if self.tracker is None or time is None:
            building, floor = scan_building, scan_floor
            confidence, probabilities = scan_confidence, proba
        else:
            track = self.tracker.update(time, proba, xy, cov)
            building, floor = track.building, track.floor
            confidence, probabilities = track.confidence, track.belief
            xy, cov = track.xy, track.cov
        message = f'building {building}, floor {floor} (p={confidence:.2f})'
        if (building, floor) != (scan_building, scan_floor):
            message += (f'; this scan alone: building {scan_building}, '
                        f'floor {scan_floor} (p={scan_confidence:.2f})')
        level = OK
        if confidence < self.min_confidence:
            level = WARN
            message += f'; confidence below {self.min_confidence:g}'
        if scan.known < self.min_known_aps:
            level = WARN
            message += (f'; only {scan.known} known APs (< '
                        f'{self.min_known_aps})')
        return Place(building, floor, confidence, probabilities, scan.known,
                     scan.unknown, scan.clipped, level, message,
                     scan_building, scan_floor, scan_confidence, xy, cov,
                     scan_xy, sigma, coverage, knn_sigma, mismatch)


def step_sigmas(before_xy, before_cov, after_xy):
    """
    Return how far ``after_xy`` is from ``before_xy``, in standard deviations.

    The Mahalanobis distance under ``before_cov`` (2, 2): a jump of a
    tracked position far outside its covariance is a large value.
    """
    delta = np.asarray(after_xy, np.float64) - before_xy
    return float(np.sqrt(delta @ np.linalg.solve(before_cov, delta)))
