"""What the experiments share: the dataset as read, the default folds."""

from dataclasses import dataclass

from wifi_place_recognition.core.metrics import class_index
from wifi_place_recognition.data.fingerprints import (Fingerprints,
                                                      read_fingerprints,
                                                      ReaderOptions)
from wifi_place_recognition.training.config import TrainConfig
from wifi_place_recognition.training.folds import grouped_folds


@dataclass
class Data:
    """
    A dataset as the experiments read it.

    ``paths``: part (train, test, validation) -> files or folders;
    ``args``: ``options`` as command-line flags (for train_model and
    evaluate_model); ``train``: the training part, read.
    """

    name: str
    paths: dict
    options: ReaderOptions
    args: list
    train: Fingerprints

    def test(self):
        """Return the test part, read."""
        return read_fingerprints(self.paths['test'], role='test',
                                 options=self.options)


def default_folds(train_fp, seeds):
    """
    Return (scans, classes, y, [(seed, config, held-out masks)]).

    The training scans that detect an AP, their classes, and the default
    recipe's folds at each seed.
    """
    train_fp = train_fp.subset(~train_fp.empty_rows)
    classes, y = class_index(train_fp.building, train_fp.floor)
    per_seed = []
    for seed in seeds:
        config = TrainConfig(seed=seed)
        per_seed.append((seed, config, grouped_folds(
            train_fp, y, config.folds, config.grouping, seed).held_out))
    return train_fp, classes, y, per_seed
