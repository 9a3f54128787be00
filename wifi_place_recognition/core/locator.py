"""
Position from one scan: k-NN among the recognised floor's reference scans.

Distance-weighted k-NN among the reference scans of the building/floor the
classifier recognised. References live in the model's input space,
relative to a scan that detects nothing (where every representation and
scaling puts an undetected AP at a constant), so a scan is sparse: only
its detected APs are non-zero. They are stored by AP column (for each
class and AP, the references that detected it), so a query touches only
the references that share one of its APs, a few thousand numbers.
Coordinates are kept relative to a float64 origin.
"""

from dataclasses import dataclass

import numpy as np

#: Radius of the 95 % circle of a 2-D isotropic Gaussian, in sigmas.
R95 = float(np.sqrt(-2 * np.log(0.05)))


@dataclass
class Locator:
    """
    Reference scans with their positions, grouped by class, and k.

    ``sigma[c]`` (metres) was calibrated on held-out scans predicted as
    class c, so that a circle of 2.45 sigma holds 95 % of them.
    """

    origin: np.ndarray    # float64 (2,)
    class_start: np.ndarray  # int64 (k + 1,): references of class c
    column_start: np.ndarray  # int64 (k, n_aps + 1): entries by AP column
    entry_ref: np.ndarray  # int32: reference of each entry
    entry_value: np.ndarray  # float32: its input value (relative)
    norms: np.ndarray     # float32 (n_refs,): squared norm of each reference
    xy: np.ndarray        # float32 (n_refs, 2): position - origin
    sigma: np.ndarray     # float32 (k,)
    neighbours: int = 5
    columns: tuple = ('X', 'Y')

    @classmethod
    def build(cls, inputs, classes, xy, n_classes, neighbours=5,
              sigma=None, columns=('X', 'Y')):
        """
        Return a locator of reference ``inputs`` (relative, (n, n_aps)).

        ``classes`` is each reference's class index, ``xy`` its position.
        """
        order = np.argsort(classes, kind='stable')
        inputs, classes, xy = inputs[order], classes[order], xy[order]
        origin = xy.mean(axis=0)
        class_start = np.searchsorted(classes, np.arange(n_classes + 1))
        n_aps = inputs.shape[1]
        column_start = np.zeros((n_classes, n_aps + 1), np.int64)
        refs, values = [], []
        done = 0
        for c in range(n_classes):
            block = inputs[class_start[c]:class_start[c + 1]]
            col, row = np.nonzero(block.T)   # column-major order
            refs.append(row + class_start[c])
            values.append(block[row, col])
            counts = np.bincount(col, minlength=n_aps)
            column_start[c] = done + np.concatenate([[0], np.cumsum(counts)])
            done += len(row)
        if sigma is None:
            sigma = np.full(n_classes, np.nan)
        return cls(origin, class_start, column_start,
                   np.concatenate(refs).astype(np.int32),
                   np.concatenate(values).astype(np.float32),
                   (inputs.astype(np.float64) ** 2).sum(axis=1)
                   .astype(np.float32),
                   (xy - origin).astype(np.float32),
                   np.asarray(sigma, np.float32), int(neighbours),
                   tuple(columns))

    def locate(self, columns, values, c, neighbours=None):
        """
        Return (xy metres (2,), sigma m) of one scan of class ``c``.

        ``columns``/``values``: the scan's detected APs and their relative
        inputs; ``neighbours`` overrides the model's k.
        """
        return self.weighted(self.distances(columns, values, c),
                             neighbours or self.neighbours, c)

    def distances(self, columns, values, c):
        """Return the distance of one scan to each reference of class c."""
        first, last = self.class_start[c], self.class_start[c + 1]
        if first == last:
            return np.empty(0)
        starts = self.column_start[c, columns]
        ends = self.column_start[c, np.asarray(columns) + 1]
        lengths = ends - starts
        entries = ranges(starts, lengths)
        dots = np.bincount(self.entry_ref[entries] - first,
                           self.entry_value[entries] *
                           np.repeat(values, lengths), last - first)
        return np.sqrt(np.maximum(
            self.norms[first:last] + float(np.dot(values, values))
            - 2 * dots, 0.0))

    def weighted(self, distance, k, c):
        """
        Return (xy, sigma) of the ``k`` nearest of class ``c``'s references.

        ``distance`` is from :meth:`distances`; weights are 1 / distance.
        """
        if not len(distance):
            return np.full(2, np.nan), float('nan')
        k = min(k, len(distance))
        nearest = np.argpartition(distance, k - 1)[:k]
        weight = 1.0 / np.maximum(distance[nearest], 1e-6)
        xy = weight @ self.xy[self.class_start[c] + nearest] / weight.sum()
        return self.origin + xy, float(self.sigma[c])


def ranges(starts, lengths):
    """Return the indices of the ranges [start, start + length), joined."""
    offsets = np.cumsum(lengths) - lengths
    return np.repeat(starts - offsets, lengths) + np.arange(lengths.sum())


def sparse_rows(inputs):
    """Yield (columns, values) of each row's non-zero inputs."""
    for row in inputs:
        columns = np.flatnonzero(row)
        yield columns, row[columns]


def calibrated_sigma(errors, predicted, n_classes, min_scans=30):
    """
    Return a sigma (m) per class: its 95th percentile error / R95.

    ``errors`` and ``predicted`` (class) of held-out scans; a class
    predicted for fewer than ``min_scans`` of them gets the value of all.
    """
    overall = np.quantile(errors, 0.95) / R95
    sigma = np.full(n_classes, overall)
    for c in range(n_classes):
        mine = errors[predicted == c]
        if len(mine) >= min_scans:
            sigma[c] = np.quantile(mine, 0.95) / R95
    return np.maximum(sigma, 0.1)
