"""Running the documented commands (train_model, evaluate_model) measured."""

import json
import os
from pathlib import Path
import statistics
import subprocess
import sys
import tempfile
import time

from wifi_place_recognition.core.artifact import load_model


def measured(argv):
    """Run ``argv``; return (stdout, wall seconds, peak MiB)."""
    start = time.perf_counter()
    with tempfile.TemporaryFile('w+') as out, \
            tempfile.TemporaryFile('w+') as err:
        proc = subprocess.Popen(argv, stdout=out, stderr=err,
                                env=os.environ.copy())
        _, status, usage = os.wait4(proc.pid, 0)
        seconds = time.perf_counter() - start
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read(), err.read()
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f'{" ".join(map(str, argv))} failed:\n{stderr}')
    return stdout, seconds, usage.ru_maxrss / 1024


def command(name):
    """Return the argv that runs the package's command line tool ``name``."""
    return [sys.executable, '-m', f'wifi_place_recognition.cli.{name}']


def train_and_test(flags, seed, train, test, data_args, folder):
    """
    Train by the documented command; return the test figures.

    Adds the training's wall time and peak memory, and what the model's
    selection measured on held-out training scans (``cv_*``).
    """
    model = Path(folder) / f'model-{seed}.npz'
    _, seconds, peak = measured(
        command('train_model') + ['--data', *train, *data_args, '-o', model,
                                  '--seed', str(seed), '--quiet', *flags])
    stdout, _, _ = measured(
        command('evaluate_model') + ['--model', model, '--data', *test,
                                     *data_args, '--json'])
    result = json.loads(stdout)
    result.pop('confusion')
    provenance = load_model(model).provenance
    selection = provenance.get('selection', {})
    result.update(train_seconds=seconds, train_peak_mib=peak,
                  epochs=provenance.get('epochs'),
                  cv_building_floor=selection.get('accuracy_mean'),
                  cv_position_mean_error_m=selection.get(
                      'position_mean_error_m'))
    return result


def summary(values):
    """Return mean, min, max (and the values) of a list of numbers."""
    values = [v for v in values if v is not None]
    if not values:
        return None
    return {'mean': statistics.fmean(values), 'min': min(values),
            'max': max(values), 'values': values}
