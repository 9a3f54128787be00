"""Score a model on labelled fingerprints: the offline twin of the node."""

import numpy as np

from .metrics import accuracies, confusion
from .scan import ScanMapper


def align(model, fp):
    """
    Return ``fp.rssi`` with columns in the model's AP order.

    APs the model knows but the file lacks are not detected; APs of the file
    the model does not know are ignored.
    """
    if tuple(fp.ap_ids) == tuple(model.ap_ids):
        return fp.rssi
    cols = ScanMapper(model.ap_ids).columns(fp.ap_ids)
    out = np.full((len(fp), len(model.ap_ids)), np.nan, np.float32)
    out[:, cols[cols >= 0]] = fp.rssi[:, cols >= 0]
    return out


def evaluate(model, fp):
    """Return accuracies, predictions and the confusion matrix."""
    building, floor, confidence, _ = model.predict(align(model, fp))
    result = accuracies(fp.building, fp.floor, building, floor)
    result['rows_without_ap'] = int(fp.empty_rows.sum())
    result['confusion'] = confusion(model.classes, fp.building, fp.floor,
                                    building, floor).tolist()
    result['classes'] = model.class_names
    result['predictions'] = (building, floor, confidence)
    return result
