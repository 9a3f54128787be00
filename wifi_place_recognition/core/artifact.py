"""
The model file: a numpy ``.npz`` of float32 arrays plus a JSON header.

Nothing in it is executable: arrays are read with ``allow_pickle=False``
and the header is JSON stored as a uint8 array. A SHA-256 over the header
and every array detects truncation, bit flips and tampering. Files are
written atomically (temporary file, fsync, rename), so a crash mid-write
leaves the previous file intact.
"""

import ctypes
import hashlib
import json
import zipfile
from pathlib import Path

import numpy as np

from .archive import ZIP_ERRORS
from .atomic import atomic_write
from .coverage import CoverageModel
from .locator import (LEVELS, Locator, MAX_EDGE_SIGMA_M, MAX_MISMATCH_DB,
                      METRICS)
from .model import ACTIVATIONS, Layer, PlaceModel
from .preprocessing import RssiScaler, SIGNALS
from .filter.particles import FusionParams
from .tracking import TrackingParams

FORMAT = 'wifi_place_recognition/model'
#: 2: the locator's references as int8 blocks; 3: the locator's own signal
#: representation, distance and reference groups (floor or building), and
#: position-only (one-class) models; 4: the probabilities' calibration
#: (temperature).
SCHEMA_VERSION = 4
#: Versions this one reads: a schema 3 file has no calibration section and
#: gets :data:`UNCALIBRATED` (its probabilities as its networks give them).
READABLE_SCHEMAS = (3, 4)
UNCALIBRATED = 1.0
#: Temperatures a file may hold.
TEMPERATURE_RANGE = (0.01, 100.0)
MAX_FILE_BYTES = 256 << 20
MAX_UNPACKED_BYTES = 1 << 30
#: The locator's arrays in the file (all float32: indices below 2**24 and
#: int8 codes are exact).
LOCATOR_ARRAYS = ('group_start', 'group', 'ap_start', 'ap_column', 'scale',
                  'codes', 'norms', 'xy', 'sigma')
MAX_INDEX = 1 << 24


class ModelFileError(ValueError):
    """A model file that cannot be loaded; the message says why."""


def _digest(header, arrays):
    h = hashlib.sha256(json.dumps(header, sort_keys=True).encode())
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(f'{name}|{a.dtype.str}|{a.shape}'.encode())
        h.update(a.tobytes())
    return h.hexdigest()


def save_model(model, path):
    """
    Write ``model`` to ``path`` atomically.

    Raises ValueError, and writes nothing, for a model that
    :func:`load_model` would refuse (e.g. weights that are not finite: a
    training that diverged).
    """
    arrays = dict(model.scaler.arrays())
    members = [_layer_specs(layers, f'member{m}.layer', arrays)
               for m, layers in enumerate(model.members)]
    header = {'format': FORMAT, 'schema_version': SCHEMA_VERSION,
              'ap_ids': list(model.ap_ids),
              'classes': np.asarray(model.classes).tolist(),
              'preprocessing': model.scaler.params(), 'members': members,
              'provenance': model.provenance,
              'calibration': {'temperature': float(model.temperature)}}
    if model.tracking is not None:
        header['tracking'] = model.tracking.to_dict()
    if model.fusion is not None:
        header['fusion'] = model.fusion.to_dict()
    if model.coverage is not None:
        header['coverage'] = model.coverage.to_dict()
    if model.position is not None:
        pos = model.position
        if max(len(pos.xy), len(pos.ap_column)) >= MAX_INDEX:
            raise ValueError(f'too many reference scans or rows for the '
                             f'model file ({len(pos.xy)}, '
                             f'{len(pos.ap_column)}; at most 2**24)')
        for name in LOCATOR_ARRAYS:
            arrays[f'position.{name}'] = np.asarray(getattr(pos, name),
                                                    np.float32)
        header['position'] = {'origin': [float(v) for v in pos.origin],
                              'neighbours': pos.neighbours,
                              'columns': list(pos.columns), 'units': 'm',
                              'representation': pos.representation,
                              'metric': pos.metric,
                              'edge_sigma_m': pos.edge_sigma,
                              'usual_mismatch_db': pos.usual_mismatch}
    unpacked = sum(a.nbytes for a in arrays.values())
    if unpacked > MAX_UNPACKED_BYTES:
        raise ValueError(f'the model would unpack to {unpacked} bytes, more '
                         f'than a model file may ({MAX_UNPACKED_BYTES}): '
                         f'fewer reference scans or APs')
    try:
        _build(json.loads(json.dumps(header)), arrays)
    except (KeyError, TypeError, ValueError, ArithmeticError) as exc:
        raise ValueError(f'the model is not valid, so {path} was not '
                         f'written: {exc}') from None
    header['sha256'] = _digest(header, arrays)
    arrays['header'] = np.frombuffer(json.dumps(header).encode(), np.uint8)
    with atomic_write(path) as f:
        np.savez_compressed(f, **arrays)


