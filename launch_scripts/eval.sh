#!/usr/bin/env bash
# Evaluates a checkpoint on a task: one sim (namespace /eval, M seeded episodes) answered by one
# policy node in greedy mode (`equiarm policy --mode greedy --checkpoint CKPT`, the deterministic
# action tanh(mean)), recorded by `equiarm record --all`; then `equiarm bag eval` on the bag.
#
# Options:
#   --checkpoint CKPT  the actor checkpoint (required; what `equiarm train` writes into RUN/checkpoints/)
#   --task T           block_pulling (default), block_pushing, block_picking, drawer_opening, block_in_bowl
#   --episodes M       evaluation episodes (default 20)
#   --seed S           base seed of the episodes (default 1000; the same S gives the same M scenes)
#   --preset P         reduced16 (default), reduced or paper: the network's sizes (image FRAME:INPUT, hidden, model)
#                      come from launch_scripts/configs/<preset>_<task>.json
#   --config FILE      a training config JSON to read those sizes, the camera view and the corruptions
#                      from instead (e.g. RUN/config.json)
#   --model M          equi, cnn, sen or ferm (default: the config's)
#   --out DIR          output directory; the bag is DIR/bag, logs in DIR/logs (default runs/eval-<task>-<time>)
#   --timeout-s T      give up after T seconds (default 1800)
#   --video            also write one MP4 per episode into DIR/videos (`equiarm bag video`)
# Environment: EQUIARM_BIN (the binary; when unset it is built once with cargo into CARGO_TARGET_DIR,
# default ~/.cache/equiarm/target), ROS_DOMAIN_ID (passed on to every process).
#
# Every process runs in its own process group; on exit, Ctrl-C or SIGTERM all are stopped (SIGINT,
# up to 10 s, then SIGKILL), so nothing is left running.
#
# Example:
#   bash launch_scripts/eval.sh --checkpoint runs/latest/checkpoints/latest --task block_pulling --episodes 50
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
source "$here/lib.sh"
eqa_default_signals "$0" "$@"

checkpoint="" task=block_pulling episodes=20 seed=1000 preset=reduced16 config="" model="" out="" timeout_s=1800 video=0
usage() { sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; }
while [ $# -gt 0 ]; do
  case $1 in
    --checkpoint) checkpoint=$2; shift 2 ;;
    --task) task=$2; shift 2 ;;
    --episodes) episodes=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --preset) preset=$2; shift 2 ;;
    --config) config=$2; shift 2 ;;
    --model) model=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --timeout-s) timeout_s=$2; shift 2 ;;
    --video) video=1; shift ;;
    -h|--help) usage; exit 0 ;;
    *) echo "eval.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
[ -n "$checkpoint" ] || { echo "eval.sh: --checkpoint CKPT is required (see --help)" >&2; exit 2; }
[ -e "$checkpoint" ] || { echo "eval.sh: checkpoint $checkpoint does not exist" >&2; exit 2; }
config=${config:-$here/configs/${preset}_$task.json}
[ -f "$config" ] || { echo "eval.sh: no config $config (unknown task or preset?)" >&2; exit 2; }
frame=$(eqa_config_get "$config" image_size)
input=$(eqa_config_get "$config" input_size)
hidden=$(eqa_config_get "$config" hidden)
model=${model:-$(eqa_config_get "$config" model)}
mapfile -t scene < <(eqa_scene_args "$config")
out=${out:-runs/eval-$task-$(date +%Y%m%d-%H%M%S)}

eqa_bin
eqa_recorded_run "$out" /eval/observation:equiarm_msgs/msg/Observation
bag=$EQA_BAG
eqa_start policy_eval "$out/logs/policy_eval.log" \
  "$EQUIARM_BIN" policy --namespace /eval --mode greedy --checkpoint "$checkpoint" \
  --model "$model" --hidden "$hidden" --image "$frame:$input" --seed "$seed"
eqa_start sim_eval "$out/logs/sim_eval.log" \
  "$EQUIARM_BIN" sim --namespace /eval --eval --task "$task" --seed "$seed" --resolution "$frame" "${scene[@]}" \
  --episodes "$episodes" --stamp-origin "$EQA_STAMP_ORIGIN"

eqa_log "evaluating $checkpoint ($model, hidden $hidden, image $frame:$input) on $task: $episodes episode(s), seed $seed"
failed=0
eqa_wait_sims "$timeout_s" "$out/logs" sim_eval || failed=1
sleep 2  # the last EpisodeResult reaches the recorder
eqa_stop_all
"$EQUIARM_BIN" bag eval "$bag" || failed=1
if [ "$video" = 1 ]; then
  "$EQUIARM_BIN" bag video "$bag" --out "$out/videos" || failed=1
fi
exit $failed
