"""Pieces shared by the command-line tools: data arguments and error exits."""

import functools
import os
import sys
from pathlib import Path

from ..core.artifact import ModelFileError
from ..data.fingerprints import DataError, download_uci

DEFAULT_CACHE = Path(os.environ.get('XDG_CACHE_HOME', Path.home() / '.cache')
                     ) / 'wifi_place_recognition'


def add_download_arguments(parser):
    """Add ``--download`` and ``--cache-dir``."""
    parser.add_argument('--download', action='store_true',
                        help='fetch the public UCI UJIIndoorLoc zip (once, '
                             'into --cache-dir, SHA-256 checked) and use it '
                             'where no data path is given')
    parser.add_argument('--cache-dir', type=Path, default=DEFAULT_CACHE,
                        help=f'download cache (default: {DEFAULT_CACHE})')


def data_path(given, args, what):
    """Return ``given``, else the downloaded zip, else exit with a message."""
    if given:
        return given
    if args.download:
        return str(download_uci(args.cache_dir))
    raise DataError(f'no {what} given: pass a CSV path or --download')


def main_wrapper(main):
    """Turn bad input into ``error: ...`` and exit code 2, no traceback."""
    @functools.wraps(main)
    def wrapped(argv=None):
        try:
            return main(argv)
        except (DataError, ModelFileError, ValueError, OSError) as exc:
            print(f'error: {exc}', file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            return 130
    return wrapped


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
