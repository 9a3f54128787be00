"""
Held-out groups for choosing a recipe: grouped K-fold cross-validation.

Scans of one device (or one walk, or one stretch of time) are alike, so a
random split of scans leaks and overestimates accuracy. A fold holds out
whole groups: devices (``PHONEID``) when the data has several, else walks
(one file per walk), else contiguous blocks of time (``TIMESTAMP``, or
file order). Every fold keeps every class in training; a group that would
take a class's last training scans is never held out.
"""

from dataclasses import dataclass

import numpy as np


@dataclass
class Folds:
    """Which scans each fold holds out, and what the groups were."""

    held_out: list       # one boolean mask (n,) per fold
    grouping: str        # device, walk or time, as applied
    groups: int          # number of groups
    never_held_out: list  # groups kept in training to keep every class
    note: str = ''       # why the grouping is what it is


def scan_groups(fp, grouping='auto', min_groups=2, time_blocks=16):
    """
    Return (grouping, group id per scan, note).

    ``auto`` takes devices if there are at least ``min_groups``, else walks,
    else time blocks. ``time`` cuts the scans, in time order, into
    ``time_blocks`` contiguous blocks of equal size.
    """
    device = fp.meta.get('PHONEID')
    walk = getattr(fp, 'walk', None)
    note = ''
    if grouping in ('auto', 'device') and device is not None:
        ids = np.unique(device, return_inverse=True)[1].reshape(-1)
        if ids.max() + 1 >= min_groups:
            return 'device', ids, note
        note = 'a single device: '
    if grouping == 'device':
        raise ValueError('grouping by device needs a PHONEID (device) '
                         'column with several devices')
    if grouping in ('auto', 'walk') and walk is not None:
        ids = np.unique(walk, return_inverse=True)[1].reshape(-1)
        if ids.max() + 1 >= min_groups:
            return 'walk', ids, note + 'grouped by walk (file)'
    if grouping == 'walk':
        raise ValueError('grouping by walk needs data read from several '
                         'files (one per walk)')
    stamps = fp.meta.get('TIMESTAMP')
    order = np.argsort(stamps, kind='stable') if stamps is not None \
        else np.arange(len(fp))
    ids = np.empty(len(fp), np.int64)
    ids[order] = np.arange(len(fp)) * time_blocks // len(fp)
    basis = 'TIMESTAMP' if stamps is not None else 'file order'
    return 'time', ids, note + f'grouped by {time_blocks} blocks of ' \
        f'{basis}'


def grouped_folds(fp, labels, k, grouping='auto', seed=0):
    """
    Return :class:`Folds`: ``k`` folds that hold out whole groups.

    Groups are dealt, largest first in a seeded order, to the fold with the
    fewest scans that can take them without emptying a class in its
    training part. ``labels`` is each scan's class index.
    """
    grouping, ids, note = scan_groups(fp, grouping, min_groups=k)
    n_groups = int(ids.max()) + 1
    n_classes = int(labels.max()) + 1
    per_group = np.zeros((n_groups, n_classes), np.int64)
    np.add.at(per_group, (ids, labels), 1)
    total = per_group.sum(axis=0)
    rng = np.random.default_rng(seed)
    order = rng.permutation(n_groups)
    order = order[np.argsort(-per_group[order].sum(axis=1), kind='stable')]
    held = np.zeros((k, n_classes), np.int64)
    members = [[] for _ in range(k)]
    never = []
    for g in order:
        fits = [f for f in range(k)
                if ((held[f] + per_group[g]) < total).all()]
        if not fits:
            never.append(int(g))
            continue
        f = min(fits, key=lambda f: held[f].sum())
        held[f] += per_group[g]
        members[f].append(g)
    masks = [np.isin(ids, m) for m in members if m]
    if len(masks) < 2:
        raise ValueError(f'cannot make {k} folds of whole {grouping} groups '
                         f'that keep every class in training ({n_groups} '
                         f'groups): use fewer folds or --folds 0')
    return Folds(masks, grouping, n_groups, never, note)
