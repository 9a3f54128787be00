"""The predictions CSV written by evaluate_model and replay_scans."""

import csv

import numpy as np

from ..core.atomic import atomic_write

PREDICTION_COLUMNS = ('row', 'BUILDINGID', 'FLOOR', 'pred_building',
                      'pred_floor', 'confidence')
POSITION_COLUMNS = ('x', 'y', 'sigma_m')


def write_predictions(path, fp, predictions):
    """
    Write one CSV row per input row, atomically.

    ``predictions`` maps ``building``, ``floor``, ``confidence`` (and, when
    any is finite, ``x``, ``y``, ``sigma_m``) to one array each.
    """
    located = 'x' in predictions and np.isfinite(predictions['x']).any()
    extra = POSITION_COLUMNS if located else ()
    with atomic_write(path, 'w', newline='') as f:
        w = csv.writer(f)
        w.writerow(PREDICTION_COLUMNS + extra)
        for i in range(len(fp)):
            w.writerow([i, fp.building[i], fp.floor[i],
                        int(predictions['building'][i]),
                        int(predictions['floor'][i]),
                        f'{predictions["confidence"][i]:.6f}']
                       + [f'{predictions[k][i]:.3f}' for k in extra])
