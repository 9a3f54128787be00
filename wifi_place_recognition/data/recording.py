"""
A fingerprint CSV that grows one scan at a time, safe against kills.

The file is the generic format ``train_model`` reads: ``BUILDINGID``,
``FLOOR``, ``TIMESTAMP``, then one column per AP seen so far (``100`` =
not detected). A scan of known APs is appended and fsynced; a scan with a
new AP rewrites the file atomically with the wider header. A kill therefore
loses at most the scan being written; on reopening, a torn last line is cut
off and recording continues in the same file.
"""

from collections import Counter
import math
import os
from pathlib import Path

import numpy as np

from ..core.atomic import atomic_write
from ..core.rssi import clip_plausible, plausible
from ..core.scan import normalize_ap_id
from .fingerprints import NOT_DETECTED_MARKER

LEADING = ('BUILDINGID', 'FLOOR', 'TIMESTAMP')
MISSING = f'{NOT_DETECTED_MARKER:g}'


class RecordingError(ValueError):
    """A file that this recorder cannot continue."""


class FingerprintLog:
    """Append labelled scans to ``path`` (created, or continued)."""

    def __init__(self, path):
        self.path = Path(path)
        self.ap_ids = []
        self.counts = Counter()
        if self.path.exists() and self.path.stat().st_size:
            self._continue()
        self.index = {ap: j for j, ap in enumerate(self.ap_ids)}

    def _continue(self):
        data = self.path.read_bytes()
        end = data.rfind(b'\n') + 1
        if end < len(data):             # a torn last line: cut it off
            with open(self.path, 'r+b') as f:
                f.truncate(end)
                f.flush()
                os.fsync(f.fileno())
        lines = data[:end].decode().splitlines()
        if not lines:
            raise RecordingError(f'{self.path}: no complete header line')
        header = lines[0].split(',')
        if tuple(header[:3]) != LEADING:
            raise RecordingError(f'{self.path}: not a recording (the header '
                                 f'must start with {",".join(LEADING)})')
        self.ap_ids = header[3:]
        for line in lines[1:]:
            cells = line.split(',', 2)
            self.counts[(int(cells[0]), int(cells[1]))] += 1

    def add(self, names, rssi, building, floor, timestamp):
        """
        Record one scan; return (recorded, readings left out).

        Readings that are not finite or outside the plausible RSSI range are
        left out; (0, 20] dBm is clipped to 0; a repeated AP keeps its
        strongest reading. A scan left with no reading is not recorded.
        """
        best, skipped = {}, 0
        rssi = np.array(rssi, dtype=np.float64)
        ok = plausible(rssi)    # the node would reject the whole scan
        rssi[ok] = clip_plausible(rssi[ok])[0]
        for name, value, good in zip(names, rssi.tolist(), ok):
            ap = normalize_ap_id(name)
            if not (good and ap) or ',' in ap or '\n' in ap:
                skipped += 1
                continue
            best[ap] = max(best.get(ap, -math.inf), value)
        if not best:
            return False, skipped
        new = [ap for ap in best if ap not in self.index]
        for ap in new:
            self.index[ap] = len(self.ap_ids)
            self.ap_ids.append(ap)
        cells = [MISSING] * len(self.ap_ids)
        for ap, value in best.items():
            cells[self.index[ap]] = f'{value:g}'
        row = ','.join([str(building), str(floor), f'{timestamp:.3f}']
                       + cells) + '\n'
        if new or not self.path.exists():
            self._rewrite(len(new), row)
        else:
            with open(self.path, 'a') as f:
                f.write(row)
                f.flush()
                os.fsync(f.fileno())
        self.counts[(building, floor)] += 1
        return True, skipped

    def _rewrite(self, n_new, row):
        pad = (',' + MISSING) * n_new
        with atomic_write(self.path, 'w') as out:
            out.write(','.join(LEADING + tuple(self.ap_ids)) + '\n')
            if self.path.exists():
                with open(self.path) as old:
                    next(old, None)
                    for line in old:
                        out.write(line.rstrip('\n') + pad + '\n')
            out.write(row)
