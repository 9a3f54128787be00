"""
The place changes a navigation stack acts on: a new floor, a jump.

:class:`PlaceChanges` follows the answers. It says when the confident
place (``~/current_place``) changes, and when a localiser should be
re-seeded: at the second confident answer in a row on another
building/floor than the last confident one (a single wrong scan does not
switch maps, whatever the model and its tracking:
:class:`.place_switch.PlaceSwitch`), or at a confident answer whose
position jumped (:func:`.recognizer.step_sigmas`).
"""

from ..place_switch import PlaceSwitch
from ..recognizer import step_sigmas


class PlaceChanges:
    """The current place (building, floor), and when to re-seed."""

    def __init__(self, jump_threshold=5.0):
        self.jump_threshold = jump_threshold
        self.place = None             # (building, floor), last confident
        self._switch = PlaceSwitch()  # a new place at its second answer
        self._last_position = None    # ((building, floor), xy, cov)

    def follow(self, answer, confident, jumps=True):
        """
        Take one answer; return (the place changed, why to re-seed: a list).

        ``confident``: the answer is OK (not WARN). A jump is a position
        more than ``jump_threshold`` standard deviations from the previous
        answer's on the same floor (not a reason with ``jumps`` False: the
        odometry fusion judges those). Only a confident answer changes the
        place or gives reasons, and a new place only at its second
        confident answer in a row.
        """
        key = (answer.building, answer.floor)
        reasons = []
        if answer.position is not None:
            last = self._last_position
            if jumps and last is not None and last[0] == key:
                sigmas = step_sigmas(last[1], last[2], answer.position)
                if sigmas > self.jump_threshold:
                    reasons.append(f'position jumped {sigmas:.1f} sigma')
            self._last_position = (key, answer.position, answer.position_cov)
        switch = self._switch.switches(self.place, key, confident)
        if not confident or (self.place not in (None, key) and not switch):
            return False, []
        if key == self.place:
            return False, reasons
        if self.place is not None:
            reasons.insert(0, 'building {}, floor {} before'.format(
                *self.place))
        self.place = key
        return True, reasons
