"""
What each witness testifies, and how far apart it says the localiser is.

A scan testifies when :func:`scan_doubt` has nothing against it (a scan
taken off the survey snaps to the nearest surveyed place: it must not
sound unlike the survey, and its sigma must be up to ``max_scan_sigma``,
or its coverage probability say it was taken on the survey) and the survey
covers the localiser's position (:func:`covered`). The
distances are Mahalanobis distances under the sum of both covariances,
plus floors for what neither knows and the distance the robot moved since
the localiser's stamp (ROS-free).
"""

import math

import numpy as np

from .coverage import uncovered, unlike_survey
from .filter.angles import wrap
from .filter.particles import UNKNOWN_VARIANCE


def scan_doubt(sigma, coverage, mismatch, params):
    """
    Return why a scan does not testify, or ''.

    The one rule for which scans testify (a scan's own, whatever the
    localiser's pose): a scan off the survey, its relative ``mismatch``
    above the survey's usual (:func:`.coverage.unlike_survey`; NaN: not
    known), or its k-NN sigma (m) above ``max_scan_sigma`` (a scan unlike
    every surveyed one: the sigma grows with that) unless its coverage
    probability (NaN: the model has no coverage model) says it was taken
    on the survey (:func:`.coverage.uncovered`). The probability alone
    silences no scan: on another day it calls right scans on covered
    ground off the survey.
    """
    if unlike_survey(mismatch):
        return (f'scan unlike the survey (mismatch {mismatch:.2f} times '
                f'its usual)')
    if sigma <= params.max_scan_sigma:
        return ''
    if math.isnan(coverage):
        return f'scan off the survey (sigma {sigma:.1f} m)'
    if uncovered(coverage):
        return (f'scan off the survey (sigma {sigma:.1f} m, coverage '
                f'{coverage:.2f})')
    return ''


def covered(survey, frame, xy, coverage_m):
    """
    Return True if a reference of ``survey`` lies within ``coverage_m`` of xy.

    ``survey``: {frame: (n, 2) positions}; None: every place is covered,
    a frame not in it: none.
    """
    if survey is None:
        return True
    refs = survey.get(frame)
    if refs is None or not len(refs):
        return False
    return float(np.min(np.sum((refs - xy) ** 2, axis=1))) <= coverage_m ** 2


def mahalanobis(delta, cov):
    """Return (squared Mahalanobis distance, Euclidean distance) in 2-D."""
    (x, y), ((a, b), (c, d)) = delta.tolist(), cov.tolist()
    return ((d * x * x - (b + c) * x * y + a * y * y) / (a * d - b * c),
            math.hypot(x, y))


def fused_distance(local, pose, moved, params):
    """
    Return (d2, metres, yaw degrees) between the localiser and a fused Pose.

    The yaw joins only when the fused yaw is known (its deviation up to
    ``yaw_known_sd``) and the localiser's is not unknown; else NaN.
    """
    p = params
    extra = p.floor_sd ** 2 + moved ** 2
    d2, distance = mahalanobis(local.xy - pose.xy, local.cov[:2, :2] +
                               pose.cov[:2, :2] + extra * np.eye(2))
    yaw_deg = math.nan
    if pose.yaw_sd <= p.yaw_known_sd and local.cov[2, 2] < UNKNOWN_VARIANCE:
        turn = float(wrap(local.yaw - pose.yaw))
        d2 += turn ** 2 / (local.cov[2, 2] + pose.cov[2, 2] +
                           p.yaw_floor_sd ** 2)
        yaw_deg = math.degrees(turn)
    return d2, distance, yaw_deg


def scan_distance(local, xy, sigma, moved, params):
    """Return (d2, metres) between the localiser and a scan's own position."""
    extra = sigma ** 2 + params.scan_floor_sd ** 2 + moved ** 2
    return mahalanobis(local.xy - xy, local.cov[:2, :2] + extra * np.eye(2))
