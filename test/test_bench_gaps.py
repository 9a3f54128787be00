"""The coverage benchmark's count of survey_gaps's stretches against the truth."""

from conftest import benchmark
import numpy as np


def test_stretches_found_and_listed_are_counted_in_time_order():
    check = benchmark('coverage_check')
    # in time order: a hole of 6 scans, 10 covered, 4 off (too few to be a
    # stretch), 10 covered, a hole of 7 scans
    off = np.array([1] * 6 + [0] * 10 + [1] * 4 + [0] * 10 + [1] * 7, bool)
    one_in_first = np.zeros(len(off), bool)
    one_in_first[2] = True              # found, but too short to be listed
    one_in_first[8:13] = True           # listed over covered ground
    second = np.zeros(len(off), bool)
    second[-7:] = True                  # found and listed
    short = np.zeros(len(off), bool)
    short[16:21] = True                 # the 4 off and a covered one
    rules = {'a': one_in_first, 'b': second, 'c': short}
    # the file is out of time order: the tool (and the count) sorts it
    order = np.random.default_rng(0).permutation(len(off))
    stamps = 100.0 + np.arange(len(off), dtype=float)
    found = check.stretches(~off[order], {k: v[order] for k, v in
                                          rules.items()}, stamps[order])
    assert found['true_stretches'] == 2 and found['min_scans'] == 5
    by_rule = found['by_rule']
    assert {k: (v['found'], v['listed'], v['listed_none_off'])
            for k, v in by_rule.items()} == {
        'a': (1, 1, 1), 'b': (1, 1, 0), 'c': (0, 1, 0)}
    assert by_rule['b']['recall'] == 7 / 17
    assert by_rule['a']['called_off_share'] == 6 / len(off)
    # no stamps: the file's order is the run's
    plain = check.stretches(~off, rules)
    assert plain == found
