"""Pieces shared by the command-line tools: data arguments and error exits."""

import argparse
from dataclasses import dataclass, field, fields, replace
import functools
import math
import os
import sys
from pathlib import Path

from ..core.artifact import ModelFileError
from ..core.atomic import probe_folder
from ..core.evaluation import mostly_unknown
from ..data.bags import BagOptions, is_bag, read_bags
from ..data.files import DataError, download_uci
from ..data.fingerprints import (read_fingerprints, ReaderOptions,
                                 SMALL_CLASS_POLICIES)
from ..data.poses import read_poses
from ..training.config import TrainConfig

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


def _names(text):
    return tuple(n.strip() for n in text.split(',') if n.strip())


def _column(text):
    return None if text.lower() == 'none' else text


def _pair(text):
    return None if text.lower() == 'none' else _names(text)


def add_model_arguments(parser, section):
    """Add ``--model`` and ``-o``: a model file whose ``section`` is fitted."""
    parser.add_argument('--model', type=Path, required=True,
                        help='model file from train_model (rewritten unless '
                             '-o is given)')
    parser.add_argument('-o', '--output', type=Path,
                        help=f'write the model with its {section} section '
                             f'here instead')


def model_output(args):
    """
    Return (option, path) of the model file a fit writes.

    ``--model`` rewritten in place without ``-o`` (or with ``-o`` naming
    that file), else ``-o``: for :func:`check_outputs` and the save.
    """
    if args.output is None or same_file(args.output, args.model):
        return '--model', args.model
    return '-o', args.output


def add_data_arguments(parser, training=False):
    """Add the options that say how to read fingerprint files."""
    d = ReaderOptions()
    g = parser.add_argument_group(
        'reading fingerprint files (defaults read UJIIndoorLoc and '
        'record_fingerprints files; see doc/training.md, "Fingerprint CSVs")')
    g.add_argument('--ap-columns', type=_names, default=(),
                   metavar='NAMES',
                   help='AP columns: comma-separated names or patterns '
                        '(WAP*); others are left out. Default: every '
                        'column whose values look like RSSI')
    g.add_argument('--meta-columns', type=_names, default=(),
                   metavar='NAMES',
                   help='columns that are not APs (names or patterns), '
                        'kept as metadata')
    g.add_argument('--building-column', type=_column,
                   default=d.building_column, metavar='NAME',
                   help='default: %(default)s; none: one building, '
                        'building 0 for every scan')
    g.add_argument('--floor-column', default=d.floor_column, metavar='NAME',
                   help='default: %(default)s')
    g.add_argument('--device-column', default=d.device_column,
                   metavar='NAME',
                   help='device ids, numbers or text (default: '
                        '%(default)s, when present)')
    g.add_argument('--time-column', default=d.time_column, metavar='NAME',
                   help='seconds or ISO dates (default: %(default)s, when '
                        'present)')
    g.add_argument('--position-columns', type=_pair, default=(),
                   metavar='X,Y',
                   help='coordinates in metres (default: LONGITUDE,LATITUDE '
                        'or X,Y when present; none: ignore them)')
    g.add_argument('--not-detected-marker', type=float, default=None,
                   metavar='VALUE',
                   help='the value that marks an AP as not detected IN THE '
                        'FILES (default: 100, and a value that fills most '
                        'cells at the bottom of the range is taken too, '
                        'with a note); --not-detected is what the model '
                        'uses instead')
    add_bag_arguments(parser)
    if training:
        g.add_argument('--small-classes', choices=SMALL_CLASS_POLICIES,
                       default='warn',
                       help='classes far smaller than the rest (a typo in '
                            'a label?): warn and keep them (default), drop '
                            'them, or keep them as intended')


def add_bag_arguments(parser):
    """Add the options that say how to read bags (topics, labels)."""
    d = BagOptions()
    g = parser.add_argument_group(
        'reading bags (a rosbag2 folder, .mcap or .db3 file, or a ROS 1 '
        '.bag, in place of CSVs; see doc/your-building.md, "Bags in")')
    g.add_argument('--bag-scan-topic', default=d.scan_topic, metavar='TOPIC',
                   help='sensor_msgs/msg/JointState scans (default: '
                        '%(default)s)')
    g.add_argument('--bag-odom-topic', default=d.odometry_topic,
                   metavar='TOPIC',
                   help='nav_msgs/msg/Odometry (default: %(default)s)')
    g.add_argument('--bag-pose-topic', default=d.pose_topic, metavar='TOPIC',
                   help='the localiser\'s geometry_msgs/msg/'
                        'PoseWithCovarianceStamped, interpolated to each '
                        'scan as its position (default: %(default)s; '
                        'none: no positions)')
    g.add_argument('--bag-building', type=int, default=d.building,
                   metavar='N',
                   help='building of every scan of a bag (default: '
                        '%(default)s)')
    g.add_argument('--bag-floor', type=int, default=d.floor, metavar='N',
                   help='floor of every scan of a bag (default: '
                        '%(default)s)')


