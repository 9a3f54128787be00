"""
The datasets the benchmarks read, and how: paths and reader flags.

Paths are relative to the datasets folder (``../shared/datasets`` beside
the repository by default). Panel figures: building+floor hit rate (%) on
``test.csv`` published by Quezada-Gaibor et al. (CNN-ELM, 2021; see the
panel's README): the best method and their k-NN (a per-dataset
configuration from the literature).
"""

from wifi_place_recognition.data.fingerprints import (read_fingerprints,
                                                      ReaderOptions)

WIFINE_OPTIONS = dict(floor_column='floorID', building_column=None,
                      not_detected_marker=-100.0,
                      meta_columns=('num_visible_APs', 'z'))
WIFINE_ARGS = ['--floor-column', 'floorID', '--building-column', 'none',
               '--not-detected-marker', '-100', '--meta-columns',
               'num_visible_APs,z']
DATASETS = {
    'ujiindoorloc': dict(train=['ujiindoorloc/trainingData.csv'],
                         test=['ujiindoorloc/validationData-public.csv'],
                         options={}, args=[]),
    'wifine': dict(train=['wifine/train'], test=['wifine/test'],
                   validation=['wifine/val'], options=WIFINE_OPTIONS,
                   args=WIFINE_ARGS),
}
PANEL = ('tut1', 'tut2', 'tut5', 'tut6', 'tut7', 'dsi1')
for _name in PANEL:
    DATASETS[_name] = dict(train=[f'panel/{_name}/train.csv'],
                           test=[f'panel/{_name}/test.csv'], options={},
                           args=[])
#: Robot runs (one floor each: position-only models, judged on the 95 %
#: circle): trained on one run of a site, tested on another.
ROBOT = {'b14-1-2': ('b14', 1, 2), 'b14-2-3': ('b14', 2, 3),
         'b14-3-1': ('b14', 3, 1), 'b24-2-3': ('b24', 2, 3),
         'b24-3-2': ('b24', 3, 2)}
for _name, (_site, _train, _test) in ROBOT.items():
    DATASETS[_name] = dict(
        train=[f'robot/{_site}/{_site}test{_train}/scans.csv'],
        test=[f'robot/{_site}/{_site}test{_test}/scans.csv'], options={},
        args=[])
#: Published building+floor (%): (best of the benchmark, its k-NN).
PUBLISHED = {'tut1': (91.22, 90.82), 'tut2': (94.32, 94.32),
             'tut5': (98.27, 96.84), 'tut6': (99.77, 99.66),
             'tut7': (98.36, 98.36)}


def read(root, name, part):
    """Return part ``train`` or ``test`` of dataset ``name`` under ``root``."""
    data = DATASETS[name]
    return read_fingerprints([str(root / p) for p in data[part]],
                             role='train' if part == 'train' else 'test',
                             options=ReaderOptions(**data['options']))
