"""
Fingerprint CSVs: reading and validating UJIIndoorLoc-format and generic files.

A fingerprint CSV has a header row, then one scan per row. Every column that
is not a known metadata column is an access point (AP) column, named by the
AP identifier (``WAP001`` in UJIIndoorLoc, a MAC address in your own data).
``BUILDINGID`` and ``FLOOR`` (non-negative integers) are required.

RSSI cells hold dBm values. ``100`` is the not-detected marker (as in
UJIIndoorLoc). The rules for every other value are those of :mod:`.rssi`:
values in (0, 20] dBm are clipped to 0 dBm (counted), anything else outside
[-120, 0] dBm is an error naming file, row and column. In memory a
not-detected AP is ``NaN``.
"""

import csv
import hashlib
import io
import urllib.request
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.atomic import atomic_write
from ..core.metrics import class_index
from ..core.rssi import clip_plausible, RssiError

#: Columns that are never APs (UJIIndoorLoc metadata, plus the recorder's).
META_COLUMNS = ('LONGITUDE', 'LATITUDE', 'FLOOR', 'BUILDINGID', 'SPACEID',
                'RELATIVEPOSITION', 'USERID', 'PHONEID', 'TIMESTAMP')
LABEL_COLUMNS = ('BUILDINGID', 'FLOOR')
NOT_DETECTED_MARKER = 100.0

UCI_URL = 'https://archive.ics.uci.edu/static/public/310/ujiindoorloc.zip'
#: SHA-256 of the UCI ``trainingData.csv``, checked inside a downloaded zip.
UCI_TRAINING_SHA256 = ('45ca0128bd12019c976bb4793e407c979c82995d7a5940ab72'
                       '88620247905168')
ZIP_MEMBERS = {'train': 'trainingData.csv', 'test': 'validationData.csv'}


class DataError(ValueError):
    """A fingerprint file that cannot be used, with the place that is wrong."""


@dataclass
class Fingerprints:
    """Scans as a dense matrix: ``rssi[i, j]`` is AP ``ap_ids[j]`` in scan i."""

    ap_ids: tuple
    rssi: np.ndarray            # float32 (n, m), NaN = not detected
    building: np.ndarray        # int64 (n,)
    floor: np.ndarray           # int64 (n,)
    meta: dict = field(default_factory=dict)  # other metadata columns
    source: str = ''
    clipped: int = 0            # cells clipped from (0, 20] dBm to 0 dBm
    sha256: str = ''            # of the CSV bytes

    def __len__(self):
        return len(self.building)

    @property
    def empty_rows(self):
        """Boolean mask of scans that detected no AP at all."""
        return ~np.isfinite(self.rssi).any(axis=1)

    def subset(self, mask):
        """Return the scans selected by a boolean mask or index array."""
        return Fingerprints(self.ap_ids, self.rssi[mask], self.building[mask],
                            self.floor[mask],
                            {k: v[mask] for k, v in self.meta.items()},
                            self.source, self.clipped, self.sha256)


def read_fingerprints(path, role='train'):
    """
    Read a fingerprint CSV, or a member of the UCI zip.

    ``path`` may be ``file.csv``, ``ujiindoorloc.zip`` (the member for
    ``role`` is used: trainingData.csv or validationData.csv) or
    ``archive.zip#member.csv``.
    """
    text, source = _read_text(str(path), role)
    return parse_fingerprints(text, source)


def _read_text(spec, role):
    archive, _, member = spec.partition('#')
    try:
        if archive.lower().endswith('.zip'):
            with zipfile.ZipFile(archive) as zf:
                name = _zip_member(zf, member or ZIP_MEMBERS[role], archive)
                data = zf.read(name)
            source = f'{archive}#{name}'
        else:
            data = Path(spec).read_bytes()
            source = spec
    except (OSError, zipfile.BadZipFile) as exc:
        raise DataError(f'{spec}: cannot read: {exc}') from None
    try:
        return data.decode('utf-8-sig'), (source, data)
    except UnicodeDecodeError as exc:
        raise DataError(f'{source}: not UTF-8 text ({exc.reason} at byte '
                        f'{exc.start})') from None


