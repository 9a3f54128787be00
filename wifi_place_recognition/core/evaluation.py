"""Score a model on labelled fingerprints: the offline twin of the node."""

import numpy as np

from .metrics import accuracies, confusion
from .locator import R95
from .scan import ScanMapper

#: The IPIN 2015 competition's penalties on UJIIndoorLoc (metres).
WRONG_BUILDING_M = 50.0
PER_FLOOR_M = 4.0


def align(onto, fp):
    """
    Return ``fp.rssi`` on the AP columns of ``onto``, mapped as the node does.

    ``onto``: a model, or other fingerprints (anything with ``ap_ids``).
    APs of ``onto`` that ``fp`` lacks are not detected; APs of ``fp`` that
    ``onto`` lacks are ignored; identifiers match as in the node (case and
    separators ignored) and an AP read twice keeps its strongest reading.
    """
    return ScanMapper(onto.ap_ids).map_rows(fp.ap_ids, fp.rssi)


def unknown_aps(onto, fp):
    """
    Return how many APs each scan of ``fp`` heard that ``onto`` lacks.

    What the node counts as a scan's ``unknown_aps`` (and the coverage
    features read), for rows :func:`align` maps.
    """
    lacking = ScanMapper(onto.ap_ids).columns(fp.ap_ids) < 0
    return np.isfinite(fp.rssi[:, lacking]).sum(axis=1)


def scan_answers(model, fp, widened=True):
    """
    Return (probabilities, xy, sigma, coverage, mismatch) of each scan.

    As the node answers them: :meth:`.model.PlaceModel.predict_positions`
    of the rows :func:`align` maps, the APs the model lacks counted
    (:func:`unknown_aps`); with ``widened`` false the k-NN's sigma, not
    the 95 % circle's; the mismatch over the survey's usual.
    """
    return model.predict_positions(align(model, fp), coverage=True,
                                   widened=widened,
                                   unknown=unknown_aps(model, fp))


def rows_without_known_ap(rssi):
    """Return how many scans (:func:`align`'s rows) hear no AP it knows."""
    return int(np.isnan(rssi).all(axis=1).sum())


def mostly_unknown(without, total):
    """
    Return True when most of ``total`` scans hear no AP the model knows.

    ``without``: :func:`rows_without_known_ap`'s count; the scans are
    then likely of another building (or name their APs otherwise).
    """
    return without > total / 2


def evaluate(model, fp):
    """
    Return accuracies, predictions and the confusion matrix.

    With a position model and coordinates in the data, also the 2-D error
    figures (:func:`position_errors`). ``predictions`` holds arrays:
    building, floor, confidence, and x, y, sigma (NaN without a position).
    """
    rssi = align(model, fp)
    if model.position is None:
        proba = model.predict_proba(rssi)
        xy, sigma = np.full((len(fp), 2), np.nan), np.full(len(fp), np.nan)
    else:
        proba, xy, sigma = model.predict_positions(rssi)
    best = proba.argmax(axis=1)
    building, floor = model.classes[best, 0], model.classes[best, 1]
    result = accuracies(fp.building, fp.floor, building, floor)
    result['rows_without_ap'] = int(fp.empty_rows.sum())
    result['rows_without_known_ap'] = rows_without_known_ap(rssi)
    result['confusion'] = confusion(model.classes, fp.building, fp.floor,
                                    building, floor).tolist()
    result['classes'] = model.class_names
    if model.position is not None and fp.position is not None:
        result.update(position_errors(fp, building, floor, xy, sigma))
    result['predictions'] = {
        'building': building, 'floor': floor,
        'confidence': proba[np.arange(len(best)), best],
        'x': xy[:, 0], 'y': xy[:, 1], 'sigma_m': sigma}
    return result


def position_errors(fp, building, floor, xy, sigma):
    """
    Return the 2-D position error figures (metres) of predictions.

    The penalised mean adds 50 m for a wrong building and 4 m per floor of
    difference (the IPIN 2015 ranking on UJIIndoorLoc); in-ellipse is the
    fraction of scans within their 95 % circle (radius 2.45 sigma).
    """
    error = np.linalg.norm(xy - fp.position, axis=1)
    penalised = error + WRONG_BUILDING_M * (building != fp.building) + \
        PER_FLOOR_M * np.abs(floor - fp.floor)
    return {'position_mean_error_m': float(error.mean()),
            'position_median_error_m': float(np.median(error)),
            'position_p75_error_m': float(np.quantile(error, 0.75)),
            'position_p95_error_m': float(np.quantile(error, 0.95)),
            'position_penalised_mean_error_m': float(penalised.mean()),
            'position_in_95_ellipse': float((error <= R95 * sigma).mean())}
