"""The frozen place model: preprocessing plus a numpy forward pass (no torch)."""

from dataclasses import dataclass, field

import numpy as np

from .coverage import CoverageModel, features, unheard_share
from .locator import Locator
from .preprocessing import RssiScaler, signal
from .filter.particles import FusionParams
from .tracking import TrackingParams


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
    """Return the mean over members (first axis) of softmax(logits)."""
    x = np.asarray(member_logits)
    x = np.exp(x - np.maximum.reduce(x, axis=-1, keepdims=True))
    x /= np.add.reduce(x, axis=-1, keepdims=True)
    return np.add.reduce(x, axis=0) / len(x)


def tempered(proba, temperature):
    """
    Return class probabilities (last axis) sharpened or softened by T.

    proba ** (1 / T), renormalised: the softmax of log(proba) / T. It
    keeps every scan's order of classes (so its answer); T > 1 lowers the
    top probability, T = 1 returns ``proba`` itself.
    """
    if temperature == 1.0:
        return proba
    p = np.power(proba / proba.max(axis=-1, keepdims=True),
                 1.0 / temperature)
    return p / p.sum(axis=-1, keepdims=True)


@dataclass
class Layer:
    """A dense layer ``activation(x @ weight.T + bias)`` (torch layout)."""

    weight: np.ndarray  # (out, in)
    bias: np.ndarray    # (out,)
    activation: str


def _run(x, layers):
    for layer in layers:
        x = ACTIVATIONS[layer.activation](x @ layer.weight.T + layer.bias)
    return x