def bag_options(args):
    """Return the :class:`.BagOptions` of :func:`add_bag_arguments`."""
    return BagOptions(args.bag_scan_topic, _column(args.bag_odom_topic) or '',
                      _column(args.bag_pose_topic) or '', args.bag_building,
                      args.bag_floor)


@dataclass(frozen=True)
class DataOptions:
    """
    What the command line says about the data: how to read it, where from.

    ``download``: with no path given, read the UCI zip, fetched once into
    ``cache_dir``; ``bag``: how to read bags.
    """

    reader: ReaderOptions = field(default_factory=ReaderOptions)
    download: bool = False
    cache_dir: Path = DEFAULT_CACHE
    bag: BagOptions = field(default_factory=BagOptions)


def data_options(args):
    """
    Return the :class:`DataOptions` of parsed arguments.

    Those of :func:`add_data_arguments`, and of
    :func:`add_download_arguments` when the command has them.
    """
    return DataOptions(
        ReaderOptions(
            ap_columns=args.ap_columns, meta_columns=args.meta_columns,
            building_column=args.building_column,
            floor_column=args.floor_column, device_column=args.device_column,
            time_column=args.time_column,
            position_columns=args.position_columns,
            not_detected_marker=args.not_detected_marker),
        getattr(args, 'download', False),
        getattr(args, 'cache_dir', DEFAULT_CACHE), bag_options(args))


def read_data(given, options, what, role='train', small_classes=None):
    """
    Read the data given on the command line, print how it was read.

    ``given``: the paths (or None: the downloaded zip, with
    ``options.download``); ``options``: :class:`DataOptions`;
    ``small_classes``: the policy of :class:`ReaderOptions`. Notes (columns
    left out, a detected marker ...) go to stderr always. Bags (all the
    paths, or none) are read by :func:`.bags.read_bags`.
    """
    return read_run(given, options, what, role, small_classes)[0]


def read_run(given, options, what, role='train', small_classes=None):
    """
    Return (fingerprints, odometry, poses) as :func:`read_data` reads them.

    Odometry and poses (float64 rows: stamp, x, y, yaw, ...) come from
    bags; None from CSVs, or a bag without the topic.
    """
    for i, path in enumerate(given or ()):
        twice = next((p for p in given[:i] if same_file(p, path)), None)
        if twice is not None:
            raise DataError(f'{what}: {path} is given twice (as {twice}): '
                            f'its scans would count twice')
    bags = [is_bag(p) for p in given or ()]
    if any(bags):
        if not all(bags):
            raise DataError(f'{what}: give bags or CSVs, not both')
        fp, odometry, poses = read_bags(given, options.bag)
        _print_notes(fp)
        return fp, odometry, poses
    if not given:
        if not options.download:
            raise DataError(f'no {what} given: pass a CSV path, a folder or '
                            f'--download')
        given = [download_uci(options.cache_dir)]
    reader = replace(options.reader, small_classes=small_classes)
    fp = read_fingerprints(given, role, reader)
    _print_notes(fp)
    if not len(fp):
        raise DataError(f'{what} {fp.source}: no scan left to use (the '
                        f'notes above say why)')
    return fp, None, None


def _print_notes(fp):
    for note in fp.notes:
        print(f'note: {note}', file=sys.stderr, flush=True)


def read_pose_input(path, kind, options, from_run=None):
    """
    Return the float64 (n, 4) poses of ``--odometry`` or ``--truth``.

    ``kind``: ``'odometry'`` or ``'poses'``; ``path``: a pose CSV, a bag
    (its topic of ``kind``), or None for ``from_run`` (those of the run's
    bags, as :func:`read_run` returns them). Raise :class:`DataError` when
    there are none.
    """
    option = '--odometry' if kind == 'odometry' else '--truth'
    if path is None:
        if from_run is None:
            raise DataError(f'no {option} given (the run is not a bag with '
                            f'{kind})')
        return from_run[:, :4]
    if not is_bag(path):
        return read_poses(path)
    _, odometry, poses = read_bags([path], options.bag)
    found = odometry if kind == 'odometry' else poses
    if found is None:
        raise DataError(f'{option} {path}: the bag has no {kind} topic')
    return found[:, :4]


