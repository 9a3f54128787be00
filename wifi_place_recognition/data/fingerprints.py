"""
Fingerprint CSVs in memory: the :class:`Fingerprints` schema, the front door.

A fingerprint CSV has a header row, then one scan per row; its columns have
roles (labels, device, time, position, metadata, APs: :mod:`.columns`,
renamed by :class:`ReaderOptions`). The RSSI rule of :mod:`..core.rssi`
applies to every reading; a value it refuses is an error naming file, row
and column. In memory a not-detected AP is ``NaN``. Columns whose
identifiers are the same AP (``AA-BB-...``, ``aa:bb:...``) are merged by the
node's mapping: the strongest reading wins.

A path may be a folder (its ``*.csv`` files) or several paths
(:mod:`.files`): each file is a walk, and ``Fingerprints.walk`` keeps which
file each scan came from.
"""

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..core.metrics import class_index
from ..core.rssi import clip_plausible, RssiError
from ..core.scan import ScanMapper
from .columns import (ap_columns, DEVICE, distinct_aps, few, FileColumns,
                      markers, TIME, YAW)
from .files import DataError, decode, digest, input_files

#: A class with fewer scans than this fraction of the median other class
#: is suspicious (a typo in a label?).
SMALL_CLASS_RATIO = 0.05
SMALL_CLASS_POLICIES = ('warn', 'drop', 'keep')


@dataclass(frozen=True)
class ReaderOptions:
    """
    How to read files whose columns are not named as in UJIIndoorLoc.

    ``ap_columns`` / ``meta_columns``: names or shell patterns (``WAP*``);
    ``building_column=None``: one building (0 for every scan);
    ``position_columns``: ``()`` looks for a known pair, ``None`` ignores
    coordinates; ``not_detected_marker=None``: 100 plus the obvious case;
    ``small_classes``: what to do with classes far smaller than the rest:
    ``warn`` (keep them, with a warning), ``drop``, ``keep`` (as intended),
    ``None`` (no check).
    """

    ap_columns: tuple = ()
    meta_columns: tuple = ()
    building_column: str = 'BUILDINGID'
    floor_column: str = 'FLOOR'
    device_column: str = DEVICE
    time_column: str = TIME
    position_columns: tuple = ()
    not_detected_marker: float = None
    small_classes: str = None

    def __post_init__(self):
        """Refuse options that cannot work, before any file is read."""
        if self.position_columns is not None and \
                len(self.position_columns) not in (0, 2):
            raise DataError(f'position columns: need two names (X,Y), got '
                            f'{",".join(self.position_columns)}')
        if self.small_classes not in (None,) + SMALL_CLASS_POLICIES:
            raise DataError(f'small classes: {self.small_classes!r} is not '
                            f'one of {", ".join(SMALL_CLASS_POLICIES)}')
        if self.not_detected_marker is not None and \
                not np.isfinite(self.not_detected_marker):
            raise DataError('the not-detected marker must be a number')


@dataclass
class Fingerprints:
    """Scans as a dense matrix: ``rssi[i, j]`` is AP ``ap_ids[j]`` in scan i."""

    ap_ids: tuple
    rssi: np.ndarray            # float32 (n, m), NaN = not detected
    building: np.ndarray        # int64 (n,)
    floor: np.ndarray           # int64 (n,)
    meta: dict = field(default_factory=dict)  # device (PHONEID: int or
    #                             str), time (TIMESTAMP: float64 s), others
    source: str = ''
    clipped: int = 0            # cells clipped from (0, 20] dBm to 0 dBm
    sha256: str = ''            # of the CSV bytes (several: see read)
    walk: np.ndarray = None     # str (n,): file of each scan (several files)
    position: np.ndarray = None  # float64 (n, 2), metres, when the data has
    position_columns: tuple = ()  # the two column names
    line: np.ndarray = None     # int64 (n,): line of the scan in its file
    notes: list = field(default_factory=list)  # how the data was read

    def __len__(self):
        return len(self.building)

    @property
    def empty_rows(self):
        """Boolean mask of scans that detected no AP at all."""
        return ~np.isfinite(self.rssi).any(axis=1)

    def subset(self, mask):
        """Return the scans selected by a boolean mask or index array."""
        def take(a):
            return None if a is None else a[mask]
        return replace(self, rssi=self.rssi[mask],
                       building=self.building[mask], floor=self.floor[mask],
                       meta={k: v[mask] for k, v in self.meta.items()},
                       walk=take(self.walk), position=take(self.position),
                       line=take(self.line))

    def where(self, i):
        """Return where scan ``i`` is, for messages (row, and file)."""
        text = f'row {self.line[i]}' if self.line is not None else \
            f'scan {i + 1}'
        return text if self.walk is None else f'{self.walk[i]}: {text}'

    def summary(self):
        """Return one line: scans, APs, readings per scan, classes."""
        files = '' if self.walk is None else \
            f' from {len(np.unique(self.walk))} files'
        detected = np.isfinite(self.rssi).sum(axis=1).mean() if len(self) \
            else 0.0
        classes = len(class_index(self.building, self.floor)[0])
        return (f'{self.source}: {len(self)} scans{files}, '
                f'{len(self.ap_ids)} APs, {detected:.1f} detected per scan '
                f'on average, {classes} building/floor classes, '
                f'{self.clipped} RSSI cells clipped to 0 dBm')


