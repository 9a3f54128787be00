"""
The documentation's pictures, drawn from the benchmarks' committed JSON.

    python benchmarks/figures.py [--out doc/images]

- ``panel.png``: building+floor error and position error of the default
  on every panel dataset against the baselines and the published figures
  (``results/panel.json``, ``panel-large.json``; UJIIndoorLoc's and
  WiFine's k-NN baselines from ``panel-patience5-floor.json``);
- ``confusion-ujiindoorloc.png``: the shipped model on UJIIndoorLoc's
  public test scans (``results/shipped-model-ujiindoorloc-public.json``,
  ``evaluate_model --json``), drawn by ``evaluate_model --plot``'s code;
- ``tracking-walks.png``: per walk, what tracking gained or lost in
  building+floor accuracy against single scans
  (``results/tracking-wifine-test.json``,
  ``tracking-ujiindoorloc-public.json``);
- ``robot-run.png``: one robot run per building, true path, each scan
  alone, odometry alone and the pose fused with odometry
  (``results/fusion.json``, ``benchmarks/fusion.py``).

Needs matplotlib; reads nothing but the JSON. Each PNG records the
SHA-256 of the JSON it was drawn from (its ``Source`` text), so a picture
older than its data can be told (test/test_docs.py).
"""

import argparse
import hashlib
import json
from pathlib import Path
import tempfile

import matplotlib
import numpy as np
from wifi_place_recognition.cli.plots import plot_confusion

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402 (after choosing the backend)

RESULTS = Path(__file__).resolve().parent / 'results'
IMAGES = Path(__file__).resolve().parent.parent / 'doc' / 'images'
#: Panel datasets in the order of the results page, and their labels.
PANEL = {'tut1': 'TUT1', 'tut2': 'TUT2', 'tut5': 'TUT5', 'tut6': 'TUT6',
         'tut7': 'TUT7', 'dsi1': 'DSI1', 'ujiindoorloc': 'UJIIndoorLoc',
         'wifine': 'WiFine'}
DPI = 90
#: The panel's runs, and last the first run (UJIIndoorLoc's and WiFine's
#: k-NN baselines).
PANEL_FILES = ('panel.json', 'panel-large.json', 'panel-patience5-floor.json')
CONFUSION_FILE = 'shipped-model-ujiindoorloc-public.json'
FUSION_FILE = 'fusion.json'
#: (file, title) of the tracking runs drawn.
TRACKING_RUNS = (('tracking-wifine-test.json', 'WiFine test/: 85 walks'),
                 ('tracking-ujiindoorloc-public.json',
                  'UJIIndoorLoc public: 11 phones'))
#: Building+floor accuracy (%) below which a point is drawn at the axis.
ACCURACY_FLOOR = 88.0


def _load(name):
    return json.loads((RESULTS / name).read_text())


def source(*names):
    """Return the ``Source`` text of a picture drawn from result files."""
    return '; '.join(
        f'{name} sha256:'
        f'{hashlib.sha256((RESULTS / name).read_bytes()).hexdigest()}'
        for name in names)


def panel_tables():
    """Return {dataset: (table, published best %, published k-NN %)}."""
    first = _load(PANEL_FILES[-1])['datasets']
    found = {}
    for name in PANEL_FILES[:-1]:
        for key, entry in _load(name)['datasets'].items():
            table = dict(entry['table'])
            if not any(m.startswith('k-NN') for m in table):
                table.update({m: row for m, row in first[key]['table'].items()
                              if m.startswith('k-NN')})
            found[key] = (table, entry['published_best'],
                          entry['published_knn'])
    return {key: found[key] for key in PANEL}


#: Methods drawn: (label, which row of a table, marker, colour).
CLASS_METHODS = (
    ('default (mean, seeds range)', lambda m: m == 'default', 'o', 'C0'),
    ('k-NN chosen by CV', lambda m: m.startswith('k-NN class'), 's', 'C1'),
    ('random forest', lambda m: m.startswith('random forest'), '^', 'C2'))
