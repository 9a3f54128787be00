"""
Position from one scan: k-NN among the recognised place's reference scans.

Distance-weighted k-NN among the reference scans of the building/floor the
classifier recognised (or of every floor of its building), in a
non-negative signal representation
(:func:`.preprocessing.signal`: 0 for an undetected AP, so a scan is
sparse) with a Euclidean or Sorensen (Bray-Curtis) distance; training
chooses these, and k, by cross-validation. Each group keeps a dense block
over the APs its references detect, one row per AP, quantised to int8 with
a scale per row (a step of 1/127 of the row's largest value; the distances
are those of the quantised references): a query reads the rows of its own
APs, a few dozen contiguous rows. Coordinates are kept relative to a
float64 origin.
"""

from dataclasses import dataclass, field
import math

import numpy as np

from .coverage import EDGE_RADIUS_M, one_sidedness, unlike_survey
from .preprocessing import signal, signal_dbm, SIGNALS

#: Distances the k-NN can use: Euclidean, or Sorensen (Bray-Curtis),
#: sum(abs(q - r)) / sum(q + r).
METRICS = ('euclidean', 'sorensen')

#: Radius of the 95 % circle of a 2-D isotropic Gaussian, in sigmas.
R95 = float(np.sqrt(-2 * np.log(0.05)))
#: The smallest sigma (m) a position is given.
MIN_SIGMA = 0.1
#: Largest int8 code of a reference value.
LEVELS = 127
#: A scan's mismatch (:meth:`Locator.mismatch`) is read against this many
#: of its nearest references.
MISMATCH_NEIGHBOURS = 5
#: The largest usual mismatch (dB) a model may carry: readings 60 dB off
#: their references after the offset is taken out are not a survey's.
MAX_MISMATCH_DB = 60.0
#: The largest edge sigma (m) a survey may calibrate
#: (:func:`calibrated_edge_sigma`): a 95 % circle of 37 m around an answer
#: at the survey's very edge.
MAX_EDGE_SIGMA_M = 15.0
#: The one-sidedness widens the sigma by its power: only answers with the
#: survey nearly all on one side are widened much (1/16 at 0.5). Chosen
#: on every dataset at hand (the panel's test files and the robot runs
#: with survey holes) against 2: as many circles within 90-98 % and
#: none widened past 98 % that was not already.
EDGE_POWER = 4
#: A scan that sounds unlike the survey (:func:`.coverage.unlike_survey`)
#: has its sigma widened by this (m, in quadrature). Chosen on the robot
#: runs with the threshold (``benchmarks/circle_ideas.py``).
MISMATCH_SIGMA_M = 4.0


