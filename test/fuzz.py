"""
Faulty and hostile inputs, for the robustness tests and benchmark.

Seeded malformed scans (unequal arrays, NaN and infinities, huge and tiny
values, empty and oversize arrays, non-ASCII and very long names, duplicate
MACs, zero and negative stamps, mixed with plausible scans), bad and
hostile model files, and a writer to kill mid-write.
"""

import io
import json
from pathlib import Path
import pickle
import zipfile

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


class _Payload:
    """Pickles to a call that creates ``marker`` when unpickled."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, 'w'))


def hostile_model_files(valid, folder, marker):
    """
    Write bad model files derived from the ``valid`` one; return {kind: path}.

    Kinds: truncated, empty, bit-flipped, a damaged deflate stream, a zip
    version no reader supports, a header nested too deeply to parse; wrong
    schema, wrong AP count, provenance not an object, weights not finite
    (each with a matching checksum); and two pickle payloads that would
    create ``marker`` if anything unpickled them.
    """
    # the checksum, to forge a consistent file
    from wifi_place_recognition.core.artifact import _digest
    folder = Path(folder)
    data = Path(valid).read_bytes()
    files = {}

    def write(kind, content):
        files[kind] = folder / f'{kind}.npz'
        files[kind].write_bytes(content)

    write('truncated', data[:len(data) // 2])
    write('empty', b'')
    flipped = bytearray(data)
    flipped[len(data) // 3] ^= 0x10
    write('bit_flipped', bytes(flipped))
    damaged, version = bytearray(data), bytearray(data)
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        info = max(zf.infolist(), key=lambda i: i.compress_size)
    local = info.header_offset    # 30 fixed bytes, then name and extra
    start = local + 30 + int.from_bytes(data[local + 26:local + 28],
                                        'little') + \
        int.from_bytes(data[local + 28:local + 30], 'little')
    damaged[start] = 0xff    # the first deflate block: a reserved type
    write('damaged_deflate', bytes(damaged))
    central = version.find(b'PK\x01\x02')
    version[central + 6] = 136    # "version needed to extract": 13.6
    write('unsupported_zip_version', bytes(version))
    np.savez(folder / 'deep_header.npz', header=np.frombuffer(
        b'[' * 100000 + b']' * 100000, np.uint8))
    files['deep_header'] = folder / 'deep_header.npz'
    write('pickle', pickle.dumps(_Payload(marker)))
    buf = io.BytesIO()
    np.save(buf, np.array([_Payload(marker)], dtype=object),
            allow_pickle=True)
    with zipfile.ZipFile(folder / 'pickle_in_npz.npz', 'w') as zf:
        zf.writestr('header.npy', buf.getvalue())
    files['pickle_in_npz'] = folder / 'pickle_in_npz.npz'
    with np.load(valid, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    header = json.loads(arrays.pop('header').tobytes())
    weight = header['members'][0][0]['weight']
    for kind, change, arrays_change in (
            ('wrong_schema', {'schema_version': 99}, {}),
            ('wrong_ap_count', {'ap_ids': header['ap_ids'][:-1]}, {}),
            ('provenance_not_an_object', {'provenance': []}, {}),
            ('weights_not_finite', {},
             {weight: np.full_like(arrays[weight], np.nan)})):
        forged = {k: v for k, v in header.items() if k != 'sha256'}
        forged.update(change)
        forged_arrays = {**arrays, **arrays_change}
        forged['sha256'] = _digest(forged, forged_arrays)
        files[kind] = folder / f'{kind}.npz'
        np.savez(files[kind], header=np.frombuffer(
            json.dumps(forged).encode(), np.uint8), **forged_arrays)
    return files


def rewrite_forever(path, n_aps=2000):
    """
    Save a large model to ``path`` again and again (for kill tests).

    Prints the number of each completed write.
    """
    from wifi_place_recognition.core.artifact import save_model
    from wifi_place_recognition.core.model import Layer, PlaceModel
    from wifi_place_recognition.core.preprocessing import RssiScaler
    scaler = RssiScaler().fit(np.full((2, n_aps), -60.0))
    layers = [Layer(np.ones((n_aps, n_aps), np.float32),
                    np.zeros(n_aps, np.float32), 'relu'),
              Layer(np.ones((3, n_aps), np.float32),
                    np.zeros(3, np.float32), 'linear')]
    ap_ids = tuple(f'ap{j}' for j in range(n_aps))
    classes = np.array([[0, 0], [0, 1], [1, 0]])
    write = 0
    while True:
        write += 1
        save_model(PlaceModel(ap_ids, scaler, [layers], classes,
                              {'write': write}), path)
        print(write, flush=True)
