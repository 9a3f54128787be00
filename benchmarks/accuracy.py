"""
Accuracy benchmark: named experiments on a dataset, several seeds.

Each experiment answers one question (``--suite NAME``; the list is in
``--help``; one module each in ``benchmarks/experiments/``). Protocol:
everything a recipe chooses (the epoch count, k and the representation of
k-NN) is chosen by grouped cross-validation on the training part: whole
devices (UJIIndoorLoc PHONEID) or whole walks (WiFine files), or on the
validation part when the experiment says so. The test part is only ever
evaluated, and only by the experiments that train and test recipes
(``default``, ``table1``, ``architecture``, ``validation``); the others
cross-validate on the training part alone (``search``: the selection log
of benchmarks/README.md; ``members``: the ensemble size; ``ideas``: other
uses of the network). Prints a table or progress, writes JSON.

    python benchmarks/accuracy.py --dataset ujiindoorloc --suite default
    python benchmarks/accuracy.py --dataset wifine --suite default
    python benchmarks/accuracy.py --dataset wifine --suite validation
"""

import argparse
import inspect
import json
from pathlib import Path

from wifi_place_recognition.core.atomic import atomic_write
from wifi_place_recognition.data.fingerprints import (read_fingerprints,
                                                      ReaderOptions)

from datasets import DATASETS
from experiments import registry
from experiments.common import Data

ROOT = Path(__file__).resolve().parent.parent


def main():
    """Run an experiment; print its table or progress; write JSON."""
    experiments = registry()
    p = argparse.ArgumentParser(
        description=__doc__.split('\n\n')[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog='experiments (--suite):\n' + '\n'.join(
            f'  {name:13s} {inspect.getdoc(run).splitlines()[0]}'
            for name, run in sorted(experiments.items())))
    p.add_argument('--datasets', type=Path,
                   default=ROOT.parent / 'shared' / 'datasets',
                   help='folder holding ujiindoorloc/ and wifine/')
    p.add_argument('--dataset', choices=sorted(DATASETS),
                   default='ujiindoorloc')
    p.add_argument('--suite', choices=sorted(experiments), default='default')
    p.add_argument('--members', type=int, default=5,
                   help='members: the largest ensemble cross-validated')
    p.add_argument('--variants', help='search: JSON {name: overrides}')
    p.add_argument('--seeds', type=lambda s: [int(v) for v in s.split(',')],
                   default=[0, 1, 2])
    p.add_argument('--no-baselines', action='store_true')
    p.add_argument('--recipes', type=lambda s: s.split(','), default=None,
                   help='run only the recipes whose names start with these '
                        'comma-separated words (default suite: default, '
                        'paper)')
    p.add_argument('--out', type=Path, default=None)
    args = p.parse_args()
    spec = DATASETS[args.dataset]
    paths = {part: [str(args.datasets / f) for f in spec.get(part, [])]
             for part in ('train', 'test', 'validation')}
    out = args.out or ROOT / 'benchmarks' / 'results' / \
        f'{args.dataset}-{args.suite}.json'
    options = ReaderOptions(**spec['options'])
    train_fp = read_fingerprints(paths['train'], options=options)
    data = Data(args.dataset, paths, options, spec['args'], train_fp)
    result = experiments[args.suite](args, data)
    _write(out, dict({'dataset': args.dataset, 'train': paths['train'],
                      'train_sha256': train_fp.sha256, 'seeds': args.seeds,
                      'test': None}, **result))


def _write(out, content):
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(out, 'w') as f:
        json.dump(content, f, indent=1)
    print(f'wrote {out}')


if __name__ == '__main__':
    main()