def _layer_specs(layers, prefix, arrays):
    """Put ``layers``' arrays into ``arrays``; return their header specs."""
    specs = []
    for i, layer in enumerate(layers):
        name = f'{prefix}{i}'
        arrays[f'{name}.weight'] = layer.weight.astype(np.float32)
        arrays[f'{name}.bias'] = layer.bias.astype(np.float32)
        specs.append({'weight': f'{name}.weight', 'bias': f'{name}.bias',
                      'activation': layer.activation})
    return specs


def load_model(path):
    """Load and fully validate a model file; raise :class:`ModelFileError`."""
    path = Path(path)
    try:
        header, arrays = _read(path)
        return _build(header, arrays)
    except ModelFileError as exc:
        raise ModelFileError(f'{path}: {exc}') from None
    except (KeyError, TypeError, ValueError, ArithmeticError) as exc:
        raise ModelFileError(f'{path}: malformed model file ({exc})') from None
    except RecursionError:      # reading or hashing the header
        raise ModelFileError(f'{path}: header nested too deeply: not a '
                             f'model file') from None
    finally:
        _release_freed_memory()


def _release_freed_memory():
    """
    Return freed heap memory to the system (glibc; elsewhere a no-op).

    Unpacking the file frees buffers several times the model's size, which
    the C heap would otherwise keep in the process's resident memory.
    """
    try:
        trim = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError, TypeError):   # not glibc, or Windows
        return
    trim(0)


