"""
Bad paths, options and stamps given to the offline tools.

Every output is checked before any work (a folder, a missing folder, an
input's file: refused, naming both, nothing written); the replay tools
refuse an option they do not know (a typo), a value out of range and a
topic name ROS refuses, before they send anything; replay_run refuses
streams whose time spans do not overlap or whose replay would take more
than a day before it sends anything (it slept for years), and leaves out,
counted, the odometry more than 10 s outside the scans' span;
fit_odometry counts the stretches it leaves out across an odometry gap
and names its files and their time spans when it cannot fit; replay_run
scores odometry alone only inside the odometry's span and says how many
scans it scored.
"""

import json
import math
import resource

from conftest import python_module, run, surveyed_csv
import numpy as np
from test_fusion import straight
from wifi_place_recognition.cli.common import json_ready
from wifi_place_recognition.cli.replay_run import scored

#: Seconds a command may take here: far less than a replay of a bad stamp.
QUICK = 120


def run_files(folder):
    """Write a surveyed run: scans.csv (X, Y, YAW, TIMESTAMP), odom.csv."""
    truth, odo = straight(n=1500, drift=math.radians(-1.0))
    np.savetxt(folder / 'odom.csv', odo, delimiter=',',
               header='TIMESTAMP,X,Y,YAW', comments='', fmt='%.6f')
    lines = surveyed_csv(folder / 'survey.csv', scans_per_floor=150,
                         floors=(0,)).read_text().splitlines()
    header = lines[0].split(',') + ['TIMESTAMP', 'YAW']
    x, y = header.index('X'), header.index('Y')
    rows = [','.join(header)]
    for line, i in zip(lines[1:], range(0, 1500, 10)):
        cells = line.split(',') + [f'{truth[i, 0]:.3f}', f'{truth[i, 3]:.4f}']
        cells[x], cells[y] = f'{truth[i, 1]:.3f}', f'{truth[i, 2]:.3f}'
        rows.append(','.join(cells))
    (folder / 'scans.csv').write_text('\n'.join(rows) + '\n')
    return folder / 'scans.csv', folder / 'odom.csv', odo


def write_odometry(path, rows):
    """Write odometry rows as a pose CSV."""
    np.savetxt(path, rows, delimiter=',', header='TIMESTAMP,X,Y,YAW',
               comments='', fmt='%.6f')
    return path


def refused(result, *parts):
    """Assert one error line naming ``parts``, exit 2, no traceback."""
    assert result.returncode == 2, (result.stdout, result.stderr)
    errors = [line for line in result.stderr.splitlines()
              if line.startswith('error:')]
    assert len(errors) == 1 and all(p in errors[0] for p in parts), \
        result.stderr
    assert 'Traceback' not in result.stderr


def test_fit_odometry_counts_gaps_and_names_its_files(tmp_path,
                                                      surveyed_model):
    scans, odom, odo = run_files(tmp_path)
    gapped = write_odometry(tmp_path / 'gapped.csv',
                            odo[(odo[:, 0] < 50.0) | (odo[:, 0] > 70.0)])
    report = tmp_path / 'report.json'
    result = run(python_module(
        'cli.fit_odometry', '--model', surveyed_model, '--data', scans,
        '--odometry', gapped, '-o', tmp_path / 'fitted.npz', '--report',
        report), timeout=QUICK)
    assert result.returncode == 0, result.stderr
    # 10 m of 75 m in the gap: 4 of the 24 stretches of 3 m touch it
    assert '150 posed scans inside the odometry\'s time span (0 outside)' \
        in result.stdout and '20 stretches (4 more across an odometry gap ' \
        'longer than 1 s left out)' in result.stdout, result.stdout
    assert json.loads(report.read_text())['windows_across_odometry_gaps'] \
        == 4
    # the odometry on another clock: both files and both spans named
    moved = odo.copy()
    moved[:, 0] -= 1000.0
    result = run(python_module(
        'cli.fit_odometry', '--model', surveyed_model, '--data', scans,
        '--odometry', write_odometry(tmp_path / 'moved.csv', moved), '-o',
        tmp_path / 'x.npz'), timeout=QUICK)
    refused(result, f'{scans}: the run covers 0.0 m', f'{tmp_path}/moved.csv '
            f'spans -1000.000 to -850.100 s (149.9 s), the posed scans 0.000 '
            f'to 149.000 s (149.0 s), 150 of them outside')
    one = write_odometry(tmp_path / 'one.csv', odo[:1])
    result = run(python_module(
        'cli.fit_odometry', '--model', surveyed_model, '--data', scans,
        '--odometry', one, '-o', tmp_path / 'x.npz'), timeout=QUICK)
    refused(result, f'{one}: need two or more poses in time order')
    assert not (tmp_path / 'x.npz').exists()


