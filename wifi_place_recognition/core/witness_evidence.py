"""
The witness's evidence: a CUSUM per witness (ROS-free).

Each judgement adds a step (its distance in standard deviations minus
``agree_sigmas``, at most ``max_step``); the sum stays between zero and
the alarm level.
"""

WITNESSES = ('fused', 'scans')


class Evidence:
    """The running sums of the witnesses' steps, and since when each is > 0."""

    def __init__(self):
        self.sums = dict.fromkeys(WITNESSES, 0.0)
        self.since = dict.fromkeys(WITNESSES)   # stamp it rose from 0

    def __getitem__(self, witness):
        """Return a witness's sum."""
        return self.sums[witness]

    def add(self, witness, stamp, step, alarm):
        """Add ``step`` to a witness's sum (kept in [0, alarm]); return it."""
        before = self.sums[witness]
        now = self.sums[witness] = min(max(0.0, before + step), alarm)
        if before == 0 and now > 0:
            self.since[witness] = stamp
        elif now == 0:
            self.since[witness] = None
        return now

    def clear(self):
        """Start every sum over from zero."""
        for witness in WITNESSES:
            self.sums[witness], self.since[witness] = 0.0, None

    @property
    def level(self):
        """Return the larger sum."""
        return max(self.sums.values())

    def disagreeing_for(self, now):
        """Return for how long (s) at ``now`` some sum has been > 0."""
        since = [s for s in self.since.values() if s is not None]
        return max(0.0, now - min(since)) if since else 0.0