def _zip_member(zf, wanted, archive):
    for name in zf.namelist():
        if name == wanted or name.rsplit('/', 1)[-1] == wanted:
            return name
    raise DataError(f'{archive}: no member {wanted!r} '
                    f'(has: {", ".join(zf.namelist())})')


def parse_fingerprints(text, source=('<string>', b'')):
    """Parse CSV text; ``source`` is (name used in errors, raw bytes)."""
    name, raw = source
    rows = csv.reader(io.StringIO(text))
    header = next(rows, None)
    if not header or header == ['']:
        raise DataError(f'{name}: empty file (no header row)')
    header = [h.strip() for h in header]
    columns = _check_header(header, name)
    ap_index = [i for i, h in enumerate(header) if h not in META_COLUMNS]
    meta_index = {h: i for i, h in enumerate(header) if h in META_COLUMNS}

    values = []
    for line, row in enumerate(rows, start=2):
        if not row or row == ['']:
            continue
        if len(row) != len(header):
            raise DataError(f'{name}: row {line} has {len(row)} fields, '
                            f'the header has {len(header)}')
        try:
            values.append(np.array(row, dtype=np.float64))
        except ValueError:
            _raise_bad_cell(row, header, name, line)
    if not values:
        raise DataError(f'{name}: no data rows after the header')
    table = np.vstack(values)
    bad = ~np.isfinite(table)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise DataError(f'{name}: row {r + 2}, column {header[c]}: value '
                        f'{table[r, c]:g} is not a finite number')

    rssi = table[:, ap_index]
    detected = rssi != NOT_DETECTED_MARKER
    try:
        rssi, clipped = clip_plausible(np.where(detected, rssi, np.nan))
    except RssiError as exc:
        r, c = exc.index
        raise DataError(f'{name}: row {r + 2}, column {header[ap_index[c]]}: '
                        f'{exc}') from None
    labels = {}
    for col in LABEL_COLUMNS:
        v = table[:, meta_index[col]]
        wrong = (v < 0) | (v != np.round(v))
        if wrong.any():
            r = int(np.argmax(wrong))
            raise DataError(f'{name}: row {r + 2}, column {col}: value '
                            f'{v[r]:g} is not a non-negative integer')
        labels[col] = v.astype(np.int64)
    meta = {h: table[:, i] for h, i in meta_index.items()
            if h not in LABEL_COLUMNS}
    return Fingerprints(tuple(columns[i] for i in ap_index),
                        rssi.astype(np.float32), labels['BUILDINGID'],
                        labels['FLOOR'], meta, name, clipped,
                        hashlib.sha256(raw).hexdigest())


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
                f'{fp.source}: row {rows[i] + 2}, columns BUILDINGID/FLOOR: '
                f'building {building}, floor {floor} has '
                f'{count} scan(s), fewer than {min_scans} (a typo in a '
                f'label?)')


def _check_header(header, name):
    seen = {}
    for i, h in enumerate(header):
        if not h:
            raise DataError(f'{name}: header column {i + 1} has no name')
        if h in seen:
            raise DataError(f'{name}: column {h!r} appears twice in the '
                            f'header (columns {seen[h] + 1} and {i + 1})')
        seen[h] = i
    missing = [c for c in LABEL_COLUMNS if c not in seen]
    if missing:
        hint = ''
        if len(header) == 1:
            hint = ' (the header has a single column: is the file ' \
                   'comma-separated?)'
        raise DataError(f'{name}: missing label column(s) '
                        f'{", ".join(missing)}{hint}')
    if all(h in META_COLUMNS for h in header):
        raise DataError(f'{name}: no AP columns (every column is metadata)')
    return header


def _raise_bad_cell(row, header, name, line):
    for cell, col in zip(row, header):
        try:
            float(cell)
        except ValueError:
            raise DataError(f'{name}: row {line}, column {col}: value '
                            f'{cell!r} is not a number') from None


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
