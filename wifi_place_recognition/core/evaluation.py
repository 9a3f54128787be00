"""Score a model on labelled fingerprints: the offline twin of the node."""

from .metrics import accuracies, confusion
from .scan import ScanMapper


def align(model, fp):
    """
    Return ``fp.rssi`` on the model's AP vector, mapped as the node does.

    APs the model knows but the file lacks are not detected; APs of the file
    the model does not know are ignored; identifiers match as in the node
    (case and separators ignored) and an AP read twice keeps its strongest
    reading.
    """
    return ScanMapper(model.ap_ids).map_rows(fp.ap_ids, fp.rssi)


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
