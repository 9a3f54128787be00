r"""
Where a robot's WiFi scans come from on Linux: ``iw`` and NetworkManager.

ROS-free: parsers of the tools' text output and a runner that tries the
sources in order. Each reading is a :class:`Reading`: the BSSID in
lower-case ``aa:bb:cc:dd:ee:ff`` form, the RSSI in dBm and, from ``iw``, how
long ago the AP was last seen.

- ``iw dev IF scan``: triggers a fresh scan (needs CAP_NET_ADMIN).
- ``iw dev IF scan dump``: the kernel's cached results of the last scan
  (any scan, also NetworkManager's); no privileges needed.
  Both print the kernel's whole cache: each BSS's ``last seen: N ms ago``
  tells the fresh entries from those of an earlier scan.
- ``nmcli -t -f BSSID,SIGNAL,FREQ dev wifi list ifname IF``: terse output,
  ``:`` inside a field escaped as ``\:``. SIGNAL is a percentage that
  NetworkManager computes from dBm (``nm_wifi_utils_level_to_quality``)
  with a linear map clamped to [-100, -40] dBm:
  ``percent = 100 - int(100 * (-40 - clamp(dBm, -100, -40)) / 60)``. So
  ``dBm = -40 - 0.6 * (100 - percent)`` (within 0.6 dB); 100 % means
  -40 dBm or stronger and 0 % -100 dBm or weaker: the reading is clipped
  there.
"""

import os
from pathlib import Path
import re
import signal
import subprocess
import threading
from typing import NamedTuple, Optional

from ..core.rssi import plausible

SYS_CLASS_NET = '/sys/class/net'
MAC = re.compile(r'^[0-9a-f]{2}(:[0-9a-f]{2}){5}$')
IW_SIGNAL = re.compile(r'^signal: (-?\d+(?:\.\d+)?) dBm$')
IW_AGE = re.compile(r'^last seen: (\d+) ms ago$')
IW_BOOTTIME = re.compile(r'^last seen: \d+\.\d+s \[boottime\]$')
#: FREQ begins with its number (the unit may be translated).
NM_FREQ = re.compile(r'^\d+')
NM_BEST_DBM = -40.0
NM_DB_PER_PERCENT = 0.6


class Reading(NamedTuple):
    """One AP in a scan; ``age_s`` is None when the source does not say."""

    bssid: str
    dbm: float
    age_s: Optional[float] = None


class SourceError(RuntimeError):
    """A scan source that cannot deliver; the message says why."""


def _mac(text):
    text = text.strip().lower()
    return text if MAC.match(text) else None


def _iw_reading(bssid, lines):
    """Return the Reading of one BSS block, or None if incomplete/garbled."""
    dbm = age = None
    for line in lines:
        field = line.strip()
        if field.startswith('signal:'):
            match = IW_SIGNAL.match(field)
            if not match:
                return None
            dbm = float(match.group(1))
        elif field.startswith('last seen:') and not IW_BOOTTIME.match(field):
            match = IW_AGE.match(field)
            if not match:
                return None
            age = int(match.group(1)) / 1000.0
    if bssid is None or dbm is None or not plausible(dbm):
        return None
    return Reading(bssid, dbm, age)


def parse_iw(text):
    """
    Return the readings in ``iw dev IF scan`` or ``scan dump`` output.

    Only complete ``signal: <number> dBm`` lines count; a BSS without one,
    with an implausible value (see :mod:`..core.rssi`), a garbled ``last
    seen`` line or a bad BSSID is skipped, so truncated or garbled output
    yields its complete entries.
    """
    readings, bssid, lines = [], None, None
    for line in text.splitlines() + ['BSS']:
        if line.startswith('BSS'):
            if lines is not None:
                reading = _iw_reading(bssid, lines)
                if reading:
                    readings.append(reading)
            head = line[4:].split('(')[0].split()
            bssid, lines = _mac(head[0]) if head else None, []
        elif lines is not None:
            lines.append(line)
    return readings


def nm_percent_to_dbm(percent):
    """Return the dBm that NetworkManager turned into ``percent``."""
    return NM_BEST_DBM - NM_DB_PER_PERCENT * (100.0 - float(percent))