def same_file(a, b):
    """Whether paths ``a`` and ``b`` name one file (links, ``..`` resolved)."""
    a, b = Path(a), Path(b)
    try:
        if a.exists() and b.exists():
            return a.samefile(b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def check_outputs(outputs, inputs=()):
    """
    Refuse, before any work, an output that cannot or must not be written.

    ``outputs``, ``inputs``: (option, path) pairs; None paths are left
    out. Raise ValueError naming the option and path of an output that is
    the file of an input (given by another option: ``--model`` rewritten
    in place is allowed) or of another output, that is a folder, or whose
    folder is missing or takes no new file.
    """
    outputs = [(o, Path(p)) for o, p in outputs if p is not None]
    inputs = [(o, Path(p)) for o, p in inputs if p is not None]
    for k, (option, path) in enumerate(outputs):
        for other, given in inputs:
            if other != option and same_file(path, given):
                raise ValueError(f'{option} {path} is the input {other} '
                                 f'{given}: writing it would destroy the '
                                 f'input; write elsewhere')
        for other, given in outputs[:k]:
            if same_file(path, given):
                raise ValueError(f'{option} {path} is also {other} '
                                 f'{given}: two outputs in one file')
        if path.is_dir():
            raise ValueError(f'{option} {path}: is a folder, not a file')
        folder = path.parent
        if not folder.is_dir():
            raise ValueError(f'{option} {path}: no folder {folder}')
        try:
            probe_folder(path)
        except OSError as exc:
            raise ValueError(f'{option} {path}: cannot write in the folder '
                             f'{folder} ({exc.strerror or exc})') from None


def check_output_folder(option, path):
    """Refuse (ValueError naming ``option``) an output folder that is a file."""
    if path is not None and Path(path).exists() and not Path(path).is_dir():
        raise ValueError(f'{option} {path}: is a file, not a folder')


def json_ready(value):
    """
    Return ``value`` with every non-finite float as None.

    JSON has no NaN or infinity (``json.dumps`` writes tokens that strict
    readers refuse): dump the result with ``allow_nan=False``.
    """
    if isinstance(value, dict):
        return {k: json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def option_message(exc):
    """
    Return an options object's error as the command line names it.

    Its message starts with the field's name (``max_wait must be ...``):
    the option's (``--max-wait must be ...``).
    """
    field, _, rest = str(exc).partition(' ')
    return f'--{field.replace("_", "-")} {rest}'


def topic_name(node, option, topic):
    """Refuse (ValueError naming ``option``) a topic name ROS refuses."""
    from rclpy.exceptions import NameValidationException
    from rclpy.validate_full_topic_name import validate_full_topic_name
    try:
        validate_full_topic_name(node.resolve_topic_name(topic))
    except (NameValidationException, RuntimeError) as exc:
        reason = str(exc).splitlines()[0].split(', at ')[0]  # no rcl source
        raise ValueError(f'{option} {topic!r} is not a valid topic name '
                         f'({reason})') from None


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
          f'({result["rows_without_ap"]} without any AP, '
          f'{result["rows_without_known_ap"]} without an AP the model '
          f'knows)')
    if mostly_unknown(result['rows_without_known_ap'], result['samples']):
        print('note: most scans hear no AP the model knows: another '
              'building than the model\'s, or APs named otherwise',
              file=sys.stderr)
    for key in ('building_accuracy', 'floor_accuracy',
                'building_floor_accuracy'):
        print(f'  {key.replace("_", " "):24s} {result[key]:.4f}')
    if 'position_mean_error_m' in result:
        print('  position error (m)       mean {position_mean_error_m:.2f}, '
              'median {position_median_error_m:.2f}, 75% '
              '{position_p75_error_m:.2f}, 95% {position_p95_error_m:.2f}; '
              'penalised mean {position_penalised_mean_error_m:.2f}; in the '
              '95% circle {position_in_95_ellipse:.3f}'.format(**result))
    names = result['classes']
    print('confusion (rows: true, columns: predicted)')
    print('      ' + ' '.join(f'{n:>5s}' for n in names))
    for name, row in zip(names, result['confusion']):
        print(f'{name:>5s} ' + ' '.join(f'{v:5d}' for v in row))


def _layers(text):
    return tuple(int(n) for n in text.split(',') if n.strip())


def add_training_arguments(parser, title, defaults=TrainConfig()):
    """Add one option per :class:`TrainConfig` field (``defaults``)."""
    g = parser.add_argument_group(title)
    for f in fields(TrainConfig):
        default = getattr(defaults, f.name)
        flag = '--' + f.name.replace('_', '-')
        if isinstance(default, bool):
            g.add_argument(flag, action=argparse.BooleanOptionalAction,
                           default=default)
        elif isinstance(default, tuple):
            g.add_argument(flag, type=_layers, default=default,
                           metavar='N,N,...',
                           help=f'default: {",".join(map(str, default))}')
        else:
            g.add_argument(flag, type=type(default), default=default,
                           help=f'default: {default}')


def training_config(args):
    """Return the :class:`TrainConfig` of :func:`add_training_arguments`."""
    return TrainConfig(**{f.name: getattr(args, f.name)
                          for f in fields(TrainConfig)})


def trainer():
    """Return the torch trainer; a clear error where torch is missing."""
    try:
        from ..training.trainer import train
    except ImportError as exc:
        raise ValueError(f'training needs torch ({exc}); install the '
                         f'package\'s [train] extra') from None
    return train
