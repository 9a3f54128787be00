"""The walks of a fingerprint set: one device or file, in time order."""

import numpy as np

#: Metadata columns that tell walks apart when the scans come from one file.
WALK_KEYS = ('USERID', 'PHONEID')


def split_walks(keys, times):
    """
    Return index arrays of walks: scans grouped by ``keys``, in time order.

    ``keys`` is a sequence of (n,) arrays (e.g. USERID and PHONEID);
    scans with equal keys form one walk, sorted by ``times`` (stable).
    """
    times = np.asarray(times, np.float64)
    order = np.lexsort((times,) + tuple(np.asarray(k) for k in
                                        reversed(keys)))
    new = np.zeros(max(len(order) - 1, 0), bool)
    for key in keys:
        key = np.asarray(key)[order]
        new |= key[1:] != key[:-1]
    return np.split(order, np.flatnonzero(new) + 1)


def walks(fp):
    """
    Return index arrays of ``fp``'s walks, each in TIMESTAMP order.

    Scans read from several files are one walk per file (WiFine: one file
    per trajectory); scans of one file are grouped by USERID and PHONEID
    (those present; UJIIndoorLoc). Raise ValueError without TIMESTAMP.
    """
    if 'TIMESTAMP' not in fp.meta:
        raise ValueError(f'{fp.source}: no TIMESTAMP column: the scans '
                         f'cannot be put in time order')
    if fp.walk is not None:
        keys = [fp.walk]
    else:
        keys = [fp.meta[k] for k in WALK_KEYS if k in fp.meta]
    return split_walks(keys, fp.meta['TIMESTAMP'])


def walk_name(fp, walk):
    """Return a readable name of a walk (its file, or its key values)."""
    first = walk[0]
    if fp.walk is not None:
        return str(fp.walk[first])
    return ' '.join(f'{k}={_text(fp.meta[k][first])}' for k in WALK_KEYS
                    if k in fp.meta) or 'all scans'


def _text(value):
    return f'{value:g}' if isinstance(value, (float, np.floating)) \
        else str(value)
