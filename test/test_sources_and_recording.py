"""Your own building without ROS: scan sources (iw, nmcli), the recorder file."""

import threading
import time

from conftest import FIXTURES, process_alive, wait_until
import numpy as np
import pytest
from wifi_place_recognition.data.fingerprints import read_fingerprints
from wifi_place_recognition.data.recording import FingerprintLog, RecordingError
from wifi_place_recognition.data.wifi_sources import (
    drop_stale, parse_iw, parse_nmcli, Reading, SourceError, SourceRunner,
    wireless_interfaces)


def fixture(name):
    return (FIXTURES / name).read_text()


# parsers on captured outputs -------------------------------------------------

def test_iw_scan_output():
    assert parse_iw(fixture('iw_scan.txt')) == [
        ('00:11:22:33:44:55', -45.0, 0.02), ('aa:bb:cc:dd:ee:01', -71.5, 0.25),
        ('aa:bb:cc:dd:ee:02', -88.0, None)]


def test_iw_truncated_and_garbled_output_keeps_the_complete_entries():
    assert parse_iw(fixture('iw_scan_truncated.txt')) == [
        ('00:11:22:33:44:55', -45.0, None)]
    # The output ends inside "signal: -6x.00 dBm": not a reading.
    assert parse_iw(fixture('iw_scan_cut_number.txt')) == [
        ('00:11:22:33:44:55', -45.0, 0.02)]
    # Bad MAC, "banana", -300 dBm, "dB", a garbled age, a quality: skipped.
    assert parse_iw(fixture('iw_scan_garbled.txt')) == [
        ('00:11:22:33:44:88', -60.0, None)]
    assert parse_iw('') == []


def test_iw_dump_entries_older_than_max_age_are_dropped():
    readings = parse_iw(fixture('iw_scan_dump_old_entries.txt'))
    assert [r.age_s for r in readings] == [0.12, 0.64, 1.8, 3.4, 5.2, 9.1,
                                           17.0, 29.0]
    fresh, dropped = drop_stale(readings, 5.0)
    assert [r.bssid for r in fresh] == [f'02:11:22:33:44:0{i}'
                                        for i in range(1, 5)]
    assert dropped == 4
    assert drop_stale(readings + [Reading('aa:bb:cc:dd:ee:ff', -50.0)],
                      0.1) == ([Reading('aa:bb:cc:dd:ee:ff', -50.0)], 8)


def network_manager_percent(dbm):
    """Return NetworkManager's nm_wifi_utils_level_to_quality(dbm)."""
    val = abs(min(max(dbm, -100), -40) + 40)
    return min(max(100 - int((100.0 * val) / 60.0), 0), 100)


def test_nmcli_percent_is_inverted_as_network_manager_computes_it():
    assert parse_nmcli(fixture('nmcli.txt')) == [
        ('00:11:22:33:44:55', -40.0, None),
        ('aa:bb:cc:dd:ee:01', pytest.approx(-70.6), None),
        ('aa:bb:cc:dd:ee:02', pytest.approx(-80.8), None),
        ('aa:bb:cc:dd:ee:03', -100.0, None)]
    # Every dBm NetworkManager can see, as nmcli -t prints it.
    levels = range(-110, -29)
    terse = ''.join(f'02\\:00\\:00\\:00\\:00\\:{i:02x}:'
                    f'{network_manager_percent(d)}:2412 MHz\n'
                    for i, d in enumerate(levels))
    for dbm, reading in zip(levels, parse_nmcli(terse)):
        clipped = min(max(dbm, -100), -40)      # NM's own clamp
        assert reading.dbm - 0.6 < clipped <= reading.dbm, (dbm, reading)


def test_nmcli_garbled_lines_are_skipped():
    # The last line has no FREQ: its SIGNAL may be cut (70 of 7x).
    assert parse_nmcli(fixture('nmcli_garbled.txt')) == [
        ('00:11:22:33:44:55', -40.0, None)]


