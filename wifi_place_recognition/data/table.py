"""One CSV file's cells: the header, then columns as numbers or text."""

import csv
from datetime import datetime, timezone
import io
import math
import operator
import warnings

import numpy as np

from .files import DataError

#: The largest building or floor label (an int64 takes larger ones badly).
MAX_LABEL = 10 ** 9


def read_header(text, name):
    """Return the header row's column names, or fail (none, blank, twice)."""
    header = next(csv.reader(io.StringIO(text)), None)
    if not header or header == ['']:
        raise DataError(f'{name}: empty file (no header row)')
    header = [h.strip() for h in header]
    seen = {}
    for i, h in enumerate(header):
        if not h:
            raise DataError(f'{name}: header column {i + 1} has no name')
        if h in seen:
            raise DataError(f'{name}: column {h!r} appears twice in the '
                            f'header (columns {seen[h] + 1} and {i + 1})')
        seen[h] = i
    return header


class Table:
    """
    The data rows of one file, column ``j`` of ``header`` typed on demand.

    ``textual``: the columns read as text (also those whose cells are
    mostly not numbers); errors name the file, row and column.
    """

    def __init__(self, text, name, header, textual):
        self.name, self.header = name, header
        self.numbers, self.texts, self.lines = _load(text, name, header,
                                                     textual)

    def fail(self, row, j, problem):
        """Raise a :class:`DataError` naming row ``row`` of column ``j``."""
        raise DataError(f'{self.name}: row {self.lines[row]}, column '
                        f'{self.header[j]}: {problem}')

    def blank(self, j):
        """Return a mask of the rows whose cell of column ``j`` is empty."""
        cells = self.texts.get(j)
        if cells is None:
            return np.zeros(len(self.lines), bool)
        return np.array([c == '' for c in cells], bool)

    def numeric(self, j, skip=None):
        """
        Return column ``j`` as finite float64 numbers, or fail.

        Rows of the mask ``skip`` are not read: NaN.
        """
        skip = np.zeros(len(self.lines), bool) if skip is None else skip
        cells = self.texts.get(j)
        if cells is not None:
            bad = next((r for r, c in enumerate(cells)
                        if not skip[r] and not is_number(c)), None)
            if bad is not None:
                self.fail(bad, j, f'value {cells[bad]!r} is not a number')
            values = np.array([math.nan if s else float(c)
                               for c, s in zip(cells, skip)])
        else:
            values = np.where(skip, math.nan, self.numbers[:, j])
        bad = ~(np.isfinite(values) | skip)
        if bad.any():       # 'nan', 'inf', or beyond float64
            r = int(np.argmax(bad))
            shown = repr(cells[r]) if cells is not None else f'{values[r]:g}'
            self.fail(r, j, f'value {shown} is not a finite number')
        return values

    def label(self, j):
        """Return a label column as int64, or fail naming the bad cell."""
        v = self.numeric(j)
        wrong = (v < 0) | (v != np.round(v)) | (v > MAX_LABEL)
        if wrong.any():
            r = int(np.argmax(wrong))
            self.fail(r, j, f'value {v[r]:g} is not an integer in [0, '
                      f'{MAX_LABEL}]')
        return v.astype(np.int64)

    def _numeric_text(self, j):
        """Return True if column ``j`` holds numbers (text ones converted)."""
        cells = self.texts.get(j)
        if cells is not None and all(map(is_number, cells)):
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
        if self._numeric_text(j) or is_number(self.texts[j][0]):
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
        if j not in textual and not is_number(cell) and \
                sum(map(is_number, (r[j] for r in rows))) * 2 < len(rows):
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
                    if not is_number(row[j]):
                        raise DataError(
                            f'{name}: row {lines[r]}, column {header[j]}: '
                            f'value {row[j]!r} is not a number') from None
        numbers[:, numeric] = block
    texts = {j: [r[j].strip() for r in rows] for j in sorted(textual)}
    return numbers, texts, np.array(lines)


def is_number(cell):
    """Return True if the text ``cell`` is a number."""
    try:
        float(cell)
    except ValueError:
        return False
    return True
