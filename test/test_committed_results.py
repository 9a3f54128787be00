"""
Committed results against what the committed code and model give today.

``benchmarks/results/shipped-model-ujiindoorloc-public.json`` is
``evaluate_model --json`` of the shipped model on UJIIndoorLoc's public
test scans (``benchmarks/results/README.md``); the README and the results
page quote its figures. Another CPU rounds the networks' float32 and the
k-NN's distances in another order, and a tied neighbour can flip: the
figures are compared to :data:`REL` (round 26: the position mean error
6.300 m on the machine that committed it, 6.283 m on an AMD EPYC; every
count the same).
"""

import json

from conftest import dataset_file, python_module, REPO, run
import pytest

SHIPPED = REPO / 'benchmarks' / 'results' / \
    'shipped-model-ujiindoorloc-public.json'
#: Floats agree to this share (a scan's neighbours moving on one of 556
#: scans moves the mean error by about 0.3 %); whole numbers exactly.
REL = 5e-3


def same(committed, today, where='json'):
    """Assert ``today`` equals ``committed``: floats to :data:`REL`."""
    if isinstance(committed, dict):
        assert sorted(committed) == sorted(today), where
        for key in committed:
            same(committed[key], today[key], f'{where}.{key}')
    elif isinstance(committed, list):
        assert len(committed) == len(today), where
        for i, (a, b) in enumerate(zip(committed, today)):
            same(a, b, f'{where}[{i}]')
    elif isinstance(committed, float):
        assert today == pytest.approx(committed, rel=REL), where
    else:
        assert today == committed, where


def test_the_shipped_models_result_is_what_evaluate_model_gives():
    data = dataset_file('validationData-public.csv')
    result = run(python_module('cli.evaluate_model', '--data', data,
                               '--json'))
    assert result.returncode == 0, result.stderr
    committed = json.loads(SHIPPED.read_text())
    same(committed, json.loads(result.stdout))
    # the pages quote it
    quoted = (f'{committed["building_floor_accuracy"]:.4f}',
              f'position mean error {committed["position_mean_error_m"]:.2f}'
              f' m',
              f'{committed["position_in_95_ellipse"]:.1%} of the scans')
    results_page = ' '.join((REPO / 'doc' / 'results.md').read_text().split())
    readme = ' '.join((REPO / 'README.md').read_text().split())
    for text in quoted:
        assert text in results_page, text
    assert all(text in readme for text in quoted[:2]), quoted