POSITION_METHODS = (
    ('default (mean, seeds range)', lambda m: m == 'default', 'o', 'C0'),
    ('k-NN chosen by CV',
     lambda m: m.startswith('k-NN position') and m.endswith('by CV)'), 's',
     'C1'),
    ('5-NN (Euclidean, dBm)', lambda m: m.endswith('euclidean, dBm, k=5)'),
     'v', 'C3'))


def _points(tables, chosen, figure):
    """Return [(dataset index, {mean, min, max})] of one method's figure."""
    points = []
    for i, (table, _, _) in enumerate(tables.values()):
        rows = [row for method, row in table.items() if chosen(method)]
        if rows and figure in rows[0]:
            points.append((i, rows[0][figure]))
    return points


def _draw(ax, points, scale, offset, label, marker, colour, spread,
          floor=None):
    """
    Draw one method's points (the mean; with ``spread`` the seeds' range).

    A mean below ``floor`` is drawn at the floor with its value written.
    """
    x = np.array([i for i, _ in points]) + offset
    mean = np.array([scale(v['mean']) for _, v in points])
    ends = np.array([[scale(v['min']), scale(v['max'])] for _, v in points])
    error = np.abs(ends - mean[:, None]).T if spread else None
    shown = mean if floor is None else np.maximum(mean, floor)
    ax.errorbar(x, shown, yerr=error, fmt=marker, color=colour, label=label,
                capsize=3)
    for xi, value, y in zip(x, mean, shown):
        if value != y:
            ax.annotate(f'{value:.1f}', (xi, y), textcoords='offset points',
                        xytext=(0, 6), ha='center', fontsize=7,
                        color=colour)


def draw_panel(out):
    """Draw ``panel.png``; return its path."""
    tables = panel_tables()
    one_floor = [k for k, (t, _, _) in enumerate(tables.values())
                 if t['default']['building_floor_accuracy']['min'] == 1.0]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9.5, 6.4), sharex=True)
    for offset, (label, chosen, marker, colour) in zip((-0.2, 0, 0.2),
                                                       CLASS_METHODS):
        points = [(i, v) for i, v in _points(tables, chosen,
                                             'building_floor_accuracy')
                  if i not in one_floor]
        _draw(top, points, lambda a: 100 * a, offset, label, marker,
              colour, label.startswith('default'), floor=ACCURACY_FLOOR)
    for k, (_, best, knn) in enumerate(tables.values()):
        if best is not None:
            top.plot([k - 0.35, k + 0.35], [best] * 2, color='k', lw=1,
                     label='published best' if k == 0 else None)
            top.plot([k - 0.35, k + 0.35], [knn] * 2, color='k', ls=':',
                     lw=1, label='published k-NN' if k == 0 else None)
    top.set_ylim(ACCURACY_FLOOR - 0.5, 101)     # room above 100 %
    top.set_yticks(np.arange(ACCURACY_FLOOR, 100.1, 2))
    top.set_ylabel('building+floor accuracy (%)')
    top.legend(fontsize=8, loc='upper left', bbox_to_anchor=(1.01, 1))
    top.grid(alpha=0.3, axis='y')
    top.set_title('The default on every dataset: test files, seeds 0, 1, 2'
                  '\n(DSI1 has one floor: a position-only model)',
                  fontsize=10)
    for offset, (label, chosen, marker, colour) in zip((-0.2, 0, 0.2),
                                                       POSITION_METHODS):
        _draw(bottom, _points(tables, chosen, 'position_mean_error_m'),
              float, offset, label, marker, colour,
              label.startswith('default'))
    bottom.set_ylabel('position mean error (m)')
    bottom.set_ylim(bottom=0)
    bottom.legend(fontsize=8, loc='upper left', bbox_to_anchor=(1.01, 1))
    bottom.grid(alpha=0.3, axis='y')
    bottom.set_xticks(np.arange(len(tables)), list(PANEL.values()))
    return _save(fig, out / 'panel.png', PANEL_FILES)


def draw_confusion(out):
    """Draw ``confusion-ujiindoorloc.png``; return its path."""
    with tempfile.TemporaryDirectory() as folder:
        drawn = plot_confusion(folder, _load(CONFUSION_FILE))
        image = plt.imread(drawn)
    fig = plt.figure(figsize=(image.shape[1] / DPI, image.shape[0] / DPI))
    fig.figimage(image)
    return _save(fig, out / 'confusion-ujiindoorloc.png', [CONFUSION_FILE],
                 layout=False, crop=False)


