"""``evaluate_model``: accuracy of a model file on a fingerprint CSV."""

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np

from .artifact import load_model
from .atomic import atomic_write
from .cli import add_download_arguments, data_path, main_wrapper
from .fingerprints import read_fingerprints
from .metrics import accuracies, confusion
from .resources import default_model_path
from .scan import ScanMapper

PREDICTION_COLUMNS = ('row', 'BUILDINGID', 'FLOOR', 'pred_building',
                      'pred_floor', 'confidence')


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


def print_report(result, model, source):
    """Print the accuracies and the confusion matrix, human-readable."""
    print(f'{source}: {result["samples"]} scans '
          f'({result["rows_without_ap"]} without any AP)')
    for key in ('building_accuracy', 'floor_accuracy',
                'building_floor_accuracy'):
        print(f'  {key.replace("_", " "):24s} {result[key]:.4f}')
    names = result['classes']
    print('confusion (rows: true, columns: predicted)')
    print('      ' + ' '.join(f'{n:>5s}' for n in names))
    for name, row in zip(names, result['confusion']):
        print(f'{name:>5s} ' + ' '.join(f'{v:5d}' for v in row))


def write_predictions(path, fp, predictions):
    """Write one CSV row per input row, atomically."""
    with atomic_write(path, 'w', newline='') as f:
        w = csv.writer(f)
        w.writerow(PREDICTION_COLUMNS)
        for i, (b, fl, c) in enumerate(zip(*predictions)):
            w.writerow([i, fp.building[i], fp.floor[i], int(b), int(fl),
                        f'{c:.6f}'])


@main_wrapper
def main(argv=None):
    """Evaluate; exit 2 with a message on bad input."""
    p = argparse.ArgumentParser(
        prog='evaluate_model',
        description='Building, floor and building+floor accuracy of a model '
                    'file on a labelled fingerprint CSV.')
    p.add_argument('--model', type=Path, default=None,
                   help=f'model file (default: the shipped '
                        f'{default_model_path().name})')
    p.add_argument('--data', help='labelled CSV, or the UCI zip')
    p.add_argument('--json', action='store_true',
                   help='print one JSON object instead of the report')
    p.add_argument('--predictions', metavar='OUT.csv',
                   help='write one row per input row with the prediction')
    add_download_arguments(p)
    args = p.parse_args(argv)
    model = load_model(args.model or default_model_path())
    fp = read_fingerprints(data_path(args.data, args, 'data'), role='test')
    result = evaluate(model, fp)
    predictions = result.pop('predictions')
    if args.predictions:
        write_predictions(args.predictions, fp, predictions)
    if args.json:
        print(json.dumps(result))
    else:
        print_report(result, model, fp.source)
    return 0


if __name__ == '__main__':
    sys.exit(main())
