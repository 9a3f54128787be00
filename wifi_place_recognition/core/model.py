"""The frozen place model: preprocessing plus a numpy forward pass (no torch)."""

from dataclasses import dataclass, field

import numpy as np

from .preprocessing import RssiScaler


def _relu(x):
    return np.maximum(x, 0.0, out=x)


def _elu(x):
    return np.where(x > 0, x, np.expm1(np.minimum(x, 0.0)))


def _identity(x):
    return x


#: Activation name -> numpy function; training uses the same names.
ACTIVATIONS = {'relu': _relu, 'elu': _elu, 'linear': _identity,
               'tanh': np.tanh}


#: Radius of the 95 % circle of a 2-D isotropic Gaussian, in sigmas.
R95 = float(np.sqrt(-2 * np.log(0.05)))


def mean_softmax(member_logits):
    """Return the mean over members of softmax(logits) along the last axis."""
    total = 0.0
    for x in member_logits:
        x = np.exp(x - x.max(axis=-1, keepdims=True))
        total = total + x / x.sum(axis=-1, keepdims=True)
    return total / len(member_logits)


@dataclass
class Layer:
    """A dense layer ``activation(x @ weight.T + bias)`` (torch layout)."""

    weight: np.ndarray  # (out, in)
    bias: np.ndarray    # (out,)
    activation: str


@dataclass
class PositionHead:
    """
    X, Y in metres from each member's encoder output, with a sigma.

    Each member's first ``trunk`` layers (its encoder) feed ``heads[m]``,
    whose two outputs are ``(xy - origin) / scale``; the position is the
    mean over members. ``sigma[c]`` (metres, per predicted class c) was
    calibrated on held-out scans so that the circle of radius 2.45 sigma
    (a 95 % circle for a 2-D Gaussian) holds 95 % of them.
    """

    origin: np.ndarray            # float64 (2,): metres, in ``columns``
    scale: float                  # metres per network output unit
    trunk: int                    # member layers shared with the classes
    heads: list                   # per member: list of Layer -> 2 outputs
    sigma: np.ndarray             # float32 (k,): metres per class
    columns: tuple = ('X', 'Y')   # the data's coordinate columns

    def to_metres(self, outputs):
        """Return float64 positions from mean head outputs (..., 2)."""
        return self.origin + self.scale * np.asarray(outputs, np.float64)


def _run(x, layers):
    for layer in layers:
        x = ACTIVATIONS[layer.activation](x @ layer.weight.T + layer.bias)
    return x


@dataclass
class PlaceModel:
    """
    Scaler + networks of dense layers + softmax over (building, floor).

    ``members`` holds one or more networks (lists of :class:`Layer`); the
    probabilities are the mean of their softmax outputs.
    """

    ap_ids: tuple
    scaler: RssiScaler
    members: list
    classes: np.ndarray           # int64 (k, 2): building, floor per output
    provenance: dict = field(default_factory=dict)
    tracking: object = None       # TrackingParams from the file, or None
    position: PositionHead = None  # None: a classifier only

    def outputs(self, rssi):
        """Return (probabilities (n, k), position head outputs or None)."""
        rssi = np.asarray(rssi, dtype=np.float32)
        if rssi.ndim != 2 or rssi.shape[1] != len(self.ap_ids):
            raise ValueError(f'expected RSSI of shape (n, {len(self.ap_ids)})'
                             f' (one column per model AP), got shape '
                             f'{rssi.shape}')
        inputs = self.scaler.transform(rssi)
        logits, places = [], []
        for m, layers in enumerate(self.members):
            if self.position is None:
                logits.append(_run(inputs, layers))
                continue
            trunk = self.position.trunk
            encoded = _run(inputs, layers[:trunk])
            logits.append(_run(encoded, layers[trunk:]))
            places.append(_run(encoded, self.position.heads[m]))
        return mean_softmax(logits), (np.mean(places, axis=0)
                                      if places else None)

    def predict_proba(self, rssi):
        """Return class probabilities, shape (n, k), for (n, n_aps) RSSI."""
        return self.outputs(rssi)[0]

    def predict(self, rssi):
        """Return (building, floor, confidence, probabilities) arrays."""
        proba = self.predict_proba(rssi)
        best = proba.argmax(axis=1)
        return (self.classes[best, 0], self.classes[best, 1],
                proba[np.arange(len(best)), best], proba)

    def locate(self, rssi):
        """
        Return (class probabilities, xy metres (n, 2), sigma metres (n,)).

        Raises ValueError for a model without a position head.
        """
        if self.position is None:
            raise ValueError('this model has no position output (it was '
                             'trained without coordinates)')
        proba, heads = self.outputs(rssi)
        return (proba, self.position.to_metres(heads),
                self.position.sigma[proba.argmax(axis=1)].astype(np.float64))

    @property
    def class_names(self):
        """Return ``B{building}F{floor}`` for every output."""
        return [f'B{b}F{f}' for b, f in self.classes]


class ScanForward:
    """
    The forward pass of one scan, touching only the detected APs.

    An undetected AP's network input is a constant, so its part of the
    first layer is folded into the bias once; a scan (which detects a few
    dozen of hundreds of APs) then costs a gather of those columns instead
    of the whole first matrix. The members of an ensemble share one
    architecture, so each layer runs for all of them in one batched
    product. Same probabilities as :meth:`PlaceModel.predict_proba` up to
    float32 rounding.
    """

    def __init__(self, model):
        self.model = model
        members = model.members
        n = len(members)
        empty = np.full((1, len(model.ap_ids)), np.nan, np.float32)
        self.blank = model.scaler.transform(empty)[0]
        first = [layers[0] for layers in members]
        self.width = first[0].weight.shape[0]
        # every member's first layer side by side: one gather, one product
        self.first_t = np.ascontiguousarray(np.concatenate(
            [layer.weight.T for layer in first], axis=1))
        self.first_bias = np.concatenate(
            [layer.bias + layer.weight @ self.blank for layer in first])
        self.first_act = ACTIVATIONS[first[0].activation]
        self.rest = [self._stacked([layers[i] for layers in members])
                     for i in range(1, len(members[0]))]
        position = model.position
        self.trunk = position.trunk if position else 0
        self.heads = [] if position is None else [
            self._stacked([head[i] for head in position.heads])
            for i in range(len(position.heads[0]))]
        self.shape = (n, 1, self.width)

    @staticmethod
    def _stacked(layers):
        """Return one layer of every member as batched (n, in, out) arrays."""
        return (np.stack([layer.weight.T for layer in layers]),
                np.stack([layer.bias for layer in layers])[:, None, :],
                ACTIVATIONS[layers[0].activation])

    def __call__(self, rssi):
        """Return class probabilities (k,) for one (n_aps,) RSSI vector."""
        return self.outputs(rssi)[0]

    def outputs(self, rssi):
        """Return (probabilities (k,), the position head's 2 outputs or None)."""
        columns = np.flatnonzero(~np.isnan(rssi))
        delta = self.model.scaler.transform(rssi[columns], columns) - \
            self.blank[columns]
        x = self.first_act(self.first_bias + delta @ self.first_t[columns])
        x = x.reshape(self.shape)
        place = None
        for done, (weight_t, bias, activation) in enumerate(self.rest, 1):
            if done == self.trunk:
                place = self._head(x)
            x = activation(np.matmul(x, weight_t) + bias)
        return mean_softmax(x[:, 0, :]), place

    def _head(self, x):
        for weight_t, bias, activation in self.heads:
            x = activation(np.matmul(x, weight_t) + bias)
        return x[:, 0, :].mean(axis=0)
