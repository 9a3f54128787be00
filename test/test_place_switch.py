"""The one rule for leaving a building/floor (core.place_switch), no ROS."""

from wifi_place_recognition.core.filter.fusion import Fusion
from wifi_place_recognition.core.place_switch import PlaceSwitch

F0, F1 = (0, 0), (0, 1)


def answers(switch, current, sequence):
    """Return the place after each (place, confident) answer."""
    out = []
    for place, confident in sequence:
        if current is None or switch.switches(current, place, confident):
            current = place
        out.append(current)
    return out


def test_a_new_place_at_its_second_confident_answer_in_a_row():
    assert answers(PlaceSwitch(), None, [(F0, True), (F1, True), (F0, True),
                                         (F1, True), (F1, True)]) == \
        [F0, F0, F0, F0, F1]
    # an unconfident answer in between starts the count again
    assert answers(PlaceSwitch(), F0, [(F1, True), (F1, False),
                                       (F1, True), (F1, True)]) == \
        [F0, F0, F0, F1]


def test_the_filter_follows_the_same_rule():
    # the fused pose changes floor where ~/current_place does
    fusion = Fusion(seed=0)
    places = []
    for k, (place, confident) in enumerate([(F0, True), (F1, True),
                                            (F1, False), (F1, True),
                                            (F1, True)]):
        fusion.scan(float(k), [10.0, 10.0], place, confident,
                    arrival=float(k))
        places += [pose.place for pose in fusion.expire(k + 5.0)]
    assert places == [F0, F0, F0, F0, F1], places
