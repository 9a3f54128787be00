"""
classifier_node with torch inference instead of numpy: a benchmark baseline.

Same node, same model file; only ``predict_proba`` runs the frozen layers
through torch. The shipped node never imports torch.
"""

import sys

import rclpy
from rclpy.executors import ExternalShutdownException
import torch
from wifi_place_recognition.classifier_node import ClassifierNode
from wifi_place_recognition.training import TORCH_ACTIVATIONS


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


def torch_predict_proba(model):
    """Return a predict_proba that runs ``model``'s networks in torch."""
    nets = [_torch_net(layers) for layers in model.members]

    def predict_proba(rssi):
        with torch.no_grad():
            x = torch.from_numpy(model.scaler.transform(rssi))
            return (sum(torch.softmax(net(x), dim=1) for net in nets)
                    / len(nets)).numpy()
    return predict_proba


def main():
    """Run the torch variant until SIGINT."""
    rclpy.init()
    node = ClassifierNode()
    model = node.recognizer.model
    model.predict_proba = torch_predict_proba(model)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    sys.exit(main())