def parse_nmcli(text):
    r"""
    Return the readings in ``nmcli -t -f BSSID,SIGNAL,FREQ ...`` output.

    In terse output ``:`` inside a field is escaped as ``\:``. Lines with a
    bad BSSID, a SIGNAL that is not a percentage, or no FREQ (a listing cut
    inside its last line: ``...:92:2412 MHz`` cut to ``...:9``) are skipped:
    only the FREQ field shows that SIGNAL is complete.
    """
    readings = []
    for line in text.splitlines():
        fields = re.split(r'(?<!\\):', line.strip())
        if len(fields) != 3 or not NM_FREQ.match(fields[2]):
            continue
        bssid = _mac(fields[0].replace('\\:', ':'))
        try:
            percent = float(fields[1])
        except ValueError:
            continue
        if bssid and 0.0 <= percent <= 100.0:
            readings.append(Reading(bssid, nm_percent_to_dbm(percent)))
    return readings


def drop_stale(readings, max_age_s):
    """Return (readings seen within ``max_age_s``, number dropped)."""
    fresh = [r for r in readings if r.age_s is None or r.age_s <= max_age_s]
    return fresh, len(readings) - len(fresh)


SOURCES = {
    'iw': (lambda iface: ['iw', 'dev', iface, 'scan'], parse_iw),
    'iw_dump': (lambda iface: ['iw', 'dev', iface, 'scan', 'dump'],
                parse_iw),
    'nmcli': (lambda iface: ['nmcli', '-t', '-f', 'BSSID,SIGNAL,FREQ', 'dev',
                             'wifi', 'list', 'ifname', iface], parse_nmcli),
}


def network_interfaces(sys_class_net=SYS_CLASS_NET):
    """Return the names of all network interfaces, sorted."""
    root = Path(sys_class_net)
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir())


def wireless_interfaces(sys_class_net=SYS_CLASS_NET):
    """Return the names of the wireless interfaces, sorted."""
    root = Path(sys_class_net)
    return [name for name in network_interfaces(root)
            if (root / name / 'wireless').exists() or
            (root / name / 'phy80211').exists()]


def interface_problem(name, sys_class_net=SYS_CLASS_NET):
    """Return why interface ``name`` cannot be scanned (it is missing), or None."""
    present = network_interfaces(sys_class_net)
    if name in present:
        return None
    wireless = wireless_interfaces(sys_class_net)
    return (f'interface {name!r} does not exist; {sys_class_net} has '
            f'{", ".join(present) or "none"} (wireless: '
            f'{", ".join(wireless) or "none"})')


class SourceRunner:
    """
    Runs the sources' commands; :meth:`cancel` stops the running one.

    Each command runs in its own process group (a terminal's Ctrl-C does
    not reach it; a timeout or :meth:`cancel` kills the whole group), so a
    scan can be abandoned from another thread at any moment.
    """

    def __init__(self, timeout=20.0):
        self.timeout = timeout
        self._lock = threading.Lock()
        self._proc = None
        self._cancelled = False

    def cancel(self):
        """Kill the running command; every later read fails at once."""
        with self._lock:
            self._cancelled = True
            if self._proc is not None:
                _kill_group(self._proc)

    def read(self, name, iface):
        """Run one source; return its readings or raise SourceError."""
        command, parse = SOURCES[name]
        argv = command(iface)
        with self._lock:
            if self._cancelled:
                raise SourceError('stopped')
            try:
                self._proc = subprocess.Popen(
                    argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                    stdin=subprocess.DEVNULL, text=True,
                    start_new_session=True)
            except FileNotFoundError:
                raise SourceError(f'{argv[0]} is not installed') from None
            proc = self._proc
        try:
            out, err = proc.communicate(timeout=self.timeout)
        except subprocess.TimeoutExpired:
            _kill_group(proc)
            proc.communicate()
            raise SourceError(f'{" ".join(argv)} took more than '
                              f'{self.timeout:g} s') from None
        finally:
            with self._lock:
                self._proc = None
        if self._cancelled:
            raise SourceError('stopped')
        if proc.returncode != 0:
            reason = (err.strip() or out.strip() or
                      f'exit code {proc.returncode}').splitlines()[-1]
            raise SourceError(f'{" ".join(argv)}: {reason}')
        readings = parse(out)
        if not readings and out.strip():
            raise SourceError(f'{" ".join(argv)}: output had no readable AP')
        return readings

    def scan(self, sources, iface):
        """
        Try ``sources`` in order; return (source name, readings).

        Raises :class:`SourceError` with every source's reason if none works.
        """
        reasons = []
        for name in sources:
            try:
                return name, self.read(name, iface)
            except SourceError as exc:
                reasons.append(f'{name}: {exc}')
        raise SourceError('; '.join(reasons) or 'no source configured')


def _kill_group(proc):
    """Kill ``proc`` and every process of its group (e.g. a shell's)."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
