"""
Fit the coverage model on the survey alone: its folds' held-out stretches.

Each fold of the position cross-validation holds out stretches of the
survey and places them among the scans it keeps: a held-out scan is
covered when a kept scan of its class lies within ``COVERED_M``, and its
``FEATURES`` (:mod:`wifi_place_recognition.core.coverage`) are what the
answer shows. A logistic regression (scikit-learn) on them is the
model; fitted on every fold but one and scored on that one, it reports
how well it separates (ROC AUC) and whether its probability means what
it says (reliability bins).

The held-out stretches are cut out of the survey, so they lie off the
rest of it far more often than a robot drives where nobody surveyed (a
survey driven once: half of them). Its prior, the share of scans taken
on covered ground, is therefore that of the held-out scans but at least
:data:`PRIOR_FLOOR` (the regression's intercept moved by the log-odds
between the two): on another day, a model that kept the cut's share
called a third of the scans of a covered run off the survey
(``benchmarks/coverage_check.py``).
"""

import math

import numpy as np

from ..core.coverage import COVERED_M, CoverageModel, FEATURES

#: Fewer held-out scans of either label than this: no coverage model.
MIN_EXAMPLES = 20
#: Inverse regularisation of the logistic regression.
C = 1.0
#: Reliability bins of the predicted probability.
BINS = 5
#: The least share of scans on covered ground the probability assumes.
PRIOR_FLOOR = 0.9


def _fit(x, y):
    """Return (mean, scale, coef, intercept) of a regression on ``x``."""
    from sklearn.linear_model import LogisticRegression
    mean = x.mean(axis=0)
    scale = x.std(axis=0)
    scale[scale < 1e-9] = 1.0
    fit = LogisticRegression(C=C).fit((x - mean) / scale, y)
    return mean, scale, fit.coef_[0], float(fit.intercept_[0])


def _model(params, report=None, prior_shift=0.0):
    mean, scale, coef, intercept = params
    return CoverageModel(tuple(map(float, mean)), tuple(map(float, scale)),
                         tuple(map(float, coef)), intercept + prior_shift,
                         FEATURES, report)


def logit(p):
    """Return log(p / (1 - p)): the log-odds of a share ``p`` in (0, 1)."""
    return math.log(p / (1 - p))


def auc(score, label):
    """Return the ROC AUC of ``score`` for boolean ``label`` (ties: half)."""
    score, label = np.asarray(score, np.float64), np.asarray(label, bool)
    n1, n0 = int(label.sum()), int((~label).sum())
    if not n1 or not n0:
        return float('nan')
    _, where, counts = np.unique(score, return_inverse=True,
                                 return_counts=True)
    ranks = (np.cumsum(counts) - (counts - 1) / 2)[where.reshape(-1)]
    return float((ranks[label].sum() - n1 * (n1 + 1) / 2) / (n1 * n0))


def reliability(p, label, bins=BINS):
    """
    Return the reliability table and the expected calibration error.

    Bins of equal width of the predicted probability ``p``: scans, mean
    predicted, share actually covered.
    """
    edges = np.linspace(0, 1, bins + 1)
    which = np.clip(np.searchsorted(edges, p, side='right') - 1, 0, bins - 1)
    table, ece = [], 0.0
    for b in range(bins):
        mine = which == b
        if mine.any():
            predicted, observed = float(p[mine].mean()), float(
                label[mine].mean())
            table.append({'bin': [float(edges[b]), float(edges[b + 1])],
                          'scans': int(mine.sum()),
                          'predicted': round(predicted, 4),
                          'covered': round(observed, 4)})
            ece += mine.mean() * abs(predicted - observed)
    return table, float(ece)


def fit_coverage(x, covered, fold, log=print):
    """
    Return a :class:`CoverageModel` fitted on held-out scans, or None.

    ``x`` (n, F): their features; ``covered``: their labels; ``fold``: the
    fold that held each out. Its prior: their share covered, at least
    :data:`PRIOR_FLOOR`. None (the filter then trusts every scan alike)
    when either label has fewer than :data:`MIN_EXAMPLES` scans.
    """
    ok = np.isfinite(x).all(axis=1)
    x, covered, fold = x[ok], np.asarray(covered, bool)[ok], fold[ok]
    n1, n0 = int(covered.sum()), int((~covered).sum())
    if min(n1, n0) < MIN_EXAMPLES:
        log(f'coverage: {n1} held-out scans near a kept one, {n0} not: '
            f'too few to learn from (every scan trusted alike)')
        return None
    crossed = np.full(len(x), np.nan)
    for f in np.unique(fold):
        rest = fold != f
        if min(covered[rest].sum(), (~covered[rest]).sum()) < 2:
            continue
        crossed[~rest] = _model(_fit(x[rest], covered[rest])).probability(
            x[~rest])
    scored = np.isfinite(crossed)
    table, ece = reliability(crossed[scored], covered[scored])
    share = n1 / (n1 + n0)
    prior = max(share, PRIOR_FLOOR)
    report = {'held_out_scans': len(x), 'covered': n1, 'not_covered': n0,
              'cross_fitted_scans': int(scored.sum()),
              'auc': _rounded(auc(crossed[scored], covered[scored])),
              'ece': _rounded(ece), 'reliability': table,
              'prior': _rounded(prior),
              'protocol': f'fitted on the held-out scans of every fold '
                          f'but one, scored on that one (labels: a kept '
                          f'scan of the class within {COVERED_M:g} m), '
                          f'at their own share covered; the model\'s '
                          f'prior: that share, at least {PRIOR_FLOOR:g}'}
    log(f'coverage: {n1} held-out scans near a kept one, {n0} not; '
        f'cross-fitted ROC AUC {report["auc"]}, calibration error '
        f'{report["ece"]}; prior P(covered) {report["prior"]}')
    return _model(_fit(x, covered), report, logit(prior) - logit(share))


def _rounded(value):
    """Return ``value`` to 4 decimals, None if not finite (JSON has no NaN)."""
    return round(value, 4) if np.isfinite(value) else None
