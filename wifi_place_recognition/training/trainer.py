"""
Training the SAE + classifier with torch (Nowicki & Wietrzykowski, 2017).

The stacked autoencoder (encoder ``sae_layers``, mirrored decoder) is first
trained on reconstruction; the decoder is dropped; a classifier
(``classifier_layers`` with dropout, softmax over every building/floor class
seen) is put on top and the whole network fine-tuned with cross-entropy and
Adam. The epoch with the best building+floor accuracy on a held-out split of
the training file is kept.
"""

import copy
import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import torch
from torch import nn

from ..data.fingerprints import check_trainable
from ..core.metrics import accuracies, class_index
from ..core.model import Layer, mean_softmax, PlaceModel
from ..core.preprocessing import RssiScaler

TORCH_ACTIVATIONS = {'relu': nn.ReLU, 'elu': nn.ELU, 'tanh': nn.Tanh}
VALIDATIONS = ('phone', 'random', 'none')


#: The paper's configuration, as overrides of the defaults (which add
#: phone-like augmentation, the exponential representation and a refit on
#: all scans, chosen on held-out phones: see benchmarks/README.md).
PAPER = dict(representation='dbm', augment_offset=0.0, augment_gain=0.0,
             augment_noise=0.0, augment_dropout=0.0, refit=False)


@dataclass
class TrainConfig:
    """Every choice that shapes a model; stored in the artifact."""

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
    sae_epochs: int = 20
    epochs: int = 40
    patience: int = 10
    batch_size: int = 64
    learning_rate: float = 1e-3
    ema_epochs: float = 0.0       # weight-averaging horizon; 0: off
    validation: str = 'phone'
    validation_fraction: float = 0.2
    refit: bool = True
    ensemble: int = 1
    seed: int = 0
    threads: int = 0  # 0: torch's default

    def __post_init__(self):
        """Check values so that a bad option fails before training starts."""
        self.sae_layers = tuple(int(n) for n in self.sae_layers)
        self.classifier_layers = tuple(int(n) for n in self.classifier_layers)
        checks = [
            (all(n > 0 for n in self.sae_layers + self.classifier_layers),
             'layer sizes must be positive'),
            (self.activation in TORCH_ACTIVATIONS,
             f'activation must be one of {sorted(TORCH_ACTIVATIONS)}'),
            (0.0 <= self.dropout < 1.0, 'dropout must be in [0, 1)'),
            (self.sae_epochs >= 0 and self.epochs >= 1 and
             self.patience >= 1, 'epochs must be positive'),
            (self.ensemble >= 1, 'ensemble must be at least 1'),
            (self.ema_epochs >= 0, 'ema_epochs must be >= 0'),
            (self.batch_size >= 1 and self.learning_rate > 0,
             'batch size and learning rate must be positive'),
            (self.validation in VALIDATIONS,
             f'validation must be one of {VALIDATIONS}'),
            (0.0 < self.validation_fraction < 1.0,
             'validation fraction must be in (0, 1)'),
            (min(self.augment_offset, self.augment_gain, self.augment_noise)
             >= 0 and 0 <= self.augment_dropout < 1,
             'augmentation amounts must be >= 0 (dropout < 1)'),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)


@dataclass
class TrainReport:
    """What happened during training, for the summary and provenance."""

    best_epoch: list = field(default_factory=list)  # one per member
    validation: dict = field(default_factory=dict)
    validation_mode: str = ''    # phone, random or none, as applied
    validation_phones: list = field(default_factory=list)
    train_samples: int = 0
    validation_samples: int = 0
    dropped_empty: int = 0
    seconds: float = 0.0


def split_validation(fp, config):
    """
    Return a boolean mask of the held-out scans.

    ``phone``: whole phones (PHONEID) are held out, drawn at random until
    about ``validation_fraction`` of the scans, skipping a phone if it would
    take more than 1.5× that or the last training scans of a class.
    Falls back to ``random`` when the file has no PHONEID column.
    """
    rng = np.random.default_rng(config.seed)
    n = len(fp)
    if config.validation == 'none':
        return np.zeros(n, bool)
    phones = fp.meta.get('PHONEID')
    if config.validation == 'random' or phones is None:
        return rng.random(n) < config.validation_fraction
    labels = class_index(fp.building, fp.floor)[1]
    held = np.zeros(n, bool)
    for phone in rng.permutation(np.unique(phones)):
        if held.sum() >= config.validation_fraction * n:
            break
        candidate = held | (phones == phone)
        if candidate.sum() > 1.5 * config.validation_fraction * n:
            continue
        if len(np.unique(labels[~candidate])) < len(np.unique(labels)):
            continue
        held = candidate
    return held


