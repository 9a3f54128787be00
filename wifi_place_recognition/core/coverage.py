"""
Was a scan taken where the survey covers? A small model of the answer.

Where the survey never went, the k-NN position snaps to the nearest
surveyed stretch, and its sigma says little about that. The answer leaves
traces, though: the nearest references are farther in signal space, their
positions scatter, and the scan hears APs the references never heard.
:func:`features` reads them from one scan's distances to the references;
:class:`CoverageModel` (a logistic regression on them) turns them into the
probability that the scan lies within a few metres of a survey scan.
Training fits it on the survey alone
(:mod:`wifi_place_recognition.training.coverage`): the
cross-validation folds hold out stretches of the survey, and each held-out
scan is labelled covered when a kept scan lies near it. :func:`uncovered`
is the one rule that calls a probability off the survey,
:func:`unlike_survey` the one that calls a scan's sound off it. Numpy only.
"""

from dataclasses import dataclass
import math

import numpy as np

#: A scan is covered when a survey scan of its place lies this close (m):
#: the label the model learns, and what survey_gaps and the benchmarks
#: count as a hole.
COVERED_M = 3.0
#: Position pairs one step of :func:`distance_to_survey` compares at most.
PAIRS_PER_STEP = 1 << 20
#: Survey positions within this distance (m) of an answer count for its
#: :func:`one_sidedness`.
EDGE_RADIUS_M = 5.0
#: A scan whose coverage probability is below this counts as off the
#: survey (:func:`uncovered`: survey_gaps's stretches of a run without
#: positions, classifier_node's ``scans_off_survey``).
OFF_SURVEY_BELOW = 0.5
#: A scan whose mismatch over the survey's usual
#: (:meth:`.locator.Locator.relative_mismatch`) is above this was likely
#: taken where the survey never went, however sure its answer looks
#: (:func:`unlike_survey`: its 95 % circle is widened, it testifies
#: nothing to the witness). Chosen for the circle on the robot runs
#: (``benchmarks/circle_ideas.py``: the most circles within 90-98 % on
#: both buildings, none of the panel's test files moved farther from
#: that band).
UNLIKE_SURVEY_ABOVE = 1.4


def uncovered(probability):
    """
    Return True where a coverage probability says off the survey.

    Below :data:`OFF_SURVEY_BELOW`, or NaN; an array for an array, a
    numpy bool for one number.
    """
    return ~(np.asarray(probability, np.float64) >= OFF_SURVEY_BELOW)


def unlike_survey(mismatch):
    """
    Return True if a scan's relative mismatch says off the survey.

    Above :data:`UNLIKE_SURVEY_ABOVE`; NaN (not known) is not.
    """
    return mismatch > UNLIKE_SURVEY_ABOVE


