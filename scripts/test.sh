#!/usr/bin/env bash
# Set up .venv and run the whole test suite (the CI command). Tests that need
# UJIIndoorLoc read it from $WIFI_PR_DATASET (default:
# ../shared/datasets/ujiindoorloc if present). Arguments go to pytest, e.g.
# "-m unit" for the fast tier (tiers: test/conftest.py).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
default_data="$(cd .. && pwd)/shared/datasets/ujiindoorloc"
if [ -z "${WIFI_PR_DATASET:-}" ] && [ -d "$default_data" ]; then
  export WIFI_PR_DATASET="$default_data"
fi
exec .venv/bin/python -m pytest -q -p no:cacheprovider test "$@"
