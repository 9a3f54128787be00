"""
Column roles of fingerprint CSVs: which column is what, read from the header.

Columns have roles: the labels (``BUILDINGID``, ``FLOOR``), a device
(``PHONEID``), a time (``TIMESTAMP``), a position (``LONGITUDE``/``LATITUDE``
or ``X``/``Y``), other metadata (the rest of UJIIndoorLoc's fixed list), and
access points (AP columns, named by the AP identifier: ``WAP001``, a MAC
address, ``17``). ``ReaderOptions`` renames every role for files that name
them otherwise; default names match regardless of case.

Without ``ap_columns``, a column with no other role is an AP column when its
values look like RSSI: at least half of its readings (cells that are not
the not-detected marker) in [-120, 0) dBm. Other columns (counts, ids,
coordinates, timestamps, text) are left out as metadata, with a note naming
them. The not-detected marker is ``100`` (UJIIndoorLoc) unless given; a
value that fills most cells of most rows and is the lowest value of most
columns (WiFine's ``-100``) is taken as the marker too, with a note.
Columns whose identifiers are the same AP (``AA-BB-...``, ``aa:bb:...``)
are one AP (:func:`distinct_aps`).
"""

from fnmatch import fnmatchcase

import numpy as np

from ..core.rssi import MAX_DBM, MIN_DBM
from ..core.scan import normalize_ap_id
from .files import DataError
from .table import is_number, read_header, Table

#: UJIIndoorLoc's metadata columns (and the recorder's and robot runs'
#: heading, ``YAW``): never APs.
META_COLUMNS = ('LONGITUDE', 'LATITUDE', 'FLOOR', 'BUILDINGID', 'SPACEID',
                'RELATIVEPOSITION', 'USERID', 'PHONEID', 'TIMESTAMP', 'FRAME',
                'YAW')
#: Position columns looked for, in this order, unless named.
POSITION_PAIRS = (('LONGITUDE', 'LATITUDE'), ('X', 'Y'))
#: ``Fingerprints.meta`` keys of the device, time and heading columns.
DEVICE, TIME, YAW = 'PHONEID', 'TIMESTAMP', 'YAW'
NOT_DETECTED_MARKER = 100.0
#: What a cell of the CSVs the package writes cannot hold (it quotes none).
UNWRITABLE = ',"\r\n'


def writable_cell(text):
    """Return True when ``text`` can be a cell of the package's CSVs."""
    return bool(text) and not any(c in text for c in UNWRITABLE)


class FileColumns:
    """
    One file: its columns by role, over its cells (``table``).

    ``candidates``: the columns that may be APs, ``block`` their numbers
    (n, len(candidates)); ``meta``, ``unnamed``: metadata and columns
    left out; ``matched``: the name patterns of the options it matches.
    """

    def __init__(self, text, name, options):
        self.name = name
        self.header = read_header(text, name)
        self._roles(options)
        textual = [j for j in (self.device, self.time) if j is not None] + \
            self.meta + list(self.position or ())   # may have empty cells
        self.table = Table(text, name, self.header, textual)
        c = self.candidates      # a view when they are side by side
        numbers = self.table.numbers
        self.block = numbers[:, c[0]:c[-1] + 1] \
            if c == list(range(c[0], c[-1] + 1)) else numbers[:, c]

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

    def example(self, k):
        """Return a value of candidate ``k`` that is not RSSI, for notes."""
        j = self.candidates[k]
        texts = self.table.texts
        if j in texts:
            return repr(next(c for c in texts[j] if not is_number(c)))
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


def markers(tables, options, source, notes):
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


def few(names, limit=8):
    """Return up to ``limit`` names for a message, then how many more."""
    names = list(names)
    more = f' and {len(names) - limit} more' if len(names) > limit else ''
    return ', '.join(names[:limit]) + more


def ap_columns(tables, not_detected, options, source, notes):
    """Return the names of the AP columns, or None: every candidate."""
    if options.ap_columns:
        unnamed = dict.fromkeys(t.header[j] for t in tables
                                for j in t.unnamed)
        if unnamed:
            notes.append(f'{source}: columns not named as APs or metadata '
                         f'left out: {few(unnamed)}')
        return None
    readings, rssi_like, example = {}, {}, {}
    for t in tables:
        reading = ~np.isin(t.block, not_detected)
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
            f'{", ".join(f"{m:g}" for m in not_detected)}: see '
            f'--not-detected-marker, --ap-columns)')
    if others:
        shown = few(f'{h} (e.g. {example[h]})' for h in others)
        notes.append(f'{source}: not RSSI, left out as metadata: {shown}; '
                     f'fewer than half of their readings are in [-120, 0) '
                     f'dBm (name such columns with --meta-columns, or the '
                     f'AP columns with --ap-columns)')
    return aps


def distinct_aps(names):
    """Return the names, one per AP (the first spelling of each)."""
    first = {}
    for name in names:
        first.setdefault(normalize_ap_id(name), name)
    return tuple(first.values())
