"""Atomic file writes: readers see the old file or the new one, never a torn one."""

import contextlib
import errno
import os
import stat
import tempfile
from pathlib import Path


#: Errors of writing the file itself (no name of their own): named after it.
WRITE_ERRORS = (errno.EFBIG, errno.ENOSPC, errno.EDQUOT, errno.EIO)


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def probe_folder(path):
    """Raise OSError unless a file can be created beside ``path``."""
    path = Path(path)
    fd, probe = tempfile.mkstemp(dir=path.parent, prefix=f'.{path.name}.',
                                 suffix='.probe')
    os.close(fd)
    os.unlink(probe)


@contextlib.contextmanager
def atomic_write(path, mode='wb', **kwargs):
    """
    Yield a file object; on success it replaces ``path`` (fsynced).

    On any exception, or if the process dies, ``path`` keeps its previous
    content and the temporary file is removed (or left as ``.<name>.*.tmp``
    after a kill). An OSError of the write names ``path``, not the
    temporary file. A symbolic link stays one (its target is replaced);
    an existing file keeps its permissions, a new one gets the umask's.
    """
    shown = str(path)
    path = Path(os.path.realpath(path))
    folder = path.parent
    try:
        permissions = stat.S_IMODE(os.stat(path).st_mode)
    except OSError:
        permissions = 0o666 & ~_umask()
    try:
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=f'.{path.name}.',
                                   suffix='.tmp')
    except OSError as exc:      # no folder, not a folder, no permission
        raise OSError(exc.errno, exc.strerror, shown) from None
    try:
        try:
            os.fchmod(fd, permissions)
            f = os.fdopen(fd, mode, **kwargs)
        except BaseException:
            os.close(fd)
            raise
        with f:
            try:
                yield f
                f.flush()
                os.fsync(f.fileno())
            except OSError as exc:
                if exc.filename is not None or \
                        exc.errno not in WRITE_ERRORS:
                    raise
                raise OSError(exc.errno, exc.strerror, shown) from None
        try:
            os.replace(tmp, path)
        except OSError as exc:  # e.g. path is a folder
            raise OSError(exc.errno, exc.strerror, shown) from None
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    dir_fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)