def _read(path):
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise ModelFileError(f'cannot read: {exc.strerror}') from None
    if size == 0:
        raise ModelFileError('file is empty')
    if size > MAX_FILE_BYTES:
        raise ModelFileError(f'file is {size} bytes, more than a model '
                             f'file may be ({MAX_FILE_BYTES})')
    try:
        with zipfile.ZipFile(path) as zf:
            infos = zf.infolist()
            if sum(i.file_size for i in infos) > MAX_UNPACKED_BYTES:
                raise ModelFileError('unpacks to more than 1 GiB')
            names = [i.filename for i in infos]
            if not all(n.endswith('.npy') and '/' not in n for n in names):
                raise ModelFileError('unexpected members in the archive')
        with np.load(path, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except ModelFileError:
        raise
    except ZIP_ERRORS as exc:
        raise ModelFileError(f'not a model file, truncated or corrupt '
                             f'({str(exc) or type(exc).__name__})') from None
    except (OSError, ValueError) as exc:
        raise ModelFileError(f'not a model file or corrupt ({exc})') from None
    raw = arrays.pop('header', None)
    if raw is None or raw.dtype != np.uint8 or raw.ndim != 1:
        raise ModelFileError('no header: not a wifi_place_recognition model')
    try:
        header = json.loads(raw.tobytes().decode())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ModelFileError(f'header is not valid JSON ({exc})') from None
    if not isinstance(header, dict) or header.get('format') != FORMAT:
        raise ModelFileError('not a wifi_place_recognition model')
    if header.get('schema_version') not in READABLE_SCHEMAS:
        raise ModelFileError(f'schema version {header.get("schema_version")!r}'
                             f' is not supported (this version reads '
                             f'{" and ".join(map(str, READABLE_SCHEMAS))}): '
                             f'retrain the model with this version\'s '
                             f'train_model')
    expected = header.pop('sha256', None)
    if expected != _digest(header, arrays):
        raise ModelFileError('checksum mismatch: the file was modified or '
                             'damaged')
    return header, arrays


def _build(header, arrays):
    for name, a in arrays.items():
        if a.dtype != np.float32:
            raise ModelFileError(f'array {name} has dtype {a.dtype}, '
                                 f'expected float32')
    ap_ids = tuple(header['ap_ids'])
    if not ap_ids or not all(isinstance(a, str) for a in ap_ids):
        raise ModelFileError('ap_ids must be a non-empty list of strings')
    if len(set(ap_ids)) != len(ap_ids):
        raise ModelFileError('ap_ids has duplicates')
    classes = np.asarray(header['classes'], dtype=np.int64)
    if classes.ndim != 2 or classes.shape[1] != 2 or len(classes) < 1:
        raise ModelFileError('classes must be a list of [building, floor]')
    scaler = RssiScaler.restore(header['preprocessing'], arrays)
    for name in ('scaler.mean', 'scaler.std'):
        if arrays[name].shape != (len(ap_ids),):
            raise ModelFileError(f'{name} has shape {arrays[name].shape}, '
                                 f'expected ({len(ap_ids)},) for '
                                 f'{len(ap_ids)} APs')
        if not np.isfinite(arrays[name]).all():
            raise ModelFileError(f'{name} has values that are not finite')
    members = [_layers(specs, arrays, len(ap_ids), len(classes))
               for specs in header['members']]
    if not members and len(classes) > 1:
        raise ModelFileError('the model has no network')
    if len({tuple((layer.weight.shape, layer.activation) for layer in m)
            for m in members}) > 1:
        raise ModelFileError('the networks of the ensemble differ in shape')
    position = _position(header, arrays, len(ap_ids), len(classes))
    if not members and position is None:
        raise ModelFileError('a one-class model without a network must have '
                             'a position output')
    if position is None and 'coverage' in header:
        raise ModelFileError('a coverage section needs a position output')
    provenance = header.get('provenance', {})
    if not isinstance(provenance, dict):
        raise ModelFileError(f'provenance must be an object, not '
                             f'{type(provenance).__name__}')
    return PlaceModel(ap_ids, scaler, members, classes, provenance,
                      _section(header, TrackingParams),
                      position, _temperature(header),
                      _section(header, FusionParams),
                      _section(header, CoverageModel))


def _temperature(header):
    """Return the probabilities' temperature (schema 3: uncalibrated)."""
    if header['schema_version'] == 3:
        return UNCALIBRATED
    t = header['calibration']['temperature']
    low, high = TEMPERATURE_RANGE
    if isinstance(t, bool) or not isinstance(t, (int, float)) or \
            not low <= t <= high:
        raise ModelFileError(f'calibration: temperature {t!r} is not a '
                             f'number in [{low:g}, {high:g}]')
    return float(t)


def _section(header, kind):
    """Return a model file's optional section as ``kind`` (None: absent)."""
    if kind.SECTION not in header:
        return None
    try:
        return kind.from_dict(header[kind.SECTION])
    except (TypeError, ValueError) as exc:
        raise ModelFileError(f'{kind.SECTION} section: {exc}') from None


def _position(header, arrays, n_aps, n_classes):
    """Return the optional position locator (None: a classifier only)."""
    if 'position' not in header:
        return None
    spec = header['position']
    origin = np.asarray(spec['origin'], np.float64)
    columns, k = spec['columns'], spec['neighbours']
    if origin.shape != (2,) or not np.isfinite(origin).all() or \
            not (isinstance(k, int) and k > 0) or len(columns) != 2 or \
            not all(isinstance(c, str) for c in columns):
        raise ModelFileError('position: origin must be two finite numbers, '
                             'neighbours a positive integer and columns two '
                             'names')
    if spec['representation'] not in SIGNALS or \
            spec['metric'] not in METRICS:
        raise ModelFileError(f'position: representation must be one of '
                             f'{SIGNALS} and metric one of {METRICS}')
    # older files: not widened at the edge, no usual mismatch
    edge = _optional_number(spec, 'edge_sigma_m', MAX_EDGE_SIGMA_M)
    usual = _optional_number(spec, 'usual_mismatch_db', MAX_MISMATCH_DB)
    a = {name: arrays[f'position.{name}'] for name in LOCATOR_ARRAYS}
    if not all(np.isfinite(v).all() for v in a.values()) or \
            not all((a[i] == np.round(a[i])).all() and (a[i] >= 0).all()
                    and (a[i] < MAX_INDEX).all()
                    for i in ('group_start', 'group', 'ap_start',
                              'ap_column')):
        raise ModelFileError('position: non-finite values or indices that '
                             'are not counts below 2**24')
    group_start, group, ap_start, ap_column = (
        a[i].astype(np.int64) for i in ('group_start', 'group', 'ap_start',
                                        'ap_column'))
    if group.shape != (n_classes,) or group.max() >= n_classes:
        raise ModelFileError('position: one group per class, each a class '
                             'index, expected')
    n_groups = int(group.max()) + 1
    n_refs, n_rows = len(a['norms']), len(a['ap_column'])
    shapes_ok = (group_start.shape == ap_start.shape == (n_groups + 1,)
                 and a['norms'].ndim == a['ap_column'].ndim == 1
                 and a['scale'].shape == (n_rows,) and
                 a['xy'].shape == (n_refs, 2) and
                 a['sigma'].shape == (n_classes,))
    if not shapes_ok or group_start[0] != 0 or group_start[-1] != n_refs \
            or ap_start[0] != 0 or ap_start[-1] != n_rows or \
            (np.diff(group_start) < 0).any() or (np.diff(ap_start) < 0).any():
        raise ModelFileError('position: reference arrays of wrong shape or '
                             'inconsistent index')
    if a['codes'].shape != (int(np.diff(group_start) @ np.diff(ap_start)),) \
            or (np.abs(a['codes']) > LEVELS).any() or \
            (a['codes'] != np.round(a['codes'])).any():
        raise ModelFileError(f'position: codes must be integers in '
                             f'[-{LEVELS}, {LEVELS}], one per row and '
                             f'reference of each group')
    for g in range(n_groups):
        mine = ap_column[ap_start[g]:ap_start[g + 1]]
        if (mine >= n_aps).any() or (np.diff(mine) <= 0).any():
            raise ModelFileError(f'position: the AP columns of group {g} '
                                 f'are not ascending model columns')
    if (a['sigma'] < 0).any() or (a['scale'] < 0).any():
        raise ModelFileError('position: sigma and scales must be >= 0')
    return Locator(origin, group_start, ap_start, ap_column, a['scale'],
                   a['codes'].astype(np.int8), a['norms'], a['xy'],
                   a['sigma'], group, n_aps, k, tuple(columns),
                   spec['representation'], spec['metric'], float(edge),
                   float(usual))


def _optional_number(spec, key, top):
    """Return the position section's ``key`` (0 if absent), in [0, top]."""
    value = spec.get(key, 0.0)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            not 0 <= value <= top:
        raise ModelFileError(f'position: {key} must be a number in [0, '
                             f'{top:g}], not {value!r}')
    return value


def _layers(specs, arrays, n_inputs, n_outputs):
    layers, width = [], n_inputs
    for spec in specs:
        w, b = arrays[spec['weight']], arrays[spec['bias']]
        if spec['activation'] not in ACTIVATIONS:
            raise ModelFileError(f'unknown activation {spec["activation"]!r}')
        if w.ndim != 2 or w.shape[1] != width or b.shape != (w.shape[0],):
            raise ModelFileError(f'layer {spec["weight"]} has shape '
                                 f'{w.shape}, expected (*, {width})')
        if not (np.isfinite(w).all() and np.isfinite(b).all()):
            raise ModelFileError(f'layer {spec["weight"]} has values that '
                                 f'are not finite (a training that '
                                 f'diverged?)')
        layers.append(Layer(w, b, spec['activation']))
        width = w.shape[0]
    if width != n_outputs:
        raise ModelFileError(f'a network has {width} outputs, expected '
                             f'{n_outputs}')
    return layers
