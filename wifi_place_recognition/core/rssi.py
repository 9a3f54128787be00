"""
The one rule for which RSSI values are plausible, shared by CSVs and scans.

Plausible received signal strength lies in [-120, 0] dBm. Some phones and
drivers report a few dBm above 0 for an AP next to them: values in (0, 20]
are clipped to 0 dBm and counted. Anything else (below -120, above 20,
NaN or infinite where a reading is expected) is refused.

What "refused" means differs on purpose: the node rejects the whole scan
(a driver that emits garbage should not steer the robot), a fingerprint CSV
with such a value is an error naming the cell (training data is fixed
first), and the recorder leaves the one reading out (a survey keeps the
rest of the scan).
"""

import numpy as np

MIN_DBM = -120.0
MAX_DBM = 0.0
CLIP_LIMIT_DBM = 20.0


class RssiError(ValueError):
    """An implausible RSSI value; ``index`` locates the first one."""

    def __init__(self, message, index):
        super().__init__(message)
        self.index = index


def plausible(rssi):
    """Return a mask of the readings the rule accepts (finite, in range)."""
    rssi = np.asarray(rssi, dtype=np.float64)
    return (rssi >= MIN_DBM) & (rssi <= CLIP_LIMIT_DBM)


def clip_plausible(rssi):
    """Return ``(rssi, n_clipped)``; NaN cells mean "not detected"."""
    rssi = np.asarray(rssi, dtype=np.float64)
    if rssi.size and MIN_DBM <= rssi.min() and rssi.max() <= MAX_DBM:
        return rssi, 0      # the usual scan: nothing to refuse or clip
    bad = ~(plausible(rssi) | np.isnan(rssi))
    if bad.any():
        index = tuple(int(i) for i in np.argwhere(bad)[0])
        raise RssiError(f'RSSI {rssi[index]:g} dBm is outside the plausible '
                        f'range [{MIN_DBM:g}, {CLIP_LIMIT_DBM:g}]', index)
    above = rssi > MAX_DBM
    n_clipped = int(above.sum())
    if n_clipped:
        rssi = np.where(above, MAX_DBM, rssi)
    return rssi, n_clipped
