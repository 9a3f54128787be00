"""Headings: one rule for wrapping an angle (numpy)."""

import math

import numpy as np

TWO_PI = 2 * math.pi


def wrap(angle):
    """Return ``angle`` (rad) wrapped to [-pi, pi)."""
    return (np.asarray(angle) + math.pi) % TWO_PI - math.pi
