"""``bag_to_csv``: a bag's scans, odometry and poses as a run's CSVs."""

import argparse
from contextlib import ExitStack
import sys
from pathlib import Path

import numpy as np

from ..core.atomic import atomic_write
from ..data.bags import (is_bag, pose_labels, read_bag,
                         scan_matrix)
from ..data.columns import NOT_DETECTED_MARKER
from ..data.poses import COVARIANCE_COLUMNS, POSE_COLUMNS
from .common import (add_bag_arguments, bag_options, check_output_folder,
                     main_wrapper)

#: The files of a run, as in the shared robot runs.
FILES = ('scans.csv', 'odom.csv', 'poses.csv')


@main_wrapper
def main(argv=None):
    """Export each bag; exit 2 on a bad bag, with nothing written."""
    p = argparse.ArgumentParser(
        allow_abbrev=False, prog='bag_to_csv',
        description='Write a bag\'s scans, odometry and localiser poses as '
                    'a run folder of CSVs (scans.csv, odom.csv, poses.csv, '
                    'which every tool reads): each scan labelled with the '
                    'building and floor given and the pose interpolated '
                    'between the two poses around its stamp. Every bag is '
                    'read before anything is written; each file is replaced '
                    'whole or not at all.')
    p.add_argument('bags', nargs='+', type=Path, metavar='BAG',
                   help='rosbag2 folder, .mcap or .db3 file, or ROS 1 .bag')
    p.add_argument('-o', '--output', type=Path, required=True,
                   metavar='FOLDER',
                   help='the run folder (created); with several bags, one '
                        'sub-folder per bag, named after it')
    add_bag_arguments(p)
    args = p.parse_args(argv)
    check_output_folder('-o', args.output)
    options = bag_options(args)
    for bag in args.bags:
        if not is_bag(bag):
            raise ValueError(f'{bag}: not a bag (a rosbag2 folder with a '
                             f'metadata.yaml, or a .mcap, .db3 or .bag file)')
    names = [bag.stem if bag.is_file() else bag.name for bag in args.bags]
    if len(set(names)) < len(names):
        raise ValueError('two bags of the same name: export them one at a '
                         'time')
    recordings = [read_bag(bag, options) for bag in args.bags]
    folders = [args.output] if len(args.bags) == 1 else \
        [args.output / name for name in names]
    tables = [run_tables(r, options.building, options.floor)
              for r in recordings]
    for folder, texts in zip(folders, tables):
        stale = [name for name in FILES
                 if name not in texts and (folder / name).exists()]
        if stale:
            raise ValueError(f'{folder} holds {", ".join(stale)}, which this '
                             f'export would leave beside its own files (its '
                             f'bag has no such topic): write to another '
                             f'folder, or remove {stale[0]}')
    for folder in folders:
        folder.mkdir(parents=True, exist_ok=True)
    with ExitStack() as files:
        for folder, texts in zip(folders, tables):
            for name, text in texts.items():
                files.enter_context(atomic_write(folder / name, 'w')) \
                    .write(text)
    for folder, r, texts in zip(folders, recordings, tables):
        for note in r.notes:
            print(f'note: {note}', file=sys.stderr)
        print(f'{r.source}: {len(r.scans)} scans, '
              f'{_rows(r.odometry)} odometry poses, {_rows(r.poses)} '
              f'poses -> {folder} ({", ".join(texts)})')
    return 0


def _rows(table):
    return 0 if table is None else len(table)


def run_tables(recording, building, floor, ap_ids=None):
    """
    Return {file name: CSV text} of a :class:`.Recording`.

    ``ap_ids``: the AP columns (default: the APs the bag heard; the shared
    runs of a building all have the building's).
    """
    ap_ids, rssi = scan_matrix(recording, ap_ids)
    stamps = np.array([s[0] for s in recording.scans])
    cells = np.where(np.isnan(rssi), NOT_DETECTED_MARKER, rssi)
    columns = [np.char.mod('%.6f', stamps)]
    header = ['TIMESTAMP']
    if recording.poses is not None:
        xy, yaw = pose_labels(recording.poses, stamps)
        header += ['X', 'Y', 'YAW']
        columns += [_text(xy[:, 0]), _text(xy[:, 1]), _text(yaw)]
    columns += [np.char.mod('%g', cells[:, j]) for j in range(len(ap_ids))]
    lines = [','.join(header + list(ap_ids) + ['BUILDINGID', 'FLOOR'])]
    lines += [','.join(row) + f',{building},{floor}'
              for row in zip(*columns)]
    out = {FILES[0]: '\n'.join(lines) + '\n'}
    if recording.odometry is not None:
        out[FILES[1]] = _poses_text(recording.odometry, POSE_COLUMNS)
    if recording.poses is not None:
        out[FILES[2]] = _poses_text(recording.poses,
                                    POSE_COLUMNS + COVARIANCE_COLUMNS)
    return out


def _text(values):
    """Return cells with 6 decimals, empty where NaN (no pose)."""
    return np.where(np.isnan(values), '', np.char.mod('%.6f', values))


def _poses_text(table, header):
    rows = [f'{r[0]:.6f},{r[1]:.6f},{r[2]:.6f},{r[3]:.6f}' +
            ''.join(f',{v:.9g}' for v in r[4:]) for r in table]
    return ','.join(header) + '\n' + '\n'.join(rows) + '\n'


if __name__ == '__main__':
    sys.exit(main())
