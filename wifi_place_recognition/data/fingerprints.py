"""
Fingerprint CSVs: reading and validating them, in UJIIndoorLoc's and other forms.

A fingerprint CSV has a header row, then one scan per row. Columns have
roles: the labels (``BUILDINGID``, ``FLOOR``), a device (``PHONEID``), a time
(``TIMESTAMP``), a position (``LONGITUDE``/``LATITUDE`` or ``X``/``Y``),
other metadata (the rest of UJIIndoorLoc's fixed list), and access points
(AP columns, named by the AP identifier: ``WAP001``, a MAC address, ``17``).
:class:`ReaderOptions` renames every role for files that name them
otherwise; default names match regardless of case.

Without ``ap_columns``, a column with no other role is an AP column when its
values look like RSSI: at least half of its readings (cells that are not
the not-detected marker) in [-120, 0) dBm. Other columns (counts, ids,
coordinates, timestamps, text) are left out as metadata, with a note naming
them. The not-detected marker is ``100`` (UJIIndoorLoc) unless given; a
value that fills most cells of most rows and is the lowest value of most
columns (WiFine's ``-100``) is taken as the marker too, with a note. The
RSSI rule of :mod:`..core.rssi` applies to every reading; a value it refuses
is an error naming file, row and column. In memory a not-detected AP is
``NaN``. Columns whose identifiers are the same AP (``AA-BB-...``,
``aa:bb:...``) are merged by the node's mapping: the strongest reading wins.

A path may be a folder (its ``*.csv`` files) or several paths: each file is
a walk, and ``Fingerprints.walk`` keeps which file each scan came from.
"""

import csv
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from fnmatch import fnmatchcase
import hashlib
import io
import operator
from pathlib import Path
import urllib.request
import warnings
import zipfile

import numpy as np

from ..core.atomic import atomic_write
from ..core.metrics import class_index
from ..core.rssi import clip_plausible, MAX_DBM, MIN_DBM, RssiError
from ..core.scan import normalize_ap_id, ScanMapper

#: UJIIndoorLoc's metadata columns (and the recorder's): never APs.
META_COLUMNS = ('LONGITUDE', 'LATITUDE', 'FLOOR', 'BUILDINGID', 'SPACEID',
                'RELATIVEPOSITION', 'USERID', 'PHONEID', 'TIMESTAMP', 'FRAME')
#: Position columns looked for, in this order, unless named.
POSITION_PAIRS = (('LONGITUDE', 'LATITUDE'), ('X', 'Y'))
#: ``Fingerprints.meta`` keys of the device and time columns.
DEVICE, TIME = 'PHONEID', 'TIMESTAMP'
NOT_DETECTED_MARKER = 100.0
#: A class with fewer scans than this fraction of the median other class
#: is suspicious (a typo in a label?).
SMALL_CLASS_RATIO = 0.05
SMALL_CLASS_POLICIES = ('warn', 'drop', 'keep')

UCI_URL = 'https://archive.ics.uci.edu/static/public/310/ujiindoorloc.zip'
#: SHA-256 of the UCI ``trainingData.csv``, checked inside a downloaded zip.
UCI_TRAINING_SHA256 = ('45ca0128bd12019c976bb4793e407c979c82995d7a5940ab72'
                       '88620247905168')
ZIP_MEMBERS = {'train': 'trainingData.csv', 'test': 'validationData.csv'}


class DataError(ValueError):
    """A fingerprint file that cannot be used, with the place that is wrong."""


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
    files, source = _input_files(paths, role)
    tables = [_Table(_decode(raw, name), name, options)
              for name, _, raw in files]
    walks = [walk for _, walk, _ in files]
    if walks[0] is None:
        sha256 = hashlib.sha256(files[0][2]).hexdigest()
    else:
        digest = hashlib.sha256()
        for _, walk, raw in sorted(files, key=lambda f: f[1]):
            digest.update(walk.encode() + b'\0' +
                          len(raw).to_bytes(8, 'big') + raw)
        sha256 = digest.hexdigest()
    return _assemble(tables, walks, source, sha256, options)


