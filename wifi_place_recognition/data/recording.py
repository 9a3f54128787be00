"""
The recorder's growing CSVs, safe against kills: scans and odometry.

:class:`FingerprintLog` is the generic fingerprint format ``train_model``
reads: ``BUILDINGID``, ``FLOOR``, ``TIMESTAMP``, with positions ``X``, ``Y``
(metres), ``YAW`` (rad) and ``FRAME`` (the frame they are in), then one
column per AP seen so far (``100`` = not detected). A file has positions in
every row or in none (files of earlier recorders have ``X``, ``Y``,
``FRAME`` without ``YAW``, and keep that). A scan of known APs is appended
and fsynced; a scan with a new AP rewrites the file atomically with the
wider header. :class:`PoseLog` is a pose CSV (:mod:`.poses`: ``TIMESTAMP``,
``X``, ``Y``, ``YAW``) appended in batches. A kill therefore loses at most
what is being written; on reopening, a torn last line is cut off and
recording continues in the same file. Rows that cannot be written wait in
memory and are written with the next write that works.
"""

from collections import Counter
import contextlib
import math
import os
from pathlib import Path
import time

import numpy as np

from ..core.atomic import atomic_write, probe_folder
from ..core.rssi import clip_plausible, plausible
from ..core.scan import normalize_ap_id
from .columns import NOT_DETECTED_MARKER, writable_cell
from .poses import POSE_COLUMNS

LEADING = ('BUILDINGID', 'FLOOR', 'TIMESTAMP')
POSITION = ('X', 'Y', 'YAW', 'FRAME')
#: The position columns of files recorded before YAW was.
POSITION_WITHOUT_YAW = ('X', 'Y', 'FRAME')
MISSING = f'{NOT_DETECTED_MARKER:g}'


class RecordingError(ValueError):
    """A file that this recorder cannot continue."""


def frame_problem(frame):
    """Return why ``frame`` cannot be written as a FRAME cell, or None."""
    if not frame:
        return 'no frame_id'
    if not writable_cell(frame):
        return f'frame_id {frame!r} has a comma, quote or line break'
    return None


def odometry_path(output):
    """Return the odometry CSV beside the scans ``output``: a.csv -> a.odom.csv."""
    output = Path(output)
    stem = output.name[:-4] if output.suffix.lower() == '.csv' \
        else output.name
    return output.with_name(f'{stem}.odom.csv')


def _check_folder(path):
    """
    Create the folder of ``path`` if missing (with its parents).

    Raise RecordingError unless a file can be created in it.
    """
    folder = path.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        there = next(p for p in (folder, *folder.parents) if p.exists())
        reason = exc.strerror or exc if there.is_dir() else \
            f'{there} is not a folder'
        raise RecordingError(f'output {path}: cannot create the '
                             f'folder {folder} ({reason})') from None
    try:
        probe_folder(path)
    except OSError as exc:
        raise RecordingError(
            f'output {path}: cannot write in the folder {folder} '
            f'({exc.strerror or exc})') from None


def _complete_lines(path, header_problem):
    """
    Return the lines of ``path`` (none if absent or empty).

    Raise RecordingError, leaving the file as it is, if it has no complete
    first line or ``header_problem(first line)`` says why it is not one of
    ours; else cut a torn last line off (a kill mid-write).
    """
    if not path.exists() or not path.stat().st_size:
        return []
    data = path.read_bytes()
    end = data.rfind(b'\n') + 1
    lines = data[:end].decode(errors='replace').splitlines()
    problem = header_problem(lines[0]) if lines else 'no complete header line'
    if problem:
        raise RecordingError(f'{path}: {problem}')
    if end < len(data):
        with open(path, 'r+b') as f:
            f.truncate(end)
            f.flush()
            os.fsync(f.fileno())
    return lines


def _append(path, rows, header):
    """Append ``rows`` (``header`` first to an empty file), fsynced, or nothing."""
    with open(path, 'a') as f:
        start = f.tell()
        try:
            f.write((header if not start else '') + rows)
            f.flush()
            os.fsync(f.fileno())
        except OSError:
            with contextlib.suppress(OSError):
                f.truncate(start)   # no torn line for the next append
            raise


def _save(path, folder, text):
    """Write ``text`` to a new file named after ``path`` in ``folder``."""
    name = (f'{path.stem}.unsaved-{time.strftime("%Y%m%d-%H%M%S")}'
            f'{path.suffix}')
    saved = Path(folder) / name
    with atomic_write(saved, 'w') as out:
        out.write(text)
    return saved


