#!/usr/bin/env bash
# Faults and load (a benchmark, not a test): the suite with N training envs at the reduced CPU config
# for DURATION seconds, with three faults: kill -9 of the trainer at 1/4 (then `--resume` of its run),
# of one sim (/env2) at 1/2 (restarted), and of the recorder at 3/4 (its bag rewritten by `equiarm bag recover`,
# a new recorder started). Prints each process's RSS over time (first, peak, last and the slope over
# the second half, MB/h), the transitions the sims published, the trainer received and its replay
# holds, the updates lost to the trainer kill (at most checkpoint_every), and whether the suite went on
# after each fault. Budgets (docs/architecture.md#memory-budget): sim < 150 MB, policy < 400 MB,
# recorder < 300 MB, trainer < 8 GB.
#
#   bash bench/soak.sh [--duration 3600] [--num-envs 8] [--checkpoint-every 100] [--seed 0] [--out DIR]
#
# Runs in a private network namespace (as root or with unprivileged user namespaces) so its DDS traffic
# stays on this machine's loopback. EQUIARM_BIN: use this binary instead of building.
set -euo pipefail
args=("$@")
duration=3600 num_envs=8 ckpt=100 seed=0 out=""
while [ $# -gt 0 ]; do
  case "$1" in
    --duration) duration=$2; shift 2 ;;
    --num-envs) num_envs=$2; shift 2 ;;
    --checkpoint-every) ckpt=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    -h|--help) sed -n '2,16p' "$0"; exit 0 ;;
    *) echo "soak.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
for v in duration num_envs ckpt seed; do
  [[ ${!v} =~ ^[0-9]+$ ]] || { echo "soak.sh: --${v/ckpt/checkpoint-every} ${!v}: expected a whole number" >&2; exit 2; }
done
[ "$duration" -ge 60 ] || { echo "soak.sh: --duration $duration: at least 60 s (the faults are spread over it)" >&2; exit 2; }
source "$(dirname "$0")/../launch_scripts/lib.sh"
eqa_private_netns "$0" "${args[@]}"
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-61} ROS_LOCALHOST_ONLY=0
cd "$(dirname "$0")/.."
eqa_bin

task=block_pulling
run_dir=${out:-runs/soak-$(date +%Y%m%d-%H%M%S)}
[ -e "$run_dir" ] && { echo "soak.sh: $run_dir exists: choose another --out" >&2; exit 2; }
mkdir -p "$run_dir"
"$EQUIARM_BIN" train --preset reduced --task $task --num-envs "$num_envs" --seed "$seed" --total-updates 1000000 \
  --checkpoint-every "$ckpt" --print-config > "$run_dir/config.json"
image=$(eqa_config_get "$run_dir/config.json" image_size)
arch=(--model "$(eqa_config_get "$run_dir/config.json" model)" --hidden "$(eqa_config_get "$run_dir/config.json" hidden)"
      --image "$image:$(eqa_config_get "$run_dir/config.json" input_size)")
per_env=$(eqa_demos_per_env "$run_dir/config.json" "$num_envs")
pace=(--max-lead 10) trainer_mode=() extra=(--quiet --idle-timeout-s 600)
obs_topics=(/eval/observation:equiarm_msgs/msg/Observation)
for i in $(seq 0 $((num_envs - 1))); do obs_topics+=("/env$i/observation:equiarm_msgs/msg/Observation"); done

eqa_recorded_run "$run_dir" "${obs_topics[@]}"
eqa_suite_trainer trainer
eqa_suite_policies
eqa_suite_sims

