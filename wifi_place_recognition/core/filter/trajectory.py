"""
Score poses over a run against its truth (ROS-free): fused, scans, odometry.

A robot run is three stamped streams: scans (with the single-scan answer),
odometry poses, and the truth (e.g. AMCL's pose at each scan).
:func:`fuse_offline` runs :class:`.fusion.Fusion` over them in stamp order
(what the node does live); :func:`dead_reckoning` places odometry alone in
the map frame from a true pose inside its time span, and
:func:`odometry_alone` from the first one there; :func:`score` gives
the figures the README's robot table reports; :func:`truth_at` reads a
truth file's poses at the scans' stamps; :func:`inside_span` is the one
rule of "inside a stream's time span", :func:`time_span` says when a
stream runs, for messages.
"""

import math

import numpy as np

from ..pipeline.scan_pipeline import position_answer, ScanPipeline
from .angles import wrap
from .fusion import Fusion, relative
from .particles import UNKNOWN_VARIANCE

#: Chi-square (2 dof) of the 95 % ellipse.
CHI2_95 = -2 * math.log(0.05)


def fuse_offline(odometry, scans, fusion=None):
    """
    Return the node's pose at every scan: (xy (n, 2), yaw (n,), cov (n, 3, 3)).

    ``odometry``: (m, 4) rows of stamp, x, y, yaw; ``scans``: stamps (n,),
    xy (n, 2), optionally each scan's sigma (n,), coverage (n,) and
    mismatch over the survey's usual (n,), in stamp order. They go through
    the node's :class:`.scan_pipeline.ScanPipeline` (each scan a confident
    answer of one place, :func:`.scan_pipeline.position_answer`) as the
    node would receive them, on the stamps' clock: each message arrives at
    its stamp (a scan after odometry of the same stamp), and the node's
    timer ticks after each odometry pose and once at the end (the scans
    still waiting go through alone). A scan before any odometry gets its
    own position (yaw NaN, its variance unknown); NaN where a scan gave no
    pose.
    """
    pipeline = ScanPipeline(fusion=fusion or Fusion())
    pipeline.configure(pose_rate=0)     # the poses at scans only
    stamps, xy = scans[:2]
    sigma = scans[2] if len(scans) > 2 else np.full(len(stamps), np.nan)
    coverage = scans[3] if len(scans) > 3 else [None] * len(stamps)
    mismatch = scans[4] if len(scans) > 4 else np.full(len(stamps), np.nan)
    n = len(stamps)
    out_xy, out_yaw = np.full((n, 2), np.nan), np.full(n, np.nan)
    out_cov = np.full((n, 3, 3), np.nan)

    def keep(out):
        for p in out.poses:
            if p.source is None:    # between scans
                continue
            out_xy[p.source] = p.xy
            if p.fused:
                out_yaw[p.source], out_cov[p.source] = p.yaw, p.cov
            else:
                out_cov[p.source] = np.diag([0.0, 0.0, UNKNOWN_VARIANCE])
                out_cov[p.source, :2, :2] = p.cov

    def arrive(row):
        keep(pipeline.odometry(*row, now=row[0]))
        keep(pipeline.tick(row[0]))
    o = 0
    for i in range(n):
        while o < len(odometry) and odometry[o, 0] <= stamps[i]:
            arrive(odometry[o])
            o += 1
        keep(pipeline.answer(position_answer(xy[i], sigma[i],
                                             coverage=coverage[i],
                                             mismatch=mismatch[i]),
                             stamps[i], stamps[i], i))
    for row in odometry[o:]:
        arrive(row)
    keep(pipeline.tick(math.inf))
    return out_xy, out_yaw, out_cov


def inside_span(stamps, times):
    """Return whether each of ``stamps`` lies within the span of ``times``."""
    stamps = np.asarray(stamps, np.float64)
    return (stamps >= np.min(times)) & (stamps <= np.max(times))


def dead_reckoning(odometry, stamps, start_xy, start_yaw, start_stamp):
    """
    Return odometry alone at ``stamps`` in the map frame: (xy, yaw).

    The odometry pose at ``start_stamp`` (inside the odometry's time span,
    else ValueError) is put on the true ``start_xy``/``start_yaw`` (a rigid
    transform), as an oracle start. NaN at stamps outside the span.
    """
    t = odometry[:, 0]
    if not inside_span(start_stamp, t):
        raise ValueError(f'dead reckoning from {_seconds(start_stamp)} s: '
                         f'outside the odometry\'s time span {time_span(t)}')

    def at(s):
        x = np.interp(s, t, odometry[:, 1])
        y = np.interp(s, t, odometry[:, 2])
        yaw = np.interp(s, t, np.unwrap(odometry[:, 3]))
        return x, y, yaw
    origin = at(start_stamp)
    xy, yaw = np.empty((len(stamps), 2)), np.empty(len(stamps))
    for i, s in enumerate(stamps):
        step = relative(origin, at(s))
        c, sn = math.cos(start_yaw), math.sin(start_yaw)
        xy[i] = (start_xy[0] + c * step[0] - sn * step[1],
                 start_xy[1] + sn * step[0] + c * step[1])
        yaw[i] = wrap(start_yaw + step[2])
    outside = ~inside_span(stamps, t)
    xy[outside], yaw[outside] = np.nan, np.nan
    return xy, yaw


