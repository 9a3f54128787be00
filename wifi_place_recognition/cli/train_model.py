"""``train_model``: fingerprint CSV in, model artifact out."""

import argparse
import sys

from ..core.artifact import save_model
from ..core.evaluation import evaluate
from .common import (add_data_arguments, add_download_arguments,
                     add_training_arguments, check_outputs, data_options,
                     main_wrapper, print_report, read_data, trainer,
                     training_config)


def build_parser():
    """Return the argument parser; training options mirror TrainConfig."""
    p = argparse.ArgumentParser(
        allow_abbrev=False, prog='train_model',
        description='Train the SAE + classifier on a fingerprint CSV and '
                    'write the model artifact that classifier_node loads.')
    p.add_argument('--data', nargs='+', metavar='PATH',
                   help='training CSV(s) or folder(s) of CSVs (one walk '
                        'each), or the UCI zip')
    p.add_argument('-o', '--output', required=True,
                   help='model file to write (atomically)')
    p.add_argument('--validation', nargs='+', metavar='PATH',
                   help='choose the epochs (and the position\'s k and '
                        'sigma) on these CSV(s) or folder instead of by '
                        'cross-validation: other days, devices or walks '
                        'of the same building(s); not trained on')
    p.add_argument('--test', nargs='+', metavar='PATH',
                   help='also evaluate on these CSV(s) or folder at the end')
    p.add_argument('--quiet', action='store_true',
                   help='no per-epoch progress lines')
    add_download_arguments(p)
    add_data_arguments(p, training=True)
    add_training_arguments(
        p, 'model and training (defaults: the paper\'s network plus what '
        'cross-validation chose; see doc/training.md)')
    return p


@main_wrapper
def main(argv=None):
    """Train, save, summarise; exit 2 with a message on bad input."""
    args = build_parser().parse_args(argv)
    check_outputs([('-o', args.output)], [
        (option, path) for option in ('--data', '--validation', '--test')
        for path in getattr(args, option[2:]) or ()])
    config = training_config(args)
    data = data_options(args)
    train_fp = read_data(args.data, data, 'training data',
                         small_classes=args.small_classes)
    validation_fp = None
    if args.validation:
        validation_fp = read_data(args.validation, data, 'validation data',
                                  role='test')
    test_fp = None
    if args.test or (args.download and not args.data):
        test_fp = read_data(args.test, data, 'test data', role='test')

    def log(line):
        if not args.quiet:
            print(line, file=sys.stderr, flush=True)

    print(train_fp.summary(), file=sys.stderr, flush=True)
    model, _, report = trainer()(train_fp, config, log, validation_fp)
    save_model(model, args.output)
    networks = f'{len(model.members)} network(s) of {report.epochs} ' \
        f'epochs' if model.members else 'position only (one class)'
    print(f'wrote {args.output}: {len(model.ap_ids)} APs, '
          f'{len(model.classes)} classes, {networks}, trained in '
          f'{report.seconds:.1f} s ({report.dropped_empty} scans without '
          f'any AP left out)')
    s = report.selection
    where = f'validation data {s.get("note")}' \
        if s.get('grouping') == 'validation' else \
        f'cross-validated ({len(s.get("folds", []))} folds of whole ' \
        f'{s.get("grouping")} groups)'
    if 'accuracy_mean' in s:
        print(f'{where}: building+floor {s["accuracy_mean"]:.4f} '
              f'({s["accuracy_min"]:.4f}-{s["accuracy_max"]:.4f} over '
              f'folds) at {report.epochs} epochs')
    if 'position_mean_error_m' in s:
        print(f'{where}: position mean error '
              f'{s["position_mean_error_m"]:.2f} m ({s["position_metric"]} '
              f'distance over the {s["position_representation"]} signal '
              f'among the {s["position_scope"]}\'s references, '
              f'k={s["neighbours"]})')
    if test_fp is not None:
        print_report(evaluate(model, test_fp), model, test_fp.source)
    return 0


if __name__ == '__main__':
    sys.exit(main())
