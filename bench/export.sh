#!/usr/bin/env bash
# Export speed (issue 57): a demo.sh bag of expert episodes at 152 px (the paper's frame), then
# `equiarm bag export --format lerobot` (frames/s) and `equiarm bag video` (seconds per 50-step
# episode), each the median of R runs. Prints one JSON line. The demo runs in a private network
# namespace (tests/netns.sh) on ROS domain 39.
#
# Options: --episodes E (per env, default 5), --num-envs N (default 2), --rounds R (default 3),
#          --resolution PX (default 152).
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/equiarm/target}"
episodes=5 num_envs=2 rounds=3 resolution=152
while [ $# -gt 0 ]; do
  case $1 in
    --episodes) episodes=$2; shift 2 ;;
    --num-envs) num_envs=$2; shift 2 ;;
    --rounds) rounds=$2; shift 2 ;;
    --resolution) resolution=$2; shift 2 ;;
    *) echo "export.sh: unknown option $1" >&2; exit 2 ;;
  esac
done
source bench/demo_bag.sh
bench_demo_bag 39 --num-envs "$num_envs" --episodes "$episodes" --resolution "$resolution"
ms() { local s; s=$(date +%s%N); "$@" > /dev/null 2>&1; echo $(( ($(date +%s%N) - s) / 1000000 )); }
export_ms=() video_ms=()
for r in $(seq "$rounds"); do
  rm -rf "$work/lerobot" "$work/videos"
  export_ms+=("$(ms "$EQUIARM_BIN" bag export "$work/demo/bag" --format lerobot "$work/lerobot")")
  video_ms+=("$(ms "$EQUIARM_BIN" bag video "$work/demo/bag" --out "$work/videos")")
done
frames=$(python3 -c "import json; print(json.load(open('$work/lerobot/meta/info.json'))['total_frames'])")
videos=$(ls "$work/videos" | wc -l)
python3 - "$frames" "$videos" "$resolution" "${export_ms[*]}" "${video_ms[*]}" <<'PY'
import json, statistics, sys
frames, videos, px = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
ex = [int(x) for x in sys.argv[4].split()]
vi = [int(x) for x in sys.argv[5].split()]
e, v = statistics.median(ex), statistics.median(vi)
# a video holds one frame per step plus the last: frames + videos frames in all
print(json.dumps({"px": px, "steps": frames, "episodes": videos, "export_ms": ex, "video_ms": vi,
                  "export_frames_per_s": round(frames / e * 1000), "video_s_per_50_step_episode": round(v / 1000 / (frames + videos) * 51, 3)}))
PY