def parse_fingerprints(text, source=('<string>', b''), options=None):
    """Parse CSV text; ``source`` is (name used in errors, raw bytes)."""
    name, raw = source
    options = options or ReaderOptions()
    return _assemble([_Table(text, name, options)], [None], name,
                     hashlib.sha256(raw).hexdigest(), options)


def _input_files(paths, role):
    """Return ([(name, walk, bytes)], source) for the given paths."""
    several = len(paths) > 1
    files = []
    for spec in map(str, paths):
        if not Path(spec).is_dir():
            name, raw = _read_bytes(spec, role)
            files.append((name, name if several else None, raw))
            continue
        found = sorted(p for p in Path(spec).iterdir()
                       if p.suffix.lower() == '.csv' and p.is_file())
        if not found:
            folders = sorted(p.name for p in Path(spec).iterdir()
                             if p.is_dir())
            hint = f' (it has folders: {", ".join(folders)})' \
                if folders else ''
            raise DataError(f'{spec}: no .csv files in this folder{hint}')
        for p in found:
            files.append((str(p), str(p) if several else p.name,
                          _read_bytes(str(p), role)[1]))
    if several:
        return files, f'{paths[0]} and {len(paths) - 1} more'
    return files, str(paths[0]) if files[0][1] else files[0][0]


def _read_bytes(spec, role):
    archive, _, member = spec.partition('#')
    try:
        if archive.lower().endswith('.zip'):
            with zipfile.ZipFile(archive) as zf:
                name = _zip_member(zf, member or ZIP_MEMBERS[role], archive)
                return f'{archive}#{name}', zf.read(name)
        return spec, Path(spec).read_bytes()
    except (OSError, zipfile.BadZipFile) as exc:
        raise DataError(f'{spec}: cannot read: {exc}') from None


def _decode(data, name):
    try:
        return data.decode('utf-8-sig')
    except UnicodeDecodeError as exc:
        raise DataError(f'{name}: not UTF-8 text ({exc.reason} at byte '
                        f'{exc.start})') from None


def _zip_member(zf, wanted, archive):
    for name in zf.namelist():
        if name == wanted or name.rsplit('/', 1)[-1] == wanted:
            return name
    raise DataError(f'{archive}: no member {wanted!r} '
                    f'(has: {", ".join(zf.namelist())})')


