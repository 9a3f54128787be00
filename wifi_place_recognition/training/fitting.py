"""
Fitting one SAE + classifier network with torch.

The encoder is first trained as a stacked autoencoder on reconstruction;
the decoder is dropped, a classifier (softmax over every building/floor
class seen) is put on top and the whole network fine-tuned with
cross-entropy and Adam. Inputs stay sparse (the detected readings) and are
augmented anew each epoch.
"""

import contextlib

import numpy as np
import torch
from torch import nn

from ..core.preprocessing import RssiScaler
from .augment import ScanAugmenter
from .network import PlaceNet, SparseBatch


class _TorchState:
    """One network's own torch random stream and threads, entered per step."""

    def __init__(self, threads, seed):
        self.threads = threads
        with torch.random.fork_rng():
            torch.manual_seed(seed)
            self.rng = torch.get_rng_state()

    @contextlib.contextmanager
    def active(self):
        """Run inside with this stream (and threads); restore both after."""
        rng, threads = torch.get_rng_state(), torch.get_num_threads()
        torch.set_rng_state(self.rng)
        if self.threads:
            torch.set_num_threads(self.threads)
        try:
            yield
        finally:
            self.rng = torch.get_rng_state()
            torch.set_rng_state(rng)
            torch.set_num_threads(threads)


class _Inputs:
    """
    Network inputs of the training scans, augmented anew each epoch.

    Kept sparse (the detected readings, relative to a scan that detects
    nothing): an epoch's augmentation and scaling touch a few dozen
    readings per scan, and batches are :class:`SparseBatch`.
    """

    def __init__(self, rssi, scaler, config, seed):
        self.scaler = scaler
        self.n = len(rssi)
        self.blank = scaler.blank()
        self.augmenter = ScanAugmenter(rssi, config, seed) \
            if config.augmenting else None
        if self.augmenter is None:
            rows, cols = np.nonzero(~np.isnan(rssi))
            self.fixed = self._entries(rows, cols, rssi[rows, cols])
        self.batch_size = config.batch_for(self.n)
        self.generator = torch.Generator().manual_seed(seed)

    def _entries(self, rows, cols, dbm):
        """Return (row starts, columns, relative inputs) of sorted readings."""
        starts = np.searchsorted(rows, np.arange(self.n + 1))
        inputs = self.scaler.transform(dbm, cols) - self.blank[cols]
        return starts, cols.astype(np.int64), inputs.astype(np.float32)

    def epoch(self):
        """Yield (indices, SparseBatch) mini-batches of one shuffled epoch."""
        starts, cols, inputs = self.fixed if self.augmenter is None else \
            self._entries(*self.augmenter.readings())
        blank = torch.from_numpy(self.blank)
        order = torch.randperm(self.n, generator=self.generator)
        for idx in torch.split(order, self.batch_size):
            first = starts[idx.numpy()]
            lengths = starts[idx.numpy() + 1] - first
            entries = _ranges(first, lengths)
            offsets = np.cumsum(lengths) - lengths
            yield idx, SparseBatch(torch.from_numpy(cols[entries]),
                                   torch.from_numpy(offsets),
                                   torch.from_numpy(inputs[entries]), blank)


def _ranges(starts, lengths):
    """Return the indices of the ranges [start, start + length), joined."""
    offsets = np.cumsum(lengths) - lengths
    return np.repeat(starts - offsets, lengths) + np.arange(lengths.sum())


def _predicted(net, x, proba):
    """Return the classes ``net`` predicts for ``x`` (or probabilities)."""
    net.eval()
    with torch.no_grad():
        logits = net(x)
        out = torch.softmax(logits, dim=1) if proba else logits.argmax(dim=1)
    net.train()
    return out.numpy()


def fit_network(rssi, y, n_classes, scaler, config, epochs, seed,
                held_out=None, log=print, proba=False):
    """
    Train one network on ``rssi`` (NaN = not detected) and class indices.

    With ``held_out`` = (inputs, class indices), also return the held-out
    predicted classes after every epoch (with ``proba``, their class
    probabilities). Returns (net, [per-epoch arrays]).
    """
    predictions = []
    for _, (net, predicted) in zip(range(epochs), training_epochs(
            rssi, y, n_classes, scaler, config, seed, held_out, log, proba,
            epochs)):
        if predicted is not None:
            predictions.append(predicted)
    net.eval()
    return net, predictions


def training_epochs(rssi, y, n_classes, scaler, config, seed, held_out=None,
                    log=print, proba=False, most=None):
    """
    Train one network; yield (net, held-out predictions) after each epoch.

    As :func:`fit_network`, one fine-tuning epoch at a time, until the
    caller stops (``most`` only numbers the log lines). Each network keeps
    its own random stream, so networks trained side by side (the folds)
    are the same as trained one after the other.
    """
    state = _TorchState(config.threads, seed)
    with state.active():
        inputs = _Inputs(rssi, scaler, config, seed)
        net = PlaceNet(rssi.shape[1], n_classes, config)
        sae = net.autoencoder()
        optimiser = torch.optim.Adam(sae.parameters(),
                                     lr=config.learning_rate)
        for epoch in range(1, config.sae_epochs + 1):
            total = 0.0
            for _, x in inputs.epoch():
                optimiser.zero_grad()
                loss = nn.functional.mse_loss(sae(x), x.dense())
                loss.backward()
                optimiser.step()
                total += loss.item() * len(x.offsets)
            log(f'  sae epoch {epoch:3d}/{config.sae_epochs}  '
                f'reconstruction mse {total / len(rssi):.4f}')
        optimiser = torch.optim.Adam(net.parameters(),
                                     lr=config.learning_rate)
    epoch = 0
    while True:
        epoch += 1
        predicted = None
        with state.active():
            total = 0.0
            for idx, x in inputs.epoch():
                optimiser.zero_grad()
                loss = nn.functional.cross_entropy(net(x), y[idx])
                loss.backward()
                optimiser.step()
                total += loss.item() * len(idx)
            line = f'  epoch {epoch:3d}' + (f'/{most}' if most else '') + \
                f'  loss {total / len(rssi):.4f}'
            if held_out is not None:
                predicted = _predicted(net, held_out[0], proba)
                classes = predicted.argmax(axis=1) if proba else predicted
                right = (classes == held_out[1].numpy()).mean()
                line += f'  held-out building+floor {right:.4f}'
        log(line)
        yield net, predicted


def best_epoch(mean, window=3):
    """
    Return the index of the best epoch of a mean held-out curve.

    The curve is smoothed over ``window`` epochs first: single epochs move
    by more than the curve does over many (fold and epoch noise).
    """
    if len(mean) < window:
        return int(np.argmax(mean))
    smooth = np.convolve(mean, np.ones(window) / window, mode='valid')
    return int(np.argmax(smooth)) + window // 2


def config_scaler(config):
    """Return the (unfitted) scaler of a training configuration."""
    return RssiScaler(config.not_detected, config.scaling,
                      config.representation)
