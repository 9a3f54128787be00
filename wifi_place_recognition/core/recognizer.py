"""Scan in, place out: the ROS-free core that classifier_node wraps."""

from dataclasses import dataclass

import numpy as np

from .model import ScanForward
from .scan import ScanMapper

OK, WARN = 'ok', 'warn'


@dataclass
class Place:
    """The answer for one scan."""

    building: int
    floor: int
    confidence: float
    probabilities: np.ndarray   # one per model class
    known_aps: int
    unknown_aps: int
    clipped: int
    level: str                  # OK or WARN
    message: str


class PlaceRecognizer:
    """
    Classify single scans with a :class:`PlaceModel` and two thresholds.

    The level is WARN when the confidence is below ``min_confidence`` or
    fewer than ``min_known_aps`` APs of the scan are known to the model.
    :meth:`classify` raises :class:`ScanRejected` for a scan it cannot use.
    ``forward`` turns a model-ordered RSSI vector into class probabilities
    (default: the numpy :class:`ScanForward` of ``model``).
    """

    def __init__(self, model, min_confidence=0.5, min_known_aps=3,
                 max_aps=4096, forward=None):
        self.model = model
        self.forward = forward or ScanForward(model)
        self.mapper = ScanMapper(model.ap_ids, max_aps)
        self.min_confidence = min_confidence
        self.min_known_aps = min_known_aps

    def classify(self, names, rssi):
        """Return a :class:`Place` for parallel AP name / RSSI sequences."""
        scan = self.mapper.map(names, rssi)
        proba = self.forward(scan.rssi)
        best = int(proba.argmax())
        building, floor = (int(v) for v in self.model.classes[best])
        confidence = float(proba[best])
        message = f'building {building}, floor {floor} (p={confidence:.2f})'
        level = OK
        if confidence < self.min_confidence:
            level = WARN
            message += f'; confidence below {self.min_confidence:g}'
        if scan.known < self.min_known_aps:
            level = WARN
            message += (f'; only {scan.known} known APs (< '
                        f'{self.min_known_aps})')
        return Place(building, floor, confidence, proba, scan.known,
                     scan.unknown, scan.clipped, level, message)
