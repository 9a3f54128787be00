"""
Robot runs from ROS bags: the scans, odometry and poses of a recording.

A bag is a rosbag2 folder (``metadata.yaml``), a rosbag2 file (``.mcap``,
``.db3``) or a ROS 1 ``.bag``, read with the pure-Python ``rosbags``
library (no ROS install needed). Three topics, named by :class:`BagOptions`
(a leading ``/`` or none): the scans (``sensor_msgs/msg/JointState``:
``name`` = BSSID, ``position`` = RSSI dBm, as on ``wifi/scan``), the
odometry (``nav_msgs/msg/Odometry``) and the localiser's poses
(``geometry_msgs/msg/PoseWithCovarianceStamped``, e.g. ``amcl_pose``);
each message at its ``header.stamp``. A topic of another type is refused
naming the type; the scans are needed, the odometry and poses not (a tool
that needs them says so).

The labelling rule (:func:`pose_labels`) is the recorders'
(:mod:`.core.pose_label`, with its default ``max_pose_age``): a scan gets
the pose linearly interpolated (yaw along the shorter arc) between the
two poses around its stamp when both are within ``max_pose_age``, else
the nearest within it; a scan with neither gets none and is left out of
a labelled run, with a note (doc/your-building.md, "Bags in").

A scan's readings follow the recorder's rule: readings that are not
finite or not plausible RSSI are left out (counted), (0, 20] dBm is
clipped to 0, an AP read twice keeps its strongest reading, and a scan
left with no reading is left out (counted).
"""

from dataclasses import dataclass, field
import hashlib
from pathlib import Path

import numpy as np

from ..core.pose_label import blend, MAX_POSE_AGE, pair, Pose
from ..core.rssi import clip_plausible, plausible
from ..core.scan import normalize_ap_id, ScanMapper
from .columns import TIME, writable_cell, YAW
from .files import DataError
from .fingerprints import Fingerprints
from .poses import COVARIANCE_COLUMNS  # noqa: F401 (the poses' columns)
from .table import MAX_LABEL

SCAN_TYPE = 'sensor_msgs/msg/JointState'
ODOMETRY_TYPE = 'nav_msgs/msg/Odometry'
POSE_TYPE = 'geometry_msgs/msg/PoseWithCovarianceStamped'
#: File suffixes of bags (a rosbag2 folder is one with a metadata.yaml).
BAG_SUFFIXES = ('.mcap', '.db3', '.bag')
#: The pose columns of the localiser's poses: those of a pose CSV, then
#: the covariances of the shared runs' ``poses.csv``.


@dataclass(frozen=True)
class BagOptions:
    """
    How to read bags: the topics (empty: none) and the scans' labels.

    Topics with or without a leading ``/``; ``building`` and ``floor``
    label every scan.
    """

    scan_topic: str = 'wifi/scan'
    odometry_topic: str = 'odom'
    pose_topic: str = 'amcl_pose'
    building: int = 0
    floor: int = 0

    def __post_init__(self):
        """Refuse options that cannot work, before any bag is read."""
        if not _topic(self.scan_topic):
            raise DataError('no scan topic given')
        if not (0 <= self.building <= MAX_LABEL and
                0 <= self.floor <= MAX_LABEL):
            raise DataError(f'building {self.building}, floor '
                            f'{self.floor}: labels are from 0 to '
                            f'{MAX_LABEL}')


@dataclass
class Recording:
    """
    What a bag holds, in stamp order.

    ``scans``: (stamp s, AP names, RSSI dBm) per kept scan; ``odometry``:
    float64 (n, 4) stamp, x, y, yaw; ``poses``: float64 (n, 8) stamp, x, y,
    yaw and :data:`COVARIANCE_COLUMNS` (None: no such topic).
    """

    source: str
    scans: list
    odometry: np.ndarray = None
    poses: np.ndarray = None
    sha256: str = ''
    notes: list = field(default_factory=list)


def is_bag(path):
    """Return whether ``path`` names a bag (rather than a CSV or a folder)."""
    path = Path(path)
    if path.is_dir():
        return (path / 'metadata.yaml').is_file()
    return path.suffix.lower() in BAG_SUFFIXES


