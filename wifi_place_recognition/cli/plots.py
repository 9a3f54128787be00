"""
Pictures of an evaluation (``evaluate_model --plot DIR``), with matplotlib.

Only the command line imports this module, and only for ``--plot``: the
node never needs matplotlib.
"""

from pathlib import Path

import numpy as np

from ..core.evaluation import align


def _pyplot():
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def plot_evaluation(folder, model, fp, result, predictions, baseline=None):
    """
    Write PNG pictures into ``folder``; return their paths.

    ``confusion.png`` always; with positions ``error_cdf.png`` (against
    ``baseline``, errors in metres of another method, if given) and one
    ``map_B{b}F{f}.png`` per building/floor of the data.
    """
    plt = _pyplot()
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = [_confusion(plt, folder, result)]
    if 'position_mean_error_m' in result:
        xy = np.stack([predictions['x'], predictions['y']], axis=1)
        error = np.linalg.norm(xy - fp.position, axis=1)
        written.append(_cdf(plt, folder, error, baseline))
        written += _maps(plt, folder, fp, xy, error)
    return written


def plot_confusion(folder, result):
    """Write ``confusion.png`` of an evaluation ``result``; return its path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    return _confusion(_pyplot(), folder, result)


def _confusion(plt, folder, result):
    matrix = np.asarray(result['confusion'], float)
    rows = matrix.sum(axis=1, keepdims=True)
    share = np.divide(matrix, rows, out=np.zeros_like(matrix),
                      where=rows > 0)
    names = result['classes']
    fig, ax = plt.subplots(figsize=(1 + 0.55 * len(names),
                                    0.8 + 0.5 * len(names)))
    ax.imshow(share, cmap='Blues', vmin=0, vmax=1)
    for (i, j), count in np.ndenumerate(matrix):
        if count:
            ax.text(j, i, int(count), ha='center', va='center', fontsize=8,
                    color='white' if share[i, j] > 0.5 else 'black')
    ax.set_xticks(range(len(names)), names, rotation=90)
    ax.set_yticks(range(len(names)), names)
    ax.set_xlabel('predicted')
    ax.set_ylabel('true')
    ax.set_title(f'building+floor accuracy '
                 f'{result["building_floor_accuracy"]:.4f}')
    return _save(plt, fig, folder / 'confusion.png')


def _cdf(plt, folder, error, baseline):
    fig, ax = plt.subplots(figsize=(6, 4))
    curves = [('this model', error)]
    if baseline is not None:
        curves.append(baseline)
    for label, e in curves:
        e = np.sort(e)
        ax.plot(e, np.arange(1, len(e) + 1) / len(e),
                label=f'{label} (mean {e.mean():.2f} m, median '
                      f'{np.median(e):.2f} m)')
    ax.set_xlabel('2-D position error (m)')
    ax.set_ylabel('fraction of scans')
    ax.set_xlim(0, np.quantile(np.concatenate([c[1] for c in curves]),
                               0.98))
    ax.grid(alpha=0.3)
    ax.legend(loc='lower right')
    return _save(plt, fig, folder / 'error_cdf.png')


def _maps(plt, folder, fp, xy, error):
    vmax = np.quantile(error, 0.95)
    return [_save(plt, map_figure(plt, fp, xy, error, b, f, vmax),
                  folder / f'map_B{b}F{f}.png')
            for b, f in sorted(set(zip(fp.building.tolist(),
                                       fp.floor.tolist())))]


def map_figure(plt, fp, xy, error, building, floor, vmax):
    """
    Return the figure of one floor's errors: true positions, lines on.

    The axes count metres from a round origin (named in their labels),
    not in matplotlib's offset notation (``+4.864e6``).
    """
    here = (fp.building == building) & (fp.floor == floor)
    origin = np.floor(fp.position[here].min(axis=0) / 100) * 100
    truth, guess = fp.position[here] - origin, xy[here] - origin
    fig, ax = plt.subplots(figsize=(7, 6))
    ax.plot(np.stack([truth[:, 0], guess[:, 0]]),
            np.stack([truth[:, 1], guess[:, 1]]), color='0.7', lw=0.6,
            zorder=1)
    dots = ax.scatter(truth[:, 0], truth[:, 1], c=error[here], s=12,
                      cmap='viridis', vmin=0, vmax=vmax, zorder=2)
    fig.colorbar(dots, ax=ax, label='error (m)')
    ax.set_aspect('equal')
    ax.ticklabel_format(useOffset=False, style='plain')
    for set_label, name, zero in zip((ax.set_xlabel, ax.set_ylabel),
                                     fp.position_columns, origin):
        set_label(f'{name} (m, from {zero:.0f})' if zero else f'{name} (m)')
    ax.set_title(f'building {building}, floor {floor}: {here.sum()} scans, '
                 f'mean error {error[here].mean():.2f} m\n(dot: true '
                 f'position, line: to the prediction)', fontsize=10)
    return fig


def _save(plt, fig, path):
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def knn_baseline(model, train_fp, fp, k=5):
    """
    Return (label, errors in m) of distance-weighted k-NN regression.

    Neighbours among all training scans, in the model's own input
    representation (scikit-learn).
    """
    from sklearn.neighbors import KNeighborsRegressor
    x_train = model.scaler.transform(align(model, train_fp))
    x_test = model.scaler.transform(align(model, fp))
    knn = KNeighborsRegressor(k, weights='distance')
    knn.fit(x_train, train_fp.position)
    error = np.linalg.norm(knn.predict(x_test) - fp.position, axis=1)
    return f'{k}-NN regression', error
