"""What stays apart: the core from ROS and torch, a test run from another."""

import json
import os
from pathlib import Path
import sys
from xml.etree import ElementTree

from conftest import DOMAIN_ID, REPO, run, TEST_DIR
import numpy as np
import pytest
from ros_helpers import Client, NodeProcess
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.recognizer import PlaceRecognizer
from wifi_place_recognition.core.resources import default_model_path

# Every ROS package the nodes declare (package.xml), e.g. rclpy, messages.
ROS = tuple(e.text for tag in ('depend', 'exec_depend') for e in
            ElementTree.parse(REPO / 'package.xml').getroot().iter(tag)
            if not e.text.startswith('python3-'))
TRAINING = ('torch', 'sklearn')

IMPORT_AND_CLASSIFY = '''
import importlib, json, pkgutil, sys

blocked = set(sys.argv[1].split(','))
early = sorted(m for m in sys.modules if m.partition('.')[0] in blocked)
assert not early, f'imported before the block: {early}'


class Block:
    """Make every blocked top-level package impossible to import."""

    def find_spec(self, name, path=None, target=None):
        if name.partition('.')[0] in blocked:
            raise ImportError(f'{name} is blocked in this test')


sys.meta_path.insert(0, Block())
imported = []
for name in sys.argv[2].split(','):
    module = importlib.import_module(f'wifi_place_recognition.{name}')
    imported.append(module.__name__)
    for info in pkgutil.iter_modules(getattr(module, '__path__', [])):
        imported.append(importlib.import_module(
            f'{module.__name__}.{info.name}').__name__)
from wifi_place_recognition.core.artifact import load_model
from wifi_place_recognition.core.recognizer import PlaceRecognizer
from wifi_place_recognition.core.resources import default_model_path
model = load_model(default_model_path())
place = PlaceRecognizer(model).classify(model.ap_ids[:6], [-60.0] * 6)
leaked = sorted(m for m in sys.modules if m.partition('.')[0] in blocked)
print(json.dumps({'imported': imported, 'leaked': leaked,
                  'place': [place.building, place.floor, place.confidence]}))
'''


@pytest.mark.parametrize('blocked, imports, some', [
    # the core and fingerprint I/O: no ROS, no torch
    (ROS + TRAINING, ('core', 'data'),
     ('core.recognizer', 'core.model', 'data.fingerprints')),
    # what a robot runs: the nodes and the tools that need no training
    (TRAINING, ('core', 'data', 'ros', 'cli.evaluate_model',
                'cli.replay_scans'),
     ('ros.classifier_node', 'ros.record_fingerprints', 'cli.replay_scans')),
], ids=['core without ROS and torch', 'nodes without torch and sklearn'])
def test_imports_and_classifies_with_packages_blocked(blocked, imports, some):
    result = run([sys.executable, '-c', IMPORT_AND_CLASSIFY, ','.join(blocked),
                  ','.join(imports)])
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    assert out['leaked'] == []
    assert {f'wifi_place_recognition.{m}' for m in some} <= \
        set(out['imported'])
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


def test_a_running_node_leaves_the_message_code_generator_out(ros, tmp_path):
    # rosidl_generator_py imports its code generator (lark, empy) if it can;
    # the executables block it: 2.4 MiB of RSS a running node never uses.
    env = dict(os.environ, PYTHONVERBOSE='1')    # every import on stderr
    proc = NodeProcess(tmp_path, [str(Path(sys.executable).parent /
                                      'classifier_node')], env=env)
    model = load_model(default_model_path())
    client = Client(ros)
    try:
        client.wait_ready(proc, (model.ap_ids[:6], [-60.0] * 6))
        client.close()
    finally:
        code, log = proc.stop()
    assert code == 0, log[-2000:]
    assert "import 'rclpy'" in log and "import 'service_msgs'" in log
    assert "import 'lark'" not in log
    assert "import 'rosidl_generator_py.generate_py_impl'" not in log