class FingerprintLog:
    """
    Append labelled scans to ``path`` (created, or continued).

    With ``positions``, every scan has a position and the file the ``X``,
    ``Y``, ``YAW``, ``FRAME`` columns; a file is continued only the way it
    started (``yaw`` is False for a file without ``YAW``: its scans go on
    without). A scan that cannot be written (the folder gone, the disk
    full) waits in memory (``pending``; the error in ``write_error``) until
    :meth:`flush` writes it, or :meth:`save_pending` puts it in another
    file.
    """

    def __init__(self, path, positions=False):
        self.path = Path(path)
        self.positions = positions
        self.leading = LEADING + (POSITION if positions else ())
        self.ap_ids = []
        self.counts = Counter()
        self.pending = []       # (leading cells, {ap: dBm}) not yet written
        self.write_error = None
        _check_folder(self.path)
        lines = _complete_lines(self.path, self._header_problem)
        if lines:
            self.leading = LEADING + self._position_columns(lines[0])
            self.ap_ids = lines[0].split(',')[len(self.leading):]
            for line in lines[1:]:
                cells = line.split(',', 2)
                self.counts[(int(cells[0]), int(cells[1]))] += 1
        self.yaw = 'YAW' in self.leading
        self.index = {ap: j for j, ap in enumerate(self.ap_ids)}
        self.written_aps = len(self.ap_ids)     # AP columns in the file

    @staticmethod
    def _position_columns(line):
        header = tuple(line.split(','))
        return next((c for c in (POSITION, POSITION_WITHOUT_YAW)
                     if header[3:3 + len(c)] == c), ())

    def _header_problem(self, line):
        if tuple(line.split(',')[:3]) != LEADING:
            return (f'not a recording (the header must start with '
                    f'{",".join(LEADING)})')
        if bool(self._position_columns(line)) != self.positions:
            return 'recorded ' + (
                'without positions (no X,Y[,YAW],FRAME columns): cannot add '
                'positions half-way; record them to a new file'
                if self.positions else
                'with positions (X,Y[,YAW],FRAME columns): cannot continue '
                'without them; set pose_topic, or use a new file')
        return None

    def add(self, names, rssi, building, floor, timestamp, position=None):
        """
        Record one scan, then :meth:`flush`; return (recorded, left out).

        Readings that are not finite or outside the plausible RSSI range are
        left out; (0, 20] dBm is clipped to 0; a repeated AP keeps its
        strongest reading. A scan left with no reading is not recorded.
        ``position`` is (x, y, yaw, frame), given if and only if the log
        has positions (the yaw is left out of a file without ``YAW``). A
        recorded scan that cannot be written yet stays in ``pending``.
        """
        if (position is not None) != self.positions:
            raise ValueError('a position is needed exactly when the log '
                             'has positions')
        if position is not None and frame_problem(position[3]):
            raise RecordingError(frame_problem(position[3]))
        best, skipped = {}, 0
        rssi = np.array(rssi, dtype=np.float64)
        ok = plausible(rssi)    # the node would reject the whole scan
        rssi[ok] = clip_plausible(rssi[ok])[0]
        for name, value, good in zip(names, rssi.tolist(), ok):
            ap = normalize_ap_id(name)
            if not (good and writable_cell(ap)):
                skipped += 1
                continue
            best[ap] = max(best.get(ap, -math.inf), value)
        if not best:
            return False, skipped
        for ap in best:
            if ap not in self.index:
                self.index[ap] = len(self.ap_ids)
                self.ap_ids.append(ap)
        where = []
        if position is not None:
            x, y, yaw, frame = position
            where = [f'{x:.3f}', f'{y:.3f}'] + \
                ([f'{yaw:.4f}'] if self.yaw else []) + [frame]
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
                _append(self.path, self._rows(), self.header())
        except OSError as exc:
            self.write_error = exc
            return False
        self.written_aps = len(self.ap_ids)
        self.pending.clear()
        self.write_error = None
        return True

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
        saved = _save(self.path, folder, self.header() + self._rows())
        self.pending.clear()
        return saved


class PoseLog:
    """
    Append poses to the pose CSV ``path`` (created, or continued) in batches.

    :meth:`add` keeps a pose (stamp s, x, y m, yaw rad) in ``pending``;
    :meth:`flush` appends all pending ones at once, fsynced. On failure they
    stay (the error in ``write_error``, the file cut back) for the next
    flush, or :meth:`save_pending`. ``written`` counts the rows written.
    Poses that :func:`.poses.read_poses` would refuse are not kept.
    """

    HEADER = ','.join(POSE_COLUMNS) + '\n'

    def __init__(self, path):
        self.path = Path(path)
        self.pending = []       # lines not yet written
        self.write_error = None
        self.written = 0
        self.last_stamp = -math.inf
        header = self.HEADER.strip()
        _check_folder(self.path)
        lines = _complete_lines(self.path, lambda line: None if line == header
                                else f'not a pose recording (the header '
                                     f'must be {header})')
        if len(lines) > 1:
            cell = lines[-1].split(',')[0]
            try:
                self.last_stamp = float(cell)
            except ValueError:
                raise RecordingError(
                    f'{self.path}: row {len(lines)}, column TIMESTAMP: '
                    f'{cell!r} is not a number') from None

    def add(self, stamp, x, y, yaw):
        """
        Keep one pose to write; return None, or (kind, why) if refused.

        ``kind`` is ``'invalid'`` (a value not finite) or
        ``'out_of_order'`` (a stamp earlier than the last one kept; equal
        stamps are kept).
        """
        if not all(math.isfinite(v) for v in (stamp, x, y, yaw)):
            return 'invalid', (f'stamp, x, y, yaw = {stamp}, {x}, {y}, '
                               f'{yaw} is not finite')
        line = f'{stamp:.6f},{x:.4f},{y:.4f},{yaw:.6f}\n'
        stamp = float(line.split(',', 1)[0])    # as read back
        if stamp < self.last_stamp:
            return 'out_of_order', (f'stamp {stamp:.6f} is earlier than the '
                                    f'last recorded, {self.last_stamp:.6f}')
        self.last_stamp = stamp
        self.pending.append(line)
        return None

    def flush(self):
        """Write the pending poses; return True when none is left waiting."""
        if not self.pending:
            return True
        try:
            _append(self.path, ''.join(self.pending), self.HEADER)
        except OSError as exc:
            self.write_error = exc
            return False
        self.written += len(self.pending)
        self.pending.clear()
        self.write_error = None
        return True

    def save_pending(self, folder):
        """
        Write the pending poses to a new pose CSV in ``folder``; return it.

        Named after ``path`` with ``.unsaved-<time>``. Raises OSError.
        """
        saved = _save(self.path, folder, self.HEADER + ''.join(self.pending))
        self.written += len(self.pending)
        self.pending.clear()
        return saved