class _Table:
    """One file: its columns by role and their values, before merging."""

    def __init__(self, text, name, options):
        self.name = name
        header = next(csv.reader(io.StringIO(text)), None)
        if not header or header == ['']:
            raise DataError(f'{name}: empty file (no header row)')
        self.header = _check_header([h.strip() for h in header], name)
        self._roles(options)
        textual = [j for j in (self.device, self.time) if j is not None] + \
            self.meta
        self.numbers, self.texts, self.lines = _load(text, name, self.header,
                                                     textual)
        c = self.candidates      # a view when they are side by side
        self.block = self.numbers[:, c[0]:c[-1] + 1] \
            if c == list(range(c[0], c[-1] + 1)) else self.numbers[:, c]

    def _find(self, wanted, role, required):
        """Return the column named ``wanted`` (any case), or None."""
        if wanted in self.index:
            return self.index[wanted]
        folded = [j for h, j in self.index.items()
                  if h.lower() == wanted.lower()]
        if len(folded) == 1:
            return folded[0]
        if required:
            raise DataError(f'{self.name}: no {role} column {wanted!r}')
        return None

    def _roles(self, options):
        header, name = self.header, self.name
        self.index = {h: j for j, h in enumerate(header)}
        labels = {'FLOOR': options.floor_column}
        if options.building_column is not None:
            labels = {'BUILDINGID': options.building_column, **labels}
        found = {key: self._find(col, 'label', False)
                 for key, col in labels.items()}
        missing = [labels[k] for k, j in found.items() if j is None]
        if missing:
            hint = ' (the header has a single column: is the file ' \
                'comma-separated?)' if len(header) == 1 else \
                _label_hint(header)
            raise DataError(f'{name}: missing label column(s) '
                            f'{", ".join(missing)}{hint}')
        self.building, self.floor = found.get('BUILDINGID'), found['FLOOR']
        self.device = self._find(options.device_column, 'device',
                                 options.device_column != DEVICE)
        self.time = self._find(options.time_column, 'time',
                               options.time_column != TIME)
        self.position, unused = None, []
        if options.position_columns:
            self.position = tuple(self._find(c, 'position', True)
                                  for c in options.position_columns)
        for pair in POSITION_PAIRS if not options.position_columns else ():
            cols = tuple(self._find(c, 'position', False) for c in pair)
            if None in cols:
                continue
            if options.position_columns is None:
                unused += cols          # coordinates ignored: metadata
            else:
                self.position = cols
                break
        roles = {}
        for role, j in [('building', self.building), ('floor', self.floor),
                        ('device', self.device), ('time', self.time)] + \
                list(zip(('position', 'position'), self.position or ())):
            if j in roles:
                raise DataError(f'{name}: column {header[j]!r} cannot be '
                                f'the {roles[j]} and the {role} column')
            if j is not None:
                roles[j] = role
        rest = [j for j in range(len(header)) if j not in roles]

        def matching(patterns):
            return [j for j in rest
                    if any(fnmatchcase(header[j], p) for p in patterns)]
        self.meta = sorted(set(matching(options.meta_columns)) | {
            j for j in rest if header[j] in META_COLUMNS or j in unused})
        rest = [j for j in rest if j not in self.meta]
        self.matched = {p for p in options.meta_columns + options.ap_columns
                        if any(fnmatchcase(header[j], p)
                               for j in range(len(header)))}
        if options.ap_columns:
            self.candidates = matching(options.ap_columns)
            self.unnamed = [j for j in rest if j not in self.candidates]
        else:
            self.candidates, self.unnamed = rest, []
        if not self.candidates:
            raise DataError(f'{name}: no AP columns (' + (
                f'none matches {", ".join(map(repr, options.ap_columns))})'
                if options.ap_columns else 'every column is metadata)'))

    def fail(self, row, j, problem):
        """Raise a :class:`DataError` naming row ``row`` of column ``j``."""
        raise DataError(f'{self.name}: row {self.lines[row]}, column '
                        f'{self.header[j]}: {problem}')

    def numeric(self, j):
        """Return column ``j`` as finite float64 numbers, or fail."""
        if j in self.texts:
            cells = self.texts[j]
            bad = next(r for r, c in enumerate(cells) if not _is_number(c))
            self.fail(bad, j, f'value {cells[bad]!r} is not a number')
        values = self.numbers[:, j]
        bad = ~np.isfinite(values)
        if bad.any():
            r = int(np.argmax(bad))
            self.fail(r, j, f'value {values[r]:g} is not a finite number')
        return values.copy()

    def label(self, j):
        """Return a label column as int64, or fail naming the bad cell."""
        v = self.numeric(j)
        wrong = (v < 0) | (v != np.round(v))
        if wrong.any():
            r = int(np.argmax(wrong))
            self.fail(r, j, f'value {v[r]:g} is not a non-negative integer')
        return v.astype(np.int64)

    def _numeric_text(self, j):
        """Return True if column ``j`` holds numbers (text ones converted)."""
        cells = self.texts.get(j)
        if cells is not None and all(map(_is_number, cells)):
            self.numbers[:, j] = np.array(cells, np.float64)
            del self.texts[j]
        return j not in self.texts

    def device_ids(self, j):
        """Return device ids: int64 when all are integers, else text."""
        if not self._numeric_text(j):
            cells = self.texts[j]
            if '' in cells:
                self.fail(cells.index(''), j, 'empty device id')
            return np.array(cells)
        v = self.numeric(j)
        if (v == np.round(v)).all():
            return v.astype(np.int64)
        return np.array([f'{x:g}' for x in v])

    def times(self, j):
        """Return times in seconds: numbers, or ISO dates (UTC if naive)."""
        if self._numeric_text(j) or _is_number(self.texts[j][0]):
            return self.numeric(j)
        out = np.empty(len(self.lines))
        for r, cell in enumerate(self.texts[j]):
            try:
                t = datetime.fromisoformat(cell)
            except ValueError:
                self.fail(r, j, f'value {cell!r} is neither a number nor '
                          f'an ISO date (2017-08-18 11:59:23)')
            if t.tzinfo is None:
                t = t.replace(tzinfo=timezone.utc)
            out[r] = t.timestamp()
        return out

    def metadata(self, j):
        """Return a metadata column: float64 numbers, else its text."""
        if self._numeric_text(j):
            return self.numbers[:, j].copy()
        return np.array(self.texts[j])

    def example(self, k):
        """Return a value of candidate ``k`` that is not RSSI, for notes."""
        j = self.candidates[k]
        if j in self.texts:
            return repr(next(c for c in self.texts[j] if not _is_number(c)))
        v = self.block[:, k]
        odd = ~((v >= MIN_DBM) & (v < MAX_DBM))
        return f'{v[int(np.argmax(odd))]:g}'


