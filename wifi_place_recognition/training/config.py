"""Every choice that shapes a trained model, checked before training starts."""

import math
from dataclasses import dataclass

from ..core.locator import METRICS
from ..core.preprocessing import SIGNALS

ACTIVATION_NAMES = ('relu', 'elu', 'tanh')
GROUPINGS = ('auto', 'device', 'walk', 'time')
#: batch_size 0: about this many optimiser steps per epoch, in powers of
#: two between these bounds (UJIIndoorLoc and WiFine: 512).
STEPS_PER_EPOCH = 20
BATCH_BOUNDS = (32, 512)
#: Which references a scan's position k-NN searches: those of its
#: recognised floor, or of every floor of its building.
SCOPES = ('floor', 'building')
#: The widest layer, the largest learning rate and seed a recipe may have.
MAX_WIDTH, MAX_LEARNING_RATE, MAX_SEED = 8192, 1.0, 2 ** 32 - 1


@dataclass
class TrainConfig:
    """
    The training recipe; stored whole in the model file.

    Defaults: the paper's network (SAE 256-128-64 pre-trained on
    reconstruction, classifier 128-128 with dropout, Adam, -110 dBm for
    undetected APs, one mean/std) plus what cross-validation over held-out
    devices chose (benchmarks/README.md): the exponential representation,
    phone-like augmentation, the epoch count chosen on the mean
    cross-validated curve, then an ensemble trained on all scans; and
    what the panel's folds chose: the batch size from the number of
    scans, a cap the curve does not reach (patience), the position
    k-NN's scope, signal, distance and k chosen by the folds.
    """

    sae_layers: tuple = (256, 128, 64)
    classifier_layers: tuple = (128, 128)
    activation: str = 'relu'
    dropout: float = 0.2
    not_detected: float = -110.0
    scaling: str = 'joint'
    representation: str = 'exponential'
    augment_offset: float = 10.0  # dB, uniform +- per scan
    augment_gain: float = 0.1     # fraction, uniform +- per scan
    augment_noise: float = 2.0    # dB, normal std per reading
    augment_dropout: float = 0.1  # probability to drop a detected AP
    sae_epochs: int = 10
    epochs: int = 60              # the most; selection stops earlier
    patience: int = 10            # epochs without a better held-out mean
    batch_size: int = 0           # 0: from the number of scans
    learning_rate: float = 3e-3
    neighbours: int = 0           # k of the position k-NN; 0: by the folds
    position_representation: str = ''  # signal of the k-NN; '': by folds
    position_metric: str = ''     # distance of the k-NN; '': by the folds
    position_scope: str = ''      # floor or building; '': by the folds
    folds: int = 4                # cross-validation folds; 0: no selection
    grouping: str = 'auto'        # what a fold holds out (see selection)
    ensemble: int = 3
    seed: int = 0
    threads: int = 0              # 0: torch's default

    def __post_init__(self):
        """Check values so that a bad option fails before training starts."""
        self.sae_layers = tuple(int(n) for n in self.sae_layers)
        self.classifier_layers = tuple(int(n) for n in self.classifier_layers)
        numbers = {name: getattr(self, name) for name in (
            'dropout', 'not_detected', 'augment_offset', 'augment_gain',
            'augment_noise', 'augment_dropout', 'learning_rate')}
        checks = [
            (all(math.isfinite(v) for v in numbers.values()),
             f'every number must be finite, not '
             f'{ {k: v for k, v in numbers.items() if not math.isfinite(v)} }'),
            (self.sae_layers and all(0 < n <= MAX_WIDTH for n in
                                     self.sae_layers +
                                     self.classifier_layers),
             f'layer sizes must be from 1 to {MAX_WIDTH} (and sae_layers not '
             f'empty), not {self.sae_layers} and {self.classifier_layers}'),
            (self.activation in ACTIVATION_NAMES,
             f'activation must be one of {ACTIVATION_NAMES}'),
            (0.0 <= self.dropout < 1.0, 'dropout must be in [0, 1)'),
            (self.sae_epochs >= 0 and self.epochs >= 1 and
             self.patience >= 1,
             'sae_epochs must be >= 0, epochs and patience >= 1'),
            (self.folds == 0 or self.folds >= 2,
             'folds must be 0 (no selection) or at least 2'),
            (self.grouping in GROUPINGS,
             f'grouping must be one of {GROUPINGS}'),
            (self.ensemble >= 1, 'ensemble must be at least 1'),
            (self.batch_size >= 0 and
             0 < self.learning_rate <= MAX_LEARNING_RATE,
             f'batch size must be >= 0 (0: from the data) and learning rate '
             f'in (0, {MAX_LEARNING_RATE:g}], not {self.batch_size} and '
             f'{self.learning_rate!r}'),
            (self.position_representation in ('',) + SIGNALS,
             f'position_representation must be one of {SIGNALS} '
             f'(or empty: chosen by the folds)'),
            (self.position_metric in ('',) + METRICS,
             f'position_metric must be one of {METRICS} (or '
             f'empty: chosen by the folds)'),
            (self.position_scope in ('',) + SCOPES,
             f'position_scope must be one of {SCOPES} (or empty: chosen by '
             f'the folds)'),
            (min(self.augment_offset, self.augment_gain, self.augment_noise)
             >= 0 and self.augment_gain < 1 and
             0 <= self.augment_dropout < 1,
             'augmentation amounts must be >= 0 (gain and dropout < 1)'),
            (self.threads >= 0, 'threads must be >= 0'),
            (0 <= self.seed <= MAX_SEED,
             f'seed must be from 0 to {MAX_SEED}, not {self.seed}'),
            (self.neighbours >= 0, 'neighbours must be >= 0'),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)

    def batch_for(self, n):
        """Return the mini-batch size for ``n`` training scans."""
        if self.batch_size:
            return self.batch_size
        low, high = BATCH_BOUNDS
        return int(min(high, max(low, 2 ** round(
            math.log2(max(n, 1) / STEPS_PER_EPOCH)))))

    def fold_seed(self, k):
        """Return the seed of fold ``k``'s network (apart from members')."""
        return self.seed + 1000 * (k + 1)

    @property
    def augmenting(self):
        """Return True when any augmentation amount is set."""
        return bool(self.augment_offset or self.augment_gain or
                    self.augment_noise or self.augment_dropout)


#: The paper's recipe as overrides of the defaults: dBm input, no
#: augmentation, one network, 20 SAE epochs at batch 64, lr 1e-3.
PAPER = dict(representation='dbm', augment_offset=0.0, augment_gain=0.0,
             augment_noise=0.0, augment_dropout=0.0, ensemble=1,
             sae_epochs=20, batch_size=64, learning_rate=1e-3)
