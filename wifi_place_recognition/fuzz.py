"""
A seeded generator of malformed and random scans, for robustness tests.

Every kind of scan a faulty driver or a hostile peer could send:
unequal arrays, NaN and infinities, huge and tiny values, empty and
oversize arrays, non-ASCII and very long names, duplicate MACs, zero and
negative stamps, mixed with plausible scans of the model's APs.
"""

import numpy as np
from sensor_msgs.msg import JointState

KINDS = ('plausible', 'unequal', 'non_finite', 'extreme', 'empty',
         'oversize', 'odd_names', 'duplicates', 'odd_stamp')


def _message(names, rssi, rng):
    msg = JointState(name=list(names),
                     position=[float(v) for v in rssi])
    msg.header.stamp.sec = int(rng.integers(1, 2**31 - 1))
    msg.header.frame_id = 'fuzz'
    return msg


def fuzz_scan(kind, ap_ids, rng, oversize=100_000):
    """Return one JointState scan of the given kind."""
    k = int(rng.integers(1, 30))
    names = list(rng.choice(ap_ids, size=k))
    rssi = rng.uniform(-110, 0, size=k)
    if kind == 'unequal':
        rssi = rssi[:int(rng.integers(0, k))] if rng.random() < 0.5 else \
            np.append(rssi, rng.uniform(-110, 0, size=3))
    elif kind == 'non_finite':
        rssi[rng.integers(0, k)] = rng.choice([np.nan, np.inf, -np.inf])
    elif kind == 'extreme':
        rssi[rng.integers(0, k)] = rng.choice([1e308, -1e308, 1e-300,
                                               -1e-300, 1e6, -1e6, 0.0])
    elif kind == 'empty':
        names, rssi = [], []
    elif kind == 'oversize':
        names = [f'{i:012x}' for i in range(oversize)]
        rssi = np.full(oversize, -70.0)
    elif kind == 'odd_names':
        names = [rng.choice(['ñandú-☃-', 'x' * 10_000, '', ' ', '\t',
                             '00:00:00:00:00:00', 'é' * 300]) + str(i)
                 for i in range(k)]
    elif kind == 'duplicates':
        names = [names[0]] * k
    msg = _message(names, rssi, rng)
    if kind == 'odd_stamp':
        msg.header.stamp.sec = int(rng.choice([0, -1, -2**31]))
        msg.header.stamp.nanosec = int(rng.choice([0, 2**32 - 1]))
    return msg


def fuzz_scans(ap_ids, count, seed=0, oversize_every=2000):
    """Yield ``count`` scans of all kinds; one oversize per ``oversize_every``."""
    rng = np.random.default_rng(seed)
    kinds = [k for k in KINDS if k != 'oversize']
    for i in range(count):
        kind = 'oversize' if i % oversize_every == oversize_every - 1 else \
            kinds[int(rng.integers(0, len(kinds)))]
        yield fuzz_scan(kind, list(ap_ids), rng)