def _label_hint(header):
    like = [h for h in header
            if 'floor' in h.lower() or 'build' in h.lower()]
    return (' (name them with --floor-column / --building-column, '
            '--building-column none for one building'
            + (f'; columns like labels: {", ".join(like)}' if like else '')
            + ')')


def _check_header(header, name):
    seen = {}
    for i, h in enumerate(header):
        if not h:
            raise DataError(f'{name}: header column {i + 1} has no name')
        if h in seen:
            raise DataError(f'{name}: column {h!r} appears twice in the '
                            f'header (columns {seen[h] + 1} and {i + 1})')
        seen[h] = i
    return header


def _load(text, name, header, textual):
    """
    Return (numbers, texts, lines) of the data rows.

    ``numbers`` is float64 (n, columns), NaN in text columns; ``texts``
    maps the columns read as text (``textual``, and those whose cells are
    mostly not numbers) to their cells; ``lines`` is each row's line.
    """
    width = len(header)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            numbers = np.loadtxt(io.StringIO(text), delimiter=',',
                                 skiprows=1, dtype=np.float64, ndmin=2,
                                 comments=None, quotechar='"')
        if numbers.shape[1] == width and len(numbers) and \
                '\n\n' not in text.replace('\r', ''):
            return numbers, {}, np.arange(len(numbers)) + 2
    except ValueError:
        pass
    rows, lines = [], []
    reader = csv.reader(io.StringIO(text))
    next(reader)
    for line, row in enumerate(reader, start=2):
        if not row or row == ['']:
            continue
        if len(row) != width:
            raise DataError(f'{name}: row {line} has {len(row)} fields, '
                            f'the header has {width}')
        rows.append(row)
        lines.append(line)
    if not rows:
        raise DataError(f'{name}: no data rows after the header')
    textual = set(textual)
    for j, cell in enumerate(rows[0]):
        if j not in textual and not _is_number(cell) and \
                sum(map(_is_number, (r[j] for r in rows))) * 2 < len(rows):
            textual.add(j)
    numeric = [j for j in range(width) if j not in textual]
    numbers = np.full((len(rows), width), np.nan)
    if numeric:
        get = operator.itemgetter(*numeric)
        block = np.empty((len(rows), len(numeric)))
        for r, row in enumerate(rows):
            try:
                block[r] = get(row)
            except ValueError:
                for j in numeric:
                    if not _is_number(row[j]):
                        raise DataError(
                            f'{name}: row {lines[r]}, column {header[j]}: '
                            f'value {row[j]!r} is not a number') from None
        numbers[:, numeric] = block
    texts = {j: [r[j].strip() for r in rows] for j in sorted(textual)}
    return numbers, texts, np.array(lines)


def _is_number(cell):
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _assemble(tables, walks, source, sha256, options):
    """Decide markers and AP columns over all files; return one dataset."""
    notes = []
    matched = set().union(*(t.matched for t in tables))
    for pattern in options.meta_columns + options.ap_columns:
        if pattern not in matched:
            raise DataError(f'{source}: no column matches {pattern!r} '
                            f'(named as an AP or metadata column)')
    markers = _markers(tables, options, source, notes)
    ap_names = _ap_columns(tables, markers, options, source, notes)
    parts = [_finish(t, ap_names, markers, source, notes) for t in tables]
    fp = _merge(parts, walks, source, sha256, notes)
    if options.building_column is None:
        notes.append(f'{source}: no building column: building 0 for every '
                     f'scan')
    fp.notes = list(dict.fromkeys(notes))
    if options.small_classes is not None:
        fp = _small_classes(fp, options.small_classes)
    return fp


