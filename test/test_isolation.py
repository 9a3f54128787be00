"""What stays apart: the core from ROS and torch, a test run from another."""

import json
import sys

from conftest import DOMAIN_ID, run, TEST_DIR
import numpy as np
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.recognizer import PlaceRecognizer
from wifi_place_recognition.core.resources import default_model_path

BLOCKED = ('rclpy', 'torch', 'rcl_interfaces', 'sensor_msgs',
           'diagnostic_msgs', 'ament_index_python')

WITHOUT_ROS_AND_TORCH = '''
import importlib, json, pkgutil, sys

blocked = set(sys.argv[1].split(','))
early = sorted(m for m in sys.modules if m.partition('.')[0] in blocked)
assert not early, f'imported before the block: {early}'


class Block:
    """Make every blocked top-level package impossible to import."""

    def find_spec(self, name, path=None, target=None):
        if name.partition('.')[0] in blocked:
            raise ImportError(f'{name} is blocked (core without ROS/torch)')


sys.meta_path.insert(0, Block())
imported = []
for layer in ('core', 'data'):
    package = importlib.import_module(f'wifi_place_recognition.{layer}')
    for info in pkgutil.iter_modules(package.__path__):
        imported.append(importlib.import_module(
            f'{package.__name__}.{info.name}').__name__)
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.recognizer import PlaceRecognizer
from wifi_place_recognition.core.resources import default_model_path
model = load_model(default_model_path())
place = PlaceRecognizer(model).classify(model.ap_ids[:6], [-60.0] * 6)
leaked = sorted(m for m in sys.modules if m.partition('.')[0] in blocked)
print(json.dumps({'imported': imported, 'leaked': leaked,
                  'place': [place.building, place.floor, place.confidence]}))
'''


def test_core_and_data_work_without_ros_and_torch():
    result = run([sys.executable, '-c', WITHOUT_ROS_AND_TORCH,
                  ','.join(BLOCKED)])
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    assert out['leaked'] == []
    assert {'wifi_place_recognition.core.recognizer',
            'wifi_place_recognition.core.model',
            'wifi_place_recognition.data.fingerprints'} <= set(out['imported'])
    # The same answer as with everything importable.
    model = load_model(default_model_path())
    place = PlaceRecognizer(model).classify(model.ap_ids[:6], [-60.0] * 6)
    assert out['place'][:2] == [place.building, place.floor]
    np.testing.assert_allclose(out['place'][2], place.confidence, rtol=1e-6)


CLAIM = ('import sys; sys.path.insert(0, sys.argv[1]); import conftest; '
         'print(conftest.DOMAIN_ID); d = int(sys.argv[2]); '
         'conftest.claim_domain_id(range(d, d + 1))')


def test_a_concurrent_run_cannot_take_this_runs_domain_id():
    result = run([sys.executable, '-c', CLAIM, TEST_DIR, str(DOMAIN_ID)])
    # The other run got another id, and not ours even when it asks for it.
    assert result.stdout.strip().isdigit(), result.stderr
    assert int(result.stdout) != DOMAIN_ID
    assert result.returncode == 1
    assert 'held by another live test run' in result.stderr
