"""
classifier_node with torch inference instead of numpy: a benchmark baseline.

Same node, same model file; only the recognizer's forward pass runs the
frozen layers through torch (dense, as torch would). The shipped node never
imports torch.
"""

import sys

import torch
from wifi_place_recognition.core.artifact import ModelFileError
from wifi_place_recognition.core.model import mean_softmax
from wifi_place_recognition.ros.classifier_node import ClassifierNode
from wifi_place_recognition.ros.runner import run
from wifi_place_recognition.training.network import TORCH_ACTIVATIONS


def _torch_net(layers):
    modules = []
    for layer in layers:
        linear = torch.nn.Linear(*layer.weight.shape[::-1])
        linear.weight.data = torch.from_numpy(layer.weight)
        linear.bias.data = torch.from_numpy(layer.bias)
        modules.append(linear)
        if layer.activation != 'linear':
            modules.append(TORCH_ACTIVATIONS[layer.activation]())
    return torch.nn.Sequential(*modules).eval()


def torch_forward(model):
    """Return a one-scan forward pass that runs ``model``'s nets in torch."""
    nets = [_torch_net(layers) for layers in model.members]

    def forward(columns, inputs):
        x = model.blank.copy()
        x[columns] += inputs
        with torch.no_grad():
            x = torch.from_numpy(x[None, :])
            return mean_softmax([net(x).numpy() for net in nets])[0]
    return forward


def torch_node():
    """Return a classifier node whose inference runs in torch."""
    return ClassifierNode(make_forward=torch_forward)


if __name__ == '__main__':
    sys.exit(run(torch_node, startup_errors=(ModelFileError,)))
