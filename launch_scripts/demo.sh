#!/usr/bin/env bash
# Shows a task without training: N sim + policy pairs with the expert policy (`equiarm policy --mode
# expert`, which answers each Observation with the expert action the sim carries), recorded by
# `equiarm record --all`, for E episodes per env; then `equiarm bag eval` on the bag.
#
# Options:
#   --task T         block_pulling (default), block_pushing, block_picking, drawer_opening, block_in_bowl
#   --num-envs N     sim + policy pairs /env0 ... /envN-1 (default 2)
#   --episodes E     episodes per env (default 3)
#   --seed S         env K uses seed S+K (default 0)
#   --resolution PX  image size (default: the reduced preset's, launch_scripts/configs/reduced_<task>.json)
#   --out DIR        output directory; the bag is DIR/bag, logs in DIR/logs (default runs/demo-<task>-<time>)
#   --timeout-s T    give up after T seconds (default 600)
# Environment: EQUIARM_BIN (the binary; when unset it is built once with cargo into CARGO_TARGET_DIR,
# default ~/.cache/equiarm/target), ROS_DOMAIN_ID (passed on to every process).
#
# Every process runs in its own process group; on exit, Ctrl-C or SIGTERM all are stopped (SIGINT,
# up to 10 s, then SIGKILL), so nothing is left running.
#
# Example:
#   bash launch_scripts/demo.sh --task block_picking --num-envs 3 --episodes 5
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
source "$here/lib.sh"
eqa_default_signals "$0" "$@"

task=block_pulling num_envs=2 episodes=3 seed=0 resolution="" out="" timeout_s=600
usage() { sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; }
while [ $# -gt 0 ]; do
  case $1 in
    --task) task=$2; shift 2 ;;
    --num-envs) num_envs=$2; shift 2 ;;
    --episodes) episodes=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --resolution) resolution=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --timeout-s) timeout_s=$2; shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "demo.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
config="$here/configs/reduced_$task.json"
[ -f "$config" ] || { echo "demo.sh: unknown task '$task' (no $config)" >&2; exit 2; }
resolution=${resolution:-$(eqa_config_get "$config" image_size)}
out=${out:-runs/demo-$task-$(date +%Y%m%d-%H%M%S)}

eqa_bin
obs_topics=()
for ((k = 0; k < num_envs; k++)); do obs_topics+=("/env$k/observation:equiarm_msgs/msg/Observation"); done
eqa_recorded_run "$out" "${obs_topics[@]}"
bag=$EQA_BAG
sims=()
for ((k = 0; k < num_envs; k++)); do
  eqa_start "policy_env$k" "$out/logs/policy_env$k.log" \
    "$EQUIARM_BIN" policy --namespace "/env$k" --mode expert --seed $((seed + k))
  eqa_start "sim_env$k" "$out/logs/sim_env$k.log" \
    "$EQUIARM_BIN" sim --namespace "/env$k" --task "$task" --seed $((seed + k)) --resolution "$resolution" \
    --episodes "$episodes" --stamp-origin "$EQA_STAMP_ORIGIN"
  sims+=("sim_env$k")
done

eqa_log "running $num_envs env(s) of $task, $episodes expert episode(s) each; logs in $out/logs"
failed=0
eqa_wait_sims "$timeout_s" "$out/logs" "${sims[@]}" || failed=1
sleep 2  # the last EpisodeResults reach the recorder
eqa_stop_all
"$EQUIARM_BIN" bag eval "$bag" || failed=1
exit $failed
