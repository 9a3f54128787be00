"""Hostile and faulty input: torn writes, fuzzed scans, a flood of scans."""

import ctypes
import os
from pathlib import Path
import select
import shutil
import signal
import struct
import subprocess
import sys
import time

from conftest import (FAST, python_module, synthetic_csv, TEST_DIR,
                      wait_until)
from fuzz import fuzz_scans
import numpy as np
import pytest
from ros_helpers import running_node
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.resources import default_model_path
from wifi_place_recognition.ros.messages import status_values

SAVE_LOOP = (f'import sys; sys.path.insert(0, {str(TEST_DIR)!r}); '
             'from fuzz import rewrite_forever; rewrite_forever(sys.argv[1])')


class Creations:
    """Files created in a folder from now on, as Linux inotify reports them."""

    IN_CREATE = 0x100
    EVENT = struct.Struct('iIII')   # wd, mask, cookie, length of the name

    def __init__(self, folder):
        self.folder = Path(folder)
        libc = ctypes.CDLL(None, use_errno=True)
        self.fd = libc.inotify_init1(os.O_CLOEXEC)
        if self.fd < 0 or libc.inotify_add_watch(
                self.fd, os.fsencode(folder), self.IN_CREATE) < 0:
            raise OSError(ctypes.get_errno(), f'inotify on {folder}')

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        os.close(self.fd)

    def next(self, suffix, timeout):
        """Return the path of the next file created ending in ``suffix``."""
        deadline = time.monotonic() + timeout
        while select.select([self.fd], [], [],
                            max(0.0, deadline - time.monotonic()))[0]:
            events, offset = os.read(self.fd, 1 << 16), 0
            while offset < len(events):
                *_, size = self.EVENT.unpack_from(events, offset)
                offset += self.EVENT.size + size
                name = os.fsdecode(events[offset - size:offset].rstrip(b'\0'))
                if name.endswith(suffix):
                    return self.folder / name
        return None


def _kill_mid_write(proc, creations, timeout, delay=0.0):
    """
    SIGKILL ``proc`` ``delay`` s after it creates a temporary file.

    Return True if the kill landed mid-write: the temporary file is left
    behind (a finished write renames it, a failed one removes it).
    """
    deadline = time.monotonic() + timeout
    tmp = None
    while tmp is None and proc.poll() is None and \
            time.monotonic() < deadline:
        tmp = creations.next('.tmp', 1.0)
    time.sleep(delay)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    if tmp is None or not tmp.exists():
        return False
    tmp.unlink()
    return True


def test_sigkill_while_saving_never_tears_the_model_file(tmp_path):
    path = tmp_path / 'model.npz'
    rng = np.random.default_rng(0)
    mid_write, attempts = 0, 0
    while mid_write < 12:
        attempts += 1
        assert attempts <= 40, (f'only {mid_write} of {attempts - 1} kills '
                                f'landed while a write was in progress')
        proc = subprocess.Popen([sys.executable, '-c', SAVE_LOOP, str(path)],
                                stdout=subprocess.PIPE, text=True)
        assert proc.stdout.readline(), 'the writer died before its first write'
        with Creations(tmp_path) as creations:   # a 16 MB write: ~40 ms
            mid_write += _kill_mid_write(proc, creations, 60,
                                         rng.uniform(0, 0.03))
        finished = [1] + [int(n) for n in proc.stdout.read().split()]
        model = load_model(path)        # never a torn file
        # The last finished write (or one killed between rename and print).
        assert model.provenance['write'] in (finished[-1], finished[-1] + 1), \
            (model.provenance['write'], finished[-1])


def test_sigkill_of_train_model_keeps_the_previous_artifact(tmp_path):
    path = tmp_path / 'model.npz'
    shutil.copyfile(default_model_path(), path)
    # A short run of a wide model: a 4 MB file takes a few ms to write.
    data = synthetic_csv(tmp_path / 'wide.csv', n_aps=1000)
    argv = python_module('cli.train_model', '--data', data, '-o', path, *FAST,
                         '--sae-layers', '1024,16', '--sae-epochs', '1',
                         '--epochs', '2', '--folds', '0')
    for attempt in range(3):
        before = path.read_bytes()
        with Creations(tmp_path) as creations:
            proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL,
                                    stderr=subprocess.DEVNULL)
            if _kill_mid_write(proc, creations, 300):
                break
        load_model(path)                # the write finished before the kill
    else:
        pytest.fail('no kill of train_model landed mid-write in 3 runs')
    assert path.read_bytes() == before
    load_model(path)


@pytest.fixture
def fuzz_node(ros, synthetic, tmp_path):
    """Start a node on the synthetic model with the default max_aps."""
    with running_node(ros, tmp_path, synthetic[1], 'fuzzed_node') as started:
        yield started


def test_fuzzed_scans_never_kill_the_node(fuzz_node):
    client, proc, model = fuzz_node
    for msg in fuzz_scans(model.ap_ids, 10_000, seed=1):
        client.publish(msg)
        if client.sent % 200 == 0:
            wait_until(lambda: False, 0.01, client.node)
    assert proc.proc.poll() is None, proc.stop()[1]
    counts, values = client.settled_counts()
    assert counts['received'] > 1000, counts
    assert counts['rejected'] > 100 and counts['answered'] > 10, counts
    assert values['rejected/internal_error'] == '0'
    ids = model.ap_ids[:5]
    expected = model.predict(np.where(
        np.isin(np.array(model.ap_ids), ids), -55.0, np.nan)[None, :])
    status = client.send(ids, [-55.0] * 5)
    assert status_values(status)['building'] == str(expected[0][0])
    assert status_values(status)['floor'] == str(expected[1][0])


def test_a_flood_keeps_memory_bounded_and_answers_the_newest(fuzz_node):
    client, proc, model = fuzz_node
    _, before = client.settled_counts()
    names = list(model.ap_ids[:8])
    t0 = time.monotonic()
    while time.monotonic() - t0 < 5.0:
        for _ in range(100):
            client.publish(client.scan(names, [-60.0] * 8))
        wait_until(lambda: False, 0.001, client.node)
    newest = client.scan(names, [-60.0] * 8)
    # Best-effort delivery may lose a scan of a burst: resend until answered.
    assert client.resend_until_answered(newest, 60) is not None, \
        f'the newest scan was not answered within 60 s; {proc.stop()[1]}'
    counts, after = client.settled_counts()
    assert counts['dropped'] > 0, counts
    growth = float(after['peak_rss_mib']) - float(before['rss_mib'])
    assert growth < 100, (before['rss_mib'], after['peak_rss_mib'])
