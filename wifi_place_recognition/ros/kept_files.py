"""
A recorder's growing files, kept through write faults (for the nodes).

:class:`KeptFiles` holds a node's :class:`.data.recording.FingerprintLog`
and :class:`.data.recording.PoseLog` files: a write that fails is counted
once per fault and logged (throttled), the rows wait in memory and are
written by the next write that works (:meth:`KeptFiles.flush`, every
second); those still waiting when the node stops go to a new file in the
temporary folder (or the home folder), which the log names.
"""

from pathlib import Path
import tempfile

THROTTLE_S = 10.0


class KeptFiles:
    """The files of a node that logs to ``logger`` and counts in ``counts``."""

    def __init__(self, logger, counts):
        self.logger = logger
        self.counts = counts
        #: (log, what its rows are, its write-error count) of each file;
        #: the first one's rows are also written with each scan.
        self.files = []
        self._failing = set()

    def add(self, log, what, errors):
        """Keep ``log``, whose rows are ``what``, counting in ``errors``."""
        self.files.append((log, what, errors))
        self.counts[errors] = 0

    def check(self, log):
        """Log a write error of ``log`` (throttled), or that it works again."""
        _, what, errors = next(f for f in self.files if f[0] is log)
        if log.write_error is not None:
            if log.path not in self._failing:
                self.counts[errors] += 1
            self._failing.add(log.path)
            self.logger.error(
                f'cannot write {log.path}: {log.write_error}; '
                f'{len(log.pending)} {what} kept in memory, retrying every '
                f'second' + (' and with each scan' if log is self.files[0][0]
                             else ''), throttle_duration_sec=THROTTLE_S)
        elif log.path in self._failing:
            self._failing.discard(log.path)
            self.logger.info(f'writing {log.path} works again: the '
                             f'{what} kept in memory are written')

    def flush(self):
        """Write what waits in memory; log how it went."""
        for log, _, _ in self.files:
            if log.pending:
                log.flush()
                self.check(log)

    def failing(self):
        """Return the message of the files that cannot be written, or ''."""
        first = self.files[0][0]
        return ''.join(
            f'cannot write{"" if log is first else " " + log.path.name}: '
            f'{log.write_error}; {len(log.pending)} {what} kept in memory; '
            for log, what, _ in self.files if log.write_error is not None)

    def save(self):
        """Write what waits (else to a fallback file): the node stops."""
        for log, what, _ in self.files:
            if log.pending and not log.flush():
                self._save_pending(log, what)

    def _save_pending(self, log, what):
        n = len(log.pending)
        for folder in (tempfile.gettempdir(), Path.home()):
            try:
                path = log.save_pending(folder)
            except OSError as exc:
                self.logger.error(f'cannot save to {folder}: {exc}')
                continue
            self.logger.error(
                f'cannot write {log.path}: {log.write_error}; the {n} '
                f'{what} not in it are saved in {path}')
            return
        self.logger.fatal(f'{n} {what} could not be saved')
