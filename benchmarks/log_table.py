"""
Print the selection log: every variant's held-out-phone and test accuracy.

    python benchmarks/log_table.py benchmarks/results/search*.json ...

One markdown row per variant: per-seed held-out building+floor accuracy
(the selection criterion), its mean, per-seed test accuracy and its mean.
"""

import json
import sys


def main():
    """Print the rows for the JSON files given."""
    print('| variant | held-out phones, seeds 0/1/2 | mean | test, seeds '
          '0/1/2 | mean | test building |')
    print('|---|---|---|---|---|---|')
    for path in sys.argv[1:]:
        with open(path) as f:
            result = json.load(f)
        for name, row in result['table'].items():
            runs = result['runs'][name]
            held = ' / '.join(
                f'{r["held_out"]["building_floor_accuracy"]:.3f}'
                for r in runs)
            test = ' / '.join(
                f'{r["test"]["building_floor_accuracy"]:.3f}' for r in runs)
            print(f'| {name} | {held} | '
                  f'{row["held_out_building_floor"]["mean"]:.4f} | {test} | '
                  f'{row["test_building_floor"]["mean"]:.4f} | '
                  f'{row["test_building"]["mean"]:.4f} |')


if __name__ == '__main__':
    main()