def _markers(tables, options, source, notes):
    """Return the input values that mean "not detected"."""
    if options.not_detected_marker is not None:
        return (float(options.not_detected_marker),)
    minima = np.concatenate([np.fmin.reduce(t.block, axis=0)
                             for t in tables])
    minima = minima[np.isfinite(minima)]
    if not len(minima):
        return (NOT_DETECTED_MARKER,)
    values, counts = np.unique(minima, return_counts=True)
    bottom = float(values[np.argmax(counts)])   # the lowest of most columns
    if bottom >= MAX_DBM:
        return (NOT_DETECTED_MARKER,)
    rows = sum(int(((t.block == bottom).mean(axis=1) > 0.5).sum())
               for t in tables)
    if rows * 2 <= sum(len(t.block) for t in tables):
        return (NOT_DETECTED_MARKER,)
    share = sum(int((t.block == bottom).sum()) for t in tables) / \
        sum(t.block.size for t in tables)
    notes.append(f'{source}: {bottom:g} fills {share:.0%} of the cells of '
                 f'the AP columns and is the lowest value of '
                 f'{np.mean(minima == bottom):.0%} of them: read as "not '
                 f'detected" (--not-detected-marker sets the marker)')
    return (NOT_DETECTED_MARKER, bottom)


def _few(names, limit=8):
    names = list(names)
    more = f' and {len(names) - limit} more' if len(names) > limit else ''
    return ', '.join(names[:limit]) + more


def _ap_columns(tables, markers, options, source, notes):
    """Return the names of the AP columns, or None: every candidate."""
    if options.ap_columns:
        unnamed = dict.fromkeys(t.header[j] for t in tables
                                for j in t.unnamed)
        if unnamed:
            notes.append(f'{source}: columns not named as APs or metadata '
                         f'left out: {_few(unnamed)}')
        return None
    readings, rssi_like, example = {}, {}, {}
    for t in tables:
        reading = ~np.isin(t.block, markers)
        like = reading & (t.block >= MIN_DBM) & (t.block < MAX_DBM)
        for k, n, r in zip(range(len(t.candidates)), reading.sum(axis=0),
                           like.sum(axis=0)):
            h = t.header[t.candidates[k]]
            readings[h] = readings.get(h, 0) + int(n)
            rssi_like[h] = rssi_like.get(h, 0) + int(r)
            if r * 2 < n and h not in example:
                example[h] = t.example(k)
    aps = {h for h in readings if rssi_like[h] * 2 >= readings[h]}
    others = [h for h in readings if h not in aps]
    if not aps:
        raise DataError(
            f'{source}: no AP columns: no column has at least half of its '
            f'readings in [-120, 0) dBm (e.g. {others[0]} = '
            f'{example[others[0]]}; not detected is '
            f'{", ".join(f"{m:g}" for m in markers)}: see '
            f'--not-detected-marker, --ap-columns)')
    if others:
        shown = _few(f'{h} (e.g. {example[h]})' for h in others)
        notes.append(f'{source}: not RSSI, left out as metadata: {shown}; '
                     f'fewer than half of their readings are in [-120, 0) '
                     f'dBm (name such columns with --meta-columns, or the '
                     f'AP columns with --ap-columns)')
    return aps


def _distinct_aps(names):
    """Return the names, one per AP (the first spelling of each)."""
    first = {}
    for name in names:
        first.setdefault(normalize_ap_id(name), name)
    return tuple(first.values())


