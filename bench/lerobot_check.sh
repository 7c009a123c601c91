#!/usr/bin/env bash
# LeRobot's own `LeRobotDataset(repo_id, root=OUT)` (PyPI lerobot 0.4.4, the newest for Python 3.11;
# the v3.0 format is the same in 0.6) loads `equiarm bag export --format lerobot` of a demo.sh bag:
# its length equals the transitions launch_scripts/bag_transitions.py joins, the actions, rewards and
# done flags equal them, and the images equal the bag's frames. Not part of the test command (torch is
# several GB): creates (once) a virtual environment outside the clone. Prints one JSON line.
#
# Options: --episodes E (per env, default 3), --num-envs N (default 2), --task T (default block_pulling).
# Runs the demo in a private network namespace (tests/netns.sh) on ROS domain 38.
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
episodes=3 num_envs=2 task=block_pulling
while [ $# -gt 0 ]; do
  case $1 in
    --episodes) episodes=$2; shift 2 ;;
    --num-envs) num_envs=$2; shift 2 ;;
    --task) task=$2; shift 2 ;;
    *) echo "lerobot_check.sh: unknown option $1" >&2; exit 2 ;;
  esac
done
venv="${EQUIARM_VENV_DIR:-$HOME/.cache/equiarm/venvs}/lerobot-check-$(sha256sum bench/requirements-lerobot.txt | cut -c1-12)"
if [ ! -f "$venv/.complete" ]; then
  rm -rf "$venv"
  python3 -m venv "$venv"
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r bench/requirements-lerobot.txt
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps lerobot==0.4.4
  touch "$venv/.complete"
fi
source bench/demo_bag.sh
bench_demo_bag 38 --task "$task" --num-envs "$num_envs" --episodes "$episodes"
"$venv/bin/python" launch_scripts/bag_transitions.py "$work/demo/bag" --npz "$work/t.npz" > /dev/null
start=$(date +%s%N)
"$EQUIARM_BIN" bag export "$work/demo/bag" --format lerobot "$work/lerobot" >&2
export_ms=$(( ($(date +%s%N) - start) / 1000000 ))
HF_HUB_OFFLINE=1 HF_HOME="$work/hf" EXPORT_MS=$export_ms "$venv/bin/python" - "$work" <<'PY'
import json, os, sys
import numpy as np
from lerobot.datasets.lerobot_dataset import LeRobotDataset

work = sys.argv[1]
t = dict(np.load(os.path.join(work, "t.npz")))
ds = LeRobotDataset("equiarm/export", root=os.path.join(work, "lerobot"))
n = len(ds)
assert n == len(t["reward"]), (n, len(t["reward"]))
f = np.float32
a = t["action"]
want = np.column_stack([np.clip(a[:, 0], f(0), f(1)) * f(2) - f(1), np.clip(a[:, 1:4], f(-0.05), f(0.05)) / f(0.05),
                        np.clip(a[:, 4], -f(np.pi / 4), f(np.pi / 4)) / f(np.pi / 4)]).astype(np.float32)
# bag_transitions.py sorts by env and obs_seq; the export numbers episodes as they complete: match by
# (env, episode, step), the env and episode of each exported episode being in meta/episodes.
eps = ds.meta.episodes
key_of_row = {}
theirs = {(str(e), int(p), int(s)): i for i, (e, p, s) in enumerate(zip(t["env"], t["episode"], t["step"]))}
max_image_err = 0
for i in range(n):
    item = ds[i]
    e = int(item["episode_index"])
    key = (eps[e]["env"], int(eps[e]["env_episode"]), int(item["frame_index"]))
    j = theirs[key]
    assert np.array_equal(item["action"].numpy(), want[j]), key
    assert item["next.reward"].item() == t["reward"][j], key
    assert bool(item["next.done"]) == bool(t["done"][j]), key
    img = (item["observation.image"].numpy().transpose(1, 2, 0) * 255).round().astype(np.uint8)
    max_image_err = max(max_image_err, int(np.abs(img.astype(int) - t["obs_color"][j].astype(int)).max()))
    assert np.array_equal(item["observation.depth"].numpy(), t["obs_depth"][j]), key
    assert isinstance(item["task"], str) and item["task"]
assert max_image_err == 0, max_image_err
print(json.dumps({"frames": n, "episodes": ds.num_episodes, "fps": ds.fps, "tasks": ds.meta.total_tasks,
                  "joined_by_bag_transitions": int(len(t["reward"])), "image_max_abs_error": max_image_err,
                  "export_ms": int(os.environ["EXPORT_MS"]), "frames_per_s": round(n / max(int(os.environ["EXPORT_MS"]), 1) * 1000)}))
PY
