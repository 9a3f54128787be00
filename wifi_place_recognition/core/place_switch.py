"""
One rule for leaving a building/floor: its second confident answer in a row.

A single confident answer of another place (a wrong scan, a WiFi twin on
the floor above) does not switch maps; a second in a row does, and any
other answer in between (unconfident, or of the current place) starts
the count again. classifier_node's place changes and the fusion's filter
both follow it, so ``~/current_place`` and the fused pose change floor at
the same scan.
"""


class PlaceSwitch:
    """Say when an answer switches from the current place to its own."""

    def __init__(self):
        self.candidate = None   # another place, answered confidently once

    def reset(self):
        """Forget the candidate."""
        self.candidate = None

    def switches(self, current, place, confident):
        """
        Return True when ``place`` replaces ``current`` at this answer.

        ``current`` None (no place yet) is never switched from: the first
        place is taken as it comes.
        """
        other = current is not None and place != current
        switch = other and confident and self.candidate == place
        self.candidate = place if other and confident and not switch \
            else None
        return switch