@dataclass
class Locator:
    """
    Reference scans with their positions, in groups, and k.

    Class c searches the references of group ``group[c]``: its own floor
    (groups = classes), or every floor of its building (a scan's nearest
    references may lie on the floor above, at the same x, y).

    A scan's sigma grows with its distance to the nearest reference (a
    scan unlike every reference is placed less surely): ``sigma[c]``
    (metres per unit of distance) was calibrated on held-out scans
    predicted as class c, so that a circle of 2.45 sigma holds 95 % of
    them; it is at least :data:`MIN_SIGMA`. Held-out stretches the survey
    never covered are placed at the edge of the nearest surveyed one, and
    farther off than that sigma says, however like the references it
    sounds: the sigma is widened to ``hypot(sigma, edge_sigma * side **
    EDGE_POWER)``, side the answer's :func:`.coverage.one_sidedness`
    among the references, ``edge_sigma`` (m) calibrated on held-out scans
    off the survey (:func:`calibrated_edge_sigma`; 0: not widened).
    ``usual_mismatch`` (dB): the median :meth:`mismatch` of held-out scans
    on covered ground, what another day's scans there show too (0: not
    known); a scan that sounds unlike the survey
    (:func:`.coverage.unlike_survey`) is widened by
    :data:`MISMATCH_SIGMA_M` too.
    """

    origin: np.ndarray    # float64 (2,)
    group_start: np.ndarray  # int64 (g + 1,): references of group g
    ap_start: np.ndarray  # int64 (g + 1,): rows of group g in ap_column
    ap_column: np.ndarray  # int64: the model AP column of each row
    scale: np.ndarray     # float32: per row, reference input = code * scale
    codes: np.ndarray     # int8: group by group, (rows, references) blocks
    norms: np.ndarray     # float32 (n_refs,): squared L2 norm (euclidean)
    #                       or L1 norm (sorensen) of each reference
    xy: np.ndarray        # float32 (n_refs, 2): position - origin
    sigma: np.ndarray     # float32 (k,): m per unit of nearest distance
    group: np.ndarray     # int64 (k,): the group class c searches
    n_aps: int            # width of the model's AP vector
    neighbours: int = 5
    columns: tuple = ('X', 'Y')
    representation: str = 'positive'  # one of preprocessing.SIGNALS
    metric: str = 'euclidean'         # one of METRICS
    edge_sigma: float = 0.0   # m, added at a one-sided answer (see above)
    usual_mismatch: float = 0.0  # dB, on covered ground (see above)
    blocks: list = field(init=False, repr=False)   # views into codes
    row_of: np.ndarray = field(init=False, repr=False)  # (g, n_aps), -1
    by_x: list = field(init=False, repr=False)  # per group: (order, x)

    def __post_init__(self):
        """Index the blocks: each group's rows by model AP column."""
        if self.representation not in SIGNALS or self.metric not in METRICS:
            raise ValueError(f'representation must be one of {SIGNALS} and '
                             f'metric one of {METRICS}, not '
                             f'{self.representation!r}, {self.metric!r}')
        if not 0 <= self.edge_sigma <= MAX_EDGE_SIGMA_M:
            raise ValueError(f'edge_sigma must be in [0, '
                             f'{MAX_EDGE_SIGMA_M:g}] m, not '
                             f'{self.edge_sigma!r}')
        if not 0 <= self.usual_mismatch <= MAX_MISMATCH_DB:
            raise ValueError(f'usual_mismatch must be in [0, '
                             f'{MAX_MISMATCH_DB:g}] dB, not '
                             f'{self.usual_mismatch!r}')
        n_groups = len(self.group_start) - 1
        refs = np.diff(self.group_start)
        rows = np.diff(self.ap_start)
        ends = np.cumsum(rows * refs)
        self.blocks = [self.codes[end - n * m:end].reshape(n, m)
                       for end, n, m in zip(ends, rows, refs)]
        self.row_of = np.full((n_groups, self.n_aps), -1, np.int32)
        for g in range(n_groups):
            self.row_of[g, self.ap_column[self.ap_start[g]:
                                          self.ap_start[g + 1]]] = \
                np.arange(rows[g])
        self.by_x = []
        for g in range(n_groups):
            x = self.xy[self.group_start[g]:self.group_start[g + 1], 0]
            order = np.argsort(x, kind='stable')
            self.by_x.append((order, x[order]))

    @classmethod
    def build(cls, rssi, classes, xy, n_classes, neighbours=5,
              sigma=None, columns=('X', 'Y'), representation='positive',
              metric='euclidean', group=None, edge_sigma=0.0,
              usual_mismatch=0.0):
        """
        Return a locator of reference scans ``rssi`` (dBm, NaN: undetected).

        ``classes`` is each reference's class index, ``xy`` its position;
        ``group`` the group each class searches (default: its own).
        """
        group = np.arange(n_classes) if group is None else \
            np.asarray(group, np.int64)
        n_groups = int(group.max()) + 1
        inputs = signal(rssi, representation)
        groups = group[classes]
        order = np.argsort(groups, kind='stable')
        inputs, groups, xy = inputs[order], groups[order], xy[order]
        origin = xy.mean(axis=0)
        group_start = np.searchsorted(groups, np.arange(n_groups + 1))
        aps, scales, codes, norms = [], [], [], []
        for g in range(n_groups):
            block = inputs[group_start[g]:group_start[g + 1]]
            detected = np.flatnonzero((block != 0).any(axis=0))
            rows = block[:, detected].T.astype(np.float64)
            scale = (np.abs(rows).max(axis=1, initial=0.0) / LEVELS
                     ).astype(np.float32)
            code = np.rint(rows / scale[:, None]).astype(np.int8)
            aps.append(detected)
            scales.append(scale)
            codes.append(code.ravel())
            stored = code * scale[:, None].astype(np.float64)
            norms.append((stored ** 2 if metric == 'euclidean' else stored)
                         .sum(axis=0))
        if sigma is None:
            sigma = np.full(n_classes, np.nan)
        return cls(origin, group_start,
                   np.concatenate([[0], np.cumsum([len(a) for a in aps])]),
                   np.concatenate(aps).astype(np.int64),
                   np.concatenate(scales), np.concatenate(codes),
                   np.concatenate(norms).astype(np.float32),
                   (xy - origin).astype(np.float32),
                   np.asarray(sigma, np.float32), group, inputs.shape[1],
                   int(neighbours), tuple(columns), representation, metric,
                   float(edge_sigma), float(usual_mismatch))

    def locate(self, columns, rssi, c, neighbours=None):
        """
        Return (xy metres (2,), sigma m) of one scan of class ``c``.

        ``columns``/``rssi``: the scan's detected APs and their readings
        (dBm); ``neighbours`` overrides the model's k.
        """
        return self.weighted(
            self.distances(columns, signal(rssi, self.representation), c),
            neighbours or self.neighbours, c)

    def distances(self, columns, values, c):
        """
        Return the distance of one scan to each reference class c searches.

        ``values``: the signal (:attr:`representation`) of the scan's
        detected AP ``columns``.
        """
        g = self.group[c]
        first, last = self.group_start[g], self.group_start[g + 1]
        if first == last:
            return np.empty(0)
        rows = self.row_of[g, columns]
        shared = rows >= 0
        rows = rows[shared]
        scale = self.scale[self.ap_start[g] + rows]
        if self.metric == 'sorensen':
            refs = self.blocks[g][rows] * scale[:, None]
            # in place: one temporary of (APs x references) floats, not two
            common = np.minimum(refs, values[shared, None], out=refs).sum(
                axis=0)
            total = self.norms[first:last] + float(values.sum())
            return 1.0 - 2.0 * common / np.maximum(total, 1e-12)
        dots = (values[shared] * scale) @ \
            self.blocks[g][rows].astype(np.float32)
        return np.sqrt(np.maximum(
            self.norms[first:last] + float(np.dot(values, values))
            - 2 * dots, 0.0))

    def weighted(self, distance, k, c):
        """
        Return (xy, sigma) of the ``k`` nearest references of class ``c``.

        ``distance`` is from :meth:`distances`; weights are 1 / distance.
        """
        if not len(distance):
            return np.full(2, np.nan), float('nan')
        xy, nearest = self.positions(distance, (k,), c)
        return xy[0], max(float(self.sigma[c] * nearest), MIN_SIGMA)

    def widened(self, xy, sigma, c, mismatch=math.nan):
        """
        Return the sigma (m) of an answer ``xy`` of class c, widened.

        hypot(sigma, edge_sigma * side ** EDGE_POWER), side the answer's
        one-sidedness among c's references, and hypot with
        :data:`MISMATCH_SIGMA_M` when the scan's ``mismatch``
        (:meth:`relative_mismatch`; NaN: not known) says it sounds unlike
        the survey (:func:`.coverage.unlike_survey`): the 95 % circle's
        sigma. ``sigma``: the k-NN's (:meth:`weighted`).
        """
        if self.edge_sigma and np.isfinite(xy).all():
            sigma = math.hypot(sigma, self.edge_sigma *
                               self.one_sidedness(xy, c) ** EDGE_POWER)
        if unlike_survey(mismatch):
            sigma = math.hypot(sigma, MISMATCH_SIGMA_M)
        return sigma

    def one_sidedness(self, xy, c):
        """
        Return the :func:`.coverage.one_sidedness` of an answer xy (m).

        Among the references class c searches; only those within
        EDGE_RADIUS_M of it in x are read (kept sorted by x).
        """
        at = np.asarray(xy, np.float64) - self.origin
        order, sorted_x = self.by_x[self.group[c]]
        first, last = np.searchsorted(sorted_x, (at[0] - EDGE_RADIUS_M,
                                                 at[0] + EDGE_RADIUS_M))
        return one_sidedness(at[None],
                             self.reference_xy(c)[order[first:last]])[0]

    def mismatch(self, columns, rssi, c, distance):
        """
        Return how unlike its nearest references a scan sounds (dB).

        Over the scan's APs (``columns``, ``rssi`` dBm) that any of its
        :data:`MISMATCH_NEIGHBOURS` nearest references of class c heard
        (``distance``: :meth:`distances`): the root mean square of the
        scan's reading less the loudest of theirs, after taking out the
        median of those differences (a device or a day that hears every
        AP louder or softer). A scan taken where the survey never went
        hears the APs it shares with the references it resembles most
        at other strengths than they did. NaN with fewer than two such
        APs.
        """
        if len(distance) == 0:
            return float('nan')
        g = self.group[c]
        k = min(MISMATCH_NEIGHBOURS, len(distance))
        near = np.argpartition(distance, k - 1)[:k]
        rows = self.row_of[g, columns]
        shared = rows >= 0
        rows = rows[shared]
        codes = self.blocks[g][rows][:, near]
        heard = (codes > 0).any(axis=1)
        if heard.sum() < 2:
            return float('nan')
        loudest = signal_dbm(codes[heard].max(axis=1) *
                             self.scale[self.ap_start[g] + rows[heard]]
                             .astype(np.float64), self.representation)
        delta = np.asarray(rssi, np.float64)[shared][heard] - loudest
        return float(np.sqrt(np.mean((delta - np.median(delta)) ** 2)))

    def relative_mismatch(self, columns, rssi, c, distance):
        """Return :meth:`mismatch` over :attr:`usual_mismatch` (NaN: none)."""
        if not self.usual_mismatch:
            return float('nan')
        return self.mismatch(columns, rssi, c, distance) / \
            self.usual_mismatch

    def positions(self, distance, ks, c):
        """
        Return the k-NN position of every k of ``ks``, and the nearest distance.

        The distance-weighted mean of the k nearest references of class
        ``c`` (1 / distance weights), for each k of ``ks`` at once.
        """
        if not len(distance):
            return np.full((len(ks), 2), np.nan), np.nan
        n = min(max(ks), len(distance))
        near = np.argpartition(distance, n - 1)[:n]
        near = near[np.argsort(distance[near], kind='stable')]
        weight = 1.0 / np.maximum(distance[near], 1e-6)
        xy = np.cumsum(weight[:, None] * self.reference_xy(c)[near], axis=0)
        last = np.minimum(ks, n) - 1
        return (self.origin + xy[last] / np.cumsum(weight)[last, None],
                float(distance[near[0]]))

    def reference_xy(self, c):
        """Return the positions (- origin) of the references c searches."""
        g = self.group[c]
        return self.xy[self.group_start[g]:self.group_start[g + 1]]

    def map_xy(self, c):
        """Return the positions (m, float64) of the references c searches."""
        return self.origin + self.reference_xy(c).astype(np.float64)


