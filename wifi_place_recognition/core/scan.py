"""One WiFi scan (AP identifiers + RSSI) onto a model's AP vector, with checks."""

from dataclasses import dataclass

import numpy as np

from .rssi import clip_plausible, RssiError

#: Rejection reasons, in the order the checks run.
REJECT_REASONS = ('length_mismatch', 'empty', 'oversize', 'non_finite',
                  'implausible_rssi', 'no_known_ap')


def normalize_ap_id(ap_id):
    """
    Return the comparable form of an AP identifier.

    Case is ignored and ``-`` separators become ``:``, so
    ``AA-BB-CC-00-11-22`` and ``aa:bb:cc:00:11:22`` match; a bare 12-digit
    hex MAC gets colons. Dataset names such as ``WAP017`` compare
    case-insensitively.
    """
    text = ap_id.strip().lower().replace('-', ':')
    if len(text) == 12 and all(c in '0123456789abcdef' for c in text):
        text = ':'.join(text[i:i + 2] for i in range(0, 12, 2))
    return text


class ScanRejected(ValueError):
    """A scan that cannot be classified; ``reason`` is in REJECT_REASONS."""

    def __init__(self, reason, detail):
        super().__init__(f'{reason}: {detail}')
        self.reason = reason


@dataclass
class MappedScan:
    """A scan's known APs: model columns (ascending) and their RSSI."""

    columns: np.ndarray  # int64, each model AP at most once
    rssi: np.ndarray     # float64 dBm, the strongest reading of each
    known: int
    unknown: int
    clipped: int


class ScanMapper:
    """Map scans onto the AP order of ``ap_ids``."""

    def __init__(self, ap_ids, max_aps=4096, cache_size=65536):
        self.index = {normalize_ap_id(a): j for j, a in enumerate(ap_ids)}
        self.size = len(ap_ids)
        self.max_aps = max_aps
        self._cache = {}    # name as received -> column (names repeat)
        self._cache_size = cache_size

    def _column(self, name):
        column = self._cache.get(name)
        if column is None:
            column = self.index.get(normalize_ap_id(name), -1)
            if len(self._cache) >= self._cache_size:
                self._cache.clear()
            self._cache[name] = column
        return column

    def columns(self, names):
        """Return each name's column in the model, or -1 if unknown."""
        return np.fromiter(map(self._column, names), dtype=np.int64,
                           count=len(names))

    def place(self, cols, rssi):
        """
        Return readings on the AP vector: ``rssi[..., i]`` to ``cols[i]``.

        ``rssi`` is one scan or rows of scans (NaN = not detected). Unknown
        APs (column -1) are left out; an AP read twice keeps its strongest
        reading.
        """
        known = cols >= 0
        rssi = np.asarray(rssi, np.float32)
        vector = np.full(rssi.shape[:-1] + (self.size,), np.nan, np.float32)
        np.fmax.at(vector.T, cols[known], rssi.T[known])   # APs first
        return vector

    def map_rows(self, names, rssi):
        """Return rows of scans over AP ``names`` on the AP vector."""
        return self.place(self.columns(names), rssi)

    def map(self, names, rssi):
        """
        Return the :class:`MappedScan` of one scan; raise ScanRejected.

        An AP seen twice keeps its strongest reading; unknown APs are
        ignored and counted; RSSI follows the rule of :mod:`.rssi`.
        """
        if len(names) != len(rssi):
            raise ScanRejected('length_mismatch', f'{len(names)} names but '
                               f'{len(rssi)} RSSI values')
        if not len(names):
            raise ScanRejected('empty', 'the scan lists no AP')
        if len(names) > self.max_aps:
            raise ScanRejected('oversize', f'{len(names)} APs, more than '
                               f'max_aps={self.max_aps}')
        values = np.asarray(rssi, dtype=np.float64)
        if np.isnan(values).any():
            raise ScanRejected('non_finite', 'an RSSI value is NaN')
        try:
            values, clipped = clip_plausible(values)
        except RssiError as exc:
            kind = 'non_finite' if np.isinf(values[exc.index]) else \
                'implausible_rssi'
            name = repr(names[exc.index[0]])
            if len(name) > 40:
                name = name[:37] + '...'
            raise ScanRejected(kind, f'{name}: {exc}') from None
        cols = self.columns(names)
        known = cols >= 0
        if not known.any():
            raise ScanRejected('no_known_ap', f'none of the {len(names)} APs '
                               f'is known to the model')
        order = np.lexsort((-values[known], cols[known]))  # strongest first
        cols, values = cols[known][order], values[known][order]
        first = np.empty(len(cols), bool)  # an AP read twice: its strongest
        first[0] = True
        np.not_equal(cols[1:], cols[:-1], out=first[1:])
        return MappedScan(cols[first], values[first], int(first.sum()),
                          int((~known).sum()), clipped)