def read_fingerprints(path, role='train', options=None):
    """
    Read fingerprints from a CSV, a folder of CSVs, several paths or a zip.

    ``path`` may be ``file.csv``, a folder (every ``*.csv`` in it, one walk
    each), a list of such paths, ``ujiindoorloc.zip`` (the member for
    ``role``: trainingData.csv or validationData.csv) or
    ``archive.zip#member.csv``. With several files, ``sha256`` is a digest
    over each file's name and bytes, in name order.
    """
    options = options or ReaderOptions()
    paths = [path] if isinstance(path, (str, Path)) else list(path)
    if not paths:
        raise DataError('no data path given')
    files, source = input_files(paths, role)
    tables = [FileColumns(decode(raw, name), name, options)
              for name, _, raw in files]
    return _assemble(tables, [walk for _, walk, _ in files], source,
                     digest(files), options)


def parse_fingerprints(text, source=('<string>', b''), options=None):
    """Parse CSV text; ``source`` is (name used in errors, raw bytes)."""
    name, raw = source
    options = options or ReaderOptions()
    return _assemble([FileColumns(text, name, options)], [None], name,
                     digest([(name, None, raw)]), options)


def _assemble(tables, walks, source, sha256, options):
    """Decide markers and AP columns over all files; return one dataset."""
    notes = []
    matched = set().union(*(t.matched for t in tables))
    for pattern in options.meta_columns + options.ap_columns:
        if pattern not in matched:
            raise DataError(f'{source}: no column matches {pattern!r} '
                            f'(named as an AP or metadata column)')
    not_detected = markers(tables, options, source, notes)
    ap_names = ap_columns(tables, not_detected, options, source, notes)
    parts = [_finish(t, ap_names, not_detected, source, notes)
             for t in tables]
    fp = _merge(parts, walks, source, sha256, notes)
    if options.building_column is None:
        notes.append(f'{source}: no building column: building 0 for every '
                     f'scan')
    fp.notes = list(dict.fromkeys(notes))
    if options.small_classes is not None:
        fp = _small_classes(fp, options.small_classes)
    return fp


def _yaw(cells, j, unplaced):
    """
    Return the heading (rad) of the placed rows, or fail naming the cell.

    A heading beyond +-2 pi is not in radians (degrees, or garbage).
    """
    yaw = cells.numeric(j, skip=unplaced)
    beyond = np.abs(np.nan_to_num(yaw)) > 2 * np.pi
    if beyond.any():
        r = int(np.argmax(beyond))
        cells.fail(r, j, f'value {yaw[r]:g} is beyond +-2 pi (a heading in '
                   f'radians)')
    return yaw


def _finish(t, ap_names, not_detected, source, notes):
    """Return one file's :class:`Fingerprints` (AP columns of its own)."""
    cells = t.table
    ks = [k for k, j in enumerate(t.candidates)
          if ap_names is None or t.header[j] in ap_names]
    cols = [t.candidates[k] for k in ks]
    for j in cols:
        if j in cells.texts:
            cells.numeric(j)                # fails on the first text cell
    raw = t.block if len(ks) == len(t.candidates) else t.block[:, ks]
    missing = np.isin(raw, not_detected)
    bad = ~(missing | np.isfinite(raw))
    if bad.any():
        r, k = np.argwhere(bad)[0]
        cells.fail(r, cols[k], f'value {raw[r, k]:g} is not a finite number')
    try:
        rssi, clipped = clip_plausible(np.where(missing, np.nan, raw))
    except RssiError as exc:
        r, k = exc.index
        cells.fail(r, cols[k], str(exc))
    names = [t.header[j] for j in cols]
    ids = distinct_aps(names)
    if len(ids) < len(names):
        same = [h for h in names if h not in ids]
        notes.append(f'{source}: columns {few(same)} name the AP of an '
                     f'earlier column (case and separators ignored): '
                     f'merged, the strongest reading wins')
        rssi = ScanMapper(ids).map_rows(names, rssi)
    left_out = set(t.candidates) - set(cols)
    meta = {t.header[j]: cells.metadata(j)
            for j in sorted(t.meta + t.unnamed + list(left_out))}
    if t.device is not None:
        meta[DEVICE] = cells.device_ids(t.device)
    if t.time is not None:
        meta[TIME] = cells.times(t.time)
    position, position_columns = None, ()
    unplaced = np.zeros(len(cells.lines), bool)
    if t.position is not None:
        unplaced = np.logical_and.reduce([cells.blank(j)
                                          for j in t.position])
        position = np.stack([cells.numeric(j, skip=unplaced)
                             for j in t.position], axis=1)
        position_columns = tuple(t.header[j] for j in t.position)
        if YAW in meta:
            meta[YAW] = _yaw(cells, t.header.index(YAW), unplaced)
    building = np.zeros(len(cells.lines), np.int64) if t.building is None \
        else cells.label(t.building)
    fp = Fingerprints(ids, rssi.astype(np.float32), building,
                      cells.label(t.floor), meta, t.name, clipped,
                      position=position, position_columns=position_columns,
                      line=cells.lines)
    if unplaced.any():
        notes.append(f'{source}: {int(unplaced.sum())} row(s) with empty '
                     f'{" and ".join(position_columns)} left out (rows '
                     f'{few(map(str, cells.lines[unplaced]))})')
        fp = fp.subset(~unplaced)
    return fp