def calibrated_sigma(errors, nearest, predicted, n_classes, min_scans=30):
    """
    Return the sigma scale per class: m per unit of nearest distance.

    ``errors`` (m), ``nearest`` (distance to the nearest reference) and
    ``predicted`` (class) of held-out scans: the class's 95th percentile
    of error / nearest, over R95; a class predicted for fewer than
    ``min_scans`` of them gets the value of all.
    """
    ratio = errors / np.maximum(nearest, 1e-6)
    scale = np.full(n_classes, np.quantile(ratio, 0.95) / R95)
    for c in range(n_classes):
        mine = ratio[predicted == c]
        if len(mine) >= min_scans:
            scale[c] = np.quantile(mine, 0.95) / R95
    return scale


def calibrated_edge_sigma(errors, sigma, side, target=0.95):
    """
    Return the least edge sigma (m) that puts ``target`` of scans inside.

    ``errors`` (m), ``sigma`` (m, the calibrated one) and ``side`` (the
    answers' one-sidedness) of held-out scans: the smallest e (at most
    :data:`MAX_EDGE_SIGMA_M`) for which ``target`` of them lie within
    R95 hypot(sigma, e side^EDGE_POWER); 0 if they already do.
    """
    return least_widening(errors, sigma,
                          np.asarray(side, np.float64) ** EDGE_POWER, target)


def least_widening(errors, sigma, weight, target=0.95):
    """
    Return the least e (m) that puts ``target`` of scans inside.

    Inside: within R95 hypot(sigma, e weight) of the truth; ``errors``
    (m), ``sigma`` (m) and ``weight`` one per scan; at most
    :data:`MAX_EDGE_SIGMA_M`, 0 if they already are.
    """
    errors, sigma, weight = (np.asarray(a, np.float64)
                             for a in (errors, sigma, weight))
    if not len(errors):
        return 0.0
    missing = np.sqrt(np.maximum((errors / R95) ** 2 - sigma ** 2, 0.0))
    with np.errstate(divide='ignore', invalid='ignore'):
        needed = np.where(missing == 0, 0.0, missing / weight)
    needed = np.nan_to_num(needed, nan=np.inf)
    return float(min(np.quantile(needed, target, method='higher'),
                     MAX_EDGE_SIGMA_M))
