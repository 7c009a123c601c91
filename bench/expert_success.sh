#!/usr/bin/env bash
# Expert planner success counts per task for seeds 0-99 (acceptance: >= 95 each).
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
exec cargo run --locked --release -p equiarm_sim --example expert_success -- "$@"
