"""``evaluate_model``: accuracy of a model file on a fingerprint CSV."""

import argparse
import json
import sys
from pathlib import Path

from ..core.artifact import load_model
from ..core.evaluation import evaluate
from ..core.resources import default_model_path
from ..data.predictions import write_predictions
from .common import (add_data_arguments, add_download_arguments, main_wrapper,
                     print_report, read_data)


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
    p.add_argument('--data', nargs='+', metavar='PATH',
                   help='labelled CSV(s) or folder(s) of CSVs, or the UCI '
                        'zip')
    p.add_argument('--json', action='store_true',
                   help='print one JSON object instead of the report')
    p.add_argument('--predictions', metavar='OUT.csv',
                   help='write one row per input row with the prediction')
    add_download_arguments(p)
    add_data_arguments(p)
    args = p.parse_args(argv)
    model = load_model(args.model or default_model_path())
    fp = read_data(args.data, args, 'data', role='test')
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
