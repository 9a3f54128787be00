"""What one step of the pipeline gives to publish: plain typed objects."""

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Pose:
    """
    A pose to publish (``~/pose``), and on ``initialpose`` when ``initial``.

    ``source``: the caller's own stamp of the scan or odometry message it
    belongs to (handed back as given); ``yaw`` None: a scan's own position
    (``cov`` 2 x 2), else the fused pose (``cov`` 3 x 3 over x, y, yaw).
    ``initial``: why to re-seed the localiser with it (empty: do not).
    """

    stamp: float
    source: object
    xy: np.ndarray
    cov: np.ndarray
    place: tuple                 # (building, floor)
    yaw: float = None
    initial: list = field(default_factory=list)

    @property
    def fused(self):
        """Return True for a pose fused with odometry (it has a yaw)."""
        return self.yaw is not None


@dataclass
class Rejected:
    """A scan not answered: ``reason`` (a short name) and ``detail``."""

    reason: str
    detail: str


@dataclass
class Outputs:
    """
    Everything one input gives to publish.

    ``answer``: the scan's :class:`.recognizer.Place` (None: rejected, or
    not a scan); ``place_changed``: the answer's place is the new current
    place; ``poses`` in the order they are due; ``problems``: warnings
    to log (odometry faults, scans fused alone, errors inside the filter).
    """

    answer: object = None
    rejected: Rejected = None
    latency_ms: float = float('nan')
    place_changed: bool = False
    poses: list = field(default_factory=list)
    problems: list = field(default_factory=list)
