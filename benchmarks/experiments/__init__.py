"""
The accuracy benchmark's experiments, by the name ``--suite`` takes.

Each module here answers one question: its ``EXPERIMENTS`` maps names to
functions ``run(args, data)`` (``data``: :class:`.common.Data`) that return
the JSON content of the run. A new question is a new module; no other file
changes.
"""

import importlib
import pkgutil


def registry():
    """Return {name: run function} of every module in this folder."""
    found = {}
    for info in pkgutil.iter_modules(__path__):
        module = importlib.import_module(f'{__name__}.{info.name}')
        for name, run in getattr(module, 'EXPERIMENTS', {}).items():
            if name in found:
                raise ValueError(f'experiment {name!r} is defined twice')
            found[name] = run
    return found