def distance_to_survey(xy, survey_xy):
    """
    Return each position's distance (m) to the nearest survey position.

    inf with no survey position, NaN for a position with NaN; compared in
    steps of at most :data:`PAIRS_PER_STEP` pairs.
    """
    xy = np.asarray(xy, np.float64)
    survey_xy = np.asarray(survey_xy, np.float64)
    out = np.full(len(xy), np.inf)
    if not len(survey_xy):
        return out
    step = max(1, PAIRS_PER_STEP // len(survey_xy))
    for start in range(0, len(xy), step):
        out[start:start + step] = np.linalg.norm(
            xy[start:start + step, None] - survey_xy[None], axis=2).min(
                axis=1)
    return out


def distance_by_place(xy, place, survey_xy, survey_place):
    """
    Return each position's distance (m) to the survey of its place.

    To the nearest survey position with the same label. ``place``,
    ``survey_place``: one label per row (a class index, or rows such as
    building and floor); inf where the survey has no position of the
    place, else NaN for a position with NaN.
    """
    xy = np.asarray(xy, np.float64)
    survey_xy = np.asarray(survey_xy, np.float64)
    labels = np.concatenate([np.asarray(place), np.asarray(survey_place)])
    code = np.unique(labels, axis=0, return_inverse=True)[1].reshape(-1)
    mine, theirs = code[:len(xy)], code[len(xy):]
    out = np.full(len(xy), np.inf)
    for label in np.unique(mine):
        rows = mine == label
        out[rows] = distance_to_survey(xy[rows], survey_xy[theirs == label])
    return out


def one_sidedness(xy, survey_xy, radius=EDGE_RADIUS_M):
    """
    Return how one-sided the survey lies around each answer (0 to 1).

    The mean resultant length of the directions from the answer ``xy``
    ((n, 2) m) to the ``survey_xy`` positions within ``radius`` (those on
    the answer itself not counted); 1 with fewer than two, NaN for an
    answer with NaN. Inside a corridor the survey lies on both sides of
    the answer (near 0); a scan taken where the survey never went is
    answered at the edge of the nearest surveyed stretch (near 1). A
    feature of geometry: it does not rest on signal-space distances,
    which another day's signal offsets shift.
    """
    xy = np.asarray(xy, np.float64)
    survey_xy = np.asarray(survey_xy)     # float32 (relative) stays so
    out = np.full(len(xy), np.nan)
    for i, p in enumerate(xy):
        if not np.isfinite(p).all():
            continue
        delta = survey_xy - p.astype(survey_xy.dtype)
        d2 = np.einsum('ij,ij->i', delta, delta)
        near = np.flatnonzero((d2 < radius ** 2) & (d2 > 1e-12))
        if len(near) < 2:
            out[i] = 1.0
            continue
        towards = delta[near].astype(np.float64)
        towards /= np.sqrt(d2[near])[:, None]
        out[i] = float(np.linalg.norm(towards.mean(axis=0)))
    return out


#: What :func:`features` returns, in order.
FEATURES = ('log_sigma', 'log_neighbour_ratio', 'log_spread',
            'unheard_share')
#: Metres added to the neighbours' spread before its log (0 is common).
SPREAD_FLOOR = 0.5
#: Neighbours the features look at (whatever k the position uses).
NEIGHBOURS = 5


def features(locator, distance, c, unheard_share):
    """
    Return the :data:`FEATURES` of one scan (an array), NaN if unplaced.

    ``distance``: the scan's distance to each reference class ``c``
    searches (:meth:`.locator.Locator.distances`); ``unheard_share``: the
    share of the scan's APs that no reference there heard (APs unknown
    to the model included). The sigma is the class's calibrated one;
    the neighbour ratio is the :data:`NEIGHBOURS` nearest distances' mean
    over the nearest; the spread is their references' distance-weighted
    spatial standard deviation (m).
    """
    out = np.full(len(FEATURES), np.nan)
    if not len(distance):
        return out
    k = min(NEIGHBOURS, len(distance))
    near = np.argpartition(distance, k - 1)[:k]
    d = np.maximum(distance[near], 1e-6)
    weight = 1.0 / d
    weight /= weight.sum()
    xy = locator.reference_xy(c)[near].astype(np.float64)
    centre = weight @ xy
    spread = math.sqrt(float(weight @ ((xy - centre) ** 2).sum(axis=1)))
    nearest = float(d.min())
    out[:] = (math.log(max(float(locator.sigma[c]) * nearest, 1e-3)),
              math.log(float(d.mean()) / nearest),
              math.log(spread + SPREAD_FLOOR), unheard_share)
    return out


def unheard_share(locator, columns, c, unknown=0):
    """
    Return the share of a scan's APs no reference of class ``c`` heard.

    ``columns``: the scan's model AP columns; ``unknown``: how many more
    APs it heard that the model does not know.
    """
    heard = len(columns) + unknown
    if not heard:
        return 1.0
    g = locator.group[c]
    return (unknown + int((locator.row_of[g, columns] < 0).sum())) / heard


@dataclass(frozen=True)
class CoverageModel:
    """
    P(covered | features): a logistic regression on standardised features.

    ``report``: how it was fitted and how reliable it was on held-out
    stretches of the survey (free-form, JSON-ready).
    """

    SECTION = 'coverage'

    mean: tuple
    scale: tuple
    coef: tuple
    intercept: float
    features: tuple = FEATURES
    report: dict = None

    def __post_init__(self):
        """Refuse a model that does not fit :data:`FEATURES`."""
        if tuple(self.features) != FEATURES:
            raise ValueError(f'coverage features {list(self.features)}: '
                             f'this version computes {list(FEATURES)}')
        n = len(FEATURES)
        for name in ('mean', 'scale', 'coef'):
            value = getattr(self, name)
            if not (isinstance(value, (list, tuple)) and len(value) == n
                    and all(_finite(v) for v in value)):
                raise ValueError(f'coverage {name} = {value!r}: expected '
                                 f'{n} finite numbers')
        if not all(v > 0 for v in self.scale):
            raise ValueError(f'coverage scale = {list(self.scale)!r}: '
                             f'expected numbers > 0')
        if not _finite(self.intercept):
            raise ValueError(f'coverage intercept = {self.intercept!r}: '
                             f'expected a finite number')
        if self.report is not None and not isinstance(self.report, dict):
            raise ValueError('coverage report must be an object')
        object.__setattr__(self, '_w', np.asarray(self.coef, np.float64) /
                           np.asarray(self.scale, np.float64))
        object.__setattr__(self, '_b', float(self.intercept) - float(
            self._w @ np.asarray(self.mean, np.float64)))

    def probability(self, x):
        """Return P(covered) of feature rows ``x`` ((n, F) or (F,))."""
        z = np.clip(np.asarray(x, np.float64) @ self._w + self._b, -30, 30)
        return 1.0 / (1.0 + np.exp(-z))

    def to_dict(self):
        """Return the model file's section."""
        return {'features': list(self.features), 'mean': list(self.mean),
                'scale': list(self.scale), 'coef': list(self.coef),
                'intercept': self.intercept, 'report': self.report}

    @classmethod
    def from_dict(cls, data):
        """Build from a file's section; raise ValueError naming the fault."""
        if not isinstance(data, dict):
            raise ValueError(f'coverage must be an object, got '
                             f'{type(data).__name__}')
        unknown = sorted(set(data) - {'features', 'mean', 'scale', 'coef',
                                      'intercept', 'report'})
        if unknown:
            raise ValueError(f'unknown coverage key(s) {", ".join(unknown)}')
        try:
            return cls(tuple(data['mean']), tuple(data['scale']),
                       tuple(data['coef']), data['intercept'],
                       tuple(data['features']), data.get('report'))
        except KeyError as exc:
            raise ValueError(f'coverage: {exc.args[0]} missing') from None
        except TypeError as exc:
            raise ValueError(f'coverage: {exc}') from None


def _finite(value):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:       # an integer too large for a float
        return False
