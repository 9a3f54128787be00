"""The scanner's inputs: cut ``nmcli`` listings, a missing interface."""

from conftest import python_module, run
import pytest
from wifi_place_recognition.data.wifi_sources import (interface_problem,
                                                      parse_nmcli)

LISTING = ('00\\:11\\:22\\:33\\:44\\:55:100:2412 MHz\n'
           'AA\\:BB\\:CC\\:DD\\:EE\\:B6:92:5180 MHz\n')


def test_nmcli_listing_cut_inside_its_last_line_keeps_the_complete_lines():
    whole = parse_nmcli(LISTING)
    assert [r.bssid for r in whole] == ['00:11:22:33:44:55',
                                        'aa:bb:cc:dd:ee:b6']
    assert whole[1].dbm == pytest.approx(-44.8)
    # Cut at every character of the last line: the first line stays, and
    # the last one counts only once its FREQ has begun (SIGNAL complete).
    first = len(LISTING.splitlines()[0]) + 1
    freq = LISTING.rindex(':') + 1
    for cut in range(first, len(LISTING)):
        readings = parse_nmcli(LISTING[:cut])
        assert readings == (whole if cut > freq else whole[:1]), \
            LISTING[first:cut]
    # A line with a field missing in the middle, or an empty FREQ.
    assert parse_nmcli('AA\\:BB\\:CC\\:DD\\:EE\\:B6:2412 MHz\n'
                       'AA\\:BB\\:CC\\:DD\\:EE\\:B7:92:\n') == []


def test_interface_problem_names_the_interfaces_there(tmp_path):
    (tmp_path / 'eth0').mkdir()
    (tmp_path / 'wlp2s0' / 'phy80211').mkdir(parents=True)
    assert interface_problem('wlp2s0', tmp_path) is None
    assert interface_problem('eth0', tmp_path) is None
    assert interface_problem('wlan9', tmp_path) == (
        f"interface 'wlan9' does not exist; {tmp_path} has eth0, wlp2s0 "
        f"(wireless: wlp2s0)")


def test_scanner_with_a_missing_interface_is_one_error_line():
    result = run(python_module('ros.wifi_scanner_node', '--ros-args', '-p',
                               'interface:=wlan9'), timeout=30)
    assert result.returncode == 1, result.stderr
    ours = [line for line in result.stderr.splitlines() if '[rcl]' not in line]
    assert len(ours) == 1, result.stderr
    assert ("] [wifi_scanner_node]: cannot start: interface 'wlan9' does not "
            "exist; /sys/class/net has ") in ours[0], result.stderr
    assert ' lo' in ours[0] and '(wireless: ' in ours[0], result.stderr
