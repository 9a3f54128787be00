#!/usr/bin/env bash
# The main job: start classifier_node with the shipped model and tracking on,
# replay the UJIIndoorLoc test scans through it over ROS 2 walk after walk
# (one phone each, in TIMESTAMP order), printing live progress and, per walk
# and overall, each scan's own answer beside the tracked one. The node's own
# log goes to a file (named first), not between the progress lines.
# Usage: scripts/demo.sh [TEST_CSV]
# Without TEST_CSV the public UCI zip is downloaded (once) and its
# validationData.csv is replayed.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
if [ $# -gt 0 ]; then data=(--data "$1"); else data=(--download); fi
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$((RANDOM % 90 + 10))}"
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
log="${TMPDIR:-/tmp}/wifi_place_recognition-demo-node.log"
echo "classifier_node's log: $log"
.venv/bin/classifier_node --ros-args -p tracking:=true >"$log" 2>&1 &
node=$!
trap 'kill -INT $node 2>/dev/null; wait $node' EXIT
.venv/bin/replay_scans "${data[@]}"
