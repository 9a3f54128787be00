"""Accuracy figures for building/floor predictions."""

import numpy as np


def class_index(building, floor):
    """
    Return the distinct (building, floor) classes and each scan's class.

    ``classes`` is a sorted int64 (k, 2) array, ``index`` (n,) the row of
    each scan's class in it.
    """
    pairs = np.stack([np.asarray(building, np.int64),
                      np.asarray(floor, np.int64)], axis=1)
    classes, index = np.unique(pairs, axis=0, return_inverse=True)
    return classes, index.reshape(-1)


def accuracies(building, floor, pred_building, pred_floor):
    """Return building, floor (number right) and building+floor accuracy."""
    b_ok = np.asarray(building) == np.asarray(pred_building)
    f_ok = np.asarray(floor) == np.asarray(pred_floor)
    return {'samples': int(len(b_ok)),
            'building_accuracy': float(b_ok.mean()),
            'floor_accuracy': float(f_ok.mean()),
            'building_floor_accuracy': float((b_ok & f_ok).mean())}


def confusion(classes, building, floor, pred_building, pred_floor):
    """Return a (k, k) count matrix, rows = true class, cols = predicted."""
    index = {(int(b), int(f)): i for i, (b, f) in enumerate(classes)}
    k = len(classes)
    matrix = np.zeros((k, k), dtype=np.int64)
    for t, p in zip(zip(building, floor), zip(pred_building, pred_floor)):
        ti = index.get((int(t[0]), int(t[1])))
        if ti is not None:
            matrix[ti, index[(int(p[0]), int(p[1]))]] += 1
    return matrix


def reliability(confidence, right, bins=10):
    """
    Return the reliability table of top-class confidences.

    One row per non-empty equal-width bin of ``confidence`` (0-1): its
    bounds, scans, mean confidence and share ``right``.
    """
    confidence = np.asarray(confidence, np.float64)
    right = np.asarray(right, bool)
    index = np.minimum((confidence * bins).astype(np.int64), bins - 1)
    return [{'low': b / bins, 'high': (b + 1) / bins,
             'scans': int((index == b).sum()),
             'confidence': float(confidence[index == b].mean()),
             'accuracy': float(right[index == b].mean())}
            for b in range(bins) if (index == b).any()]


def expected_calibration_error(confidence, right, bins=10):
    """Return the ECE: scan-weighted mean of abs(accuracy - confidence)."""
    rows = reliability(confidence, right, bins)
    return float(sum(r['scans'] * abs(r['accuracy'] - r['confidence'])
                     for r in rows) / max(len(confidence), 1))


#: Thresholds of the risk-coverage curve: 0, 0.01, ..., 1.
THRESHOLDS = np.round(np.linspace(0.0, 1.0, 101), 2)


def risk_coverage(confidence, right, thresholds=THRESHOLDS):
    """
    Return, per threshold, the share of scans answered and their accuracy.

    A scan is answered when its ``confidence`` is at least the threshold
    (accuracy None when none is).
    """
    confidence = np.asarray(confidence, np.float64)
    right = np.asarray(right, bool)
    out = []
    for t in thresholds:
        answered = confidence >= t
        out.append({'threshold': float(t),
                    'coverage': float(answered.mean()),
                    'accuracy': float(right[answered].mean())
                    if answered.any() else None})
    return out
