"""The witness run offline over stamped streams, as the node runs it live."""

from .witness import Witness


def replay(localiser, fused, params=None, frame='map', scans=None,
           survey=None):
    """
    Run a :class:`.witness.Witness` over stamped streams, event by event.

    ``localiser`` and ``fused``: (stamps (n,), xy (n, 2), yaw (n,),
    cov (n, 3, 3)) in stamp order, in ``frame`` (``localiser`` may be
    None: it never published); ``scans``: (stamps, xy, sigma[, coverage[,
    mismatch]]) or None; ``survey``: the surveyed positions (None:
    everywhere). Taken in stamp order (the localiser's first, then the
    scans', at equal stamps); rows the witness refuses (a NaN but the
    coverage's or the mismatch's, a coverage outside 0-1, a mismatch
    below 0 or inf) are skipped.
    Every seed proposed is sent. Yield (stamp, judgement or None, the
    witness's state after it) for every event.
    """
    witness = Witness(params, None if survey is None else {frame: survey})
    events = [(float(t), 2, i) for i, t in enumerate(fused[0])]
    if localiser is not None:
        events += [(float(t), 0, i) for i, t in enumerate(localiser[0])]
    if scans is not None:
        events += [(float(t), 1, i) for i, t in enumerate(scans[0])]
    for stamp, kind, i in sorted(events):
        judgement = None
        if kind == 0:
            witness.localiser(stamp, frame, localiser[1][i],
                              localiser[2][i], localiser[3][i])
        elif kind == 2:
            judgement = witness.fused(stamp, frame, fused[1][i],
                                      fused[2][i], fused[3][i])
        else:
            judgement = witness.scan(stamp, frame, *(s[i] for s in
                                                     scans[1:]))
        if judgement is not None and judgement.seed:
            witness.seeded(stamp)
        yield stamp, judgement, witness.state


def judge_offline(localiser, fused, params=None, frame='map', scans=None,
                  survey=None):
    """Return the judgements of :func:`replay` (same arguments)."""
    return [j for _, j, _ in replay(localiser, fused, params, frame, scans,
                                    survey) if j is not None]