def _dense(sizes, activation, dropout=0.0):
    layers = []
    for n_in, n_out in zip(sizes[:-1], sizes[1:]):
        layers += [nn.Linear(n_in, n_out), TORCH_ACTIVATIONS[activation]()]
        if dropout:
            layers.append(nn.Dropout(dropout))
    return layers


class PlaceNet(nn.Module):
    """Encoder (from the SAE) + classifier; outputs logits."""

    def __init__(self, n_inputs, n_classes, config):
        super().__init__()
        self.activation = config.activation
        self.encoder = nn.Sequential(*_dense(
            (n_inputs,) + config.sae_layers, config.activation))
        head = (config.sae_layers[-1],) + config.classifier_layers
        self.head = nn.Sequential(
            *_dense(head, config.activation, config.dropout),
            nn.Linear(head[-1], n_classes))

    def forward(self, x):
        """Return logits."""
        return self.head(self.encoder(x))

    def frozen_layers(self):
        """Return the dense layers as numpy :class:`Layer` objects."""
        linears = [m for m in self.modules() if isinstance(m, nn.Linear)]
        return [Layer(m.weight.detach().numpy().copy(),
                      m.bias.detach().numpy().copy(),
                      'linear' if m is linears[-1] else self.activation)
                for m in linears]


def augment(rssi, config, rng):
    """
    Return scans as another phone might see them (NaN = not detected).

    Per scan a gain and an offset, per reading Gaussian noise and random
    loss; readings pushed below the not-detected floor are lost.
    """
    n = len(rssi)
    out = rssi * (1 + rng.uniform(-config.augment_gain, config.augment_gain,
                                  (n, 1)))
    out += rng.uniform(-config.augment_offset, config.augment_offset, (n, 1))
    if config.augment_noise:
        out += rng.normal(0, config.augment_noise, out.shape)
    floor = config.not_detected if config.not_detected < 0 else -110.0
    lost = (rng.random(out.shape) < config.augment_dropout) | (out < floor)
    out[lost] = np.nan
    return np.minimum(out, 0.0, out=out).astype(np.float32)


class _Batches:
    """Shuffled mini-batches of network inputs, augmented if configured."""

    def __init__(self, rssi, scaler, config):
        self.config = config
        self.augmenting = (config.augment_offset or config.augment_gain or
                           config.augment_noise or config.augment_dropout)
        self.rssi = rssi
        self.inputs = None if self.augmenting else \
            torch.as_tensor(scaler.transform(rssi))
        self.scaler = scaler
        self.generator = torch.Generator().manual_seed(config.seed)
        self.rng = np.random.default_rng(config.seed)

    def __len__(self):
        return len(self.rssi)

    def __iter__(self):
        order = torch.randperm(len(self.rssi), generator=self.generator)
        for idx in torch.split(order, self.config.batch_size):
            if self.augmenting:
                raw = augment(self.rssi[idx.numpy()], self.config, self.rng)
                yield idx, torch.as_tensor(self.scaler.transform(raw))
            else:
                yield idx, self.inputs[idx]


def _pretrain_sae(net, batches, config, log):
    sizes = (batches.rssi.shape[1],) + config.sae_layers
    decoder = nn.Sequential(*_dense(sizes[::-1], config.activation)[:-1])
    sae = nn.Sequential(net.encoder, decoder)
    optimiser = torch.optim.Adam(sae.parameters(), lr=config.learning_rate)
    for epoch in range(1, config.sae_epochs + 1):
        total = 0.0
        for _, x in batches:
            optimiser.zero_grad()
            loss = nn.functional.mse_loss(sae(x), x)
            loss.backward()
            optimiser.step()
            total += loss.item() * len(x)
        log(f'sae epoch {epoch:3d}/{config.sae_epochs}  '
            f'reconstruction mse {total / len(batches):.4f}')


def _predict_labels(nets, x, classes):
    """Return (building, floor) from the mean softmax of ``nets``."""
    logits = []
    with torch.no_grad():
        for net in nets:
            was_training = net.training
            net.eval()
            logits.append(net(x).numpy())
            net.train(was_training)
    best = mean_softmax(logits).argmax(axis=1)
    return classes[best, 0], classes[best, 1]


