"""
Fingerprint files: paths, folders and zips to bytes; the UCI download.

A path may be a CSV file, a folder (every ``*.csv`` in it, one walk each),
``ujiindoorloc.zip`` (the member for the role: trainingData.csv or
validationData.csv) or ``archive.zip#member.csv``.
"""

import hashlib
from pathlib import Path
import urllib.request
import zipfile

from ..core.archive import ZIP_ERRORS
from ..core.atomic import atomic_write

UCI_URL = 'https://archive.ics.uci.edu/static/public/310/ujiindoorloc.zip'
#: SHA-256 of the UCI ``trainingData.csv``, checked inside a downloaded zip.
UCI_TRAINING_SHA256 = ('45ca0128bd12019c976bb4793e407c979c82995d7a5940ab72'
                       '88620247905168')
ZIP_MEMBERS = {'train': 'trainingData.csv', 'test': 'validationData.csv'}


class DataError(ValueError):
    """A fingerprint file that cannot be used, with the place that is wrong."""


def input_files(paths, role):
    """
    Return ([(name, walk, bytes)], source) for the given paths.

    ``walk`` is None for a single file; with several files (a folder or
    several paths) it names the file each scan will come from.
    """
    several = len(paths) > 1
    files = []
    for spec in map(str, paths):
        if not Path(spec).is_dir():
            name, raw = _read_bytes(spec, role)
            files.append((name, name if several else None, raw))
            continue
        found = sorted(p for p in Path(spec).iterdir()
                       if p.suffix.lower() == '.csv' and p.is_file())
        if not found:
            folders = sorted(p.name for p in Path(spec).iterdir()
                             if p.is_dir())
            hint = f' (it has folders: {", ".join(folders)})' \
                if folders else ''
            raise DataError(f'{spec}: no .csv files in this folder{hint}')
        for p in found:
            files.append((str(p), str(p) if several else p.name,
                          _read_bytes(str(p), role)[1]))
    if several:
        return files, f'{paths[0]} and {len(paths) - 1} more'
    return files, str(paths[0]) if files[0][1] else files[0][0]


def digest(files):
    """
    Return the SHA-256 of the files of :func:`input_files`.

    One file: of its bytes; several: over each file's name and bytes, in
    name order.
    """
    if files[0][1] is None:
        return hashlib.sha256(files[0][2]).hexdigest()
    sha = hashlib.sha256()
    for _, walk, raw in sorted(files, key=lambda f: f[1]):
        sha.update(walk.encode() + b'\0' + len(raw).to_bytes(8, 'big') + raw)
    return sha.hexdigest()


def decode(data, name):
    """
    Return the text of a file's bytes (UTF-8, with or without BOM).

    Lines may end in LF, CR LF or a bare CR: each becomes LF.
    """
    try:
        text = data.decode('utf-8-sig')
    except UnicodeDecodeError as exc:
        raise DataError(f'{name}: not UTF-8 text ({exc.reason} at byte '
                        f'{exc.start})') from None
    return text.replace('\r\n', '\n').replace('\r', '\n') if '\r' in text \
        else text


def _read_bytes(spec, role):
    archive, _, member = spec.partition('#')
    try:
        if archive.lower().endswith('.zip'):
            with zipfile.ZipFile(archive) as zf:
                name = _zip_member(zf, member or ZIP_MEMBERS[role], archive)
                return f'{archive}#{name}', zf.read(name)
        return spec, Path(spec).read_bytes()
    except (OSError, *ZIP_ERRORS) as exc:
        raise DataError(f'{spec}: cannot read: '
                        f'{str(exc) or type(exc).__name__}') from None


def _zip_member(zf, wanted, archive):
    for name in zf.namelist():
        if name == wanted or name.rsplit('/', 1)[-1] == wanted:
            return name
    raise DataError(f'{archive}: no member {wanted!r} '
                    f'(has: {", ".join(zf.namelist())})')


def download_uci(cache_dir, url=UCI_URL, sha256=UCI_TRAINING_SHA256):
    """
    Fetch the UCI zip into ``cache_dir`` (once) and return its path.

    The zip itself has no published checksum; its ``trainingData.csv`` has
    (see the dataset README), so that member's SHA-256 is verified. The file
    is written atomically: an interrupted download leaves nothing behind.
    """
    cache_dir = Path(cache_dir)
    target = cache_dir / 'ujiindoorloc.zip'
    if target.exists():
        return target
    cache_dir.mkdir(parents=True, exist_ok=True)
    try:
        with atomic_write(target, 'w+b') as out, \
                urllib.request.urlopen(url) as resp:
            while chunk := resp.read(1 << 20):
                out.write(chunk)
            try:
                with zipfile.ZipFile(out) as zf:
                    member = _zip_member(zf, ZIP_MEMBERS['train'], url)
                    digest = hashlib.sha256(zf.read(member)).hexdigest()
            except zipfile.BadZipFile:
                raise DataError(f'{url}: download is not a zip file') \
                    from None
            if digest != sha256:
                raise DataError(f'{url}: trainingData.csv has SHA-256 '
                                f'{digest}, expected {sha256}')
    except OSError as exc:
        raise DataError(f'{url}: download failed: {exc}') from None
    return target
