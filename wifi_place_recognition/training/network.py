"""The torch network: SAE encoder + classifier, and its export to numpy layers."""

from typing import NamedTuple

import torch
from torch import nn

from ..core.model import Layer

TORCH_ACTIVATIONS = {'relu': nn.ReLU, 'elu': nn.ELU, 'tanh': nn.Tanh}


def dense(sizes, activation, dropout=0.0):
    """Return Linear + activation (+ dropout) modules for consecutive sizes."""
    layers = []
    for n_in, n_out in zip(sizes[:-1], sizes[1:]):
        layers += [nn.Linear(n_in, n_out), TORCH_ACTIVATIONS[activation]()]
        if dropout:
            layers.append(nn.Dropout(dropout))
    return layers


class SparseBatch(NamedTuple):
    """
    A mini-batch of scans by their detected APs only.

    The network input of a scan is ``blank`` (a scan that detects nothing)
    plus, at ``columns``, ``values``; ``offsets`` start each scan's entries
    (``torch.nn.functional.embedding_bag`` layout). The first layer then
    costs a few dozen columns per scan instead of every AP.
    """

    columns: torch.Tensor  # int64 (entries,)
    offsets: torch.Tensor  # int64 (scans,)
    values: torch.Tensor   # float32 (entries,)
    blank: torch.Tensor    # float32 (n_aps,)

    def dense(self):
        """Return the (scans, n_aps) inputs."""
        n = len(self.offsets)
        lengths = torch.diff(self.offsets,
                             append=torch.tensor([len(self.columns)]))
        rows = torch.repeat_interleave(torch.arange(n), lengths)
        out = self.blank.repeat(n, 1)
        out[rows, self.columns] += self.values
        return out


class PlaceNet(nn.Module):
    """Encoder (pre-trained as an SAE) + classifier; outputs logits."""

    def __init__(self, n_inputs, n_classes, config):
        super().__init__()
        self.activation = config.activation
        self.encoder = nn.Sequential(*dense(
            (n_inputs,) + config.sae_layers, config.activation))
        head = (config.sae_layers[-1],) + config.classifier_layers
        self.head = nn.Sequential(
            *dense(head, config.activation, config.dropout),
            nn.Linear(head[-1], n_classes))

    def forward(self, x):
        """Return logits of dense inputs or a :class:`SparseBatch`."""
        return self.head(self.encode(x))

    def encode(self, x):
        """Return the encoder's output (the code)."""
        if not isinstance(x, SparseBatch):
            return self.encoder(x)
        first = self.encoder[0]
        h = nn.functional.embedding_bag(
            x.columns, first.weight.t().contiguous(), x.offsets, mode='sum',
            per_sample_weights=x.values) + first(x.blank)
        return self.encoder[1:](h)

    def autoencoder(self):
        """Return encoder + a fresh mirrored decoder, for pre-training."""
        sizes = [m.in_features for m in self.encoder
                 if isinstance(m, nn.Linear)]
        sizes.append(self.encoder[-2].out_features)
        return _AutoEncoder(self, nn.Sequential(
            *dense(sizes[::-1], self.activation)[:-1]))

    def frozen_layers(self):
        """Return the dense layers as numpy :class:`Layer` objects."""
        linears = [m for m in self.modules() if isinstance(m, nn.Linear)]
        return [Layer(m.weight.detach().numpy().copy(),
                      m.bias.detach().numpy().copy(),
                      'linear' if m is linears[-1] else self.activation)
                for m in linears]


class _AutoEncoder(nn.Module):
    """A network's encoder with a decoder: inputs -> reconstruction."""

    def __init__(self, net, decoder):
        super().__init__()
        self.net, self.decoder = net, decoder

    def parameters(self, recurse=True):
        """Yield the weights of the encoder and the decoder, not the head."""
        yield from self.net.encoder.parameters(recurse)
        yield from self.decoder.parameters(recurse)

    def forward(self, x):
        """Return the reconstruction of dense inputs or a SparseBatch."""
        return self.decoder(self.net.encode(x))