# The latest pid started as each name (a restart is started under a new name and replaces the old one).
declare -A current=()
for i in "${!EQA_NAMES[@]}"; do current[${EQA_NAMES[$i]}]=${EQA_PIDS[$i]}; done
rss_kib() { awk '/^VmRSS:/ {print $2}' "/proc/$1/status" 2>/dev/null || true; }
updates() { sed -n 's/.*"charts\/updates": *\([0-9.]*\).*/\1/p' "$run_dir/metrics.jsonl" 2>/dev/null | tail -n 1 | cut -d. -f1; }
restart() { # OLD NEW: NEW replaces OLD in the table of processes
  unset "current[$1]"
  current[$2]=$(eqa_pid "$2")
}
echo "== soak: $num_envs envs, $duration s, run directory $run_dir (ROS_DOMAIN_ID=$ROS_DOMAIN_ID)"
t0=$SECONDS fault=0 lost="" went_on=() victim=$(( num_envs > 2 ? 2 : num_envs - 1 ))
while [ $((SECONDS - t0)) -lt "$duration" ]; do
  sleep 10
  t=$((SECONDS - t0))
  for name in "${!current[@]}"; do
    r=$(rss_kib "${current[$name]}")
    [ -n "$r" ] && echo "$t $name $r" >> "$run_dir/rss.tsv"
  done
  if [ $fault = 0 ] && [ $t -ge $((duration / 4)) ]; then
    u=$(updates); ck=$(cat "$run_dir/checkpoints/latest" 2>/dev/null || echo none)
    eqa_log "fault 1: kill -9 the trainer at $u updates (latest checkpoint $ck)"
    kill -KILL "${current[trainer]}"; sleep 2
    eqa_suite_trainer trainer2 --resume "$run_dir"; restart trainer trainer2
    resumed=$(sed -n 's/.*resumed .* at \([0-9]*\) updates.*/\1/p' "$run_dir/logs/trainer2.log" | head -n 1)
    lost="$((u - ${resumed:-0})) (killed at ~$u, resumed at ${resumed:-?}; checkpoint every $ckpt; updates are logged every 10)"
    fault=1 mark=$u
  elif [ $fault = 1 ] && [ $t -ge $((duration / 2)) ]; then
    u=$(updates); went_on+=("after the trainer kill: updates ${resumed:-?} -> $u")
    eqa_log "fault 2: kill -9 sim$victim"
    kill -KILL "${current[sim$victim]}"; sleep 2
    eqa_suite_sim "$victim" "sim${victim}b"; restart "sim$victim" "sim${victim}b"
    fault=2 mark=$u
  elif [ $fault = 2 ] && [ $t -ge $((duration * 3 / 4)) ]; then
    u=$(updates); went_on+=("after the sim kill: updates $mark -> $u, sim${victim}b ended $(grep -c 'ended after' "$run_dir/logs/sim${victim}b.log" || true) episodes")
    eqa_log "fault 3: kill -9 the recorder; bag recover; a new recorder"
    kill -KILL "${current[recorder]}"; sleep 1
    "$EQUIARM_BIN" bag recover "$run_dir/bag" "$run_dir/bag_recovered" > "$run_dir/logs/recover.log" 2>&1 || true
    eqa_start recorder2 "$run_dir/logs/recorder2.log" "$EQUIARM_BIN" record --all -q -o "$run_dir/bag2" \
      /episodes:equiarm_msgs/msg/EpisodeResult /transitions:equiarm_msgs/msg/Transition "${obs_topics[@]}"
    restart recorder recorder2
    fault=3 mark=$u
  fi
done
u=$(updates); [ $fault = 3 ] && went_on+=("after the recorder kill: updates $mark -> $u")
eqa_log "stopping the suite"
eqa_stop_all
trap - EXIT

echo
echo "== RSS per process (MB): first, peak, last, slope over the second half (MB/h)"
awk -v half=$((duration / 2)) '
  { t=$1; n=$2; r=$3/1024; if (!(n in first)) first[n]=r; last[n]=r; if (r>peak[n]) peak[n]=r
    if (t >= half) { k[n]++; st[n]+=t; sr[n]+=r; stt[n]+=t*t; str[n]+=t*r } }
  END { for (n in first) { s = (k[n] > 1 && k[n]*stt[n]-st[n]^2 > 0) ? (k[n]*str[n]-st[n]*sr[n])/(k[n]*stt[n]-st[n]^2)*3600 : 0
        printf "  %-12s %8.1f %8.1f %8.1f %+9.1f\n", n, first[n], peak[n], last[n], s } }' "$run_dir/rss.tsv" | sort
echo "== transitions"
pub=0; for f in "$run_dir"/logs/sim[0-9]*.log; do n=$(sed -n 's/.*SimStats { steps: \([0-9]*\),.*/\1/p' "$f" | tail -n 1); pub=$((pub + ${n:-0})); done
echo "  published by the training sims that exited cleanly: $pub (a killed sim reports nothing)"
grep -h "received .* transitions" "$run_dir"/logs/trainer*.log | sed 's/^/  /' || true
grep -h "; replay " "$run_dir"/logs/trainer*.log | sed 's/^/  /' || true
echo "== faults"
echo "  updates lost to the trainer kill: ${lost:-none (the run was too short)}"
for w in "${went_on[@]}"; do echo "  $w"; done
grep -h "messages\|skipped\|lost" "$run_dir/logs/recover.log" 2>/dev/null | head -n 5 | sed 's/^/  bag recover: /' || true
[ -d "$run_dir/bag2" ] && "$EQUIARM_BIN" bag info "$run_dir/bag2" | grep -E "^(Files|Messages):" | sed 's/^/  new recorder: /'
echo "== run directory $run_dir"
