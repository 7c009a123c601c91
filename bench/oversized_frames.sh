#!/usr/bin/env bash
# Oversized frames (issue 61; a benchmark, not a test): the peak RSS of the policy node and of the
# trainer while a Cyclone DDS peer publishes Observations announcing an 8192x8192 frame (two valid
# zstd frames of zeros, about 10 KB on the wire, 335 MB decompressed) on /env0/observation at RATE Hz,
# against a round without the peer. Each round runs the suite (one training env and the eval pair,
# the reduced preset, block pulling, the same seed) for SECONDS and reads VmHWM (peak RSS) from
# /proc at its end; the peer starts once the sims run. Prints per node: peak RSS without, with, the
# ratio, the training env's progress in each round (a bad frame must not hold the real ones up) and
# what the nodes counted as refused.
#
#   bash bench/oversized_frames.sh [--seconds 60] [--rate 10] [--out DIR]
#
# Runs in a private network namespace (as root or with unprivileged user namespaces), so its DDS traffic
# stays on this machine's loopback. EQUIARM_BIN: use this binary instead of building.
set -euo pipefail
args=("$@")
seconds=60 rate=10 out=""
while [ $# -gt 0 ]; do
  case "$1" in
    --seconds) seconds=$2; shift 2 ;;
    --rate) rate=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    -h|--help) sed -n '2,14p' "$0"; exit 0 ;;
    *) echo "oversized_frames.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
for v in seconds rate; do
  [[ ${!v} =~ ^[1-9][0-9]*$ ]] || { echo "oversized_frames.sh: --$v ${!v}: expected a whole number above 0" >&2; exit 2; }
done
source "$(dirname "$0")/../launch_scripts/lib.sh"
eqa_private_netns "$0" "${args[@]}"
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-62} ROS_LOCALHOST_ONLY=0
cd "$(dirname "$0")/.."
source tests/python_env.sh
eqa_bin

task=block_pulling seed=0 num_envs=1
out=${out:-runs/oversized-$(date +%Y%m%d-%H%M%S)}
[ -e "$out" ] && { echo "oversized_frames.sh: $out exists: choose another --out" >&2; exit 2; }
trap eqa_on_exit EXIT; trap 'exit 130' INT; trap 'exit 143' TERM
hwm_kib() { awk '/^VmHWM:/ {print $2}' "/proc/$1/status" 2>/dev/null || echo 0; }

# round NAME FLOOD: one round in $out/NAME; FLOOD=1 starts the peer. Sets peak_trainer, peak_policy.
round() {
  run_dir=$out/$1
  mkdir -p "$run_dir/logs"
  "$EQUIARM_BIN" train --preset reduced --task $task --num-envs $num_envs --seed $seed --total-updates 1000000 \
    --print-config > "$run_dir/config.json"
  image=$(eqa_config_get "$run_dir/config.json" image_size)
  arch=(--model "$(eqa_config_get "$run_dir/config.json" model)" --hidden "$(eqa_config_get "$run_dir/config.json" hidden)"
        --image "$image:$(eqa_config_get "$run_dir/config.json" input_size)")
  per_env=$(eqa_demos_per_env "$run_dir/config.json" $num_envs)
  pace=(--max-lead 10) trainer_mode=() extra=(--idle-timeout-s 600)
  eqa_suite_trainer trainer
  eqa_suite_policies
  eqa_suite_sims
  if [ "$2" = 1 ]; then
    eqa_start peer "$run_dir/logs/peer.log" "$EQUIARM_PYTHON" tests/python/dds_peer.py oversized \
      "$ROS_DOMAIN_ID" "$seconds" rt/env0/observation "$rate"
  fi
  sleep "$seconds"
  [ "$2" = 1 ] && { eqa_wait_for peer 30 || eqa_log "the peer did not finish in time"; }
  peak_trainer=$(hwm_kib "$(eqa_pid trainer)") peak_policy=$(hwm_kib "$(eqa_pid policy0)")
  eqa_stop_all
  EQA_PIDS=() EQA_NAMES=()
}

echo "== oversized frames: $seconds s per round, $rate Hz, runs in $out (ROS_DOMAIN_ID=$ROS_DOMAIN_ID)"
round quiet 0
quiet_trainer=$peak_trainer quiet_policy=$peak_policy
round flooded 1
echo
echo "== peak RSS (MB) without the peer, with it, ratio"
awk -v qt="$quiet_trainer" -v ft="$peak_trainer" -v qp="$quiet_policy" -v fp="$peak_policy" 'BEGIN {
  printf "  %-8s %8.1f %8.1f %6.3f\n", "trainer", qt / 1024, ft / 1024, (qt > 0 ? ft / qt : 0)
  printf "  %-8s %8.1f %8.1f %6.3f\n", "policy", qp / 1024, fp / 1024, (qp > 0 ? fp / qp : 0) }'
echo "== the peer"
grep -h '"event"' "$out/flooded/logs/peer.log" | sed 's/^/  /' || true
echo "== the training env's progress (commands the policy sent, the trainer's replay)"
for r in quiet flooded; do
  c=$(sed -n 's/.*sent \([0-9]*\) commands, skipped \([0-9]*\) observations.*/\1 sent, \2 skipped/p' "$out/$r/logs/policy0.log" | tail -n 1)
  p=$(sed -n 's/.*; replay \([0-9]*\)$/\1/p' "$out/$r/logs/trainer.log" | tail -n 1)
  printf '  %-8s policy %s; replay %s\n' "$r" "${c:-?}" "${p:-?}"
done
echo "== what the nodes refused (flooded round)"
grep -h "skipping Observation\|skipped .* observations" "$out/flooded/logs/policy0.log" | sed 's/^/  policy: /' | tail -n 3 || true
grep -h "malformed .* (observations" "$out/flooded/logs/trainer.log" | sed 's/^/  trainer: /' || true
grep -h "malformed .* (observations" "$out/quiet/logs/trainer.log" | sed 's/^/  trainer, quiet round: /' || true