def odometry_alone(odometry, stamps, xy, yaw):
    """
    Return odometry alone at ``stamps``, from the first true pose in it.

    :func:`dead_reckoning` from the earliest stamp inside the odometry's
    time span with a finite true ``xy`` and ``yaw``: (xy (n, 2), yaw (n,)),
    NaN outside the span (all NaN when no true pose lies inside it).
    """
    stamps = np.asarray(stamps, np.float64)
    start = inside_span(stamps, odometry[:, 0]) & \
        np.isfinite(xy).all(axis=1) & np.isfinite(yaw)
    if not start.any():
        return np.full((len(stamps), 2), np.nan), np.full(len(stamps), np.nan)
    first = np.flatnonzero(start)[np.argmin(stamps[start])]
    return dead_reckoning(odometry, stamps, xy[first], yaw[first],
                          stamps[first])


def _seconds(value):
    """Return the text of a stamp or a duration (s), huge ones short."""
    return f'{value:.3f}' if abs(value) < 1e12 else f'{value:.4g}'


def time_span(stamps):
    """Return the text of the time span of ``stamps`` (s), for messages."""
    stamps = np.asarray(stamps, np.float64)
    if not len(stamps):
        return 'no stamps'
    low, high = float(np.min(stamps)), float(np.max(stamps))
    return '{} to {} s ({} s)'.format(
        _seconds(low), _seconds(high),
        f'{high - low:.1f}' if high - low < 1e12 else f'{high - low:.4g}')


def truth_at(poses, stamps):
    """
    Return true (xy (n, 2), yaw (n,)) at ``stamps`` from (m, 4) ``poses``.

    Linear between the poses around each stamp (yaw along the shorter
    arc); NaN outside their time span.
    """
    t = poses[:, 0]
    inside = inside_span(stamps, t)
    xy = np.column_stack([np.interp(stamps, t, poses[:, 1]),
                          np.interp(stamps, t, poses[:, 2])])
    yaw = wrap(np.interp(stamps, t, np.unwrap(poses[:, 3])))
    xy[~inside], yaw = np.nan, np.where(inside, yaw, np.nan)
    return xy, yaw


def score(stamps, truth_xy, xy, truth_yaw=None, yaw=None, cov=None,
          settle_s=30.0):
    """
    Return error figures (m, degrees, shares) of poses against the truth.

    Mean, median, p95 and max error; the time after the first stamp from
    which the error stays below 2 m; the largest error after ``settle_s``;
    the median yaw error after ``settle_s``; the share of scans whose true
    position lies in the 95 % ellipse of ``cov``. Rows with NaN are left
    out.
    """
    ok = np.isfinite(xy).all(axis=1) & np.isfinite(truth_xy).all(axis=1)
    if not ok.any():
        return {'scans': 0}
    error = np.linalg.norm(xy - truth_xy, axis=1)
    since = stamps - stamps[0]
    late = ok & (since >= settle_s)
    above = np.flatnonzero(ok & (error >= 2.0))
    out = {'scans': int(ok.sum()),
           'mean_m': float(error[ok].mean()),
           'median_m': float(np.median(error[ok])),
           'p95_m': float(np.quantile(error[ok], 0.95)),
           'max_m': float(error[ok].max()),
           'below_2m_from_s': float(since[above[-1] + 1]) if len(above) and
           above[-1] + 1 < len(since) else
           (0.0 if not len(above) else math.inf),
           'max_after_settle_m': float(error[late].max()) if late.any()
           else math.nan}
    if yaw is not None and truth_yaw is not None:
        good = late & np.isfinite(yaw) & np.isfinite(truth_yaw)
        out['yaw_median_deg_after_settle'] = float(np.degrees(np.median(
            np.abs(wrap(yaw[good] - truth_yaw[good]))))) if good.any() \
            else math.nan
    if cov is not None:
        good = ok & np.isfinite(cov[:, :2, :2]).all(axis=(1, 2))
        delta = (truth_xy - xy)[good]
        inside = [d @ np.linalg.solve(c + 1e-12 * np.eye(2), d) <= CHI2_95
                  for d, c in zip(delta, cov[good, :2, :2])]
        out['in_95_ellipse'] = float(np.mean(inside)) if inside else math.nan
    return out
