"""
A model's position references rebuilt from new scans, without torch.

The network answers the building and floor; the position is a k-NN among
reference scans (:class:`.locator.Locator`). :func:`with_references`
returns a copy of a model whose references are other scans (the survey
plus what a robot recorded since) on the model's own AP columns: the
network's input is fixed, so APs it lacks are ignored (as the node ignores
them) and none is added or removed. The model's locator choices are kept
(k, signal, distance, the group each class searches, each class's
calibrated sigma), and so are its network, temperature, coverage model,
tracking and fusion sections. Scans of a building/floor the model does
not know, or that hear none of its APs, are left out and counted. Numpy
only.
"""

from collections import Counter
import copy
from dataclasses import replace
import time

import numpy as np

from .evaluation import align
from .locator import Locator
from .model import PlaceModel

#: The provenance key of a references-only update.
PROVENANCE = 'references_update'


def with_references(model, parts, base):
    """
    Return (a copy of ``model`` with new references, what each part gave).

    ``parts``: fingerprints with positions (``ap_ids``, ``rssi``,
    ``building``, ``floor``, ``position``, ``source``, ``sha256``),
    together the references; ``base``: the model's name (its file), for
    the provenance. Each part's entry: its source and SHA-256, its scans,
    those used and those left out (``unknown_place``: a count per
    ``B{building}F{floor}``; ``no_known_ap``).
    """
    if not isinstance(model, PlaceModel):
        raise TypeError(f'model: expected a PlaceModel, not '
                        f'{type(model).__name__}')
    if model.position is None:
        raise ValueError('the model has no position output: it has no '
                         'references to update')
    if not isinstance(base, str) or not base:
        raise ValueError(f'base {base!r}: name the model (its file)')
    if not parts:
        raise ValueError('no scans given for the references')
    index = {(int(b), int(f)): c for c, (b, f) in enumerate(model.classes)}
    rssi, y, xy, given = [], [], [], []
    for part in parts:
        _check(part)
        mapped = align(model, part)
        c = np.array([index.get(key, -1) for key in
                      zip(part.building.tolist(), part.floor.tolist())],
                     np.int64)
        heard = np.isfinite(mapped).any(axis=1)
        use = (c >= 0) & heard
        unknown = Counter(f'B{b}F{f}' for b, f in zip(
            part.building[c < 0].tolist(), part.floor[c < 0].tolist()))
        given.append({'source': part.source, 'sha256': part.sha256,
                      'scans': len(part), 'used': int(use.sum()),
                      'left_out': {'unknown_place': dict(sorted(
                          unknown.items())), 'no_known_ap': int(
                              ((c >= 0) & ~heard).sum())}})
        rssi.append(mapped[use])
        y.append(c[use])
        xy.append(np.asarray(part.position, np.float64)[use])
    y = np.concatenate(y)
    old = model.position
    empty = [name for c, name in enumerate(model.class_names)
             if old.group[c] not in old.group[y]]
    if empty:
        raise ValueError(f'no reference scan for {", ".join(empty)}: the '
                         f'scans must cover every building/floor the model '
                         f'searches')
    position = Locator.build(np.concatenate(rssi), y, np.concatenate(xy),
                             len(model.classes), old.neighbours, old.sigma,
                             old.columns, old.representation, old.metric,
                             old.group, old.edge_sigma, old.usual_mismatch)
    provenance = copy.deepcopy(model.provenance)
    provenance[PROVENANCE] = {
        'kind': 'references only: the network, its APs, temperature, '
                'coverage model and locator choices of the model kept',
        'from': base, 'references': len(y), 'parts': given,
        'created': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())}
    return replace(model, scaler=copy.deepcopy(model.scaler),
                   members=copy.deepcopy(model.members), position=position,
                   provenance=provenance), given


def _check(part):
    """Refuse scans that cannot be references, naming the fault."""
    n = len(part.building)
    where = part.source or 'scans'
    if part.position is None:
        raise ValueError(f'{where}: no positions (X, Y); references need '
                         f'them')
    shapes = {'rssi': (np.shape(part.rssi), (n, len(part.ap_ids))),
              'floor': (np.shape(part.floor), (n,)),
              'position': (np.shape(part.position), (n, 2))}
    for name, (shape, expected) in shapes.items():
        if shape != expected:
            raise ValueError(f'{where}: {name} of shape {shape}, expected '
                             f'{expected}')
    bad = np.flatnonzero(~np.isfinite(part.position).all(axis=1))
    if len(bad):
        raise ValueError(f'{where}: scan {bad[0] + 1} has position '
                         f'{part.position[bad[0]].tolist()}, not finite')
