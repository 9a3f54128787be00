"""The main job, ``scripts/demo.sh``, as the README runs it, on a few scans."""

import os

from conftest import dataset_file, REPO, run


def test_the_demo_keeps_the_nodes_log_out_of_its_progress(tmp_path):
    rows = dataset_file('validationData-public.csv').read_text().splitlines()
    scans = tmp_path / 'scans.csv'
    scans.write_text('\n'.join(rows[:41]) + '\n')
    result = run(['bash', REPO / 'scripts' / 'demo.sh', scans],
                 env={**os.environ, 'TMPDIR': str(tmp_path)}, timeout=600)
    assert result.returncode == 0, result.stdout + result.stderr
    assert '40/40 scans answered' in result.stdout, result.stdout
    assert '[INFO]' not in result.stdout + result.stderr, result.stderr
    log = tmp_path / 'wifi_place_recognition-demo-node.log'
    assert f"classifier_node's log: {log}" in result.stdout
    assert 'current place: building' in log.read_text()