def test_sources_fall_back_in_order_and_say_why(fake_tools):
    fake_tools('iw', 'if [ "$4" = dump ]; then cat "{}"; exit 0; fi\n'
               'echo "command failed: Operation not permitted (-1)" >&2\n'
               'exit 255\n'.format(FIXTURES / 'iw_scan.txt'))
    runner = SourceRunner()
    source, readings = runner.scan(['iw', 'iw_dump', 'nmcli'], 'wlan0')
    assert source == 'iw_dump' and len(readings) == 3
    with pytest.raises(SourceError) as err:
        runner.scan(['iw', 'nmcli'], 'wlan0')
    assert 'Operation not permitted' in str(err.value)
    assert 'nmcli is not installed' in str(err.value)
    fake_tools('nmcli', 'echo "some unrelated text"\n')
    with pytest.raises(SourceError, match='no readable AP'):
        runner.read('nmcli', 'wlan0')


def test_a_hanging_command_times_out_or_is_cancelled_with_its_children(
        fake_tools, tmp_path):
    pids = tmp_path / 'pids'
    fake_tools('iw', f'sleep 1000 & echo $! >> "{pids}"; wait\n')
    t0 = time.monotonic()
    with pytest.raises(SourceError, match='took more than 0.5 s'):
        SourceRunner(timeout=0.5).read('iw', 'wlan0')
    assert time.monotonic() - t0 < 3
    runner = SourceRunner(timeout=60)
    threading.Timer(0.5, runner.cancel).start()
    t0 = time.monotonic()
    with pytest.raises(SourceError, match='stopped'):
        runner.scan(['iw', 'iw_dump'], 'wlan0')
    assert time.monotonic() - t0 < 3
    children = [int(p) for p in pids.read_text().split()]
    assert len(children) == 2
    assert wait_until(lambda: not any(map(process_alive, children)), 5), children


def test_wireless_interfaces(tmp_path):
    (tmp_path / 'eth0').mkdir()
    (tmp_path / 'wlp2s0' / 'wireless').mkdir(parents=True)
    assert wireless_interfaces(tmp_path) == ['wlp2s0']
    assert wireless_interfaces(tmp_path / 'none') == []


# the recorder file -------------------------------------------------------------

def test_recording_widens_the_header_and_trains(tmp_path):
    path = tmp_path / 'rec.csv'
    log = FingerprintLog(path)
    assert log.add(['AA-BB-CC-00-00-01', 'x'], [-50.0, float('nan')], 0, 0,
                   1.0) == (True, 1)
    log.add(['aa:bb:cc:00:00:01', 'AA:BB:CC:00:00:02'], [-55.0, 3.0], 0, 1,
            2.0)
    log.add(['AA:BB:CC:00:00:02', 'AA:BB:CC:00:00:02'], [-80.0, -60.0], 0, 1,
            3.0)
    assert log.add(['a'], [float('inf')], 0, 1, 4.0) == (False, 1)
    # names a CSV header cannot hold unquoted: left out, counted
    assert log.add(['a,b', 'a"b', 'c\rd', 'e\nf'], [-50.0] * 4, 0, 1,
                   5.0) == (False, 4)
    fp = read_fingerprints(path)
    assert fp.ap_ids == ('aa:bb:cc:00:00:01', 'aa:bb:cc:00:00:02')
    np.testing.assert_array_equal(fp.rssi, [[-50, np.nan], [-55, 0],
                                            [np.nan, -60]])
    assert fp.floor.tolist() == [0, 1, 1]
    assert fp.meta['TIMESTAMP'].tolist() == [1.0, 2.0, 3.0]


def test_recording_continues_after_a_torn_line(tmp_path):
    path = tmp_path / 'rec.csv'
    FingerprintLog(path).add(['aa:bb:cc:00:00:01'], [-50.0], 1, 2, 1.0)
    with open(path, 'a') as f:
        f.write('1,2,2.000,-6')          # killed mid-append
    log = FingerprintLog(path)
    assert log.counts == {(1, 2): 1}
    log.add(['aa:bb:cc:00:00:01'], [-40.0], 1, 2, 3.0)
    assert read_fingerprints(path).rssi[:, 0].tolist() == [-50.0, -40.0]
    (tmp_path / 'other.csv').write_text('WAP001,FLOOR\n-50,1\n')
    with pytest.raises(RecordingError, match='not a recording'):
        FingerprintLog(tmp_path / 'other.csv')
