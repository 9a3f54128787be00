"""``evaluate_model``: accuracy of a model file on a fingerprint CSV."""

import argparse
import json
import sys
from pathlib import Path


from ..core.artifact import load_model
from ..core.evaluation import evaluate
from ..core.metrics import (expected_calibration_error, reliability,
                            risk_coverage)
from ..core.resources import default_model_path
from ..data.predictions import write_predictions
from .common import (add_data_arguments, add_download_arguments,
                     check_output_folder, check_outputs, data_options,
                     json_ready, main_wrapper, print_report, read_data)


@main_wrapper
def main(argv=None):
    """Evaluate; exit 2 with a message on bad input."""
    p = argparse.ArgumentParser(
        allow_abbrev=False, prog='evaluate_model',
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
    p.add_argument('--plot', metavar='DIR',
                   help='write PNG pictures (confusion matrix; with '
                        'positions the error CDF and a map per floor); '
                        'needs matplotlib')
    p.add_argument('--plot-baseline', nargs='+', metavar='PATH',
                   help='training data for a k-NN regression baseline in '
                        'the error CDF (needs scikit-learn)')
    add_download_arguments(p)
    add_data_arguments(p)
    args = p.parse_args(argv)
    if args.plot_baseline and not args.plot:
        p.error('--plot-baseline draws in the --plot pictures: give --plot')
    check_output_folder('--plot', args.plot)
    check_outputs([('--predictions', args.predictions)],
                  [('--model', args.model)] +
                  [('--data', d) for d in args.data or ()] +
                  [('--plot-baseline', d) for d in args.plot_baseline or ()])
    model = load_model(args.model or default_model_path())
    fp = read_data(args.data, data_options(args), 'data', role='test')
    result = evaluate(model, fp)
    predictions = result.pop('predictions')
    result['calibration'] = calibration(fp, predictions, model)
    if args.plot:
        _plot(args, model, fp, result, predictions)
    if args.predictions:
        write_predictions(args.predictions, fp, predictions)
    if args.json:
        print(json.dumps(json_ready(result), allow_nan=False))
    else:
        print_report(result, model, fp.source)
        c = result['calibration']
        print(f'  probabilities            temperature {c["temperature"]:g}, '
              f'expected calibration error {c["ece"]:.4f} (10 bins)')
    return 0


def calibration(fp, predictions, model):
    """
    Return how well the confidences match the hit rate.

    The expected calibration error and reliability table (10 bins of the
    top-class probability) and the risk-coverage curve: per threshold, the
    share of scans whose confidence reaches it and their building+floor
    accuracy.
    """
    right = (predictions['building'] == fp.building) & \
        (predictions['floor'] == fp.floor)
    confidence = predictions['confidence']
    return {'temperature': model.temperature,
            'ece': expected_calibration_error(confidence, right),
            'reliability': reliability(confidence, right),
            'risk_coverage': risk_coverage(confidence, right)}


def _plot(args, model, fp, result, predictions):
    try:
        from .plots import knn_baseline, plot_evaluation
        baseline = None
        if args.plot_baseline and 'position_mean_error_m' in result:
            train_fp = read_data(args.plot_baseline, data_options(args),
                                 'baseline data')
            baseline = knn_baseline(model, train_fp, fp)
        paths = plot_evaluation(args.plot, model, fp, result, predictions,
                                baseline)
    except ImportError as exc:
        raise ValueError(f'--plot needs matplotlib (and --plot-baseline '
                         f'scikit-learn): {exc}') from None
    print(f'wrote {len(paths)} pictures to {args.plot}', file=sys.stderr)


if __name__ == '__main__':
    sys.exit(main())