def _fit(rssi, y, scaler, config, epochs, val, classes, log):
    """Train a fresh network; with ``val``, keep the best epoch."""
    torch.manual_seed(config.seed)
    batches = _Batches(rssi, scaler, config)
    net = PlaceNet(rssi.shape[1], len(classes), config)
    _pretrain_sae(net, batches, config, log)
    optimiser = torch.optim.Adam(net.parameters(), lr=config.learning_rate)
    # With ema_epochs the kept weights are an exponential moving average of
    # the trained ones over about that many epochs (Polyak averaging):
    # smoother, and what is selected and exported.
    steps = len(batches) / config.batch_size * config.ema_epochs
    keep = 1.0 / max(1.0, steps)
    kept = copy.deepcopy(net) if config.ema_epochs else net
    best = (-1.0, 0, None, {})
    for epoch in range(1, epochs + 1):
        total = 0.0
        for idx, x in batches:
            optimiser.zero_grad()
            loss = nn.functional.cross_entropy(net(x), y[idx])
            loss.backward()
            optimiser.step()
            total += loss.item() * len(idx)
            if kept is not net:
                with torch.no_grad():
                    for k, p in zip(kept.parameters(), net.parameters()):
                        k.lerp_(p, keep)
        line = f'epoch {epoch:3d}/{epochs}  loss {total / len(rssi):.4f}'
        if val is not None:
            xv, bv, fv = val
            scores = accuracies(bv, fv, *_predict_labels([kept], xv, classes))
            line += (f'  held-out building+floor '
                     f'{scores["building_floor_accuracy"]:.4f}')
            if scores['building_floor_accuracy'] > best[0]:
                best = (scores['building_floor_accuracy'], epoch,
                        {k: v.clone() for k, v in kept.state_dict().items()},
                        scores)
            elif epoch - best[1] >= config.patience:
                log(line + '  (early stop)')
                break
        log(line)
    if val is not None:
        kept.load_state_dict(best[2])
    kept.eval()
    return kept, best[1] or epochs, best[3]


def train(fp, config, log=print):
    """
    Train on :class:`Fingerprints`; return (PlaceModel, nets, report).

    ``config.ensemble`` networks (seeds ``seed``, ``seed + 1`` …) are each
    early-stopped on the held-out scans; with ``refit`` each is then
    trained again from scratch on all scans for its selected epoch count.
    """
    start = time.perf_counter()
    if config.threads:
        torch.set_num_threads(config.threads)
    check_trainable(fp)
    report = TrainReport()
    usable = ~fp.empty_rows
    report.dropped_empty = int((~usable).sum())
    fp = fp.subset(usable)
    classes, y_all = class_index(fp.building, fp.floor)
    y_all = torch.as_tensor(y_all)
    held = split_validation(fp, config)
    report.train_samples = int((~held).sum())
    report.validation_samples = int(held.sum())
    report.validation_mode = config.validation
    if config.validation == 'phone' and 'PHONEID' not in fp.meta:
        report.validation_mode = 'random'
    if report.validation_mode == 'phone':
        report.validation_phones = sorted(
            int(p) for p in np.unique(fp.meta['PHONEID'][held]))

    scaler = RssiScaler(config.not_detected, config.scaling,
                        config.representation)
    scaler.fit(fp.rssi[~held])
    val = None
    if held.any():
        val = (torch.as_tensor(scaler.transform(fp.rssi[held])),
               fp.building[held], fp.floor[held])
        log(f'training on {report.train_samples} scans, selecting on '
            f'{report.validation_samples} held-out scans '
            f'({report.validation_mode})')
    nets, epochs = [], []
    for k in range(config.ensemble):
        member = replace(config, seed=config.seed + k)
        if config.ensemble > 1:
            log(f'ensemble member {k + 1}/{config.ensemble}')
        net, best_epoch, _ = _fit(fp.rssi[~held], y_all[~held], scaler,
                                  member, config.epochs, val, classes, log)
        nets.append(net)
        epochs.append(best_epoch)
    report.best_epoch = epochs
    if val is not None:
        b, f = _predict_labels(nets, val[0], classes)
        report.validation = accuracies(val[1], val[2], b, f)
    if config.refit and held.any():
        scaler.fit(fp.rssi)
        nets = []
        for k, n_epochs in enumerate(epochs):
            log(f'refit {k + 1}/{config.ensemble} on all {len(fp)} scans '
                f'for {n_epochs} epochs')
            nets.append(_fit(fp.rssi, y_all, scaler,
                             replace(config, seed=config.seed + k), n_epochs,
                             None, classes, log)[0])
    report.seconds = time.perf_counter() - start
    provenance = {
        'config': asdict(config),
        'training_data': {'source': fp.source, 'sha256': fp.sha256,
                          'scans': len(fp), 'dropped_empty':
                          report.dropped_empty, 'clipped_cells': fp.clipped},
        'selection': {'held_out': report.validation_mode,
                      'held_out_phones': report.validation_phones,
                      'held_out_scans': report.validation_samples,
                      'best_epoch': report.best_epoch,
                      'metrics': report.validation},
        'train_seconds': round(report.seconds, 2),
        'versions': {'torch': torch.__version__, 'numpy': np.__version__},
        'created': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime()),
    }
    model = PlaceModel(fp.ap_ids, scaler,
                       [net.frozen_layers() for net in nets], classes,
                       provenance)
    return model, nets, report