def _finish(t, ap_names, markers, source, notes):
    """Return one file's :class:`Fingerprints` (AP columns of its own)."""
    ks = [k for k, j in enumerate(t.candidates)
          if ap_names is None or t.header[j] in ap_names]
    cols = [t.candidates[k] for k in ks]
    for j in cols:
        if j in t.texts:
            t.numeric(j)                    # fails on the first text cell
    raw = t.block if len(ks) == len(t.candidates) else t.block[:, ks]
    missing = np.isin(raw, markers)
    bad = ~(missing | np.isfinite(raw))
    if bad.any():
        r, k = np.argwhere(bad)[0]
        t.fail(r, cols[k], f'value {raw[r, k]:g} is not a finite number')
    try:
        rssi, clipped = clip_plausible(np.where(missing, np.nan, raw))
    except RssiError as exc:
        r, k = exc.index
        t.fail(r, cols[k], str(exc))
    names = [t.header[j] for j in cols]
    ids = _distinct_aps(names)
    if len(ids) < len(names):
        same = [h for h in names if h not in ids]
        notes.append(f'{source}: columns {_few(same)} name the AP of an '
                     f'earlier column (case and separators ignored): '
                     f'merged, the strongest reading wins')
        rssi = ScanMapper(ids).map_rows(names, rssi)
    left_out = set(t.candidates) - set(cols)
    meta = {t.header[j]: t.metadata(j)
            for j in sorted(t.meta + t.unnamed + list(left_out))}
    if t.device is not None:
        meta[DEVICE] = t.device_ids(t.device)
    if t.time is not None:
        meta[TIME] = t.times(t.time)
    position, position_columns = None, ()
    if t.position is not None:
        position = np.stack([t.numeric(j) for j in t.position], axis=1)
        position_columns = tuple(t.header[j] for j in t.position)
    building = np.zeros(len(t.lines), np.int64) if t.building is None \
        else t.label(t.building)
    return Fingerprints(ids, rssi.astype(np.float32), building,
                        t.label(t.floor), meta, t.name, clipped,
                        position=position, position_columns=position_columns,
                        line=t.lines)


def _merge(parts, walks, source, sha256, notes):
    """Return the parts (files) as one :class:`Fingerprints`."""
    first = parts[0]
    ids = _distinct_aps(ap for p in parts for ap in p.ap_ids)
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
                     f'out: {_few(sorted(dropped))}')
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

    Needs scans that detect an AP, at least two building/floor classes, and
    ``min_scans`` scans per class (a class with one scan is usually a typo
    in a label).
    """
    rows = np.flatnonzero(~fp.empty_rows)
    if not len(rows):
        raise DataError(f'{fp.source}: no scan detects any AP')
    classes, labels = class_index(fp.building[rows], fp.floor[rows])
    _, first, counts = np.unique(labels, return_index=True,
                                 return_counts=True)
    if len(classes) < 2:
        raise DataError(f'{fp.source}: only one building/floor class '
                        f'(building {classes[0][0]}, floor '
                        f'{classes[0][1]}); need at least two')
    for (building, floor), i, count in zip(classes, first, counts):
        if count < min_scans:
            raise DataError(
                f'{fp.source}: {fp.where(rows[i])}, columns BUILDINGID/'
                f'FLOOR: building {building}, floor {floor} has '
                f'{count} scan(s), fewer than {min_scans} (a typo in a '
                f'label?)')


def download_uci(cache_dir, url=UCI_URL, sha256=UCI_TRAINING_SHA256):
    """
    Fetch the UCI zip into ``cache_dir`` (once) and return its path.

    The zip itself has no published checksum; its ``trainingData.csv`` has
    (see the dataset README), so that member's SHA-256 is verified. The file
    is written atomically: an interrupted download leaves nothing behind.
    """
    cache_dir = Path(cache_dir)
    target = cache_dir / 'ujiindoorloc.zip'
    if target.exists():
        return target
    cache_dir.mkdir(parents=True, exist_ok=True)
    try:
        with atomic_write(target, 'w+b') as out, \
                urllib.request.urlopen(url) as resp:
            while chunk := resp.read(1 << 20):
                out.write(chunk)
            try:
                with zipfile.ZipFile(out) as zf:
                    member = _zip_member(zf, ZIP_MEMBERS['train'], url)
                    digest = hashlib.sha256(zf.read(member)).hexdigest()
            except zipfile.BadZipFile:
                raise DataError(f'{url}: download is not a zip file') \
                    from None
            if digest != sha256:
                raise DataError(f'{url}: trainingData.csv has SHA-256 '
                                f'{digest}, expected {sha256}')
    except OSError as exc:
        raise DataError(f'{url}: download failed: {exc}') from None
    return target
