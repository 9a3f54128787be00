"""
A fingerprint CSV that grows one scan at a time, safe against kills.

The file is the generic format ``train_model`` reads: ``BUILDINGID``,
``FLOOR``, ``TIMESTAMP``, with positions ``X``, ``Y`` (metres) and
``FRAME`` (the frame they are in), then one column per AP seen so far
(``100`` = not detected). A file has positions in every row or in none. A
scan of known APs is appended and fsynced; a scan with a new AP rewrites
the file atomically with the wider header. A kill therefore loses at most
the scan being written; on reopening, a torn last line is cut off and
recording continues in the same file.
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
POSITION = ('X', 'Y', 'FRAME')
MISSING = f'{NOT_DETECTED_MARKER:g}'


class RecordingError(ValueError):
    """A file that this recorder cannot continue."""


def frame_problem(frame):
    """Return why ``frame`` cannot be written as a FRAME cell, or None."""
    if not frame:
        return 'no frame_id'
    if any(c in frame for c in ',"\r\n'):
        return f'frame_id {frame!r} has a comma, quote or line break'
    return None


class FingerprintLog:
    """
    Append labelled scans to ``path`` (created, or continued).

    With ``positions``, every scan has a position and the file the ``X``,
    ``Y``, ``FRAME`` columns; a file is continued only the way it started.
    """

    def __init__(self, path, positions=False):
        self.path = Path(path)
        self.positions = positions
        self.leading = LEADING + (POSITION if positions else ())
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
        if (tuple(header[3:6]) == POSITION) != self.positions:
            raise RecordingError(
                f'{self.path}: recorded ' + (
                    'without positions (no X,Y,FRAME columns): cannot add '
                    'positions half-way; record them to a new file'
                    if self.positions else
                    'with positions (X,Y,FRAME columns): cannot continue '
                    'without them; set pose_topic, or use a new file'))
        self.ap_ids = header[len(self.leading):]
        for line in lines[1:]:
            cells = line.split(',', 2)
            self.counts[(int(cells[0]), int(cells[1]))] += 1

    def add(self, names, rssi, building, floor, timestamp, position=None):
        """
        Record one scan; return (recorded, readings left out).

        Readings that are not finite or outside the plausible RSSI range are
        left out; (0, 20] dBm is clipped to 0; a repeated AP keeps its
        strongest reading. A scan left with no reading is not recorded.
        ``position`` is (x, y, frame), given if and only if the log has
        positions.
        """
        if (position is not None) != self.positions:
            raise ValueError('a position is needed exactly when the log '
                             'has positions')
        if position is not None and frame_problem(position[2]):
            raise RecordingError(frame_problem(position[2]))
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
        where = [] if position is None else \
            [f'{position[0]:.3f}', f'{position[1]:.3f}', position[2]]
        row = ','.join([str(building), str(floor), f'{timestamp:.3f}']
                       + where + cells) + '\n'
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
            out.write(','.join(self.leading + tuple(self.ap_ids)) + '\n')
            if self.path.exists():
                with open(self.path) as old:
                    next(old, None)
                    for line in old:
                        out.write(line.rstrip('\n') + pad + '\n')
            out.write(row)