def draw_tracking(out):
    """Draw ``tracking-walks.png``; return its path."""
    fig, axes = plt.subplots(1, 2, figsize=(8, 4))
    for ax, (name, title) in zip(axes, TRACKING_RUNS):
        walks = _load(name)['walks']
        scans = np.array([w['scans'] for w in walks])
        single = np.array([w['single_right'] for w in walks]) / scans
        tracked = np.array([w['tracked_right'] for w in walks]) / scans
        gain = 100 * (tracked - single)
        ax.axhline(0, color='0.6', lw=1)
        ax.scatter(100 * single, gain, s=8 + scans / 4, alpha=0.6)
        ax.set_xlabel('single scans: building+floor accuracy (%)')
        ax.set_ylabel('tracked minus single (points)')
        ax.set_title(f'{title} (dot size: scans)\ntracking helped on '
                     f'{(gain > 0).sum()}, hurt on {(gain < 0).sum()}, '
                     f'changed nothing on {(gain == 0).sum()}', fontsize=9)
        ax.grid(alpha=0.3)
    return _save(fig, out / 'tracking-walks.png',
                 [name for name, _ in TRACKING_RUNS])


def draw_robot(out):
    """Draw ``robot-run.png``; return its path."""
    pairs = {name: pair for name, pair in _load(FUSION_FILE)['pairs'].items()
             if 'trajectory' in pair}
    fig, axes = plt.subplots(1, len(pairs), figsize=(5 * len(pairs), 4.6))
    for ax, (name, pair) in zip(np.atleast_1d(axes), pairs.items()):
        path = {k: np.array(v) for k, v in pair['trajectory'].items()}
        for key, style, label in (
                ('odometry', dict(color='0.7', lw=1), 'odometry alone'),
                ('single', dict(color='tab:orange', lw=0, marker='.',
                                ms=3), 'each scan alone (the model)'),
                ('truth', dict(color='k', lw=2), 'truth (AMCL)'),
                ('fused', dict(color='tab:blue', lw=1.2),
                 'fused with odometry')):
            ax.plot(path[key][:, 0], path[key][:, 1], label=label, **style)
        truth = path['truth']
        pad = 3
        ax.set_xlim(truth[:, 0].min() - pad, truth[:, 0].max() + pad)
        ax.set_ylim(truth[:, 1].min() - pad, truth[:, 1].max() + pad)
        ax.set_aspect('equal')
        test, trained = name.split(' <- ')
        fused = np.mean([r['mean_m'] for r in pair['fused_fitted']])
        ax.set_title(f'run {test}, model trained on run {trained}\n'
                     f'mean error: fused {fused:.2f} m, each scan '
                     f'{pair["single"]["mean_m"]:.2f} m, odometry '
                     f'{pair["odometry"]["mean_m"]:.0f} m', fontsize=10)
        ax.set_xlabel('x (m, map frame)')
        ax.set_ylabel('y (m, map frame)')
        ax.grid(alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc='lower center', ncol=len(labels),
               fontsize=10, markerscale=3, frameon=False)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    return _save(fig, out / 'robot-run.png', [FUSION_FILE], layout=False)


def _save(fig, path, files, layout=True, crop=True):
    """Save ``fig`` with its sources: laid out, its blank margins cropped."""
    if layout:
        fig.tight_layout()
    fig.savefig(path, dpi=DPI, metadata={'Source': source(*files)},
                bbox_inches='tight' if crop else None, pad_inches=0.05)
    plt.close(fig)
    return path


def main():
    """Draw every picture into ``--out``."""
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--out', type=Path, default=IMAGES,
                   help='folder of the pictures (default: doc/images)')
    out = p.parse_args().out
    out.mkdir(parents=True, exist_ok=True)
    for draw in (draw_panel, draw_confusion, draw_tracking, draw_robot):
        print(draw(out))


if __name__ == '__main__':
    main()
