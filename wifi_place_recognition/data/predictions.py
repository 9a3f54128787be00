"""The predictions CSV written by evaluate_model and replay_scans."""

import csv

from ..core.atomic import atomic_write

PREDICTION_COLUMNS = ('row', 'BUILDINGID', 'FLOOR', 'pred_building',
                      'pred_floor', 'confidence')


def write_predictions(path, fp, predictions):
    """Write one CSV row per input row, atomically."""
    with atomic_write(path, 'w', newline='') as f:
        w = csv.writer(f)
        w.writerow(PREDICTION_COLUMNS)
        for i, (b, fl, c) in enumerate(zip(*predictions)):
            w.writerow([i, fp.building[i], fp.floor[i], int(b), int(fl),
                        f'{c:.6f}'])