def _library():
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import get_typestore, Stores
    except ImportError:
        raise DataError('reading bags needs the rosbags package (pip install '
                        'rosbags)') from None
    return AnyReader, get_typestore(Stores.ROS2_JAZZY)


def _topic(name):
    return '/' + name.strip('/') if name and name.strip('/') else ''


def _stamp(header):
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def _yaw(q):
    return np.arctan2(2.0 * (q.w * q.z + q.x * q.y),
                      1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _digest(path):
    path = Path(path)
    files = sorted(path.iterdir()) if path.is_dir() else [path]
    sha = hashlib.sha256()
    for f in files:
        if f.is_file():
            sha.update(f.name.encode() + b'\0')
            with open(f, 'rb') as data:
                while chunk := data.read(1 << 20):
                    sha.update(chunk)
    return sha.hexdigest()


def read_bag(path, options=BagOptions()):
    """
    Return the :class:`Recording` of a bag; raise :class:`DataError`.

    Refused, in one line naming the bag: a path that is not a bag or
    cannot be read (truncated, corrupt), a scan topic that is missing or
    has no message, a topic of the wrong type, a message whose stamp is
    zero or earlier than the one before on its topic.
    """
    AnyReader, typestore = _library()
    path = Path(path)
    if not path.exists():
        raise DataError(f'{path}: no such bag')
    wanted = {_topic(options.scan_topic): ('scans', SCAN_TYPE),
              _topic(options.odometry_topic): ('odometry', ODOMETRY_TYPE),
              _topic(options.pose_topic): ('poses', POSE_TYPE)}
    wanted.pop('', None)
    if len(wanted) < 1 + bool(_topic(options.odometry_topic)) + \
            bool(_topic(options.pose_topic)):
        raise DataError(f'{path}: one topic named for two streams')
    try:
        with AnyReader([path], default_typestore=typestore) as reader:
            rows = _messages(reader, path, wanted)
    except DataError:
        raise
    except Exception as exc:    # the library's errors: truncated, corrupt
        text = str(exc).strip().splitlines()
        raise DataError(f'{path}: cannot read the bag, truncated or '
                        f'corrupt? ({type(exc).__name__}'
                        f'{": " + text[0] if text else ""})') from None
    return _recording(path, rows, wanted)


def _messages(reader, path, wanted):
    """Return {kind: [rows]} of the wanted topics (None: topic absent)."""
    found = {c.topic: c.msgtype for c in reader.connections}
    rows = {}
    for topic, (kind, msgtype) in wanted.items():
        if topic not in found:
            if kind == 'scans':
                present = ', '.join(sorted(found)) or 'none'
                raise DataError(f'{path}: no topic {topic} (the scans; '
                                f'topics in the bag: {present}; give '
                                f'--bag-scan-topic)')
            continue
        if found[topic] != msgtype:
            raise DataError(f'{path}: topic {topic} is {found[topic]}, not '
                            f'{msgtype} (the {kind})')
        rows[kind] = []
    connections = [c for c in reader.connections if c.topic in wanted]
    for connection, _, raw in reader.messages(connections=connections):
        kind = wanted[connection.topic][0]
        msg = reader.deserialize(raw, connection.msgtype)
        stamp = _stamp(msg.header)
        out = rows[kind]
        if not stamp > 0:
            raise DataError(f'{path}: topic {connection.topic}, message '
                            f'{len(out) + 1}: stamp zero (header.stamp '
                            f'not set)')
        if out and stamp < out[-1][0]:
            raise DataError(f'{path}: topic {connection.topic}, message '
                            f'{len(out) + 1}: stamp {stamp:.6f} is earlier '
                            f'than the one before, {out[-1][0]:.6f} (time '
                            f'going backwards)')
        if kind == 'scans':
            out.append((stamp, list(msg.name), np.asarray(msg.position,
                                                          np.float64)))
            continue
        pose = msg.pose.pose
        row = [stamp, pose.position.x, pose.position.y,
               _yaw(pose.orientation)]
        if kind == 'poses':
            c = msg.pose.covariance
            row += [c[0], c[1], c[7], c[35]]
        out.append(row)
    return rows


def _recording(path, rows, wanted):
    """Return the :class:`Recording` of the rows; check what they hold."""
    scan_topic = next(t for t, (k, _) in wanted.items() if k == 'scans')
    scans, left_out, readings = [], 0, 0
    for stamp, names, rssi in rows['scans']:
        kept = _readings(names, rssi)
        if kept is None:
            left_out += 1
            continue
        readings += len(names) - len(kept[0])
        scans.append((stamp,) + kept)
    if not scans:
        raise DataError(f'{path}: no scan with a usable reading on '
                        f'{scan_topic} ({len(rows["scans"])} messages)')
    notes = []
    if left_out or readings:
        notes.append(f'{path}: {left_out} scan(s) with no usable reading '
                     f'and {readings} reading(s) (RSSI not finite or '
                     f'implausible, an AP name a CSV cell cannot hold, or '
                     f'names and RSSI of different lengths) left out')
    for topic, (kind, _) in wanted.items():
        if kind != 'scans' and kind not in rows:
            notes.append(f'{path}: no topic {topic} (the {kind})')

    def table(kind):
        if kind not in rows:
            return None
        if not rows[kind]:
            raise DataError(f'{path}: topic {_named(wanted, kind)} has no '
                            f'message')
        out = np.array(rows[kind], np.float64)
        finite = np.isfinite(out).all(axis=1)
        if not finite.any():
            raise DataError(f'{path}: topic {_named(wanted, kind)} has no '
                            f'message with a finite pose')
        if not finite.all():
            notes.append(f'{path}: {int((~finite).sum())} message(s) on '
                         f'{_named(wanted, kind)} with a pose or covariance '
                         f'that is not finite left out')
        return out[finite]
    return Recording(str(path), scans, table('odometry'), table('poses'),
                     _digest(path), notes)


def _named(wanted, kind):
    return next(t for t, (k, _) in wanted.items() if k == kind)


def _readings(names, rssi):
    """Return (AP ids, RSSI) kept from one scan by the recorder's rule."""
    if len(names) != len(rssi):
        return None
    ok = plausible(rssi)
    best = {}
    for name, value in zip([n for n, good in zip(names, ok) if good],
                           clip_plausible(rssi[ok])[0].tolist()):
        ap = normalize_ap_id(name)
        if writable_cell(ap):
            best[ap] = max(best.get(ap, -np.inf), value)
    if not best:
        return None
    return tuple(best), np.array(list(best.values()), np.float64)


def pose_labels(poses, stamps, max_age=MAX_POSE_AGE):
    """
    Return (xy (n, 2), yaw (n,)) at ``stamps``: the labelling rule.

    :mod:`.core.pose_label` over the poses (rows stamp, x, y, yaw, in
    stamp order; one map's, as a bag is one building and floor); NaN
    where no pose is within ``max_age`` seconds.
    """
    rows = [Pose(*row[:4], None) for row in poses.tolist()]
    times = [p.stamp for p in rows]
    out = np.full((len(stamps), 3), np.nan)
    for n, t in enumerate(np.asarray(stamps, np.float64).tolist()):
        found = pair(times, t, max_age)
        if found is not None:
            out[n] = blend(rows[found[0]], rows[found[1]], found[2])
    return out[:, :2], out[:, 2]


def heard_aps(recording):
    """Return the AP ids a recording's scans heard, sorted."""
    return tuple(sorted({ap for _, names, _ in recording.scans
                         for ap in names}))


def scan_matrix(recording, ap_ids=None):
    """
    Return (AP ids, float32 RSSI (n, m), NaN = not heard).

    ``ap_ids``: the columns (default: the APs heard, sorted); one the scans
    heard but ``ap_ids`` lacks is refused (ValueError naming it).
    """
    ap_ids = heard_aps(recording) if ap_ids is None else tuple(ap_ids)
    mapper = ScanMapper(ap_ids)
    rssi = np.full((len(recording.scans), len(ap_ids)), np.nan, np.float32)
    for i, (_, names, values) in enumerate(recording.scans):
        columns = mapper.columns(names)
        if (columns < 0).any():
            raise ValueError(f'AP {names[int(np.argmin(columns))]} is not '
                             f'among the {len(ap_ids)} columns given')
        rssi[i, columns] = values
    return ap_ids, rssi


def fingerprints(recording, building=0, floor=0):
    """
    Return the scans of a :class:`Recording` as :class:`.Fingerprints`.

    Labelled ``building``, ``floor``; ``TIMESTAMP`` in ``meta``; with poses,
    ``X``, ``Y`` and ``YAW`` by :func:`pose_labels` (scans it leaves
    unlabelled left out, with a note), as a run's ``scans.csv`` reads.
    """
    ap_ids, rssi = scan_matrix(recording)
    n = len(rssi)
    stamps = np.array([s[0] for s in recording.scans], np.float64)
    fp = Fingerprints(ap_ids, rssi, np.full(n, building, np.int64),
                      np.full(n, floor, np.int64), {TIME: stamps},
                      recording.source, sha256=recording.sha256,
                      notes=list(recording.notes))
    if recording.poses is None:
        return fp
    xy, yaw = pose_labels(recording.poses, stamps)
    fp.position, fp.position_columns = xy, ('X', 'Y')
    fp.meta[YAW] = yaw
    unplaced = ~np.isfinite(xy).all(axis=1)
    if unplaced.all():
        raise DataError(f'{recording.source}: no scan has a pose within '
                        f'{MAX_POSE_AGE:g} s of it')
    if unplaced.any():
        fp.notes.append(f'{recording.source}: {int(unplaced.sum())} scan(s) '
                        f'with no pose within {MAX_POSE_AGE:g} s left out')
        fp = fp.subset(~unplaced)
    return fp


def read_bags(paths, options=BagOptions()):
    """
    Return (:class:`.Fingerprints`, odometry, poses) of one or more bags.

    Several bags are one run in the order of their first scans (each
    scan's bag in ``walk``), refused if they overlap in time; odometry
    and poses (float64 rows as in :class:`Recording`, None when a bag
    lacks the topic) are joined.
    """
    recordings = sorted((read_bag(p, options) for p in paths),
                        key=lambda r: r.scans[0][0])
    for a, b in zip(recordings, recordings[1:]):
        if b.scans[0][0] <= a.scans[-1][0]:
            raise DataError(f'{a.source} and {b.source} overlap in time: '
                            f'give the bags of one run, or one at a time')
    parts = [fingerprints(r, options.building, options.floor)
             for r in recordings]
    if len(parts) == 1:
        fp = parts[0]
    else:
        fp = _joined(parts, recordings)

    def joined(kind):
        tables = [getattr(r, kind) for r in recordings]
        return None if any(t is None for t in tables) else \
            np.concatenate(tables)
    return fp, joined('odometry'), joined('poses')


def _joined(parts, recordings):
    """Return the scans of several bags as one :class:`.Fingerprints`."""
    ap_ids = tuple(sorted({ap for p in parts for ap in p.ap_ids}))
    mapper = ScanMapper(ap_ids)
    first = parts[0]
    placed = first.position is not None
    if any((p.position is not None) != placed for p in parts):
        raise DataError(f'{recordings[0].source} and others: some bags have '
                        f'poses, some not')
    sha = hashlib.sha256(''.join(r.sha256 for r in recordings).encode())
    meta = {k: np.concatenate([p.meta[k] for p in parts])
            for k in first.meta}
    return Fingerprints(
        ap_ids, np.concatenate([mapper.map_rows(p.ap_ids, p.rssi)
                                for p in parts]),
        np.concatenate([p.building for p in parts]),
        np.concatenate([p.floor for p in parts]), meta,
        f'{first.source} and {len(parts) - 1} more', sha256=sha.hexdigest(),
        walk=np.concatenate([np.full(len(p), p.source) for p in parts]),
        position=np.concatenate([p.position for p in parts])
        if placed else None,
        position_columns=first.position_columns,
        notes=[n for p in parts for n in p.notes])
