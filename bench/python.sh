#!/usr/bin/env bash
# The Python package's env steps per second at 152 px RGBD (`equiarm.make`, `equiarm.make_vec(8)`),
# its overhead per step over the same Rust loop without Python, beside the PyBullet BulletArm-like
# step in the same run (bench/python_env.py). Builds the wheel in release, as `pip install ./python`
# does, and installs it into its own virtual environment (with pybullet). Extra arguments go to
# bench/python_env.py, e.g. `bash bench/python.sh --steps 300 --rounds 3`.
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
EQUIARM_REQUIREMENTS="$PWD/bench/requirements-python.txt" source tests/python_env.sh
wheels=$(mktemp -d)
trap 'rm -rf "$wheels"' EXIT
"$EQUIARM_PYTHON" -m maturin build --locked --release -m python/Cargo.toml -i "$EQUIARM_PYTHON" -o "$wheels" --quiet
"$EQUIARM_PYTHON" -m pip install --quiet --disable-pip-version-check --force-reinstall --no-deps "$wheels"/equiarm-*.whl
cd "$wheels"  # import the installed package, not python/equiarm
"$EQUIARM_PYTHON" "$OLDPWD/bench/python_env.py" --peer "$OLDPWD/bench/pybullet_peer.py" "$@"