def _merge(parts, walks, source, sha256, notes):
    """Return the parts (files) as one :class:`Fingerprints`."""
    first = parts[0]
    ids = distinct_aps(ap for p in parts for ap in p.ap_ids)
    mapper = ScanMapper(ids)
    rssi = np.concatenate([p.rssi if p.ap_ids == ids else
                           mapper.map_rows(p.ap_ids, p.rssi) for p in parts])

    def roles(p):
        return {'device': DEVICE in p.meta, 'time': TIME in p.meta,
                'position': p.position is not None}
    for p in parts[1:]:
        for role, present in roles(p).items():
            if present != roles(first)[role]:
                raise DataError(f'{p.source}: has {"a" if present else "no"} '
                                f'{role} column, unlike {first.source}')
    keys = [k for k in first.meta if all(k in p.meta for p in parts)]
    dropped = {k for p in parts for k in p.meta} - set(keys)
    if dropped:
        notes.append(f'{source}: metadata columns not in every file left '
                     f'out: {few(sorted(dropped))}')
    meta = {}
    for k in keys:
        values = [p.meta[k] for p in parts]
        if len({v.dtype.kind for v in values}) > 1:
            values = [v.astype(str) for v in values]
        meta[k] = np.concatenate(values)
    walk = None if walks[0] is None else \
        np.concatenate([np.full(len(p), w) for p, w in zip(parts, walks)])
    position = None if first.position is None else \
        np.concatenate([p.position for p in parts])
    return Fingerprints(
        ids, rssi, np.concatenate([p.building for p in parts]),
        np.concatenate([p.floor for p in parts]), meta, source,
        sum(p.clipped for p in parts), sha256, walk, position,
        first.position_columns, np.concatenate([p.line for p in parts]))


def _small_classes(fp, policy):
    """Warn about, drop or keep classes far smaller than the others."""
    classes, labels = class_index(fp.building, fp.floor)
    counts = np.bincount(labels, minlength=len(classes))
    small = [c for c in range(len(classes)) if len(classes) > 1 and
             counts[c] < SMALL_CLASS_RATIO * np.median(np.delete(counts, c))]
    if not small:
        return fp
    listed = '; '.join(
        f'building {classes[c][0]}, floor {classes[c][1]}: {counts[c]} '
        f'scan(s), first at {fp.where(int(np.argmax(labels == c)))}'
        for c in small)
    median = int(np.median(counts))
    if policy == 'drop':
        fp = fp.subset(~np.isin(labels, small))
        note = f'classes far smaller than the rest left out: {listed}'
    elif policy == 'keep':
        note = f'classes far smaller than the rest kept as asked: {listed}'
    else:
        note = (f'classes far smaller than the rest (median {median} scans '
                f'per class; a typo in a label?): {listed}; kept '
                f'(--small-classes drop leaves them out, --small-classes '
                f'keep keeps them as intended)')
    fp.notes = fp.notes + [f'{fp.source}: {note}']
    return fp


def check_trainable(fp, min_scans=2):
    """
    Raise :class:`DataError` unless ``fp`` can train a classifier.

    Needs scans that detect an AP, at least two building/floor classes (or
    one with positions: a position-only model), and ``min_scans`` scans per
    class (a class with one scan is usually a typo in a label).
    """
    rows = np.flatnonzero(~fp.empty_rows)
    if not len(rows):
        raise DataError(f'{fp.source}: no scan detects any AP')
    classes, labels = class_index(fp.building[rows], fp.floor[rows])
    _, first, counts = np.unique(labels, return_index=True,
                                 return_counts=True)
    if len(classes) < 2 and fp.position is None:
        raise DataError(f'{fp.source}: only one building/floor class '
                        f'(building {classes[0][0]}, floor '
                        f'{classes[0][1]}) and no positions: a classifier '
                        f'needs at least two classes, a one-class '
                        f'(position-only) model needs X, Y columns')
    for (building, floor), i, count in zip(classes, first, counts):
        if count < min_scans:
            raise DataError(
                f'{fp.source}: {fp.where(rows[i])}, columns BUILDINGID/'
                f'FLOOR: building {building}, floor {floor} has '
                f'{count} scan(s), fewer than {min_scans} (a typo in a '
                f'label?)')
