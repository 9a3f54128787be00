"""The torch network: SAE encoder + classifier, and its export to numpy layers."""

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
        """Return logits."""
        return self.head(self.encoder(x))

    def autoencoder(self):
        """Return encoder + a fresh mirrored decoder, for pre-training."""
        sizes = [m.in_features for m in self.encoder
                 if isinstance(m, nn.Linear)]
        sizes.append(self.encoder[-2].out_features)
        decoder = dense(sizes[::-1], self.activation)[:-1]
        return nn.Sequential(self.encoder, *decoder)

    def frozen_layers(self):
        """Return the dense layers as numpy :class:`Layer` objects."""
        linears = [m for m in self.modules() if isinstance(m, nn.Linear)]
        return [Layer(m.weight.detach().numpy().copy(),
                      m.bias.detach().numpy().copy(),
                      'linear' if m is linears[-1] else self.activation)
                for m in linears]
