"""Recipe variants cross-validated on the training part alone (no test file)."""

import json
from pathlib import Path
import sys
import time

import numpy as np
from wifi_place_recognition.core.metrics import class_index
from wifi_place_recognition.training.config import TrainConfig
from wifi_place_recognition.training.selection import cross_validate


def search(args, data):
    """Cross-validate each variant of ``--variants`` (JSON); no test file."""
    train_fp = data.train
    variants = json.loads(Path(args.variants).read_text())
    train_fp = train_fp.subset(~train_fp.empty_rows)
    classes, y = class_index(train_fp.building, train_fp.floor)
    import torch
    y = torch.from_numpy(y)
    runs = []
    for name, overrides in variants.items():
        for seed in args.seeds:
            config = TrainConfig(**dict(overrides, seed=seed))
            start = time.perf_counter()
            s = cross_validate(train_fp, y, len(classes), config,
                               log=lambda line: None)
            curves = np.asarray(s['curves'])
            runs.append({
                'variant': name, 'overrides': overrides, 'seed': seed,
                'cv_accuracy_at_choice': s['accuracy_mean'],
                'cv_accuracy_plateau': float(curves[:, 1:].mean()),
                'fold_plateaus': curves[:, 1:].mean(axis=1).tolist(),
                'epochs': s['epochs'],
                'position_mean_error_m': s.get('position_mean_error_m'),
                'seconds': time.perf_counter() - start})
            r = runs[-1]
            print(f'{name:40s} seed {seed}: plateau '
                  f'{r["cv_accuracy_plateau"]:.4f} (folds '
                  + ' '.join(f'{v:.3f}' for v in r['fold_plateaus'])
                  + f'), position {r["position_mean_error_m"] or 0:.2f} m, '
                  f'{r["seconds"]:.0f} s', file=sys.stderr, flush=True)
    return {'runs': runs}


EXPERIMENTS = {'search': search}
