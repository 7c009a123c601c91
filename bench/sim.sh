#!/usr/bin/env bash
# Simulator step + 152 px RGBD render per task, beside a PyBullet BulletArm-like step in the same run
# (installs pybullet into its own virtual environment once). Extra arguments go to the benchmark,
# e.g. `bash bench/sim.sh --steps 300 --rounds 3`.
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
EQUIARM_REQUIREMENTS="$PWD/bench/requirements-sim.txt" source tests/python_env.sh
exec cargo bench --locked -p equiarm_sim --bench step_render -- --peer "$EQUIARM_PYTHON" "$@"
