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

    def predict_proba(self, rssi):
        """Return class probabilities, shape (n, k), for (n, n_aps) RSSI."""
        rssi = np.asarray(rssi, dtype=np.float32)
        if rssi.ndim != 2 or rssi.shape[1] != len(self.ap_ids):
            raise ValueError(f'expected RSSI of shape (n, {len(self.ap_ids)})'
                             f' (one column per model AP), got shape '
                             f'{rssi.shape}')
        inputs = self.scaler.transform(rssi)
        return mean_softmax([self._logits(inputs, layers)
                             for layers in self.members])

    @staticmethod
    def _logits(x, layers):
        for layer in layers:
            x = ACTIVATIONS[layer.activation](x @ layer.weight.T + layer.bias)
        return x

    def predict(self, rssi):
        """Return (building, floor, confidence, probabilities) arrays."""
        proba = self.predict_proba(rssi)
        best = proba.argmax(axis=1)
        return (self.classes[best, 0], self.classes[best, 1],
                proba[np.arange(len(best)), best], proba)

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
    of the whole first matrix. Same probabilities as
    :meth:`PlaceModel.predict_proba` up to float32 rounding.
    """

    def __init__(self, model):
        self.model = model
        empty = np.full((1, len(model.ap_ids)), np.nan, np.float32)
        self.blank = model.scaler.transform(empty)[0]
        self.first = [(np.ascontiguousarray(layers[0].weight.T),
                       layers[0].bias + layers[0].weight @ self.blank,
                       ACTIVATIONS[layers[0].activation])
                      for layers in model.members]
        self.rest = [[(np.ascontiguousarray(layer.weight.T), layer.bias,
                       ACTIVATIONS[layer.activation]) for layer in layers[1:]]
                     for layers in model.members]

    def __call__(self, rssi):
        """Return class probabilities (k,) for one (n_aps,) RSSI vector."""
        columns = np.flatnonzero(~np.isnan(rssi))
        delta = self.model.scaler.transform(rssi[columns], columns) - \
            self.blank[columns]
        logits = []
        for (first_t, first_bias, first_act), rest in zip(self.first,
                                                          self.rest):
            x = first_act(first_bias + delta @ first_t[columns])
            for weight_t, bias, activation in rest:
                x = activation(x @ weight_t + bias)
            logits.append(x)
        return mean_softmax(logits)