@dataclass
class PlaceModel:
    """
    Scaler + networks of dense layers + softmax over (building, floor).

    ``members`` holds one or more networks (lists of :class:`Layer`); the
    probabilities are the mean of their softmax outputs, tempered by
    ``temperature`` (:func:`tempered`; fitted on validation data, else 1).
    A model of one
    class has no network (``members`` empty): every scan is that class,
    with probability 1, and the model is there for its position output.
    """

    ap_ids: tuple
    scaler: RssiScaler
    members: list
    classes: np.ndarray           # int64 (k, 2): building, floor per output
    provenance: dict = field(default_factory=dict)
    tracking: TrackingParams = None  # from the file, or None
    position: Locator = None      # None: a classifier only
    temperature: float = 1.0      # of the probabilities (1: as computed)
    fusion: FusionParams = None   # odometry fusion, from the file, or None
    coverage: CoverageModel = None  # P(a scan is covered), or None
    blank: np.ndarray = field(init=False, repr=False)
    first_t: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        """
        Keep the inputs of a scan that detects nothing (the reference).

        The members' first layers are stored side by side, transposed
        (``first_t``: one row per AP, what a scan's forward pass gathers);
        each member's first weight becomes a view into it, not a copy. A
        model is not changed after it is built (its forward pass keeps
        these arrays).
        """
        self.blank = self.scaler.blank()
        if not self.members:
            if len(self.classes) != 1:
                raise ValueError('a model of several classes needs a network')
            self.first_t = np.zeros((len(self.ap_ids), 0), np.float32)
            return
        firsts = [layers[0] for layers in self.members]
        width = firsts[0].weight.shape[0]
        if any(layer.weight.shape[0] != width for layer in firsts):
            raise ValueError('the networks of the ensemble differ in shape')
        self.first_t = np.ascontiguousarray(np.concatenate(
            [layer.weight.T for layer in firsts], axis=1))
        for m, layer in enumerate(firsts):
            layer.weight = self.first_t[:, m * width:(m + 1) * width].T

    def predict_proba(self, rssi):
        """Return class probabilities, shape (n, k), for (n, n_aps) RSSI."""
        inputs = self._inputs(rssi)
        if not self.members:
            return np.ones((len(inputs), 1))
        return tempered(mean_softmax([_run(inputs, layers)
                                      for layers in self.members]),
                        self.temperature)

    def _inputs(self, rssi):
        rssi = np.asarray(rssi, dtype=np.float32)
        if rssi.ndim != 2 or rssi.shape[1] != len(self.ap_ids):
            raise ValueError(f'expected RSSI of shape (n, {len(self.ap_ids)})'
                             f' (one column per model AP), got shape '
                             f'{rssi.shape}')
        return self.scaler.transform(rssi)

    def predict(self, rssi):
        """Return (building, floor, confidence, probabilities) arrays."""
        proba = self.predict_proba(rssi)
        best = proba.argmax(axis=1)
        return (self.classes[best, 0], self.classes[best, 1],
                proba[np.arange(len(best)), best], proba)

    def sparse(self, rssi):
        """Return (columns, inputs) of one (n_aps,) scan's detected APs."""
        columns = np.flatnonzero(~np.isnan(rssi))
        return columns, self.relative(columns, rssi[columns])

    def relative(self, columns, rssi):
        """
        Return the inputs of readings ``rssi`` (dBm) of AP ``columns``.

        They are relative to a scan that detects nothing: what the forward
        pass and the position search work on.
        """
        return self.scaler.transform(rssi, columns) - self.blank[columns]

    def predict_positions(self, rssi, coverage=False, widened=True,
                          unknown=None):
        """
        Return (class probabilities, xy metres (n, 2), sigma metres (n,)).

        The batch form of :meth:`locate`: the sigma of the 95 % circle, or
        with ``widened`` false the k-NN's; with ``coverage``, each scan's
        probability of being covered (n,) and its mismatch (n) too.
        ``unknown``: how many more
        APs each scan heard that the model does not know (default none;
        :func:`.evaluation.unknown_aps`).

        Raises ValueError for a model without a position output.
        """
        if self.position is None:
            raise ValueError('this model has no position output (it was '
                             'trained without coordinates)')
        proba = self.predict_proba(rssi)
        best = proba.argmax(axis=1)
        xy = np.empty((len(best), 2))
        sigma, covered = np.empty(len(best)), np.full(len(best), np.nan)
        mismatch = np.empty(len(best))
        unknown = np.zeros(len(best), np.int64) if unknown is None else \
            np.asarray(unknown, np.int64)
        for i, (row, c) in enumerate(zip(np.asarray(rssi, np.float32), best)):
            columns = np.flatnonzero(~np.isnan(row))
            xy[i], circle, p, knn, mismatch[i] = self.locate(
                columns, row[columns], c, int(unknown[i]), coverage)
            sigma[i] = circle if widened else knn
            covered[i] = np.nan if p is None else p
        return (proba, xy, sigma) + ((covered, mismatch) if coverage else ())

    def locate(self, columns, rssi, c, unknown=0, coverage=True):
        """
        Return (xy (2,), sigma m, P(covered) or None, k-NN sigma m, mismatch).

        Of one scan of class c: ``sigma`` is its 95 % circle's (widened at
        the survey's edge and where it sounds unlike the survey,
        :meth:`.locator.Locator.widened`), the k-NN sigma the one before.
        ``columns``/``rssi``: its APs known to the
        model and their readings (dBm); ``unknown``: how many more it
        heard. The probability is None without a coverage model (or
        ``coverage`` false), and for a scan with no AP the model knows
        (the node rejects such a scan; offline it is not judged). The
        mismatch: how unlike its nearest references it sounds, over the
        survey's usual (:meth:`.locator.Locator.relative_mismatch`; NaN:
        not known).
        """
        locator = self.position
        distance = locator.distances(
            columns, signal(rssi, locator.representation), c)
        xy, knn = locator.weighted(distance, locator.neighbours, c)
        mismatch = locator.relative_mismatch(columns, rssi, c, distance)
        sigma = locator.widened(xy, knn, c, mismatch)
        if self.coverage is None or not coverage or not len(columns):
            return xy, sigma, None, knn, mismatch
        x = features(locator, distance, c,
                     unheard_share(locator, columns, c, unknown))
        return xy, sigma, float(self.coverage.probability(x)) \
            if np.isfinite(x).all() else None, knn, mismatch

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
    product. Same (tempered) probabilities as
    :meth:`PlaceModel.predict_proba` up to float32 rounding.
    """

    def __init__(self, model):
        self.model = model
        members = model.members
        if not members:     # one class: nothing to compute
            self.rest = None
            return
        first = [layers[0] for layers in members]
        self.width = first[0].weight.shape[0]
        self.first_t = model.first_t    # one gather, one product
        self.first_bias = np.concatenate(
            [layer.bias + layer.weight @ model.blank for layer in first])
        self.first_act = ACTIVATIONS[first[0].activation]
        self.rest = [self._stacked([layers[i] for layers in members])
                     for i in range(1, len(members[0]))]
        self.shape = (len(members), 1, self.width)

    @staticmethod
    def _stacked(layers):
        """Return one layer of every member as batched (n, in, out) arrays."""
        return (np.stack([layer.weight.T for layer in layers]),
                np.stack([layer.bias for layer in layers])[:, None, :],
                ACTIVATIONS[layers[0].activation])

    def __call__(self, columns, inputs):
        """
        Return class probabilities (k,) of one scan.

        ``columns``, ``inputs``: its detected APs, from
        :meth:`PlaceModel.relative` or :meth:`PlaceModel.sparse`.
        """
        if self.rest is None:
            return np.ones(1)
        x = self.first_act(self.first_bias + inputs @ self.first_t[columns])
        x = x.reshape(self.shape)
        for weight_t, bias, activation in self.rest:
            x = activation(np.matmul(x, weight_t) + bias)
        return tempered(mean_softmax(x[:, 0, :]), self.model.temperature)
