#!/usr/bin/env bash
# CDR encode/decode throughput of a 152x152 RGBD Observation: Rust beside Cyclone DDS Python.
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
source tests/python_env.sh
exec cargo bench --locked -p equiarm_msgs --bench cdr