def test_fit_odometry_refuses_odometry_unlike_the_run(tmp_path,
                                                      surveyed_model):
    scans, _, odo = run_files(tmp_path)
    still = odo.copy()
    still[:, 1:] = 0.0                      # a robot that never moved
    driven = np.concatenate([[0.0], np.cumsum(np.hypot(
        *np.diff(odo[:, 1:3], axis=0).T))])
    spinning = odo.copy()
    spinning[:, 3] += driven                # turning 1 rad per m more
    for rows, message in (
            (still, 'the odometry drove 0 times the true distance'),
            (spinning, 'its heading turns unlike the truth of')):
        odom = write_odometry(tmp_path / 'odom-bad.csv', rows)
        result = run(python_module(
            'cli.fit_odometry', '--model', surveyed_model, '--data', scans,
            '--odometry', odom, '-o', tmp_path / 'fitted.npz'),
            timeout=QUICK)
        refused(result, str(odom), message)
        assert not (tmp_path / 'fitted.npz').exists()
    # inside the limits: fitted
    short = odo.copy()
    short[:, 1:3] *= 0.6                    # wheels 40 % short
    turning = odo.copy()
    turning[:, 3] += 0.4 * driven           # 0.4 rad per m
    for rows in (short, turning):
        odom = write_odometry(tmp_path / 'odom-ok.csv', rows)
        result = run(python_module(
            'cli.fit_odometry', '--model', surveyed_model, '--data', scans,
            '--odometry', odom, '-o', tmp_path / 'fitted.npz'),
            timeout=QUICK)
        assert result.returncode == 0, result.stderr


def test_no_output_is_written_when_one_cannot_be(tmp_path, surveyed_model):
    scans, odom, _ = run_files(tmp_path)
    model = tmp_path / 'model.npz'
    model.write_bytes(surveyed_model.read_bytes())
    (tmp_path / 'folder').mkdir()
    for report, message in ((tmp_path / 'none' / 'r.json',
                             f'--report {tmp_path}/none/r.json: no folder'),
                            (tmp_path / 'folder', 'is a folder')):
        result = run(python_module(
            'cli.fit_odometry', '--model', model, '--data', scans,
            '--odometry', odom, '--report', report), timeout=QUICK)
        assert model.read_bytes() == surveyed_model.read_bytes()
        refused(result, message)


def test_an_output_that_is_an_input_is_refused(tmp_path, surveyed_model):
    scans, odom, _ = run_files(tmp_path)
    kept = {p: p.read_bytes() for p in (scans, odom)}
    fit = ('cli.fit_odometry', '--model', surveyed_model, '--data', scans,
           '--odometry', odom)
    replay = ('cli.replay_run', '--data', scans, '--odometry', odom,
              '--wait', '1')
    for args, message in (
            ((*fit, '-o', odom), f'-o {odom} is the input --odometry {odom}'),
            ((*fit, '--report', scans),
             f'--report {scans} is the input --data {scans}'),
            ((*fit, '-o', tmp_path / 'm.npz', '--report', tmp_path / 'm.npz'),
             'two outputs in one file'),
            (('cli.train_model', '--data', scans, '-o', scans),
             f'-o {scans} is the input --data {scans}'),
            ((*replay, '--trajectory', scans),
             f'--trajectory {scans} is the input --data {scans}'),
            ((*replay, '--json', tmp_path / 'none' / 'x.json'),
             f'--json {tmp_path}/none/x.json: no folder')):
        result = run(python_module(*args), timeout=QUICK)
        assert all(p.read_bytes() == data for p, data in kept.items()), args
        refused(result, message)
    assert not (tmp_path / 'm.npz').exists()


def test_predictions_never_overwrite_the_data(tmp_path, surveyed_model):
    scans, _, _ = run_files(tmp_path)
    kept = scans.read_bytes()
    (tmp_path / 'file').write_text('not a folder')
    for args, message in (
            (('cli.evaluate_model', '--model', surveyed_model, '--data',
              scans, '--predictions', scans),
             f'--predictions {scans} is the input --data {scans}'),
            (('cli.evaluate_model', '--model', surveyed_model, '--data',
              scans, '--predictions', tmp_path / 'p.csv', '--plot',
              tmp_path / 'file'),
             f'--plot {tmp_path}/file: is a file, not a folder'),
            (('cli.evaluate_model', '--model', surveyed_model, '--data',
              scans, '--predictions', tmp_path / 'p.csv',
              '--plot-baseline', scans), 'give --plot'),
            (('cli.replay_scans', '--data', scans, '--predictions', scans,
              '--wait', '1'),
             f'--predictions {scans} is the input --data {scans}')):
        result = run(python_module(*args), timeout=QUICK)
        assert scans.read_bytes() == kept, args
        assert result.returncode == 2 and message in result.stderr, \
            result.stderr
        assert 'Traceback' not in result.stderr
    assert not (tmp_path / 'p.csv').exists()


