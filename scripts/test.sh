#!/usr/bin/env bash
# Set up .venv and run the whole test suite (the CI command). Tests that need
# UJIIndoorLoc read it from $WIFI_PR_DATASET, by default
# ../shared/datasets/ujiindoorloc if present (test/conftest.py: the same
# however pytest is started). Arguments go to pytest, e.g. "-m unit" for the
# fast tier (tiers: test/conftest.py).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/python -m pytest -q -p no:cacheprovider test "$@"
