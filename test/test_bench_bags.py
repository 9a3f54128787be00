"""
The fusion benchmark's ``--data`` scores a folder of bags as the CSVs.

The CSVs labelled by the package's rule (the bags' labels): the shared
runs' own labels interpolate across every gap between poses.
"""

from bag_helpers import relabelled, ROBOT, run_messages, write_bag
import numpy as np
import pytest

RUNS = ('b24test2', 'b24test3')


@pytest.mark.skipif(not (ROBOT / 'b24').exists(),
                    reason='robot runs not available')
def test_a_folder_of_bags_gives_the_csvs_figures(fusion, tmp_path):
    data = tmp_path / 'bags'
    (data / 'b24').mkdir(parents=True)
    for name in RUNS:
        write_bag(data / 'b24' / name, run_messages(ROBOT / 'b24' / name))
    (site, bags), = fusion.site_runs(data, tmp_path / 'exported')
    for name in RUNS:
        relabelled(ROBOT / 'b24' / name, tmp_path / 'csv' / 'b24' / name)
    (_, csvs), = fusion.site_runs(tmp_path / 'csv', tmp_path / 'unused')
    assert site == 'b24' and [r.name for r in bags] == list(RUNS)
    for bag, csv in zip(bags, csvs):
        np.testing.assert_allclose(bag.stamps, csv.stamps, atol=1e-6)
        np.testing.assert_allclose(bag.xy, csv.xy, atol=1e-5)
        assert np.array_equal(bag.odometry, csv.odometry)
        assert bag.fp.ap_ids == csv.fp.ap_ids   # the building's columns
    figures = []
    for (train, test), folder in (((csvs[0], csvs[1]), tmp_path / 'c'),
                                  ((bags[0], bags[1]), tmp_path / 'b')):
        folder.mkdir()
        plain, fitted, kept, _ = fusion.models(train, folder, holes=True)
        model = fusion.load_model(fitted)
        single = fusion.single_scans(fusion.load_model(plain), test)
        hole = fusion.in_holes(test.xy, kept)
        fused = fusion.fused_figures(test, single, model.fusion, hole,
                                     seeds=(0,))[0][0]
        figures.append((model.fusion.drift_mean,
                        fusion.single_figures(test, single, hole)['mean_m'],
                        fused['mean_m'], fused['p95_m'], int(hole.sum())))
    # the bags were written from the CSVs' poses (6 decimals), so their
    # labels differ from the CSVs' by up to 1e-6 m: the inputs agree to
    # that, the particle filter's path to its seed-to-seed spread
    np.testing.assert_allclose(figures[0][:2], figures[1][:2], rtol=1e-5)
    assert figures[0][4] == figures[1][4]
    np.testing.assert_allclose(figures[0][2:4], figures[1][2:4], rtol=0.1)


def test_a_bag_without_odometry_stops_the_benchmark_in_one_line(
        fusion, tmp_path):
    (tmp_path / 'data' / 'b24').mkdir(parents=True)
    write_bag(tmp_path / 'data' / 'b24' / 'scans-only.mcap', [
        m for m in run_messages(ROBOT / 'b24' / RUNS[0], seconds=20)
        if m[0] == '/wifi/scan'])
    with pytest.raises(SystemExit, match='a run needs odometry'):
        list(fusion.site_runs(tmp_path / 'data', tmp_path / 'exported'))
