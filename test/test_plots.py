"""The pictures of ``evaluate_model --plot`` read on their own."""

from conftest import surveyed_csv
import numpy as np
from wifi_place_recognition.cli import plots
from wifi_place_recognition.data.fingerprints import read_fingerprints


def test_a_maps_axes_count_metres_from_a_named_origin(tmp_path):
    fp = read_fingerprints(surveyed_csv(tmp_path / 'a.csv', 20))
    xy = fp.position + [1.0, -2.0]
    error = np.linalg.norm(xy - fp.position, axis=1)
    fig = plots.map_figure(plots._pyplot(), fp, xy, error, 0, 1, 3.0)
    fig.canvas.draw()
    ax = fig.axes[0]
    # the positions lie 4,864,900 m north: no '+4.864e6' beside the axis
    for axis in (ax.xaxis, ax.yaxis):
        assert axis.get_offset_text().get_text() == ''
        ticks = [float(t.get_text().replace('\N{MINUS SIGN}', '-'))
                 for t in axis.get_ticklabels() if t.get_text()]
        assert ticks and max(map(abs, ticks)) <= 100, ticks
    assert ax.get_xlabel() == 'X (m, from -7600)', ax.get_xlabel()
    assert ax.get_ylabel() == 'Y (m, from 4864900)', ax.get_ylabel()