def test_replay_options_out_of_range_typos_and_bad_topics_are_refused(
        tmp_path):
    scans, odom, _ = run_files(tmp_path)
    replay = ('cli.replay_scans', '--data', scans, '--wait', '1')
    for args, message in (
            ((*replay, '--progress', '0'), '--progress must be at least 1'),
            ((*replay, '--limit', '0'), '--limit must be at least 1'),
            ((*replay, '--timeout', 'nan'),
             '--timeout must be a finite number > 0, not nan'),
            ((*replay, '--max-wait', '-1'), '--max-wait must be'),
            ((*replay, '--rate', '-5'), '--rate must be'),
            ((*replay, '--limt', '5'), 'unrecognized arguments: --limt 5'),
            (('cli.replay_run', '--data', scans, '--odometry', odom,
              '--wait', '1', '--sped', '5'), 'unrecognized arguments'),
            ((*replay, '--place-topic', '1bad'),
             "--place-topic '1bad' is not a valid topic name"),
            (('cli.replay_run', '--data', scans, '--odometry', odom,
              '--wait', '1', '--pose-topic', '1bad'),
             "--pose-topic '1bad' is not a valid topic name")):
        result = run(python_module(*args), timeout=QUICK)
        assert result.returncode == 2 and message in result.stderr, \
            (args, result.stderr)
        assert 'Traceback' not in result.stderr, args
        assert 'sent' not in result.stdout + result.stderr, args
    # ROS arguments still go to ROS (no node answers: exit 1 after --wait)
    result = run(python_module(*replay, '--ros-args', '-r', '__ns:=/probe',
                               '--log-level', 'warn'), timeout=QUICK)
    assert result.returncode == 1, result.stderr
    assert 'unrecognized' not in result.stderr, result.stderr


def test_replay_run_refuses_stamps_of_no_run_before_it_sends(tmp_path):
    scans, _, odo = run_files(tmp_path)
    zero = odo.copy()
    zero[:, 0] += 5000.0                      # another clock
    odom = write_odometry(tmp_path / 'zero.csv', zero)
    result = run(python_module('cli.replay_run', '--data', scans,
                               '--odometry', odom, '--wait', '1'),
                 timeout=QUICK)
    refused(result, f'the scans of {scans} span 0.000 to 149.000 s '
            f'(149.0 s), the odometry {odom} 5000.000 to 5149.900 s '
            f'(149.9 s): they do not overlap')
    # overlapping spans, but no odometry within 10 s of any scan
    apart = odo.copy()
    apart[:750, 0] -= 100.0                   # -100.000 to -25.100 s
    apart[750:, 0] += 100.0                   # 175.000 to 249.900 s
    odom = write_odometry(tmp_path / 'apart.csv', apart)
    result = run(python_module('cli.replay_run', '--data', scans,
                               '--odometry', odom, '--wait', '1'),
                 timeout=QUICK)
    refused(result, f'the odometry {odom} -100.000 to 249.900 s (349.9 s): '
            f'no odometry pose within 10 s of the scans')
    # one scan stamp far off: the scans' own span is absurd
    lines = scans.read_text().splitlines()
    cells = lines[-1].split(',')
    cells[lines[0].split(',').index('TIMESTAMP')] = '1e300'
    far = tmp_path / 'far.csv'
    far.write_text('\n'.join(lines[:-1] + [','.join(cells)]) + '\n')
    result = run(python_module('cli.replay_run', '--data', far,
                               '--odometry', tmp_path / 'odom.csv',
                               '--wait', '1'), timeout=QUICK)
    refused(result, f'the scans of {far} span 0.000 to 1e+300 s (1e+300 '
            f's), the odometry {tmp_path}/odom.csv 0.000 to 149.900 s '
            f'(149.9 s): the replay would take 1e+299 s at speed 10, more '
            f'than a day (86400 s)')
    result = run(python_module('cli.replay_run', '--data', scans,
                               '--odometry', tmp_path / 'odom.csv',
                               '--wait', 'nan'), timeout=QUICK)
    assert result.returncode == 2 and \
        '--wait must be a finite number >= 0, not nan' in result.stderr, \
        result.stderr


