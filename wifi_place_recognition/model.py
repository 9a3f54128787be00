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


@dataclass
class Layer:
    """A dense layer ``activation(x @ weight.T + bias)`` (torch layout)."""

    weight: np.ndarray  # (out, in)
    bias: np.ndarray    # (out,)
    activation: str


@dataclass
class PlaceModel:
    """Scaler + dense layers + softmax over (building, floor) classes."""

    ap_ids: tuple
    scaler: RssiScaler
    layers: list
    classes: np.ndarray           # int64 (k, 2): building, floor per output
    provenance: dict = field(default_factory=dict)

    def predict_proba(self, rssi):
        """Return class probabilities, shape (n, k), for (n, n_aps) RSSI."""
        x = self.scaler.transform(np.atleast_2d(rssi))
        for layer in self.layers:
            x = ACTIVATIONS[layer.activation](x @ layer.weight.T + layer.bias)
        x -= x.max(axis=1, keepdims=True)
        np.exp(x, out=x)
        x /= x.sum(axis=1, keepdims=True)
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
