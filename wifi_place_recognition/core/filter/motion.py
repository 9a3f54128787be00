"""
The filter's motion model: an odometry step moves every particle.

An odometry step (forward, lateral, turn in the robot frame) is applied
to every particle with noise proportional to it. Each particle also
carries a heading drift (rad per metre driven): wheel odometry's heading
often loses a steady angle per metre (a calibration bias), and the
particles that carry the right drift survive.
"""

import math

import numpy as np

from .angles import wrap


class MotionModel:
    """Move particles by an odometry step, with noise proportional to it."""

    def __init__(self, params):
        self.params = params

    def move(self, state, forward, lateral, turn, rng):
        """
        Apply one odometry step to ``state`` (n, 4: x, y, yaw, drift).

        ``forward``, ``lateral`` (m) and ``turn`` (rad) are the step in the
        robot frame at its start.
        """
        p = self.params
        n = len(state)
        distance = math.hypot(forward, lateral)
        scale = 1 + p.distance_noise * rng.standard_normal(n)
        turned = turn * (1 + p.turn_noise * rng.standard_normal(n)) + \
            state[:, 3] * distance + \
            p.heading_noise * math.sqrt(distance) * rng.standard_normal(n)
        step(state, forward, lateral, scale, turned)
        state[:, 3] += p.drift_walk * math.sqrt(distance) * \
            rng.standard_normal(n)

    def carry(self, state, forward, lateral, turn):
        """Apply one odometry step to ``state`` without noise (its drift)."""
        step(state, forward, lateral, 1.0,
             turn + state[:, 3] * math.hypot(forward, lateral))

    def spread(self, state, seconds, rng):
        """Spread ``state`` for ``seconds`` without odometry (WiFi alone)."""
        n = len(state)
        state[:, :2] += self.params.idle_speed * seconds * \
            rng.standard_normal((n, 2))
        state[:, 2] = wrap(state[:, 2] + self.params.idle_turn_rate *
                           seconds * rng.standard_normal(n))


def step(state, forward, lateral, scale, turned):
    """Move ``state`` by a step scaled by ``scale``, turning ``turned``."""
    heading = state[:, 2] + turned / 2
    cos, sin = np.cos(heading), np.sin(heading)
    state[:, 0] += scale * (forward * cos - lateral * sin)
    state[:, 1] += scale * (forward * sin + lateral * cos)
    state[:, 2] = wrap(state[:, 2] + turned)