def test_replay_run_trims_odometry_longer_than_the_scans(tmp_path):
    # 150 s of scans cut from a 450 s recording: the odometry beyond 10 s
    # of the scans is left out, counted, and the rest sent (no node here)
    scans, _, _ = run_files(tmp_path)
    _, odo = straight(n=4500)
    odo[:, 0] -= 100.05                       # -100.05 to 349.85 s
    odom = write_odometry(tmp_path / 'long.csv', odo)
    result = run(python_module('cli.replay_run', '--data', scans,
                               '--odometry', odom, '--wait', '1'),
                 timeout=QUICK)
    assert result.returncode == 1, result.stderr
    assert f'note: {odom}: sending 1690 of 4500 odometry poses, 2810 ' \
        f'left out (more than 10 s outside the scans\' time span 0.000 ' \
        f'to 149.000 s (149.0 s))' in result.stderr, result.stderr
    assert 'no classifier node took odom' in result.stderr, result.stderr


class Run:
    """The scans of a replayed run, as scored() reads them."""

    def __init__(self, stamps):
        self.meta = {'TIMESTAMP': stamps}

    def __len__(self):
        return len(self.meta['TIMESTAMP'])


def test_odometry_alone_is_scored_inside_the_odometry_only(tmp_path):
    truth, odo = straight(n=600)
    stamps = truth[::10, 0]
    true_xy, true_yaw = truth[::10, 1:3].copy(), truth[::10, 3].copy()
    true_xy[:3] = np.nan                        # no true pose
    late = odo[odo[:, 0] >= 20.0]               # odometry from 20 s
    scores, table = scored(Run(stamps), late, (true_xy, true_yaw), {})
    assert scores['scans'] == {'total': 60, 'with_true_pose': 57,
                               'without_true_pose': 3,
                               'outside_odometry': 17}
    assert scores['odometry']['scans'] == 40
    assert np.isnan(table[stamps < 20.0, 6:9]).all()
    np.testing.assert_allclose(table[stamps >= 20.0, 6:8],
                               true_xy[stamps >= 20.0], atol=1e-6)


def test_waiting_for_the_node_does_not_spin_a_core(tmp_path):
    # nothing answers: replay_run waits --wait seconds, then gives up; it
    # spun a whole core while no node took its odometry (start-up and
    # imports take 1-2 s of CPU here)
    scans, odom, _ = run_files(tmp_path)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    result = run(python_module('cli.replay_run', '--data', scans,
                               '--odometry', odom, '--wait', '12'),
                 timeout=QUICK)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    assert result.returncode == 1 and 'error: ' in result.stderr, \
        result.stderr
    cpu = (after.ru_utime + after.ru_stime) - \
        (before.ru_utime + before.ru_stime)
    assert cpu < 6.0, cpu       # a busy wait takes the whole 12 s


def test_the_same_data_given_twice_is_refused(tmp_path, surveyed_model):
    scans, _, _ = run_files(tmp_path)
    again = tmp_path / 'again.csv'
    again.symlink_to(scans)
    for args in (('cli.evaluate_model', '--model', surveyed_model, '--data',
                  scans, again),
                 ('cli.train_model', '--data', again, scans, '-o',
                  tmp_path / 'm.npz')):
        refused(run(python_module(*args), timeout=QUICK), 'is given twice',
                'its scans would count twice')
    assert not (tmp_path / 'm.npz').exists()


def test_data_with_no_usable_scan_is_refused(tmp_path, surveyed_model):
    scans, _, _ = run_files(tmp_path)
    lines = scans.read_text().splitlines()
    header = lines[0].split(',')
    x, y = header.index('X'), header.index('Y')
    rows = [line.split(',') for line in lines[1:]]
    for row in rows:
        row[x] = row[y] = ''         # no pose: every row left out
    unplaced = tmp_path / 'unplaced.csv'
    unplaced.write_text('\n'.join([lines[0]] + [','.join(r) for r in rows])
                        + '\n')
    for tool in ('cli.evaluate_model', 'cli.survey_gaps'):
        refused(run(python_module(tool, '--model', surveyed_model, '--data',
                                  unplaced), timeout=QUICK),
                f'data {unplaced}: no scan left to use')


def test_json_outputs_write_null_for_what_is_not_finite(tmp_path,
                                                        surveyed_model):
    scans, _, _ = run_files(tmp_path)
    lines = scans.read_text().splitlines()
    x = lines[0].split(',').index('X')
    cells = lines[1].split(',')
    cells[x] = '1e308'                     # an error beyond any float sum
    far = tmp_path / 'far.csv'
    far.write_text('\n'.join([lines[0], ','.join(cells)] + lines[2:]) + '\n')
    result = run(python_module('cli.evaluate_model', '--model',
                               surveyed_model, '--data', far, '--json'),
                 timeout=QUICK)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)['position_mean_error_m'] is None


def test_json_ready_replaces_what_is_not_finite_with_null():
    value = {'mean_m': math.inf, 'runs': [1.5, math.nan, (2, -math.inf)],
             'name': 'x'}
    assert json.dumps(json_ready(value), allow_nan=False) == \
        '{"mean_m": null, "runs": [1.5, null, [2, null]], "name": "x"}'
