"""Where the shipped model lives: an install's share directory, or the source tree."""

import sys
from pathlib import Path

PACKAGE = 'wifi_place_recognition'
SHIPPED_MODEL = 'ujiindoorloc.npz'


def _share_directories():
    """Yield candidate ``share/wifi_place_recognition`` folders, best first."""
    try:
        from ament_index_python.packages import (
            get_package_share_directory, PackageNotFoundError)
        try:  # colcon install, or any prefix on AMENT_PREFIX_PATH
            yield Path(get_package_share_directory(PACKAGE))
        except (PackageNotFoundError, OSError, ValueError):
            pass
    except ImportError:
        pass
    yield Path(sys.prefix) / 'share' / PACKAGE  # pip install . (no env)
    yield Path(__file__).resolve().parents[2]  # source checkout, pip -e


def default_model_path():
    """
    Return the shipped UJIIndoorLoc model's path.

    Looked up in ``share/wifi_place_recognition/models`` of the ament index
    (colcon, or ``AMENT_PREFIX_PATH``), then of the running interpreter's
    prefix (``pip install .``, no environment variable needed), then in the
    ``models/`` folder of a source checkout (``pip install -e .``).
    """
    candidates = [d / 'models' / SHIPPED_MODEL for d in _share_directories()]
    return next((c for c in candidates if c.is_file()), candidates[-1])
