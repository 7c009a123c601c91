#!/usr/bin/env bash
# Stable-Baselines3's SAC, 1,000 steps on block pulling through equiarm's Gymnasium env (the check of
# docs/python.md's SB3 example). Not part of the test command: torch from PyPI is several GB. Creates
# (once) a virtual environment with torch and stable-baselines3 outside the clone, installs the package
# with `pip install ./python` (release build), and prints one JSON line: steps, episodes, seconds.
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
venv="${EQUIARM_VENV_DIR:-$HOME/.cache/equiarm/venvs}/sb3-check"
if [ ! -f "$venv/.complete" ]; then
  rm -rf "$venv"
  python3 -m venv "$venv"
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check stable-baselines3==2.9.2 gymnasium==1.2.3
  touch "$venv/.complete"
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check --force-reinstall --no-deps ./python
cd "$venv"  # import the installed package, not python/equiarm
exec "$venv/bin/python" - <<'PY'
import json, time
import gymnasium
from stable_baselines3 import SAC
from stable_baselines3.common.monitor import Monitor
import equiarm

env = Monitor(gymnasium.make("equiarm/BlockPulling-v0", image_size=64))
model = SAC("MultiInputPolicy", env, buffer_size=10_000, learning_starts=100, batch_size=64, seed=0, verbose=0)
t0 = time.perf_counter()
model.learn(total_timesteps=1_000)
steps = model.num_timesteps
print(json.dumps({"steps": steps, "episodes": len(env.get_episode_rewards()),
                  "successes": int(sum(env.get_episode_rewards())), "seconds": round(time.perf_counter() - t0, 1),
                  "equiarm": equiarm.__version__}))
assert steps >= 1000, steps
PY
