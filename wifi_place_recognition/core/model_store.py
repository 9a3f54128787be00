"""
A folder of kept models: each one installed, its report, which is in use.

Every model installed is kept as ``<stamp>-<sha>.npz`` (``stamp``: UTC
time of the install, ``sha``: the start of the file's SHA-256) beside its
report ``<stamp>-<sha>.json``. The file ``current`` lists the installed
names in the order they were put in use, one a line: the last is in use;
a rollback removes it, so the one before is in use again. ``current.npz``
is a symbolic link to the model in use (a start-up ``model_path``). A
refused candidate leaves only its report, ``<stamp>-refused.json``.

Every file is written atomically (:mod:`.atomic`) and ``current`` last:
a failure leaves the folder as it was (a model written before the failure
is removed). ``current`` is the truth; the link follows it.
"""

from datetime import datetime, timezone
import hashlib
import json
import os
from pathlib import Path

from .atomic import atomic_write

HISTORY = 'current'
LINK = 'current.npz'


class StoreError(ValueError):
    """A models folder that cannot do what was asked; the message says why."""


def _stamp():
    return datetime.now(timezone.utc).strftime('%Y%m%dT%H%M%S%fZ')


class ModelStore:
    """The models folder ``folder`` (see the module)."""

    def __init__(self, folder):
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise StoreError(f'models folder {self.folder}: not a folder')

    def history(self):
        """Return the installed names in the order put in use (last: now)."""
        try:
            names = (self.folder / HISTORY).read_text().split()
        except FileNotFoundError:
            return []
        except (OSError, UnicodeDecodeError) as exc:
            raise StoreError(f'{self.folder / HISTORY}: cannot read it '
                             f'({exc})') from None
        outside = [n for n in names if Path(n).name != n or n in ('.', '..')]
        if outside:
            raise StoreError(f'{self.folder / HISTORY}: lists {outside[0]}, '
                             f'not a file name of the folder')
        missing = [n for n in names
                   if not (self.folder / f'{n}.npz').is_file()]
        if missing:
            raise StoreError(f'{self.folder / HISTORY}: lists '
                             f'{", ".join(missing)}, not in the folder')
        return names

    def current(self):
        """Return the path of the model in use, or None (none installed)."""
        names = self.history()
        return self.folder / f'{names[-1]}.npz' if names else None

    def install(self, model_path, report):
        """
        Keep the model file ``model_path`` with ``report``, put it in use.

        ``report`` (a dict, JSON-serialisable) gets the file's name and
        SHA-256. Return the kept model's path.
        """
        data = Path(model_path).read_bytes()
        sha = hashlib.sha256(data).hexdigest()
        name = f'{_stamp()}-{sha[:12]}'
        text = json.dumps(dict(report, file=f'{name}.npz', sha256=sha),
                          indent=1, allow_nan=False) + '\n'
        names = self.history() + [name]
        written = []
        try:
            for path, mode, content in (
                    (self.folder / f'{name}.npz', 'wb', data),
                    (self.folder / f'{name}.json', 'w', text)):
                written.append(path)
                with atomic_write(path, mode) as f:
                    f.write(content)
            self._write_history(names)
        except BaseException:
            for path in written:
                path.unlink(missing_ok=True)
            raise
        self._link(names[-1])
        return self.folder / f'{name}.npz'

    def refused(self, report):
        """Keep the report of a refused candidate; return its path."""
        path = self.folder / f'{_stamp()}-refused.json'
        text = json.dumps(report, indent=1, allow_nan=False) + '\n'
        with atomic_write(path, 'w') as f:
            f.write(text)
        return path

    def rollback(self):
        """
        Put the model in use before the current one back in use.

        Return (the model now in use, the one taken out of use); both stay
        in the folder.
        """
        names = self.history()
        if len(names) < 2:
            raise StoreError(f'models folder {self.folder}: nothing to roll '
                             f'back to ({len(names)} model(s) in use so '
                             f'far)')
        self._write_history(names[:-1])
        self._link(names[-2])
        return (self.folder / f'{names[-2]}.npz',
                self.folder / f'{names[-1]}.npz')

    def _write_history(self, names):
        """Write ``current`` atomically."""
        with atomic_write(self.folder / HISTORY, 'w') as f:
            f.write(''.join(f'{n}\n' for n in names))

    def _link(self, name):
        """Point ``current.npz`` at the model ``name`` (replaced at once)."""
        link = self.folder / LINK
        tmp = self.folder / f'.{LINK}.{os.getpid()}.tmp'
        tmp.unlink(missing_ok=True)
        os.symlink(f'{name}.npz', tmp)
        os.replace(tmp, link)
