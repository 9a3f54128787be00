"""
A fingerprint CSV that grows one scan at a time, safe against kills.

The file is the generic format ``train_model`` reads: ``BUILDINGID``,
``FLOOR``, ``TIMESTAMP``, with positions ``X``, ``Y`` (metres) and
``FRAME`` (the frame they are in), then one column per AP seen so far
(``100`` = not detected). A file has positions in every row or in none. A
scan of known APs is appended and fsynced; a scan with a new AP rewrites
the file atomically with the wider header. A kill therefore loses at most
the scan being written; on reopening, a torn last line is cut off and
recording continues in the same file. Scans that cannot be written wait in
memory and are written with the next write that works.
"""

from collections import Counter
import contextlib
import math
import os
from pathlib import Path
import tempfile
import time

import numpy as np

from ..core.atomic import atomic_write
from ..core.rssi import clip_plausible, plausible
from ..core.scan import normalize_ap_id
from .columns import NOT_DETECTED_MARKER

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
    A scan that cannot be written (the folder gone, the disk full) waits in
    memory (``pending``; the error in ``write_error``) until :meth:`flush`
    writes it, or :meth:`save_pending` puts it in another file.
    """

    def __init__(self, path, positions=False):
        self.path = Path(path)
        self.positions = positions
        self.leading = LEADING + (POSITION if positions else ())
        self.ap_ids = []
        self.counts = Counter()
        self.pending = []       # (leading cells, {ap: dBm}) not yet written
        self.write_error = None
        self._check_folder()
        if self.path.exists() and self.path.stat().st_size:
            self._continue()
        self.index = {ap: j for j, ap in enumerate(self.ap_ids)}
        self.written_aps = len(self.ap_ids)     # AP columns in the file

    def _check_folder(self):
        """
        Create the folder of ``path`` if missing (with its parents).

        Raise RecordingError unless a file can be created in it.
        """
        folder = self.path.parent
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            there = next(p for p in (folder, *folder.parents) if p.exists())
            reason = exc.strerror or exc if there.is_dir() else \
                f'{there} is not a folder'
            raise RecordingError(f'output {self.path}: cannot create the '
                                 f'folder {folder} ({reason})') from None
        try:
            fd, probe = tempfile.mkstemp(dir=self.path.parent,
                                         prefix=f'.{self.path.name}.',
                                         suffix='.probe')
            os.close(fd)
            os.unlink(probe)
        except OSError as exc:
            raise RecordingError(
                f'output {self.path}: cannot write in the folder '
                f'{self.path.parent} ({exc.strerror or exc})') from None

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
        Record one scan, then :meth:`flush`; return (recorded, left out).

        Readings that are not finite or outside the plausible RSSI range are
        left out; (0, 20] dBm is clipped to 0; a repeated AP keeps its
        strongest reading. A scan left with no reading is not recorded.
        ``position`` is (x, y, frame), given if and only if the log has
        positions. A recorded scan that cannot be written yet stays in
        ``pending``.
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
        for ap in best:
            if ap not in self.index:
                self.index[ap] = len(self.ap_ids)
                self.ap_ids.append(ap)
        where = [] if position is None else \
            [f'{position[0]:.3f}', f'{position[1]:.3f}', position[2]]
        self.pending.append(
            ([str(building), str(floor), f'{timestamp:.3f}'] + where, best))
        self.counts[(building, floor)] += 1
        self.flush()
        return True, skipped

    def _rows(self):
        """Return the pending scans as lines as wide as ``ap_ids``."""
        lines = []
        for leading, best in self.pending:
            cells = [MISSING] * len(self.ap_ids)
            for ap, value in best.items():
                cells[self.index[ap]] = f'{value:g}'
            lines.append(','.join(leading + cells) + '\n')
        return ''.join(lines)

    def flush(self):
        """
        Write the pending scans; return True when none is left waiting.

        On failure they stay pending, ``write_error`` holds the OSError and
        the file is as before (an append is cut back, a rewrite is atomic).
        """
        if not self.pending:
            return True
        try:
            if self.written_aps < len(self.ap_ids) or not self.path.exists():
                self._rewrite(self._rows())
            else:
                self._append(self._rows())
        except OSError as exc:
            self.write_error = exc
            return False
        self.written_aps = len(self.ap_ids)
        self.pending.clear()
        self.write_error = None
        return True

    def _append(self, rows):
        with open(self.path, 'a') as f:
            start = f.tell()
            try:
                f.write(rows)
                f.flush()
                os.fsync(f.fileno())
            except OSError:
                with contextlib.suppress(OSError):
                    f.truncate(start)   # no torn line for the next append
                raise

    def _rewrite(self, rows):
        pad = (',' + MISSING) * (len(self.ap_ids) - self.written_aps)
        with atomic_write(self.path, 'w') as out:
            out.write(self.header())
            if self.path.exists():
                with open(self.path) as old:
                    next(old, None)
                    for line in old:
                        out.write(line.rstrip('\n') + pad + '\n')
            out.write(rows)

    def header(self):
        """Return the header line for the APs seen so far."""
        return ','.join(self.leading + tuple(self.ap_ids)) + '\n'

    def save_pending(self, folder):
        """
        Write the pending scans to a new file in ``folder``; return its path.

        A recording of its own (header and the pending scans only), named
        after ``path`` with ``.unsaved-<time>``. Raises OSError.
        """
        name = (f'{self.path.stem}.unsaved-{time.strftime("%Y%m%d-%H%M%S")}'
                f'{self.path.suffix}')
        path = Path(folder) / name
        with atomic_write(path, 'w') as out:
            out.write(self.header() + self._rows())
        self.pending.clear()
        return path
