"""Where the shipped model lives: the package share directory, or the source tree."""

from pathlib import Path

PACKAGE = 'wifi_place_recognition'
SHIPPED_MODEL = 'ujiindoorloc.npz'


def default_model_path():
    """
    Return the shipped UJIIndoorLoc model's path.

    Looked up in ``share/wifi_place_recognition/models`` (colcon or
    ``pip install .``; needs ``AMENT_PREFIX_PATH``), else in the ``models/``
    folder of a source checkout (``pip install -e .``, ``PYTHONPATH``).
    """
    try:
        from ament_index_python.packages import (
            get_package_share_directory, PackageNotFoundError)
        try:
            share = Path(get_package_share_directory(PACKAGE))
            if (share / 'models' / SHIPPED_MODEL).exists():
                return share / 'models' / SHIPPED_MODEL
        except (PackageNotFoundError, OSError, ValueError):
            pass
    except ImportError:
        pass
    return Path(__file__).resolve().parent.parent / 'models' / SHIPPED_MODEL
