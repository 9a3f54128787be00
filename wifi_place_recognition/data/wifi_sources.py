"""
Where a robot's WiFi scans come from on Linux: ``iw`` and NetworkManager.

ROS-free: parsers of the tools' text output and a runner that tries the
sources in order. Each reading is ``(bssid, rssi_dbm)`` with the BSSID in
lower-case ``aa:bb:cc:dd:ee:ff`` form.

- ``iw dev IF scan``: triggers a fresh scan (needs CAP_NET_ADMIN).
- ``iw dev IF scan dump``: the kernel's cached results of the last scan
  (any scan, also NetworkManager's); no privileges needed.
- ``nmcli -t -f BSSID,SIGNAL,FREQ dev wifi list ifname IF``: SIGNAL is a
  percentage. NetworkManager computes it from dBm (nl80211) as
  ``100 - 70 * (-20 - dBm) / 70`` clamped to [-90, -20] dBm, i.e.
  ``percent = dBm + 120``; so ``dBm = percent - 120``, and any percentage
  under 30 reads as -90 dBm (the floor NetworkManager reports).
"""

from pathlib import Path
import re
import subprocess

MAC = re.compile(r'^[0-9a-f]{2}(:[0-9a-f]{2}){5}$')
NM_FLOOR_DBM = -90.0
NM_OFFSET_DB = 120.0


class SourceError(RuntimeError):
    """A scan source that cannot deliver; the message says why."""


def _mac(text):
    text = text.strip().lower()
    return text if MAC.match(text) else None


def parse_iw(text):
    """
    Return [(bssid, dBm)] from ``iw dev IF scan`` or ``scan dump`` output.

    Entries without a BSSID, a signal line, or a plausible dBm value are
    skipped, so truncated or garbled output yields the complete entries.
    """
    readings, bssid = [], None
    for line in text.splitlines():
        stripped = line.strip()
        if line.startswith('BSS '):
            bssid = _mac(line[4:].split('(')[0].split()[0]) \
                if len(line) > 4 else None
        elif bssid and stripped.startswith('signal:'):
            try:
                dbm = float(stripped.split()[1])
            except (IndexError, ValueError):
                continue
            if -120.0 <= dbm <= 20.0:
                readings.append((bssid, dbm))
            bssid = None
    return readings


def nm_percent_to_dbm(percent):
    """Return the dBm that NetworkManager turned into ``percent``."""
    return max(NM_FLOOR_DBM, float(percent) - NM_OFFSET_DB)


def parse_nmcli(text):
    r"""
    Return [(bssid, dBm)] from ``nmcli -t -f BSSID,SIGNAL,FREQ ...``.

    In terse output ``:`` inside a field is escaped as ``\:``.
    """
    readings = []
    for line in text.splitlines():
        fields = re.split(r'(?<!\\):', line.strip())
        if len(fields) < 2:
            continue
        bssid = _mac(fields[0].replace('\\:', ':'))
        try:
            percent = float(fields[1])
        except ValueError:
            continue
        if bssid and 0.0 <= percent <= 100.0:
            readings.append((bssid, nm_percent_to_dbm(percent)))
    return readings


SOURCES = {
    'iw': (lambda iface: ['iw', 'dev', iface, 'scan'], parse_iw),
    'iw_dump': (lambda iface: ['iw', 'dev', iface, 'scan', 'dump'],
                parse_iw),
    'nmcli': (lambda iface: ['nmcli', '-t', '-f', 'BSSID,SIGNAL,FREQ', 'dev',
                             'wifi', 'list', 'ifname', iface], parse_nmcli),
}


def wireless_interfaces(sys_class_net='/sys/class/net'):
    """Return the names of the wireless interfaces, sorted."""
    root = Path(sys_class_net)
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir()
                  if (p / 'wireless').exists() or (p / 'phy80211').exists())


def read_source(name, iface, timeout=20.0):
    """Run one source; return its readings or raise :class:`SourceError`."""
    command, parse = SOURCES[name]
    argv = command(iface)
    try:
        done = subprocess.run(argv, capture_output=True, text=True,
                              timeout=timeout)
    except FileNotFoundError:
        raise SourceError(f'{argv[0]} is not installed') from None
    except subprocess.TimeoutExpired:
        raise SourceError(f'{" ".join(argv)} took more than {timeout:g} s') \
            from None
    if done.returncode != 0:
        reason = (done.stderr.strip() or done.stdout.strip()
                  or f'exit code {done.returncode}').splitlines()[-1]
        raise SourceError(f'{" ".join(argv)}: {reason}')
    readings = parse(done.stdout)
    if not readings and done.stdout.strip():
        raise SourceError(f'{" ".join(argv)}: output had no readable AP')
    return readings


def scan(sources, iface, timeout=20.0):
    """
    Try ``sources`` in order; return (source name, readings).

    Raises :class:`SourceError` with every source's reason if none works.
    """
    reasons = []
    for name in sources:
        try:
            return name, read_source(name, iface, timeout)
        except SourceError as exc:
            reasons.append(f'{name}: {exc}')
    raise SourceError('; '.join(reasons) or 'no source configured')
